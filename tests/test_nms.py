"""The NMS loop's pure pieces, the monotone variant and the restart schedule."""
from __future__ import annotations

import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse.generators import thesis_family
from compass_sparse.nms import LOCAL_FACTOR, classify_step, reference_value
from compass_sparse.restarts import FROM_NEAR_BEST, FROM_RANDOM, FROM_START, RestartSchedule


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
    assert f"nms {st.time:.3f}s" in r.summary()
