"""The NMS loop's pure pieces, the monotone variant and the restart schedule."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.generators import thesis_family
from compass_sparse.nms.state import LOCAL_FACTOR, classify_step, reference_value
from compass_sparse.nms.restarts import FROM_NEAR_BEST, FROM_RANDOM, FROM_START, RestartSchedule


def test_reference_value_turns_monotone_near_a_solution():
    memory = [4.0, 9.0, 1.0]
    assert reference_value(memory, 0.5, 1.0, 10.0) == (9.0, 100.0)
    # within LOCAL_FACTOR of the starting residual: R <= Psi(z_k), no d-step growth
    assert reference_value(memory, 0.5, LOCAL_FACTOR * 10.0, 10.0) == (0.5, 1.0)


@pytest.mark.parametrize("psi,dist,d_allowed,descent,expected", [
    (5.0, 0.1, True, False, "D"),  # near, within 100 R: accepted without descent
    (0.5, 0.1, True, True, "O"),  # a d-step that also passes the m-step test
    (0.5, 0.1, True, False, "D"),
    (5.0, 2.0, True, True, "M"),  # too far for a d-step, sufficient decrease
    (5.0, 0.1, False, True, "M"),  # d-steps used up
    (5.0, 2.0, True, False, None),  # watchdog
    (2000.0, 0.1, True, False, None),  # beyond large * R
])
def test_classify_step(psi, dist, d_allowed, descent, expected):
    assert classify_step(psi, 10.0, 100.0, dist, 1.0, d_allowed, 1e-4,
                         lambda: descent) == expected


def test_monotone_line_search_never_raises_the_merit():
    g = thesis_family(30, family=1, seed=4)
    seen = []
    r = cs.solve_mcp(g.problem, callback=lambda info: seen.append(info.residual),
                     options={"nms": False, "crash_method": "none", "restart_limit": 0})
    assert r.success and len(seen) >= 2
    assert all(b <= a * (1 + 1e-12) for a, b in zip(seen, seen[1:]))
    # the non-monotone default accepts d-steps that may raise it; both solve
    assert cs.solve_mcp(g.problem, options={"crash_method": "none"}).success


@pytest.mark.parametrize("search", ["arc", "line"])
def test_crash_searchtype(search):
    g = thesis_family(40, family=1, seed=2)
    r = cs.solve_mcp(g.problem, options={"crash_searchtype": search,
                                         "crash_minimum_dimension": 1})
    assert r.success and r.passes["crash"].ran
    assert r.check(g.problem).natural <= 1e-6


def test_restart_schedule():
    opt = cs.Options()
    sch = RestartSchedule(opt)
    plans = [sch.plan(k, 0.5) for k in range(6)]
    assert [w for _, w in plans] == [FROM_START] * 3 + [FROM_NEAR_BEST, FROM_RANDOM,
                                                        FROM_NEAR_BEST]
    assert plans[0][0].proximal_perturbation == 0.005 and plans[0][0].crash_method == "none"
    assert plans[1][0].nms_memory_size == 2 and plans[2][0].crash_nbchange_limit == 10
    # the residual of the first restart fixes the perturbation of the later ones
    assert sch.plan(3, 1e-9)[0].proximal_perturbation == 0.005


def test_nms_pass_records_its_time():
    g = thesis_family(20, family=1, seed=5)
    r = cs.solve_mcp(g.problem)
    st = r.passes["nms"]
    assert st.ran and st.iterations == r.nit and 0.0 < st.time <= r.time
    assert f"nms {st.time:.3f} s" in r.summary()


def _badly_scaled_lcps(count, seed=1):
    """Small monotone LCPs in mixed units (row scales 1e-8 ... 1e12, column units 1e-6 ...
    1e6) with large finite bounds, some of them active at the solution."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.integers(2, 8))
        B = rng.normal(size=(n, n))
        M = B @ B.T + np.eye(n) * 0.5 + (B - B.T) * 0.3
        D = 10.0 ** rng.integers(-8, 13, size=n)
        C = 10.0 ** rng.integers(-6, 7, size=n)
        A = (D[:, None] * M) / C[None, :]
        xs = rng.normal(size=n) * C * 10
        b = -A @ xs + D * rng.normal(size=n)
        lb = np.where(rng.random(n) < 0.5, -np.inf,
                      xs - np.abs(rng.normal(size=n)) * C * 10.0 ** rng.integers(0, 12, size=n))
        ub = np.where(rng.random(n) < 0.5, np.inf,
                      xs + np.abs(rng.normal(size=n)) * C * 10.0 ** rng.integers(0, 12, size=n))
        ub = np.where(rng.random(n) < 0.2, xs - 0.5 * np.abs(xs) - C, ub)
        yield A, b, lb, np.maximum(ub, lb)


def test_segment_searches_return_points_inside_the_box():
    """The watchdog's line search took z = (1 - a) z_c + a z_N, a convex combination of
    two points in the box, unprojected: with both at one bound it rounded to a unit in the
    last place beyond it, and a SOLVED result returned x outside [l, u] (x_1 = -0.000923..512
    above u_1 = -0.000923..513; in another instance 2.8e-14 above u_2 = -166.3).  The
    projected-gradient fallback's segment search had the same form.  Both are projected
    now; on 150 badly scaled LCPs, with and without the scaling pass, every returned point
    lies in the box (exactly) and every solved one meets the tolerance there."""
    for k, (A, b, lb, ub) in enumerate(_badly_scaled_lcps(150)):
        x0 = np.clip(np.zeros(b.size), lb, ub)
        for scaling in (True, False):
            r = cs.solve_mcp(lambda x: A @ x + b, lambda x: sp.csc_matrix(A), lb, ub, x0,
                             options={"scaling": scaling, "time_limit": 10})
            assert np.all(r.x >= lb) and np.all(r.x <= ub), (k, scaling)
            if r.success:
                assert r.residual.natural <= 1e-6
