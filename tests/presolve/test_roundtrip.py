"""Round trips: presolve, solve the reduced problem, postsolve -> a solution of the original."""
import numpy as np
from hypothesis import given, settings, strategies as st

from compass_sparse.merit import natural_residual
from compass_sparse.presolve import PresolveOptions, presolve, solve_with_presolve

from ._problems import ALL_FEATS, build
from ._ref_solver import ref_solve

SETTINGS = dict(max_examples=25, deadline=None, derandomize=True)
feats_st = st.lists(st.sampled_from(ALL_FEATS), min_size=1, max_size=14)


def residual(p, x):
    return natural_residual(x, p.F_uncounted(x), p.lb, p.ub)


@settings(**SETTINGS)
@given(seed=st.integers(0, 10**6), n=st.integers(20, 60), feats=feats_st)
def test_roundtrip_solves_the_original(seed, n, feats):
    p, _ = build(seed, n, feats)
    sol = solve_with_presolve(p, ref_solve)
    assert sol.infeasible is None
    assert sol.natural_residual <= 1e-8, sol.presolve.summary_line()
    # presolve off reaches a solution of the same quality
    ref = ref_solve(p)
    assert ref.natural <= 1e-8
    # the reduced problem is the original restricted: presolving again finds nothing
    if sol.presolve.reduced is not None:
        again = presolve(sol.presolve.reduced)
        assert again.stats.removed == 0, again.counters_line()


@settings(**SETTINGS)
@given(seed=st.integers(0, 10**6), n=st.integers(20, 60), feats=feats_st)
def test_solved_start_needs_zero_iterations(seed, n, feats):
    p, _ = build(seed, n, feats)
    ref = ref_solve(p)
    assert ref.natural <= 1e-10
    warm = p.with_start(ref.x)
    res = presolve(warm)
    if res.reduced is None:
        x = res.postsolve(np.zeros(0))
    else:
        inner = ref_solve(res.reduced, tol=1e-9)
        assert inner.nit == 0
        x = res.postsolve(inner.x)
    assert residual(p, x) <= 1e-8


@settings(**SETTINGS)
@given(seed=st.integers(0, 10**6), feats=feats_st,
       off=st.lists(st.sampled_from(["fixed_variables", "empty_rows", "empty_columns",
                                     "singleton_rows", "column_singletons", "forcing_rows",
                                     "duplicate_rows", "range_fixing"]), max_size=4))
def test_any_subset_of_passes_is_valid(seed, feats, off):
    p, _ = build(seed, 30, feats)
    opts = PresolveOptions(**{k: False for k in off})
    sol = solve_with_presolve(p, ref_solve, opts)
    assert sol.natural_residual <= 1e-8
    for k in off:
        assert sol.presolve.stats.passes[k].removed == 0


def test_large_structured_problem_reduces_a_lot():
    p, info = build(7, 200)
    sol = solve_with_presolve(p, ref_solve)
    assert sol.natural_residual <= 1e-8
    assert sol.presolve.stats.n_reduced < 200
