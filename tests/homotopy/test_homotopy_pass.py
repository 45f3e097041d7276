"""The probability-one homotopy pass in a solve (compass_sparse.homotopy): path tracking
to a solution where the stabilized Newton method stalls at a stationary point of its
merit function, the divergence and time-limit statuses, when the pass starts and from
where, its options and the pass table."""

import numpy as np
import pytest

import known_problems as kp

import compass_sparse.homotopy.tracker as hom
from compass_sparse import Options, solve_mcp
from compass_sparse.generators import thesis_family
from compass_sparse.homotopy import HomotopyStatus
from compass_sparse.merit import fb_gradient, fb_phi, natural_residual
from compass_sparse.status import Status


def _projected_gradient(F, J, z, lb, ub):
    f = F(z)
    g = fb_gradient(z, f, J(z), lb, ub, fb_phi(z, f, lb, ub))
    return z - np.clip(z - g, lb, ub)


def test_nms_stalls_at_a_stationary_point_where_the_homotopy_reaches_the_solution():
    F, J, lb, ub, x0 = kp.stationary_quadratic()
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
    F, J, lb, ub, x0 = kp.stationary_quadratic()
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


def test_solve_reports_a_diverged_homotopy_as_no_progress_with_the_best_point():
    F, J, lb, ub, x0 = kp.diverging_free()
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
            raise hom.HomotopyStop(HomotopyStatus.TIME_LIMIT, "time limit reached on the path")

    monkeypatch.setattr(hom.Tracker, "_check_time", check_time)
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
    F, J = kp.quadratic([0.0, 0.0], [[2.0, 0.0], [0.0, 3.0]], [-1.0, 1.0])
    res = solve_mcp(F, J, 0.0, np.inf, [1.0, 1.0])
    assert res.success
    h = res.passes["homotopy"]
    assert not h.ran and h.reason == "NMS did not stall"
    off = solve_mcp(F, J, 0.0, np.inf, [1.0, 1.0], options={"homotopy": "off"})
    assert off.passes["homotopy"].reason == "homotopy off"


@pytest.mark.parametrize("tol", [1e-4, 1e-8, 1e-10])
def test_homotopy_meets_each_convergence_tolerance(tol):
    F, J, lb, ub, x0 = kp.stationary_quadratic()
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


def test_pass_table_names_the_stop_that_ended_the_homotopy():
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert res.passes["homotopy"].reason == "stopped on the path: solution found"


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
    import compass_sparse.nms.solver as nms_solver

    real = nms_solver.homotopy_pass

    def spy(evalr, lb, ub, z_start, opt, **kw):
        best = kw["on_point"].__self__.point  # (the solver's BestPoint.consider)
        seen.append((np.array(z_start, copy=True), best.z.copy(), kw.get("center")))
        return real(evalr, lb, ub, z_start, opt, **kw)

    monkeypatch.setattr(nms_solver, "homotopy_pass", spy)
    prob = thesis_family(10, 2, 4).problem
    res = solve_mcp(prob, options={"homotopy_start": where})
    assert res.success and natural_residual(res.x, prob.F(res.x), prob.lb, prob.ub) <= 1e-6
    assert len(seen) == 1
    z_start, best, center = seen[0]
    assert not np.array_equal(best, prob.x0)  # the two choices differ on this instance
    np.testing.assert_array_equal(z_start, best if where == "best" else prob.x0)
    np.testing.assert_array_equal(center, prob.x0)  # later paths: around the start point


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
