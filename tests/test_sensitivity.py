"""Solution sensitivities dx/dp (implicit function theorem on the active set) against
finite differences of re-solves, on a CGE model and on LCPs, and at degenerate points."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import MCP, solve_lcp, solve_mcp
from compass_sparse.sensitivity import (
    SingularSensitivityError,
    classify,
    sensitivity,
    tangent_predictor,
)

TIGHT = {"convergence_tolerance": 1e-10}


@pytest.fixture(scope="module")
def cge():
    from compass_sparse.generators.cge import static_cge

    # n = 332: above the dense-basis threshold (see benchmarks/batch.md on small models)
    return static_cge(regions=2, sectors=40, households=1, seed=1)


def _cge_problem(model, tariff):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return model.with_shock(tariff=tariff).problem


def _resolve(problem, x0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = solve_mcp(problem.with_start(x0), options=TIGHT)
    assert r.success, r.message
    return r.x


def test_cge_sensitivity_matches_finite_differences_of_resolves(cge):
    p0 = 0.2
    P = _cge_problem(cge, p0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = solve_mcp(P, options=TIGHT)
    assert res.success
    h = 1e-6  # dF/dp at fixed x by central differences of F: error ~1e-10 relative
    G = (_cge_problem(cge, p0 + h).F_uncounted(res.x)
         - _cge_problem(cge, p0 - h).F_uncounted(res.x)) / (2 * h)
    S = res.sensitivity(P, G)
    assert not S.is_degenerate and S.differentiable.all()
    H = 1e-5
    fd = (_resolve(_cge_problem(cge, p0 + H), res.x)
          - _resolve(_cge_problem(cge, p0 - H), res.x)) / (2 * H)
    rel = np.max(np.abs(fd - S.dx[:, 0])) / np.max(np.abs(fd))
    assert rel <= 1e-5, rel
    # the tariff moves the economy: a derivative that is zero would pass trivially
    assert np.max(np.abs(fd)) > 1e-2


def _lcp(n=30, seed=3):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.15, random_state=seed) - sp.random(n, n, density=0.15,
                                                                     random_state=seed + 1)
    M = (A @ A.T + sp.eye(n) * 2.0 + (A - A.T)).tocsc()  # positive definite: a P-matrix
    q0 = rng.normal(size=n)
    D = rng.normal(size=(n, 2))  # two parameters: q(p) = q0 + D p
    return M, q0, D


def test_lcp_sensitivity_matches_finite_differences_of_resolves():
    M, q0, D = _lcp()
    opts = {"convergence_tolerance": 1e-12}
    res = solve_lcp(M, q0, options=opts)
    assert res.success
    P = MCP(lambda z: M @ z + q0, lambda z: M, 0.0, np.inf, res.x)
    inact, act, deg, _ = classify(res.x, M @ res.x + q0, P.lb, P.ub, M)
    assert deg.size == 0 and inact.size > 0 and act.size > 0  # both kinds of index
    S = sensitivity(P, res.x, D)
    H = 1e-6
    for j in range(2):
        xp = solve_lcp(M, q0 + H * D[:, j], options=opts).x
        xm = solve_lcp(M, q0 - H * D[:, j], options=opts).x
        fd = (xp - xm) / (2 * H)
        assert np.max(np.abs(fd - S.dx[:, j])) <= 1e-5 * np.max(np.abs(fd))
    assert np.all(S.dx[act] == 0.0)


def _deg_problem(q):
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    return M, MCP(lambda z: M @ z + q, lambda z: M, 0.0, np.inf, np.zeros(2))


def test_degenerate_point_reports_one_sided_derivatives_matching_resolves():
    # z0 _|_ 2 z0 + z1 - p, z1 _|_ z0 + 2 z1 + 1: at p = 0, z = 0 and F_0 = 0 (degenerate);
    # z0(p) = max(p, 0) / 2, so d+ = (1/2, 0) and d- = (0, 0).
    M, P = _deg_problem(np.array([0.0, 1.0]))
    S = sensitivity(P, np.zeros(2), np.array([-1.0, 0.0]))
    assert S.is_degenerate and list(S.degenerate) == [0]
    assert not S.differentiable[0]
    h = 1e-6
    z = {s: solve_lcp(M, np.array([-s * h, 1.0]), options={"convergence_tolerance": 1e-14}).x
         for s in (+1, -1)}
    np.testing.assert_allclose(S.dx[:, 0], z[1] / h, atol=1e-8)
    np.testing.assert_allclose(S.dx_minus[:, 0], -z[-1] / h, atol=1e-8)
    np.testing.assert_allclose(S.dx[:, 0], [0.5, 0.0], atol=1e-10)
    np.testing.assert_allclose(S.dx_minus[:, 0], [0.0, 0.0], atol=1e-10)


def test_degenerate_point_is_differentiable_in_a_parameter_that_keeps_the_active_set():
    # The same degenerate point; moving q_1 (strongly active row) leaves z = 0 both ways.
    _, P = _deg_problem(np.array([0.0, 1.0]))
    S = sensitivity(P, np.zeros(2), np.array([0.0, 1.0]))
    assert S.is_degenerate and S.differentiable[0]
    np.testing.assert_array_equal(S.dx[:, 0], 0.0)


def test_active_tol_decides_whether_a_near_bound_index_is_degenerate():
    # z = 1e-5 solves z _|_ z - 1e-5: interior at the default tolerance, degenerate at 1e-4.
    P = MCP(lambda z: z - 1e-5, lambda z: np.eye(1), 0.0, np.inf, np.zeros(1))
    x = np.array([1e-5])
    S = sensitivity(P, x, np.array([-1.0]))
    assert not S.is_degenerate and S.dx[0, 0] == pytest.approx(1.0)
    S = sensitivity(P, x, np.array([-1.0]), active_tol=1e-4)
    assert S.is_degenerate
    assert S.dx[0, 0] == pytest.approx(1.0) and S.dx_minus[0, 0] == pytest.approx(0.0)


def test_singular_inactive_jacobian_raises_singular_sensitivity_error():
    # z0 + z1 = 1 twice: a continuum of interior solutions, no derivative.
    J = np.ones((2, 2))
    P = MCP(lambda z: J @ z - 1.0, lambda z: J, 0.0, np.inf, np.zeros(2))
    with pytest.raises(SingularSensitivityError, match="singular"):
        sensitivity(P, np.array([0.5, 0.5]), np.array([1.0, 0.0]))


def test_tangent_predictor_error_is_second_order_in_the_parameter_step(cge):
    x0 = _resolve(_cge_problem(cge, 0.1), cge.benchmark)
    errs = []
    for step in (0.02, 0.04):
        P = _cge_problem(cge, 0.1 + step)
        xs = _resolve(P, x0)
        xp = tangent_predictor(P, x0)
        errs.append((np.linalg.norm(xp - xs), np.linalg.norm(x0 - xs)))
    for e_pred, e_plain in errs:
        assert e_pred < 0.1 * e_plain
    # doubling the step multiplies the predictor's error by about four
    assert 2.5 < errs[1][0] / errs[0][0] < 6
