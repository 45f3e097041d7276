"""A small problem's path start and dense direct step in one compiled call
(compass_sparse.path.direct_step.dense_direct_path, with the linearization:
NewtonStep.dense_lane) against the path computing them itself (option engine =
"reference"): the same point bits, basis, code and counts."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.linalg.direct as ld
import compass_sparse.generators as gen
from compass_sparse import Options, solve_mcp
from compass_sparse.path.dense_engine import DensePathEngine


# ------------------------------------------- the path's start and direct step in one call
def _covering(M, q, lb, ub, x):
    """r = M z + q - w + v at the components (z, w, v) of x."""
    z = np.clip(x, lb, ub)
    return M @ z + q - np.maximum(z - x, 0.0) + np.maximum(x - z, 0.0)


@pytest.mark.parametrize("seed", range(4))
def test_one_call_path_start_and_dense_direct_step_give_the_paths_results_bit_for_bit(seed):
    """solve_linear_mcp with a dense direct step: the start (components, start basis,
    inward guess, r = 0 test) and the step in one compiled call give what
    PivotalPath.run gives -- the same point bits, basis, code, counts -- in the three
    outcomes (start solves, step solves, step fails and the path runs), with and
    without a warm basis."""
    from compass_sparse.path.linear_mcp import solve_linear_mcp

    seen = set()
    rng = np.random.default_rng(seed)
    for n, structure, bounds in [(1, "banded", "box"), (3, "banded", "mixed"),
                                 (8, "grid", "mixed"), (30, "banded", "mixed")]:
        g = gen.p_matrix_lcp(n, structure, seed, bounds)
        M, q, lb, ub = g.lcp
        M = sp.csc_matrix(M)
        xs = g.solution - (M @ g.solution + q)  # the normal-map point of the solution
        warm = solve_linear_mcp(M, q, lb, ub, DensePathEngine(M), Options(), xs,
                                r=_covering(M, q, lb, ub, xs)).basis
        points = [xs, xs + 1e-6 * rng.standard_normal(n), xs + rng.standard_normal(n),
                  xs + 5.0 * rng.standard_normal(n), np.clip(xs, lb, ub)]
        for x in points:
            for w0 in (None, warm):
                results = []
                for engine in ("auto", "reference"):
                    mgr = DensePathEngine(M)
                    res = solve_linear_mcp(M, q, lb, ub, mgr, Options(engine=engine), x,
                                           warm=w0, r=_covering(M, q, lb, ub, x),
                                           direct=ld.DirectFactors(dense=True))
                    results.append((res, mgr.stats.factorizations))
                (a, fa), (b, fb) = results
                assert a.code is b.code and a.t == b.t
                assert a.pivots == b.pivots and a.factorizations == b.factorizations
                assert fa == fb and a.direct_lu_nnz == b.direct_lu_nnz
                for u, v in ((a.z, b.z), (a.w, b.w), (a.v, b.v),
                             (a.basis.basic, b.basis.basic)):
                    assert np.array_equal(u, v)
                seen.add("path" if a.pivots else "direct" if a.factorizations else "start")
    assert seen == {"path", "direct", "start"}


@pytest.mark.parametrize("family,n,seed", [(1, 10, 1), (2, 10, 1), (2, 10, 2), (1, 50, 3)])
def test_solves_through_the_one_call_direct_step_are_bit_identical(family, n, seed):
    """The whole solve with the one-call step and with engine = "reference" (which also
    runs the major iterations in the Python loop, the same bits: test_nms_routes.py)."""
    from compass_sparse.generators import thesis_family

    fused = solve_mcp(thesis_family(n, family, seed).problem)
    plain = solve_mcp(thesis_family(n, family, seed).problem, options={"engine": "reference"})
    assert fused.routes["nms"] == "compiled" and plain.routes["nms"] == "python"
    assert fused.success and plain.success
    assert np.array_equal(fused.x, plain.x)
    assert (fused.nit, fused.minor_iterations, fused.restarts, fused.nfev, fused.njev) == \
        (plain.nit, plain.minor_iterations, plain.restarts, plain.nfev, plain.njev)
    assert fused.passes["path"].factorizations == plain.passes["path"].factorizations
