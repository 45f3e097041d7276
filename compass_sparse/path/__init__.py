"""The pivotal path: the linear MCP of one major iteration (thesis §3.2-3.3).

``linearize``     the linear MCP at z_k: M = J(z_k) + eps I, q = F(z_k) - M z_k and the
                  covering vector r (:class:`Linearizer`, index maps made once per pattern);
``warm``          the path's start: the components of x and the start basis (warm basis,
                  inward guess);
``pivotal``       :class:`PivotalPath`, the path itself (Python pivot loop on a basis
                  manager: ratio test, complement rule, repair, ray and cycle detection);
``dense_engine``  :class:`DensePathEngine`, the same path in compiled code on a dense LU
                  with Forrest-Tomlin updates, for small problems;
``direct_step``   a path that needs no pivot, found by one solve;
``linear_mcp``    :func:`solve_linear_mcp`: one linear MCP, its shortcuts and its Lemke
                  retry;
``outcome``       :class:`LinearCode`, :class:`PathResult`, :class:`WarmBasis`.

Which basis a path runs on (the dense engine, the dense reference basis or the sparse
basis manager) is chosen once per solve by :mod:`compass_sparse.routes`.
"""
from .linear_mcp import solve_linear_mcp
from .outcome import LinearCode, PathResult, WarmBasis
from .pivotal import PivotalPath
from .warm import components, default_basis, start_basis_with_guess

__all__ = ["LinearCode", "PathResult", "PivotalPath", "WarmBasis", "components",
           "default_basis", "solve_linear_mcp", "start_basis_with_guess"]
