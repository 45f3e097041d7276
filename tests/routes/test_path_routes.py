"""The compiled dense engine (compass_sparse.path.dense_engine) against the Python pivot
loop on the dense reference basis (compass_sparse.path.pivotal with basis.dense): the same
algorithm, so the same codes, pivots and points, on random, degenerate, rank-deficient
and infeasible linear MCPs, at the limits, from degenerate start vertices (t below 0, the
pivot budget there, the Lemke ray start, a singular inward guess), and through solve_lcp
and solve_mcp."""

from __future__ import annotations

import numpy as np
import pytest

import compass_sparse.generators as gen
from compass_sparse import MCP, Options, solve_lcp, solve_mcp
from compass_sparse.basis.dense import DenseBasis
from compass_sparse.path.dense_engine import DensePathEngine
from compass_sparse.path.outcome import LinearCode
from compass_sparse.path.pivotal import PivotalPath
from minor_log import pivot_ts


def _both(lcp, x=None, options=None, **kw):
    M, q, lb, ub = lcp
    x = np.clip(np.zeros(q.size), lb, ub) if x is None else x
    opt = options or Options()
    out = []
    for mgr in (DenseBasis, DensePathEngine):
        res = PivotalPath(M, q, lb, ub, mgr(M), opt).run(x, **kw)
        out.append(res)
    return out


def _assert_same_path(py, cc, M, q):
    assert cc.code is py.code, (py.code, cc.code, py.message, cc.message)
    assert cc.message == py.message
    assert cc.pivots == py.pivots
    assert cc.artificials == py.artificials
    assert abs(cc.t - py.t) <= 1e-9
    scale = 1.0 + np.abs(py.z).max(initial=0.0)
    assert np.max(np.abs(cc.z - py.z), initial=0.0) <= 1e-8 * scale
    assert np.array_equal(cc.basis.basic, py.basis.basic)
    assert cc.unbounded == py.unbounded
    if py.unbounded:  # the same ray: base point and direction of z
        assert np.allclose(cc.ray_base, py.ray_base, rtol=1e-8, atol=1e-8)
        assert np.allclose(cc.ray, py.ray, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("structure", ["grid", "banded"])
@pytest.mark.parametrize("bounds", ["ncp", "box", "mixed"])
@pytest.mark.parametrize("n,seed", [(12, 0), (45, 1), (100, 2)])
def test_same_path_as_python_loop_on_p_matrix_lcps(structure, bounds, n, seed):
    g = gen.p_matrix_lcp(n, structure, seed, bounds)
    py, cc = _both(g.lcp)
    _assert_same_path(py, cc, *g.lcp[:2])
    assert cc.code is LinearCode.SOLVED
    assert np.max(np.abs(cc.z - g.solution)) <= 1e-8


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("ray_start", [False, True])
def test_same_path_on_degenerate_and_rank_deficient_lcps(seed, ray_start):
    for g in (gen.obstacle_problem(8, seed, degenerate_fraction=0.5),
              gen.monotone_lcp(30, seed, rank=10),
              gen.duplicated_columns_lcp(40, seed, bounds="mixed")):
        py, cc = _both(g.lcp, ray_start=ray_start)
        _assert_same_path(py, cc, *g.lcp[:2])


@pytest.mark.parametrize("seed", [0, 1])
def test_same_status_on_infeasible_lcp(seed):
    g = gen.infeasible_lcp(20, seed)
    py, cc = _both(g.lcp, ray_start=True)
    _assert_same_path(py, cc, *g.lcp[:2])
    assert cc.code is LinearCode.RAY


def test_same_limits_cycle_and_minor():
    g = gen.p_matrix_lcp(60, "grid", 5, "mixed")
    for opt in (Options(lemke_cycle_limit=1), Options(minor_iteration_limit=3)):
        py, cc = _both(g.lcp, options=opt)
        _assert_same_path(py, cc, *g.lcp[:2])


def test_solves_agree_with_and_without_the_engine(monkeypatch):
    """solve_lcp and solve_mcp give the same statuses and points with the compiled engine
    and with the Python loop on the dense reference basis (option path_basis)."""
    cases = [gen.p_matrix_lcp(40, "banded", 3, "mixed"), gen.obstacle_problem(7, 2),
             gen.duplicated_columns_lcp(30, 1, bounds="box")]
    points = {}
    for basis in ("auto", "dense"):
        opt = {"path_basis": basis}
        points[basis] = []
        for g in cases:
            M, q, lb, ub = g.lcp
            r = solve_lcp(M, q, lb, ub, options=opt)
            assert r.routes["path"] == ("dense engine" if basis == "auto" else "dense basis")
            assert r.success, r.message
            points[basis].append(r.x)
            Md = M.toarray()

            def F(z, Md=Md, q=q):
                return Md @ z + q + 0.1 * z**3 * (z > 0)

            def J(z, Md=Md):
                return Md + np.diag(0.3 * z**2 * (z > 0))

            rm = solve_mcp(MCP(F, J, lb, ub, np.clip(np.zeros(q.size), lb, ub)), options=opt)
            assert rm.success, rm.message
            points[basis].append(rm.x)
    for a, b in zip(points["dense"], points["auto"]):
        assert np.max(np.abs(a - b)) <= 1e-6 * (1 + np.abs(b).max())


@pytest.mark.parametrize("kw", [{"growth_limit": 1.0}, {"stability_tolerance": 0.0},
                                {"growth_limit": 1e300, "stability_tolerance": 1.0}])
def test_same_path_whatever_the_update_safeguards_decline(kw):
    """The Forrest-Tomlin safeguards only choose between an update and a refactorization:
    declining (almost) every update, or none, leaves the path pivot for pivot that of the
    Python loop."""
    for g in (gen.p_matrix_lcp(60, "banded", 4, "mixed"),
              gen.duplicated_columns_lcp(40, 2, bounds="mixed")):
        M, q, lb, ub = g.lcp
        x = np.clip(np.zeros(q.size), lb, ub)
        py = PivotalPath(M, q, lb, ub, DenseBasis(M), Options()).run(x)
        eng = DensePathEngine(M, **kw)
        cc = PivotalPath(M, q, lb, ub, eng, Options()).run(x)
        _assert_same_path(py, cc, M, q)
        if kw.get("growth_limit") == 1.0 and py.pivots > 20:
            assert eng.stats.refactor_by_stability > 0


def _fam2_n10_seed1_linearization():
    """The first linearization of thesis family 2, n = 10, seed 1 at its start z0 (every
    component at a bound; at four of them F pushes inwards, so the start vertex is
    degenerate): M = J(z0), q = F(z0) - M z0, and the normal-map start x (x = z0 - F(z0)
    where F pushes outwards, x = z0 where it pushes inwards)."""
    g = gen.thesis_family(10, family=2, seed=1)
    info = g.info
    lb, ub = np.asarray(info["lb"], float), np.asarray(info["ub"], float)
    z0 = np.clip(np.asarray(info["x0"], float), lb, ub)
    D, A, b = info["D"], np.asarray(info["A"].todense() if hasattr(info["A"], "todense")
                                    else info["A"], float), info["b"]
    f = D * z0 * z0 + A @ z0 + b
    M = A + np.diag(2.0 * D * z0)
    q = f - M @ z0
    x = np.where(((z0 <= lb) & (f > 0)) | ((z0 >= ub) & (f < 0)), z0 - f, z0)
    return M, q, lb, ub, x


def test_first_path_from_a_degenerate_start_vertex_does_not_stop_with_t_at_zero():
    """At this start the first pivots make zero steps and t must go below 0 (PATH's path
    goes to t = -0.97) before it rises to 1.  With t bounded below by 0 the path ended
    after two pivots ("t decreased to 0"): on the second, t (at 2.5e-16) tied with z_1 (at
    its upper bound) and t had the tie priority of t reaching 1.  Both implementations now
    take PATH's 7 pivots and end in a solution of the linear MCP."""
    import scipy.sparse as sps

    M, q, lb, ub, x = _fam2_n10_seed1_linearization()
    Ms = sps.csc_matrix(M)
    py, cc = _both((Ms, q, lb, ub), x=x)
    _assert_same_path(py, cc, Ms, q)
    assert cc.code is LinearCode.SOLVED and cc.pivots == 7
    for res in (py, cc):
        z, w, v = res.z, res.w, res.v
        assert np.all(z >= lb) and np.all(z <= ub) and np.all(w >= 0) and np.all(v >= 0)
        # M z + q = w - v with w_i (z_i - l_i) = 0 and v_i (u_i - z_i) = 0
        scale = 1.0 + np.abs(M @ z).max() + np.abs(q).max()
        assert np.max(np.abs(M @ z + q - w + v)) <= 1e-9 * scale
        assert np.max(np.abs(w * (z - lb))) <= 1e-9 * scale
        assert np.max(np.abs(v * (ub - z))) <= 1e-9 * scale
        f = M @ z + q
        assert np.max(np.abs(z - np.clip(z - f, lb, ub))) <= 1e-9 * scale


def _degenerate_start_lcp():
    """A 3-variable LCP whose start x = (0, 0, 1) is a degenerate vertex (z_0 = w_0 = 0,
    z_1 = w_1 = 0): t enters with a zero step, on the second pivot t alone blocks at 0, and
    the path goes on through t = -2 to t = 1 and the solution z = (0, 3, 0), w = (0, 0, 9)."""
    M = np.array([[1.0, 1.0, -2.0], [1.0, 1.0, 3.0], [1.0, 3.0, 3.0]])
    q = np.array([-3.0, -3.0, 0.0])
    lb, ub = np.zeros(3), np.full(3, np.inf)
    return (M, q, lb, ub), np.array([0.0, 0.0, 1.0])


def test_path_blocked_by_t_at_zero_at_a_degenerate_start_vertex_goes_below_zero_to_t_one():
    """With t >= 0 as a bound this path ended on its second pivot ("t decreased to 0")."""
    lcp, x = _degenerate_start_lcp()
    M, q, lb, ub = lcp
    py, cc = _both(lcp, x=x)
    _assert_same_path(py, cc, M, q)
    assert cc.code is LinearCode.SOLVED and cc.pivots == 4
    for res in (py, cc):
        assert np.allclose(res.z, [0.0, 3.0, 0.0], atol=1e-12)
        assert np.allclose(M @ res.z + q, [0.0, 0.0, 9.0], atol=1e-12)


def test_lemke_ray_start_keeps_t_at_or_above_zero():
    """The ray start never lifts t's bound (its t = 0 is the start at infinity): the same
    path in both implementations, and no point of it below t = 0."""
    lcp, x = _degenerate_start_lcp()
    M, q, lb, ub = lcp
    seen = []
    for mgr in (DenseBasis, DensePathEngine):
        log = []
        path = PivotalPath(M, q, lb, ub, mgr(M), Options(), log=log.append)
        res = path.run(x, ray_start=True)
        assert path.st.t_lower == 0.0 and path.st.below_from == -1
        ts = pivot_ts(log)
        assert ts and min(ts) >= 0.0
        seen.append(res)
    _assert_same_path(*seen, M, q)


@pytest.mark.parametrize("budget,code,pivots", [(1, LinearCode.RAY, 2), (2, LinearCode.RAY, 3),
                                                 (3, LinearCode.SOLVED, 4)])
def test_pivot_budget_below_zero_ends_paths_that_do_not_get_above_zero(monkeypatch, budget,
                                                                       code, pivots):
    """t's bound is lifted on the path's second pivot (pivot count 1) and t gets above 0
    on its fourth: a budget of 1 or 2 pivots ends the path first ("t not above 0", the
    start point returned at t = 0), 3 lets it reach t = 1; both implementations alike."""
    from compass_sparse.path import _kernels as PK

    monkeypatch.setattr(PK, "BELOW_ZERO_PIVOTS", budget)
    lcp, x = _degenerate_start_lcp()
    M, q, lb, ub = lcp
    py, cc = _both(lcp, x=x)
    _assert_same_path(py, cc, M, q)
    assert cc.code is code and cc.pivots == pivots
    if code is LinearCode.RAY:
        assert cc.message == f"t not above 0 after {pivots} pivots" and not cc.unbounded
        assert cc.t == 0.0 and np.array_equal(cc.z, np.clip(x, lb, ub))


@pytest.mark.parametrize("eps,t_progress,code", [
    (1e-10, None, LinearCode.SOLVED), (1e-8, None, LinearCode.RAY),
    (1e-8, 1e-7, LinearCode.SOLVED), (1e-10, 1e-12, LinearCode.RAY)])
def test_t_below_t_progress_is_not_progress_above_zero(monkeypatch, eps, t_progress, code):
    """From x = (0, -eps, 1) the first pivot puts t at eps/3, and t blocks at 0 on the
    third.  At most T_PROGRESS (1e-9) that is not progress: the bound is lifted and the path
    reaches t = 1; above it the path has been above 0 and ends there, as with the
    tolerance moved across eps/3 either way; both implementations alike."""
    from compass_sparse.path import _kernels as PK

    if t_progress is not None:
        monkeypatch.setattr(PK, "T_PROGRESS", t_progress)
    (M, q, lb, ub), _ = _degenerate_start_lcp()
    py, cc = _both((M, q, lb, ub), x=np.array([0.0, -eps, 1.0]))
    _assert_same_path(py, cc, M, q)
    assert cc.code is code, cc.message
    if code is LinearCode.RAY:
        assert cc.message == "t decreased to 0" and cc.pivots <= 3
        assert abs(cc.t - eps / 3.0) <= 1e-3 * eps  # the path's best point
    else:
        assert np.allclose(cc.z, [0.0, 3.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_singular_inward_guess_falls_back_to_the_slack_basis_in_the_engine(seed):
    """A start where the inward guess makes z_i basic on a zero column of M: the guessed
    basis is singular (an artificial repairs it), so the path starts again on the basis
    without the guess.  The engine does this inside its one start call; it gives the
    Python loop's path (same code, pivots, point and basis)."""
    import scipy.sparse as sps

    rng = np.random.default_rng(seed)
    n = 6
    M = rng.standard_normal((n, n)) + n * np.eye(n)
    j = int(rng.integers(n))
    M[:, j] = 0.0  # z_j's column: dependent whenever z_j is basic
    M[j, j] = 0.0
    q = rng.standard_normal(n)
    q[j] = -1.0  # F_j < 0 at z = 0: the residual pushes z_j inwards
    lb, ub = np.zeros(n), np.full(n, np.inf)
    x = np.zeros(n)  # z = 0 at the lower bounds with no slack value: the guess applies
    Ms = sps.csc_matrix(M)
    r = Ms @ x + q
    assert r[j] < 0.0
    py, cc = _both((Ms, q, lb, ub), x=x, r=r)
    _assert_same_path(py, cc, Ms, q)

