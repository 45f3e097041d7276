"""Problem generators for compass_sparse: deterministic from a seed, scalable in n, and,
where possible, with a known (manufactured) solution.

Every generator returns a :class:`GeneratedProblem`.  Linear families also carry
``lcp = (M, q, lb, ub)`` (M in CSC form) so that an LCP entry point can take them directly.

Families
--------
* :func:`thesis_family` -- the dense random quadratic families of the COMPASS thesis
  (Tables 4.1 and 4.3); bounded boxes, so a solution exists but is unknown.
* :func:`sparse_quadratic` -- F = D z^2 + A z + b with a random sparse A (k per row).
* :func:`structured_quadratic` -- the same form on grid / banded couplings, scaling to
  n = 1e6, with a manufactured solution.
* :class:`BandedNonlinear`, :func:`tridiagonal_ncp` -- a strongly monotone tridiagonal
  nonlinear F (A z + a sin(z) + 0.1 z^3) and its NCP.
* :func:`p_matrix_lcp`, :func:`monotone_lcp`, :func:`obstacle_problem`,
  :func:`infeasible_lcp`, :func:`duplicated_columns_lcp` -- sparse LCPs; all but the
  infeasible one have manufactured solutions.
* :func:`traffic_equilibrium` -- the Wardrop traffic equilibrium on the Sioux Falls network
  (the GAMS model library's ``traffic``), n = 912 (8 destinations) ... 2452 (all 24).
* :func:`brute_force_lcp` -- enumerate every active set of a tiny box LCP (reference).
* :func:`manufacture`, :func:`manufactured_point` -- turn any F into an MCP with a chosen
  solution (shift F by a constant).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from compass_sparse.problem import MCP


@dataclass
class GeneratedProblem:
    """A generated instance.

    name : short description including the size and seed.
    problem : the :class:`~compass_sparse.problem.MCP`.
    solution : a known solution z* (None when unknown or when none exists).
    info : generator parameters and raw data (family-specific; see each generator).
    lcp : ``(M, q, lb, ub)`` for linear families (F(z) = M z + q, M CSC), else None.
    """

    name: str
    problem: MCP
    solution: np.ndarray | None
    info: dict = field(default_factory=dict)
    lcp: tuple | None = None


from .manufactured import manufacture, manufactured_point, ManufacturedPoint  # noqa: E402
from .thesis import thesis_family  # noqa: E402
from .sparse import (BandedNonlinear, QuadraticF, sparse_quadratic,  # noqa: E402
                     structured_quadratic, tridiagonal_ncp)
from .lcp import (  # noqa: E402
    brute_force_lcp,
    duplicated_columns_lcp,
    infeasible_lcp,
    lcp_problem,
    monotone_lcp,
    obstacle_problem,
    p_matrix_lcp,
)
from .traffic import traffic_equilibrium  # noqa: E402

__all__ = [
    "BandedNonlinear",
    "GeneratedProblem",
    "ManufacturedPoint",
    "QuadraticF",
    "manufacture",
    "manufactured_point",
    "thesis_family",
    "sparse_quadratic",
    "structured_quadratic",
    "p_matrix_lcp",
    "monotone_lcp",
    "obstacle_problem",
    "infeasible_lcp",
    "duplicated_columns_lcp",
    "brute_force_lcp",
    "lcp_problem",
    "traffic_equilibrium",
    "tridiagonal_ncp",
]
