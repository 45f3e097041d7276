"""The probability-one homotopy pass (compass_sparse.homotopy): the smoothed projection,
path tracking to a solution where the stabilized Newton method stalls at a stationary
point of its merit function, the divergence and time-limit statuses, and the pass table."""
import copy

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.homotopy as hom
from compass_sparse import MCP, Options, solve_mcp
from compass_sparse.generators import thesis_family
from compass_sparse.homotopy import HomotopyStatus, SmoothedNormalMap, track_paths
from compass_sparse.merit import fb_gradient, fb_phi, natural_residual
from compass_sparse.result import Status


def _quadratic(D, A, b):
    D, A, b = (np.asarray(v, dtype=float) for v in (D, A, b))

    def F(x):
        return D * x * x + A @ x + b

    def J(x):
        return sp.csc_matrix(np.diag(2.0 * D * x) + A)

    return F, J


# A one-dimensional MCP on the box [-3.04, 3.18] with F(x) = 0.27 x^2 - 0.69 x - 5.68 < 0
# on the whole box: its only solution is the upper bound.  The merit function has a
# stationary point over the box at the lower bound (F decreases there, so the Newton
# model pushes the wrong way and no descent direction stays in the box).
STATIONARY = dict(D=[0.27], A=[[-0.69]], b=[-5.68], lb=[-3.04], ub=[3.18], x0=[-2.9])


def _stationary_problem():
    d = STATIONARY
    F, J = _quadratic(d["D"], d["A"], d["b"])
    return F, J, np.array(d["lb"]), np.array(d["ub"]), np.array(d["x0"])


def _projected_gradient(F, J, z, lb, ub):
    f = F(z)
    g = fb_gradient(z, f, J(z), lb, ub, fb_phi(z, f, lb, ub))
    return z - np.clip(z - g, lb, ub)


def test_nms_stalls_at_a_stationary_point_where_the_homotopy_reaches_the_solution():
    F, J, lb, ub, x0 = _stationary_problem()
    stalled = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "off", "restart_limit": 0})
    assert not stalled.success
    assert stalled.residual.fb_norm > 0.1
    # ... at a stationary point of the merit function over the box, not a solution:
    assert np.linalg.norm(_projected_gradient(F, J, stalled.x, lb, ub)) <= 1e-8
    assert natural_residual(stalled.x, F(stalled.x), lb, ub) > 0.1

    res = solve_mcp(F, J, lb, ub, x0, options={"restart_limit": 0})
    assert res.success and res.status is Status.SOLVED
    assert natural_residual(res.x, F(res.x), lb, ub) <= 1e-6
    assert res.x == pytest.approx(ub, abs=1e-6)  # the unique solution
    h = res.passes["homotopy"]
    assert h.ran and h.iterations > 0 and h.factorizations > 0 and h.time > 0


def test_homotopy_alone_reaches_the_solution_of_the_stationary_problem():
    F, J, lb, ub, x0 = _stationary_problem()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert res.success
    assert natural_residual(res.x, F(res.x), lb, ub) <= 1e-6
    assert res.nit == 1  # the homotopy pass alone: no Newton iteration of NMS ran
    assert [h.step for h in res.history] == ["", "-H"]


@pytest.mark.parametrize("family,n,seed", [(1, 30, 0), (2, 20, 1)])
def test_homotopy_alone_solves_thesis_instances(family, n, seed):
    g = thesis_family(n, family, seed=seed)
    res = solve_mcp(g.problem, options={"homotopy": "only"})
    assert res.success, res.message
    info = g.info
    f = info["D"] * res.x ** 2 + info["A"] @ res.x + info["b"]
    assert natural_residual(res.x, f, info["lb"], info["ub"]) <= 1e-6


def _diverging_problem(n=2):
    # F(x) = -x on free variables: the solution is 0, but the zero curve of
    # H = lam (-x) + (1 - lam)(x - a) is x = (1 - lam) a / (1 - 2 lam), unbounded at lam = 1/2.
    def F(x):
        return -x

    def J(x):
        return -sp.identity(x.size, format="csc")

    return F, J, np.full(n, -np.inf), np.full(n, np.inf), np.ones(n)


def test_path_divergence_is_reported_with_its_status():
    F, J, lb, ub, x0 = _diverging_problem()
    ev = MCP(F, J, lb, ub, x0).evaluator
    seen = []
    out = track_paths(ev, lb, ub, x0, Options(homotopy_path_limit=2),
                      on_point=lambda z, f, phi, psi: seen.append(psi),
                      rng=np.random.default_rng(0))
    assert out.status is HomotopyStatus.DIVERGED
    assert out.path_status == [HomotopyStatus.DIVERGED] * 2
    assert out.lam == pytest.approx(0.5, abs=1e-3)  # where (1 - 2 lam) vanishes
    # the best point is kept: the lowest merit seen on the paths
    assert out.z is not None and 0.5 * np.sum(F(out.z) ** 2) == pytest.approx(min(seen))


def test_solve_reports_a_diverged_homotopy_as_no_progress_with_the_best_point():
    F, J, lb, ub, x0 = _diverging_problem()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert res.status is Status.NO_PROGRESS and not res.success
    assert "diverged" in res.message
    assert res.passes["homotopy"].reason.startswith("diverged")
    assert res.residual.fb_norm <= np.linalg.norm(F(x0))  # never worse than the start


def test_homotopy_time_limit_status_keeps_the_best_point(monkeypatch):
    # The deadline passes after 5 path steps (a clock that cannot depend on the machine's
    # speed: 0.05 s was enough to solve this instance on a quiet machine).
    calls = {"n": 0}

    def check_time(self):
        calls["n"] += 1
        if calls["n"] > 5:
            raise hom._Stop(HomotopyStatus.TIME_LIMIT, "time limit reached on the path")

    monkeypatch.setattr(hom._Tracker, "_check_time", check_time)
    g = thesis_family(60, 1, seed=3)
    start = solve_mcp(g.problem, options={"major_iteration_limit": 0})
    res = solve_mcp(g.problem, options={"homotopy": "only"})
    assert res.status is Status.TIME_LIMIT and not res.success
    assert res.x.shape == (60,) and np.all(np.isfinite(res.x))
    assert res.residual.fb_norm <= start.residual.fb_norm  # the best point, kept
    h = res.passes["homotopy"]
    assert h.ran and h.reason.startswith("time limit") and h.iterations >= 1


def test_a_solve_stopped_before_the_homotopy_says_so():
    g = thesis_family(60, 1, seed=3)
    res = solve_mcp(g.problem, options={"time_limit": 1e-9})
    assert res.status is Status.TIME_LIMIT
    assert res.passes["homotopy"].reason == "not reached (time_limit)"


def test_pass_table_says_why_the_homotopy_did_not_run():
    F, J = _quadratic([0.0, 0.0], [[2.0, 0.0], [0.0, 3.0]], [-1.0, 1.0])
    res = solve_mcp(F, J, 0.0, np.inf, [1.0, 1.0])
    assert res.success
    h = res.passes["homotopy"]
    assert not h.ran and h.reason == "NMS did not stall"
    off = solve_mcp(F, J, 0.0, np.inf, [1.0, 1.0], options={"homotopy": "off"})
    assert off.passes["homotopy"].reason == "homotopy off"


# ------------------------------------------------------------------ the smoothed projection
@pytest.mark.parametrize("mu", [1e-1, 1e-4, 1e-8])
def test_smoothed_projection_tends_to_the_projection_with_error_at_most_mu(mu):
    lb = np.array([-1.0, -1.0, -np.inf, -np.inf, 0.0])
    ub = np.array([2.0, np.inf, 3.0, np.inf, 0.0])
    sm = SmoothedNormalMap(lb, ub)
    rng = np.random.default_rng(0)
    for x in list(rng.uniform(-5, 5, (50, 5))) + [np.array([-1e12, 1e12, 1e12, -1e12, 1.0])]:
        p, dx, dmu = sm.project(x, mu)
        # |s_mu(r) - max(r, 0)| <= mu, and both bounds contribute at most mu each
        assert np.all(np.abs(p - np.clip(x, lb, ub)) <= 2 * mu + 1e-12 * np.abs(x))
        assert np.all((dx >= 0) & (dx <= 1))
        assert np.all(np.isfinite(dmu))


def test_smoothed_projection_derivatives_match_finite_differences():
    lb = np.array([-1.0, -1.0, -np.inf, -np.inf])
    ub = np.array([2.0, np.inf, 3.0, np.inf])
    sm = SmoothedNormalMap(lb, ub)
    x = np.array([-0.9, 0.3, 2.95, 7.0])
    mu, h = 0.05, 1e-7
    p, dx, dmu = sm.project(x, mu)
    fd_x = (sm.project(x + h, mu)[0] - sm.project(x - h, mu)[0]) / (2 * h)
    fd_mu = (sm.project(x, mu + h)[0] - sm.project(x, mu - h)[0]) / (2 * h)
    assert dx == pytest.approx(fd_x, rel=1e-6, abs=1e-8)
    assert dmu == pytest.approx(fd_mu, rel=1e-6, abs=1e-8)


@pytest.mark.parametrize("mu", [1.0, 1e-3, 1e-8, 0.0, 1e-200, 1e200])
def test_compiled_smoothed_projection_gives_the_array_formulas_bits(mu):
    lb = np.array([-1.0, -1.0, -np.inf, -np.inf, 0.0, 2.0])
    ub = np.array([2.0, np.inf, 3.0, np.inf, 0.0, 2.0])
    sm = SmoothedNormalMap(lb, ub)
    rng = np.random.default_rng(1)
    xs = list(rng.uniform(-5, 5, (100, 6))) + [np.array([-1e12, 1e12, 1e12, -1e12, 1.0, 2.0]),
                                                np.array([-1.0, -1.0, 3.0, 0.0, 0.0, 2.0])]
    for x in xs:
        for got, ref in zip(sm.project(x, mu), sm.project_arrays(x, mu)):
            assert np.array_equal(got, ref)


def test_dense_end_game_and_bordered_factors_match_the_sparse_route(monkeypatch):
    """The dense route (compiled dense copy of J, LAPACK's getrf/getrs called directly)
    follows the same path as the sparse one on a problem that needs the homotopy."""
    F, J, lb, ub, x0 = _stationary_problem()
    dense = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    monkeypatch.setattr(hom, "DENSE_MAX_N", 0)
    monkeypatch.setattr(hom, "DENSE_DENSITY", 2.0)
    sparse = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert dense.success and sparse.success
    assert dense.residual.natural <= 1e-6
    assert dense.x == pytest.approx(sparse.x, abs=1e-8)
    assert dense.passes["homotopy"].iterations == sparse.passes["homotopy"].iterations


def test_sparse_bordered_solve_follows_the_same_path_as_the_dense_one(monkeypatch):
    g = thesis_family(15, 1, seed=2)
    dense = solve_mcp(g.problem, options={"homotopy": "only"})
    monkeypatch.setattr(hom, "DENSE_MAX_N", 0)
    monkeypatch.setattr(hom, "DENSE_DENSITY", 2.0)
    sparse = solve_mcp(thesis_family(15, 1, seed=2).problem, options={"homotopy": "only"})
    assert dense.success and sparse.success
    assert sparse.x == pytest.approx(dense.x, abs=1e-5)
    assert sparse.passes["homotopy"].iterations == pytest.approx(
        dense.passes["homotopy"].iterations, rel=0.2)


@pytest.mark.parametrize("tol", [1e-4, 1e-8, 1e-10])
def test_homotopy_meets_each_convergence_tolerance(tol):
    F, J, lb, ub, x0 = _stationary_problem()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only",
                                               "convergence_tolerance": tol})
    assert res.success and res.residual.fb_norm <= tol


def test_homotopy_options_are_validated():
    from compass_sparse.exceptions import OptionError

    with pytest.raises(OptionError):
        Options(homotopy="sometimes")
    with pytest.raises(OptionError):
        Options(homotopy_end_lambda=1.5)
    with pytest.raises(OptionError):
        Options(homotopy_smoothing=0.0)


def test_tight_path_tracking_reaches_the_same_solution(monkeypatch):
    # CORRECTOR_TOLERANCE only decides how closely the path is followed; a 1e4 times
    # tighter value must follow the same curve to the same end point (the stationary
    # problem's unique solution, and the same solution of a thesis instance).
    F, J, lb, ub, x0 = _stationary_problem()
    g = thesis_family(25, 2, seed=4)
    loose = [solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"}),
             solve_mcp(g.problem, options={"homotopy": "only"})]
    monkeypatch.setattr(hom, "CORRECTOR_TOLERANCE", hom.CORRECTOR_TOLERANCE * 1e-4)
    tight = [solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"}),
             solve_mcp(thesis_family(25, 2, seed=4).problem, options={"homotopy": "only"})]
    for a, b in zip(loose, tight):
        assert a.success and b.success
        assert a.x == pytest.approx(b.x, abs=1e-6)
        assert b.passes["homotopy"].iterations >= a.passes["homotopy"].iterations


def test_corrector_accepts_tiny_steps_from_a_base_point_on_the_curve_to_tracking_accuracy():
    # The accepted points are on the curve only to CORRECTOR_TOLERANCE; a first correction
    # of that size must not reject a tiny step (it once rejected every step down to 1e-9
    # and ended paths of family 2 at n = 500 as "step too small").
    F, J, lb, ub, x0 = _stationary_problem()
    ev = MCP(F, J, lb, ub, x0).evaluator
    tr = hom._Tracker(ev, lb, ub, Options(), deadline=None, on_point=None, tol=1e-12, log=None)
    a = x0.copy()
    y = np.append(a, 0.3)
    for _ in range(30):  # Newton in x at fixed lam: onto the curve ...
        H, Hx, Hlam = tr.residual(y, a, True)
        y[:-1] += np.linalg.solve(Hx, -H)
    assert np.linalg.norm(tr.residual(y, a, False)[0]) <= 1e-12
    y[:-1] += 0.5 * hom.CORRECTOR_TOLERANCE  # ... then off it by half the tolerance
    H, Hx, Hlam = tr.residual(y, a, True)
    v = np.array([0.0, 1.0])
    Bf = tr.factor(Hx, Hlam, v)
    tau = Bf.solve(np.array([0.0, 1.0]))
    tau /= np.linalg.norm(tau)
    tr._y = y
    out, ok = tr._correct(y + 1e-9 * tau, a, Bf, v)
    assert ok
    yc = out[0]
    assert np.linalg.norm(tr.residual(yc, a, False)[0]) <= 1e-6


def test_pass_table_names_the_stop_that_ended_the_homotopy():
    F, J, lb, ub, x0 = _stationary_problem()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert res.passes["homotopy"].reason == "stopped on the path: solution found"


def test_step_limit_ends_every_path_with_its_status():
    g = thesis_family(20, 2, seed=1)
    res = solve_mcp(g.problem, options={"homotopy": "only", "homotopy_step_limit": 2,
                                        "homotopy_path_limit": 2})
    assert not res.success and res.status is Status.NO_PROGRESS
    h = res.passes["homotopy"]
    assert h.reason.startswith("step limit") and "(2 paths, 4 steps" in h.reason


def test_a_smaller_divergence_bound_stops_the_path_earlier():
    F, J, lb, ub, x0 = _diverging_problem()
    ev = MCP(F, J, lb, ub, x0).evaluator
    lams = []
    for bound in (1e2, 1e4):
        out = track_paths(ev, lb, ub, x0, Options(homotopy_path_limit=1,
                                                  homotopy_divergence_bound=bound),
                          rng=np.random.default_rng(0))
        assert out.status is HomotopyStatus.DIVERGED
        lams.append(out.lam)
    # x = (1 - lam) a / (1 - 2 lam) passes 1e2 (1 + |a|) before 1e4 (1 + |a|)
    assert lams[0] < lams[1] < 0.5


def test_end_game_from_the_end_of_the_path_only_still_solves():
    F, J, lb, ub, x0 = _stationary_problem()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only", "homotopy_end_lambda": 1.0})
    assert res.success


@pytest.mark.parametrize("route", ["compiled", "arrays"])
def test_a_non_finite_correction_shortens_the_step_instead_of_failing_the_solve(
        monkeypatch, route):
    # _Bordered.solve raises on a non-finite solution; in the corrector that once escaped
    # the pass.  Every third corrector solve fails here (the tangent's right-hand side is
    # e_{n+1}): the pass must carry on with shorter steps.  A dense problem's corrector
    # solves in the compiled chord step (-1 for a non-finite correction), the array route
    # through _Bordered.solve.
    calls = {"n": 0}
    # (the Python route's dense corrector: the compiled tracker calls chord_step inside
    # compiled code, test_compiled_tracker_carries_on_past_rejected_corrector_points)
    monkeypatch.setattr(hom, "COMPILED_TRACKER", False)
    if route == "compiled":
        chord = hom.chord_step

        def flaky(*args):
            calls["n"] += 1
            return -1.0 if calls["n"] % 3 == 0 else chord(*args)

        monkeypatch.setattr(hom, "chord_step", flaky)
    else:
        solve = hom._Bordered.solve

        def flaky(self, b):
            if b[-1] == 1.0 and not np.any(b[:-1]):
                return solve(self, b)
            calls["n"] += 1
            if calls["n"] % 3 == 0:
                raise np.linalg.LinAlgError("non-finite solution of the bordered system")
            return solve(self, b)

        monkeypatch.setattr(hom, "_floats", lambda *args: False)
        monkeypatch.setattr(hom._Bordered, "solve", flaky)
    F, J, lb, ub, x0 = _stationary_problem()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert calls["n"] >= 3
    assert res.x.shape == (1,) and res.passes["homotopy"].ran
    assert res.success or res.status is Status.NO_PROGRESS


@pytest.mark.parametrize("mu", [1e-300, 1e300])
def test_extreme_homotopy_smoothing_does_not_turn_the_smoothed_projection_into_nan(mu):
    # mu^2 underflowed to 0 below 1e-154 (0/0 where x sits on a bound) and overflowed above
    # 1e154: the path then ended on NaN with numpy warnings.  Both ends of the option's
    # range now give the same projection as a moderate mu would in the limit.
    import warnings

    lb, ub = np.array([0.0, -1.0, -np.inf]), np.array([np.inf, 1.0, 2.0])
    x = np.array([0.0, 1.0, -3.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        p, dx, dmu = SmoothedNormalMap(lb, ub).project(x, mu)
    assert np.all(np.isfinite(p)) and np.all(np.isfinite(dx)) and np.all(np.isfinite(dmu))
    assert np.all((lb <= p) & (p <= ub))
    if mu < 1:  # the smoothing vanishes: the projection itself
        np.testing.assert_allclose(p, np.clip(x, lb, ub), atol=1e-12)


# ------------------------------------------------------------------ when the pass is entered
def test_homotopy_after_restarts_default_depends_on_whether_its_systems_are_dense():
    """None (the default): 0 where the homotopy factors densely (n <= 300, or nnz(J) >=
    0.1 n^2), 3 -- after PATH's three restart configurations -- on larger sparse
    problems; an explicit value is kept.  Both sides of both bounds."""
    from compass_sparse.options import HOMOTOPY_DENSE_DENSITY, HOMOTOPY_DENSE_MAX_N

    assert (HOMOTOPY_DENSE_MAX_N, HOMOTOPY_DENSE_DENSITY) == (hom.DENSE_MAX_N,
                                                              hom.DENSE_DENSITY)
    o = Options()
    assert o.homotopy_after_restarts is None
    n = HOMOTOPY_DENSE_MAX_N
    assert o.restarts_before_homotopy(n, 3 * n) == 0
    assert o.restarts_before_homotopy(n + 1, 3 * (n + 1)) == 3
    m = 1000
    dense_nnz = int(np.ceil(HOMOTOPY_DENSE_DENSITY * m * m))
    assert o.restarts_before_homotopy(m, dense_nnz) == 0
    assert o.restarts_before_homotopy(m, dense_nnz - 1) == 3
    assert Options(homotopy_after_restarts=2).restarts_before_homotopy(10, 10) == 2
    assert Options(homotopy_after_restarts=0).restarts_before_homotopy(10**5, 10**5) == 0


@pytest.mark.parametrize("where", ["best", "start"])
def test_homotopy_start_option_picks_the_first_paths_start(where, monkeypatch):
    """homotopy_start = 'best' hands the homotopy the best point NMS found before it
    stalled, 'start' the start point; both solve the instance (thesis family 2, n = 10,
    seed 4: its best point is not the start point.  Seed 5 served until the crash stopped
    before steps that raise ||Phi||: its NMS now finds no point better than the start
    before the homotopy)."""
    seen = []
    real = hom.homotopy_pass

    def spy(solver, z_start, **kw):
        seen.append((np.array(z_start, copy=True), solver.best.z.copy(), kw.get("center")))
        return real(solver, z_start, **kw)

    monkeypatch.setattr(hom, "homotopy_pass", spy)
    prob = thesis_family(10, 2, 4).problem
    res = solve_mcp(prob, options={"homotopy_start": where})
    assert res.success and natural_residual(res.x, prob.F(res.x), prob.lb, prob.ub) <= 1e-6
    assert len(seen) == 1
    z_start, best, center = seen[0]
    assert not np.array_equal(best, prob.x0)  # the two choices differ on this instance
    np.testing.assert_array_equal(z_start, best if where == "best" else prob.x0)
    np.testing.assert_array_equal(center, prob.x0)  # later paths: around the start point


def test_later_homotopy_paths_start_at_random_points_around_the_center(monkeypatch):
    """track_paths: path 1 from z_start, paths 2 and 3 from random points of the box drawn
    around ``center`` (a one-step limit ends every path)."""
    g = thesis_family(10, 2, 1)
    p = g.problem
    starts, centers = [], []
    follow, draw = hom._Tracker.follow, hom.random_point

    def spy_follow(self, a, polish=None):
        starts.append(a.copy())
        return follow(self, a, polish=polish)

    def spy_draw(rng, z0, lb, ub):
        centers.append(np.array(z0, copy=True))
        return draw(rng, z0, lb, ub)

    monkeypatch.setattr(hom._Tracker, "follow", spy_follow)
    monkeypatch.setattr(hom, "random_point", spy_draw)
    z1 = np.clip(p.x0 + 0.5, p.lb, p.ub)
    out = track_paths(p.evaluator, p.lb, p.ub, z1, Options(homotopy_step_limit=1),
                      center=p.x0, rng=np.random.default_rng(0))
    assert out.paths == 3 and len(starts) == 3 and len(centers) == 2
    np.testing.assert_array_equal(starts[0], z1)
    for c in centers:
        np.testing.assert_array_equal(c, p.x0)
    assert not any(np.array_equal(s, z1) or np.array_equal(s, p.x0) for s in starts[1:])


def test_small_problem_enters_the_homotopy_at_its_first_stall():
    """billups from 0: NMS stalls at a local minimizer of the merit function.  By default
    the homotopy follows at once (no restart, each of which stalled at the same point);
    with homotopy_after_restarts = 3, PATH's three restarts come first.  Both solve it."""
    F = lambda x: np.array([(x[0] - 1.0) ** 2 - 1.01])  # noqa: E731
    J = lambda x: np.array([[2.0 * (x[0] - 1.0)]])  # noqa: E731
    first = solve_mcp(F, J, 0.0, np.inf, np.zeros(1))
    late = solve_mcp(F, J, 0.0, np.inf, np.zeros(1),
                     options={"homotopy_after_restarts": 3})
    for r in (first, late):
        assert r.success and abs(r.x[0] - (1.0 + np.sqrt(1.01))) <= 1e-6
        assert r.passes["homotopy"].ran
    assert first.restarts == 0 and late.restarts == 3
    assert first.nit < late.nit  # (the restarts repeat points: F evaluations are memo hits)


@pytest.mark.parametrize("n,family,seed", [(1, 1, 0), (7, 2, 1), (30, 1, 2)])
def test_compiled_homotopy_values_and_bordered_matrix_give_the_array_expressions_bits(
        monkeypatch, n, family, seed):
    """_Tracker.residual's dense route (the map's values and the bordered matrix in one
    compiled pass each) against its array expressions, at points along lam in [0, 1]:
    H, H_x and H_lam bit for bit, and the factors of the bordered matrix too."""
    g = thesis_family(n, family, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    a = np.clip(rng.normal(size=n), p.lb, p.ub)

    def pieces(arrays):
        with monkeypatch.context() as m:
            if arrays:
                m.setattr(hom, "_floats", lambda *args: False)
            tr = hom._Tracker(p.evaluator, p.lb, p.ub, Options(), deadline=None,
                              on_point=None, tol=1e-12, log=None)
            out = []
            for lam in (0.0, 0.3, 0.999, 1.0):
                y = np.append(a + rng.normal(scale=0.1, size=n), lam)
                H, Hx, Hlam = tr.residual(y, a, True)
                v = rng.normal(size=n + 1)
                out.append((H.copy(), np.array(Hx), np.array(Hlam)))
                out.append(tr.factor(Hx, Hlam, v).lu)
            return out

    state = rng.bit_generator.state
    compiled = pieces(False)
    rng.bit_generator.state = state
    reference = pieces(True)
    for got, ref in zip(compiled, reference):
        for u, w in zip(got, ref):
            assert np.array_equal(u, w)


# ------------------------------------------------------------------ compiled dense steps
@pytest.mark.parametrize("m", [1, 2, 7, 40])
def test_compiled_lu_solve_agrees_with_lapack_getrs(m):
    """lu_solve on getrf's factors (row interchanges included) against LAPACK's getrs, to
    rounding; a non-finite solution is reported."""
    import scipy.linalg as sla

    from compass_sparse._homotopy_kernels import lu_solve

    rng = np.random.default_rng(m)
    for _ in range(5):
        B = np.asfortranarray(rng.normal(size=(m, m)))
        lu, piv, info = hom._getrf(B.copy(order="F"), overwrite_a=True)
        assert info == 0
        b = rng.normal(size=m)
        x = b.copy()
        assert lu_solve(lu, piv, x)
        ref = sla.lu_solve((lu, piv), b)
        np.testing.assert_allclose(x, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
        np.testing.assert_allclose(B @ x, b, atol=1e-9 * (1 + np.abs(b).max()))
    lu[-1, -1] = 0.0  # a zero pivot: the solution overflows
    assert not lu_solve(lu, piv, np.ones(m))


@pytest.mark.parametrize("n,family,seed", [(1, 1, 0), (7, 2, 1), (30, 1, 2)])
def test_compiled_tangent_and_chord_steps_agree_with_the_array_route(monkeypatch, n, family,
                                                                     seed):
    """The dense route's tangent (unit_tangent) and corrector (chord_correction around F)
    against the array route (_Bordered.solve, residual): the same tangent, turning flag,
    corrected point and step factor to rounding, at points along lam in (0, 1)."""
    g = thesis_family(n, family, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    a = np.clip(rng.normal(size=n), p.lb, p.ub)
    tr = hom._Tracker(p.evaluator, p.lb, p.ub, Options(), deadline=None, on_point=None,
                      tol=1e-12, log=None)
    compared = 0
    for lam in (0.05, 0.2, 0.4, 0.6):
        y = np.append(a + rng.normal(scale=0.1, size=n), lam)
        for _ in range(30):  # Newton in x at fixed lam: onto the curve
            H, Hx, Hlam = tr.residual(y, a, True)
            y[:-1] += np.linalg.solve(Hx, -H)
        v = rng.normal(size=n + 1)
        v /= np.linalg.norm(v)
        H, Hx, Hlam = tr.residual(y, a, True)
        Bf = tr.factor(Hx, Hlam, v)
        tau, turned = tr._tangent(Bf, v)
        e = np.zeros(n + 1)
        e[-1] = 1.0
        w = Bf.solve(e)
        ref = w / np.linalg.norm(w) * (1.0 if w @ v >= 0 else -1.0)
        np.testing.assert_allclose(tau, ref, rtol=1e-10, atol=1e-12)
        assert turned == int(ref[-1] * v[-1] < 0)
        tr._y = y
        yp = y + 1e-3 * tau
        fast = tr._correct(yp, a, Bf, v)
        with monkeypatch.context() as mp:
            mp.setattr(hom, "_floats", lambda *args: False)
            slow = tr._correct(yp, a, Bf, v)
        assert fast[1] == slow[1]
        if fast[1]:
            compared += 1
            np.testing.assert_allclose(fast[0][0], slow[0][0], rtol=1e-10, atol=1e-12)
            assert abs(fast[0][1] - slow[0][1]) <= 1e-8 * abs(slow[0][1])
    assert compared >= 2


@pytest.mark.parametrize("n,lam", [(1, 0.3), (7, 0.999), (30, 1.0), (12, 1.2)])
def test_chord_step_is_the_correction_then_the_next_smoothed_projection_bit_for_bit(n, lam):
    """chord_step (one call per chord iteration of the dense corrector) gives what
    chord_correction followed by smoothed_projection at the corrected point, with the
    tracker's mu(lam) (0 past lam = 1), gives: the same y, d, p, dp/dx, dp/dmu and ||d||
    bits; a non-finite correction (-1.0) leaves p alone."""
    from compass_sparse._homotopy_kernels import (chord_correction, chord_step,
                                                  smoothed_projection)

    g = thesis_family(n, 2, seed=n)
    p = g.problem
    rng = np.random.default_rng(n)
    a = np.clip(rng.normal(size=n), p.lb, p.ub)
    tr = hom._Tracker(p.evaluator, p.lb, p.ub, Options(), deadline=None, on_point=None,
                      tol=1e-12, log=None)
    y = np.append(a + rng.normal(scale=0.1, size=n), lam)
    v = rng.normal(size=n + 1)
    H, Hx, Hlam = tr.residual(y, a, True)
    lu, piv = tr.factor(Hx, Hlam, v).lu
    yp = y + 1e-3 * rng.normal(size=n + 1)
    pt = np.empty(n)
    smoothed_projection(yp[:n], tr._mu(float(yp[n])), tr.lb, tr.ub, pt, np.empty(n),
                        np.empty(n))
    f = p.F(pt)
    y1, p1, d1, dx1, dm1 = yp.copy(), pt.copy(), np.empty(n + 1), np.empty(n), np.empty(n)
    dn1 = chord_step(f, y1, yp, p1, a, v, lu, piv, d1, tr.mu0, tr.lb, tr.ub, dx1, dm1)
    y2, p2, d2, dx2, dm2 = yp.copy(), pt.copy(), np.empty(n + 1), np.empty(n), np.empty(n)
    dn2 = chord_correction(f, y2, yp, p2, a, v, lu, piv, d2)
    smoothed_projection(y2[:n], tr._mu(float(y2[n])), tr.lb, tr.ub, p2, dx2, dm2)
    assert dn1 == dn2 >= 0.0
    for u, w in ((y1, y2), (d1, d2), (p1, p2), (dx1, dx2), (dm1, dm2)):
        assert u.tobytes() == w.tobytes()
    bad = lu.copy()
    bad[-1, -1] = 0.0  # a zero pivot: the correction is not finite
    p3 = pt.copy()
    assert chord_step(f, yp.copy(), yp, p3, a, v, bad, piv, np.empty(n + 1), tr.mu0, tr.lb,
                      tr.ub, np.empty(n), np.empty(n)) == -1.0
    assert p3.tobytes() == pt.tobytes()


@pytest.mark.parametrize("family,seed", [(1, 10), (2, 1), (2, 5), (2, 27)])
def test_compiled_dense_path_steps_reach_the_array_routes_solution(monkeypatch, family, seed):
    """homotopy = 'only' on thesis instances at n = 10 with the dense route's compiled steps
    and with the array route: both solve, at the same solution."""
    prob = thesis_family(10, family, seed).problem
    got = solve_mcp(prob, options={"homotopy": "only"})
    with monkeypatch.context() as mp:
        mp.setattr(hom, "_floats", lambda *args: False)
        ref = solve_mcp(thesis_family(10, family, seed).problem, options={"homotopy": "only"})
    for r in (got, ref):
        assert r.success and natural_residual(r.x, prob.F(r.x), prob.lb, prob.ub) <= 1e-6
    np.testing.assert_allclose(got.x, ref.x, atol=1e-5)


def test_end_game_dense_solve_agrees_with_scipy_and_is_not_finite_when_singular():
    """The end game's dense Newton solve (getrf and the compiled triangular solves) gives
    scipy's lu_factor + lu_solve to rounding; an exactly singular matrix gives a
    non-finite step, which the end game refuses."""
    import scipy.linalg as sla

    rng = np.random.default_rng(11)
    for n in (1, 2, 5, 12):
        for _ in range(5):
            A = rng.normal(size=(n, n)) + n * np.eye(n)
            b = rng.normal(size=n)
            want = sla.lu_solve(sla.lu_factor(A), b)
            got = hom._solve_square(A.copy(), b, True)
            assert np.allclose(got, want, rtol=1e-12, atol=1e-12)
    S = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not np.isfinite(hom._solve_square(S, np.array([1.0, 0.0]), True)).all()


def test_homotopy_random_generator_is_made_only_when_a_second_path_starts():
    """The generator of the later paths' start points is asked for when a second path
    starts, and only then: a pass that ends on its first path never makes it."""
    F, J, lb, ub, x0 = _diverging_problem()
    made = []

    def rng():
        made.append(1)
        return np.random.default_rng(0)

    out = track_paths(MCP(F, J, lb, ub, x0).evaluator, lb, ub, x0,
                      Options(homotopy_path_limit=3), rng=rng)
    assert out.paths == 3 and len(made) == 1
    made.clear()
    out = track_paths(MCP(F, J, lb, ub, x0).evaluator, lb, ub, x0,
                      Options(homotopy_path_limit=1), rng=rng)
    assert out.paths == 1 and made == []


@pytest.mark.parametrize("family,n,seed", [(2, 10, 1), (1, 20, 12), (2, 50, 22)])
def test_corrector_points_are_within_the_tolerance_of_the_curve(monkeypatch, family, n,
                                                                 seed):
    """The corrector stops on an estimate of its point's distance to the curve
    (CORRECTOR_ESTIMATE): every accepted point is checked against the curve's point on the
    same hyperplane, found by running the chord iterations to 1e-13 from the same
    predictor.  The estimate assumes the contraction of the last two corrections holds:
    the distances stay within twice CORRECTOR_TOLERANCE (1 + ||y||) (measured: at most
    0.96 times it on these instances), most within it."""
    assert hom.CORRECTOR_ESTIMATE
    # the Python route's corrector, instrumented (the compiled tracker's points are its
    # bits: test_compiled_tracker_follows_the_python_routes_points_bit_for_bit)
    monkeypatch.setattr(hom, "COMPILED_TRACKER", False)
    orig = hom._Tracker._correct
    seen = []

    def checked(self, yp, a, Bf, v):
        out, ok = orig(self, yp, a, Bf, v)
        if ok:
            with monkeypatch.context() as m:
                m.setattr(hom, "CORRECTOR_TOLERANCE", 1e-13)
                m.setattr(hom, "CORRECTOR_ESTIMATE", False)
                m.setattr(hom, "CORRECTOR_ITERATIONS", 60)
                ref, ok_ref = orig(self, yp, a, Bf, v)
            if ok_ref:
                tol = hom.CORRECTOR_TOLERANCE * (1.0 + np.linalg.norm(yp))
                seen.append(np.linalg.norm(out[0] - ref[0]) / tol)
        return out, ok

    monkeypatch.setattr(hom._Tracker, "_correct", checked)
    r = solve_mcp(thesis_family(n, family, seed).problem)
    assert r.success and r.passes["homotopy"].ran
    assert len(seen) >= 5
    assert max(seen) <= 2.0, max(seen)
    assert np.median(seen) <= 1.0


@pytest.mark.parametrize("limit", [1, 2, 3])
def test_homotopy_starts_after_homotopy_stationary_limit_stalled_iterations(limit):
    """In the run the homotopy follows, NMS stops after homotopy_stationary_limit major
    iterations without progress (billups: every iteration from the start stalls), and the
    homotopy then solves the problem; restart_stationary_limit does not decide it."""
    import known_problems as kp

    k = kp.billups()
    r = solve_mcp(k.F, k.J, k.lb, k.ub, k.x0,
                  options={"homotopy_stationary_limit": limit, "restart_stationary_limit": 7})
    assert r.success and r.passes["homotopy"].ran and r.restarts == 0
    stalled = [h for h in r.history if h.step and "H" not in h.step]
    assert len(stalled) == limit
    assert r.nit == limit + 1  # the stalled iterations and the homotopy's
    assert natural_residual(r.x, k.F(r.x), k.lb, k.ub) <= 1e-6


def test_tracker_smoothing_scale_is_numpys_median_of_the_finite_widths():
    """mu0 = homotopy_smoothing * max(median of the finite box widths, 1e-8), the median
    taken without np.median's dispatch: np.median's value for odd and even counts, 1 when
    no width is finite."""
    rng = np.random.default_rng(2)
    opt = Options()
    for n in (1, 2, 3, 7, 10, 31):
        for _ in range(10):
            lb = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4)
            ub = lb + rng.random(n) * 10.0 ** rng.integers(-3, 4)
            lb[rng.random(n) < 0.3] = -np.inf
            tr = hom._Tracker(None, lb, ub, opt, deadline=None, on_point=None, tol=1e-6,
                              log=None)
            w = (ub - lb)[np.isfinite(ub - lb)]
            want = opt.homotopy_smoothing * max(float(np.median(w)) if w.size else 1.0,
                                                1e-8)
            assert tr.mu0 == want


@pytest.mark.parametrize("n", [10, 20])
def test_homotopy_pass_limits_blas_threads_only_from_blas_limit_min_n(monkeypatch, n):
    """The homotopy pass sets BLAS to one thread around its dense factorizations from
    BLAS_LIMIT_MIN_N on; below it (OpenBLAS keeps such small kernels on one thread) the
    thread count is not touched."""
    import contextlib

    from compass_sparse._blas import BLAS_LIMIT_MIN_N

    entered = []

    def counting():
        entered.append(1)
        return contextlib.nullcontext()

    monkeypatch.setattr(hom, "single_threaded_blas", counting)
    r = solve_mcp(thesis_family(n, 2, 1).problem, options={"homotopy": "only"})
    assert r.passes["homotopy"].ran
    assert len(entered) == (1 if n >= BLAS_LIMIT_MIN_N else 0)


def test_accepted_point_reuses_the_correctors_projection_bit_for_bit(monkeypatch):
    """An accepted point's smoothed projection is the one the corrector's last chord step
    made (no second projection): p, dp/dx and dp/dmu are the bits a fresh projection at
    that point gives, on every accepted point of a homotopy-only solve."""
    g = thesis_family(10, 2, 1)
    monkeypatch.setattr(hom, "COMPILED_TRACKER", False)  # (the Python route's residual)
    inner = hom._Tracker.residual
    reused = []

    def checked(self, y, a, want_jac):
        if want_jac and self._corrected is not None and self._corrected[0] is y:
            n = self.n
            p, dx, dmu = self.smooth.project(y[:n], self._mu(y[n]))
            assert np.array_equal(self._corrected[1], p)
            assert np.array_equal(self._dx, dx) and np.array_equal(self._dmu, dmu)
            reused.append(True)
        return inner(self, y, a, want_jac)

    monkeypatch.setattr(hom._Tracker, "residual", checked)
    r = solve_mcp(g.problem, options={"homotopy": "only"})
    assert r.success
    assert len(reused) >= 5  # the dense route accepted several points with it


def _route_runs():
    g = [(f"thesis {fam} n{n} s{seed}", thesis_family(n, fam, seed).problem)
         for fam in (1, 2) for n in (10, 20) for seed in (1, 2, 3)]
    runs = [(name, (p,), {"homotopy": "only"}) for name, p in g]
    runs += [(name + " auto", (p,), {}) for name, p in g[:3]]
    F, J, lb, ub, x0 = _stationary_problem()
    runs.append(("stationary", (F, J, lb, ub, x0), {"homotopy": "only"}))
    runs.append(("stationary, tight tracking", (F, J, lb, ub, x0),
                 {"homotopy": "only", "homotopy_initial_step": 1e-3}))
    return runs


def _record(res):
    hp = res.passes["homotopy"]
    return (res.status, res.nit, res.nfev, res.njev, res.domain_errors, hp.iterations,
            hp.factorizations, hp.reason, res.x.tobytes())


def test_compiled_tracker_follows_the_python_routes_points_bit_for_bit(monkeypatch, caplog):
    """The compiled tracker (reverse communication: one compiled call between two
    evaluations) against the Python route it replaces on dense problems: the same statuses,
    evaluations, steps, factorizations, pass reasons, log lines and bits of x."""
    import logging

    calls = {"n": 0}
    dense = hom.hk.follow_dense

    def counted(*args):
        calls["n"] += 1
        return dense(*args)

    monkeypatch.setattr(hom.hk, "follow_dense", counted)
    out = {}
    for compiled in (False, True):
        monkeypatch.setattr(hom, "COMPILED_TRACKER", compiled)
        records = []
        for _, args, opts in _route_runs():
            caplog.clear()
            with caplog.at_level(logging.INFO, logger="compass_sparse"):
                res = solve_mcp(*args, options={**opts, "verbosity": 2, "time_limit": 60})
            records.append(_record(res) + (tuple(r.getMessage() for r in caplog.records
                                                 if r.getMessage().startswith("homotopy ")),))
        out[compiled] = records
        assert (calls["n"] > 0) is compiled
    for (name, *_), a, b in zip(_route_runs(), out[False], out[True]):
        assert a == b, (name, [(u, w) for u, w in zip(a, b) if u != w])
    assert sum(r[0] is Status.SOLVED for r in out[True]) >= 12
    assert any("homotopy step" in line for r in out[True] for line in r[-1])


def test_compiled_tracker_carries_on_past_rejected_corrector_points(monkeypatch):
    """F rejected at every third corrector iterate (an exception or NaN there): the
    compiled tracker halves the step and goes on, as the Python route does, to the same
    points."""
    def run(compiled):
        monkeypatch.setattr(hom, "COMPILED_TRACKER", compiled)
        calls = {"n": 0}
        once = hom._Tracker.__init__

        def init(self, evalr, *args, **kw):
            once(self, evalr, *args, **kw)
            inner = evalr.f_once

            def flaky(x):
                calls["n"] += 1
                if calls["n"] % 3 == 0:
                    return evalr._reject("ValueError('flaky')")
                return inner(x)

            self.ev = copy.copy(evalr)
            self.ev.f_once = flaky

        monkeypatch.setattr(hom._Tracker, "__init__", init)
        res = solve_mcp(thesis_family(10, 2, 1).problem, options={"homotopy": "only"})
        return res, calls["n"]

    (a, na), (b, nb) = run(False), run(True)
    assert nb >= 3 and na == nb
    assert _record(a) == _record(b)
    assert b.domain_errors >= 1 and b.passes["homotopy"].ran
    assert b.success or b.status is Status.NO_PROGRESS


def test_dense_getrf_gives_scipys_factors_bit_for_bit():
    """The compiled tracker's getrf (numba's binding of scipy's LAPACK) against
    scipy.linalg.lapack.dgetrf: the same factors and 0-based pivots, and info > 0 at an
    exactly zero pivot."""
    import scipy.linalg as sla

    assert hom.hk.bind_lapack()
    rng = np.random.default_rng(5)
    for n in (1, 2, 3, 7, 11, 31, 64, 301):
        A = np.asfortranarray(rng.standard_normal((n, n)))
        lu, piv, info = sla.lapack.dgetrf(A)
        B = A.copy(order="F")
        p = np.empty(n, dtype=np.int32)
        assert hom.hk.dense_getrf(B, p) == info == 0
        assert np.array_equal(B, lu) and np.array_equal(p, piv)
    S = np.asfortranarray([[1.0, 2.0], [2.0, 4.0]])
    assert hom.hk.dense_getrf(S, np.empty(2, dtype=np.int32)) > 0


def test_tracker_keeps_its_python_route_when_numba_offers_no_getrf(monkeypatch):
    """getrf is bound through numba's internal LAPACK interface; a numba without it (the
    binding fails) leaves the tracker on its Python route, with the same points."""
    g = thesis_family(10, 2, 1).problem
    ref = solve_mcp(g, options={"homotopy": "only"})
    calls = []
    monkeypatch.setattr(hom.hk, "bind_lapack", lambda: calls.append(1) or False)
    monkeypatch.setattr(hom.hk, "follow_dense", lambda *a: 1 / 0)
    res = solve_mcp(g, options={"homotopy": "only"})
    assert calls and res.success
    assert _record(res) == _record(ref)
