"""Stress tests of the solver's stated tolerances: each one across its useful range.

* convergence_tolerance: the returned point meets it (||Phi||_2 <= tol) on nonlinear
  problems from 1e-4 down to 1e-12;
* pivot_tolerance / ratio_tolerance (the Harris ratio test): degenerate and rank-deficient
  LCPs still solve exactly across 1e-14 .. 1e-6;
* the crash's minimum step and the NMS minimum step: extreme values never produce a wrong
  success.
"""
import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse import generators as gen
from compass_sparse.merit import fb_phi


def _natural(p, x):
    f = p.F_uncounted(x)
    return float(np.max(np.abs(x - np.clip(x - f, p.lb, p.ub))))


@pytest.mark.parametrize("tol", [1e-4, 1e-6, 1e-8, 1e-10, 1e-12])
@pytest.mark.parametrize("seed", [0, 1])
def test_convergence_tolerance_is_met(tol, seed):
    g = gen.structured_quadratic(3000, seed=seed)
    r = cs.solve_mcp(g.problem, options={"convergence_tolerance": tol})
    assert r.success
    phi = fb_phi(r.x, g.problem.F_uncounted(r.x), g.problem.lb, g.problem.ub)
    assert np.linalg.norm(phi) <= tol
    # the natural residual is within a constant factor of ||Phi||_2 (<= 1/(2 - sqrt 2))
    assert _natural(g.problem, r.x) <= tol / (2 - np.sqrt(2)) * (1 + 1e-9)


@pytest.mark.parametrize("pivot_tol", [1e-14, 1e-11, 1e-9, 1e-6])
@pytest.mark.parametrize("ratio_tol", [0.0, 1e-12, 1e-9, 1e-6])
def test_ratio_test_tolerances_on_degenerate_lcps(pivot_tol, ratio_tol):
    opts = {"pivot_tolerance": pivot_tol, "ratio_tolerance": ratio_tol, "crash_method": "none"}
    for maker in (lambda: gen.p_matrix_lcp(200, "banded", seed=3, bounds="mixed",
                                           degenerate_fraction=0.3),
                  lambda: gen.duplicated_columns_lcp(60, 1, bounds="box")):
        g = maker()
        M, q, lb, ub = g.lcp
        r = cs.solve_lcp(M, q, lb, ub, options=opts)
        assert r.success, (pivot_tol, ratio_tol, r.message)
        f = M @ r.x + q
        assert np.max(np.abs(r.x - np.clip(r.x - f, lb, ub))) <= 1e-8


@pytest.mark.parametrize("opts", [
    {"crash_stepsize_minimum": 0.5},
    {"crash_stepsize_minimum": 1e-12},
    {"nms_stepsize_minimum": 0.5},
    {"nms_stepsize_minimum": 1e-14},
    {"gradient_stepsize_minimum": 1e-3},
])
def test_step_minimums_never_give_a_wrong_success(opts):
    for seed in range(3):
        g = gen.thesis_family(30, family=1, seed=seed)
        r = cs.solve_mcp(g.problem, options={**opts, "restart_limit": 3})
        if r.success:
            assert _natural(g.problem, r.x) <= 2e-6
        else:
            assert r.point_status is not cs.PointStatus.SOLUTION
