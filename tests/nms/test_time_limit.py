"""The time limit of a solve (compass_sparse.solve, compass_sparse.nms.solver): it counts
from the call, the start point's check included; no major iteration is started whose
factorization cannot finish in the time left; a solve the clock stopped names the rows
that keep the merit up without evaluating J after its limit, and claims no convergence.
Time is a simulated clock (every F evaluation advances it) or a factorization cost
patched to be prohibitive; no test reads the wall clock."""


import numpy as np
import pytest
import scipy.sparse as sp
from compass_sparse.generators import thesis_family

import compass_sparse as cs
from compass_sparse import Status
from compass_sparse.basis import backends
from compass_sparse.crash import projected_newton


def test_the_time_limit_counts_from_the_call_with_the_start_points_check(clock):
    """F costs 0.4 s and the limit is 0.5 s: the solve returns within 1.1 x the limit plus
    one evaluation (0.95 s) of the call.  The old code counted the limit from after the
    start point's check (F and J at x0: 0.3 s at n = 1e6), so the check's evaluation came
    on top: 1.2 s here."""
    cost = 0.4

    def F(x):
        clock.now += cost
        return x ** 2 + 1.0  # (no zero: the solve runs until a limit stops it)

    start = clock.now
    r = cs.solve_mcp(F, lambda x: sp.csc_matrix(np.diag(2.0 * x)), -np.inf, np.inf,
                     np.full(3, 0.5), options={"time_limit": 0.5, "restart_limit": 10 ** 6})
    assert r.status is Status.TIME_LIMIT
    assert clock.now - start <= 1.1 * 0.5 + cost + 1e-9, clock.now - start


def test_no_major_iteration_is_started_whose_factorization_cannot_finish(monkeypatch):
    """With a factorization predicted at 1 s per column (300 s at n = 300) and 100 s of
    limit, the solve stops before its first major iteration.  The old code started a
    major iteration with whatever time was left: at n = 1e6 with 0.34 s left, the sparse
    engine's first path took 4.5 s."""
    monkeypatch.setattr(backends, "FACTOR_SECONDS_PER_COLUMN", 1.0, raising=False)
    p = thesis_family(300, 1, 2).problem
    r = cs.solve_mcp(p, options={"time_limit": 100.0, "crash_method": "none"})
    assert r.status is Status.TIME_LIMIT and "a major iteration factors" in r.message
    assert r.nit == 0 and not r.passes["path"].ran
    np.testing.assert_array_equal(r.x, p.x0)
    # the same solve with a factorization that fits runs its major iterations
    monkeypatch.setattr(backends, "FACTOR_SECONDS_PER_COLUMN", 1e-6)
    r = cs.solve_mcp(p, options={"time_limit": 100.0, "crash_method": "none"})
    assert r.status is Status.SOLVED and r.nit > 0
    assert np.abs(r.x - np.clip(r.x - p.F(r.x), p.lb, p.ub)).max() <= 1e-6


def test_a_solve_stopped_by_the_clock_names_rows_and_claims_no_convergence():
    """F = x^2 + 1 from x = 0, the merit's stationary point, stopped by its limit at once:
    the message names the rows that keep the merit up and evaluates no J after the limit.
    The old code evaluated J at the best point and said "converged to a stationary point
    of the merit function" of a run the clock had cut before its first step."""
    evaluations = {"J": 0}

    def J(x):
        evaluations["J"] += 1
        return sp.csc_matrix(np.diag(2.0 * x))

    r = cs.solve_mcp(lambda x: x ** 2 + 1.0, J, -np.inf, np.inf, np.zeros(3),
                     options={"time_limit": 1e-9})
    assert r.status is Status.TIME_LIMIT
    assert "the rows that keep the merit up: F[0]" in r.message
    assert "stationary" not in r.message
    assert evaluations["J"] == 1 and r.njev == 1  # (the start point's, before the limit)


def test_the_crash_computes_no_direction_after_its_j_evaluation_passed_the_limit(
        clock, monkeypatch):
    """The limit passes while the crash evaluates J for its second step (0.6 s of a 0.5 s
    limit; the first step uses the start point's): no direction is computed from it (its
    reduced system and ordering cost as much again at n = 1e6).  The old code computed
    the second direction and stopped only at the factorization's check."""
    directions = []
    real = projected_newton._Steps.direction

    def direction(self, *args):
        directions.append(clock.now)
        return real(self, *args)

    monkeypatch.setattr(projected_newton._Steps, "direction", direction)
    n = 300
    rng = np.random.default_rng(5)
    A = sp.csc_matrix(sp.random(n, n, density=0.01, random_state=rng) + 4.0 * sp.identity(n))

    calls = []

    def J(x):
        calls.append(x)
        if len(calls) > 1:
            clock.now += 0.6
        return sp.csc_matrix(A + sp.diags(0.1 * np.cos(x)))

    r = cs.solve_mcp(lambda x: A @ x - 1.0 + 0.1 * np.sin(x), J, 0.0, np.inf,
                     np.full(n, 5.0), options={"time_limit": 0.5})
    assert r.status is Status.TIME_LIMIT and r.passes["crash"].reason == "time limit"
    assert len(calls) == 2 and directions == [1000.0]


@pytest.mark.parametrize("seed", range(3))
def test_moved_indices_by_masks_count_the_symmetric_difference(seed):
    """The crash's count of indices that left or joined the inactive set (by masks: the
    hashed np.setxor1d took 0.9 s at n = 1e6 in every crash step) is setxor1d's."""
    rng = np.random.default_rng(seed)
    n = 1000
    for density in (0.0, 0.1, 0.5, 1.0):
        old = np.flatnonzero(rng.random(n) < density)
        new = np.flatnonzero(rng.random(n) < density)
        for a, b in ((old, new), (old, old), (new, old)):
            assert projected_newton._moved(a, b, n) == np.setxor1d(a, b).size


def test_the_passes_stop_early_enough_for_the_result_to_be_built(monkeypatch):
    """The passes stop FINISH_SECONDS_PER_VARIABLE * n before the limit, the time the
    Result's construction takes (0.1-0.15 s at n = 1e6): at 1 s per variable a problem of
    order 300 gets no pass in a 100 s limit.  The old passes ran to the limit itself and
    the Result was built after it."""
    from compass_sparse import solve as solve_module

    monkeypatch.setattr(solve_module, "FINISH_SECONDS_PER_VARIABLE", 1.0, raising=False)
    p = thesis_family(300, 1, 2).problem
    r = cs.solve_mcp(p, options={"time_limit": 100.0})
    assert r.status is Status.TIME_LIMIT and r.nit == 0 and r.crash_iterations == 0
    monkeypatch.setattr(solve_module, "FINISH_SECONDS_PER_VARIABLE", 2e-7)
    r = cs.solve_mcp(p, options={"time_limit": 100.0})
    assert r.status is Status.SOLVED
