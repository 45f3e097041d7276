"""The fixed cost of a solve: objects made once per Jacobian pattern and shared by the
solves of one problem, the memo key made once per point, the scaling trigger's spread in
one compiled call, the residual report of a small problem.  Each test checks that the
shortcut computes what it replaces, and that a problem that needs the full work still
gets it."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import MCP, solve_mcp
from compass_sparse.problem.memo import Memo
from compass_sparse.merit import fb_phi, residual_report
from compass_sparse.linalg.csc import without_duplicates
from compass_sparse.scaling import _maxnorms, _spread, spread


def _cournot():
    def F(q):
        return np.array([1.0, 2.0]) - (10.0 - q.sum()) + q

    return MCP(F, lambda q: np.array([[2.0, 1.0], [1.0, 2.0]]), 0.0, np.inf, np.zeros(2))


def test_linearizer_made_once_per_pattern_and_shared_by_the_solves_of_a_problem():
    # (no crash: it ends these solves, and then no linearizer is needed or made)
    opt = {"crash_method": "none"}
    prob = _cournot()
    first = solve_mcp(prob.with_start(np.zeros(2)), options=opt)
    lin = prob.evaluator.pattern_cache.linearizer
    assert lin is not None
    again = solve_mcp(prob.with_start(np.zeros(2)), options=opt)
    assert prob.evaluator.pattern_cache.linearizer is lin
    # another problem object, nothing shared: the same answer and counts
    fresh = solve_mcp(_cournot().with_start(np.zeros(2)), options=opt)
    for r in (first, again):
        assert r.success and r.nit > 0
        np.testing.assert_array_equal(r.x, fresh.x)
        assert (r.nit, r.minor_iterations, r.nfev, r.njev) == (
            fresh.nit, fresh.minor_iterations, fresh.nfev, fresh.njev)


def test_pattern_store_rebuilds_when_an_undeclared_pattern_grows():
    # J is diagonal at the start and gains an off-diagonal entry away from it: the stored
    # pattern grows, so everything derived from the old pattern must be made again.
    def F(x):
        return np.array([x[0] - 1.0 + 0.5 * x[1] ** 2, x[1] - 2.0])

    def J(x):
        return sp.csc_matrix(np.array([[1.0, x[1]], [0.0, 1.0]]))

    prob = MCP(F, J, -np.inf, np.inf, np.zeros(2))
    ev = prob.evaluator
    ev.fj(np.zeros(2))
    first = ev.pattern_cache
    first.linear_rows = 7
    assert ev.pattern_cache is first and ev.pattern_cache.linear_rows == 7
    ev.fj(np.ones(2))  # J now has the (0, 1) entry: the pattern grows
    assert ev.pattern_growths == 1
    assert ev.pattern_cache is not first and ev.pattern_cache.linear_rows is None
    assert ev.pattern_cache.pattern is ev.pattern_ref
    res = solve_mcp(prob.with_start(np.zeros(2)))
    assert res.success
    np.testing.assert_allclose(res.x, [-1.0, 2.0], atol=1e-8)


def test_tiny_problem_with_a_declared_linear_row_still_presolved_in_every_solve():
    # The count of linear rows is kept per pattern; a problem that has one must still
    # reach the preprocessor on the second solve (and one without must not).
    M = np.array([[2.0, 1.0], [0.0, 1.0]])

    def F(x):
        return np.array([2.0 * x[0] + x[1] + 0.1 * x[0] ** 3 - 4.0, x[1] - 1.0])

    def J(x):
        return np.array([[2.0 + 0.3 * x[0] ** 2, 1.0], [0.0, 1.0]])

    # row 2 entirely constant (its stored zero at (1, 0) included)
    const = sp.csc_matrix((np.ones(3), ([0, 1, 1], [1, 0, 1])), shape=(2, 2))
    prob = MCP(F, J, 0.0, np.inf, np.zeros(2), constant_jac=const)
    plain = MCP(F, J, 0.0, np.inf, np.zeros(2))
    for _ in range(2):
        r = solve_mcp(prob.with_start(np.zeros(2)))
        assert r.success and r.passes["presolve"].ran
        p = solve_mcp(plain.with_start(np.zeros(2)))
        assert p.success and not p.passes["presolve"].ran
        np.testing.assert_allclose(r.x, p.x, atol=1e-9)
    del M


@pytest.mark.parametrize("x, none", [
    (np.array([1.0, np.nan]), True),
    (np.array([np.inf, -np.inf, 1.0]), False),
    (np.array([1e200, -1e300, 5e-324]), False),
    (np.array([-0.0, 0.0]), False),
])
def test_memo_key_is_none_exactly_for_points_with_a_nan(x, none):
    k = Memo.key_of(x)
    assert (k is None) == none
    if not none:  # equal points (-0.0 == 0.0) share the key
        assert k == Memo.key_of(np.where(x == 0, 0.0, x))


def test_memo_key_made_once_still_finds_the_pinned_start_point():
    prob = _cournot()
    ev = prob.evaluator.fresh()
    x0 = np.array([0.5, 0.25])
    f0, J0 = ev.fj(x0)
    ev.pin(x0)
    calls = ev.counters.nfev, ev.counters.njev
    ev.fj(np.array([1.0, 1.0]))  # a later point replaces the last one, not the pinned one
    f, J = ev.fj(x0.copy())
    assert (ev.counters.nfev, ev.counters.njev) == (calls[0] + 1, calls[1] + 1)
    np.testing.assert_array_equal(f, f0)
    np.testing.assert_array_equal(J.toarray(), J0.toarray())


@pytest.mark.parametrize("seed", range(4))
def test_spread_in_one_kernel_equals_the_maxnorm_formula(seed):
    rng = np.random.default_rng(seed)
    n = 30
    A = sp.random(n, n, density=0.2, random_state=seed, format="csc")
    A.data *= 10.0 ** rng.integers(-200, 200, A.nnz)
    A.data[:3] = [0.0, np.nan, -np.inf][: min(3, A.nnz)]  # explicit zero, NaN, inf
    A = without_duplicates(A)
    r, c = _maxnorms(A)
    expected = max(_spread(r), _spread(c))
    got = spread(A)
    assert got == expected or (np.isnan(got) and np.isnan(expected))
    assert spread(sp.csc_matrix((n, n))) == 1.0  # no positive entries


def test_residual_report_of_a_small_problem_lists_every_row_ties_lower_first():
    z = np.array([0.0, 1.0, 2.0, 3.0])
    f = np.array([0.5, 0.0, -0.5, 0.0])
    lb, ub = np.zeros(4), np.full(4, np.inf)
    rep = residual_report(z, f, lb, ub)
    aphi = np.abs(fb_phi(z, f, lb, ub))
    order = sorted(range(4), key=lambda i: (-aphi[i], i))
    assert aphi[1] == aphi[3] == 0.0  # a tie
    assert [w[0] for w in rep.worst] == [f"F[{i}]" for i in order]
    assert rep.worst_index == order[0]
    # above k_worst rows the partition route lists the same k largest
    big = residual_report(np.arange(9.0), np.linspace(-1, 1, 9), np.zeros(9),
                          np.full(9, np.inf), k_worst=3)
    assert len(big.worst) == 3
    assert [w[1] for w in big.worst] == sorted(
        np.abs(fb_phi(np.arange(9.0), np.linspace(-1, 1, 9), np.zeros(9),
                      np.full(9, np.inf))), reverse=True)[:3]


def _flat_start():
    # F = exp(-x) on [0, inf): at x = 14 the residual is 8e-7 but F is flat (not solved)
    return MCP(np.exp, None, 0.0, np.inf, np.array([14.0]), jac_sparsity=np.ones((1, 1)))


def _badly_scaled():
    s = np.array([1e6, 1.0, 1e-5])

    def F(x):
        return s * (x - np.array([1.0, 2.0, 3.0]) + 0.1 * x ** 3)

    return MCP(F, lambda x: np.diag(s * (1.0 + 0.3 * x ** 2)), 0.0, np.inf, np.zeros(3))


@pytest.mark.parametrize("make", [_cournot, _flat_start, _badly_scaled])
def test_start_verdict_handed_to_the_solver_gives_the_solve_it_recomputes(make, monkeypatch):
    from compass_sparse.nms import solver

    def run():
        r = solve_mcp(make().with_start(make().x0))
        return r.status, r.x.tolist(), r.nit, r.minor_iterations, r.nfev, r.njev, r.message

    handed = run()
    # the same solve with the verdict recomputed inside the solver (none handed to it)
    real = solver.NMSSolver.__init__
    monkeypatch.setattr(solver.NMSSolver, "__init__",
                        lambda self, *a, **k: real(self, *a, **{**k, "start_verdict": None}))
    assert run() == handed


def _random_point(rng, n, z_exponents, f_exponents):
    """(z, f, lb, ub): every bound kind, z in the box, entries over the given decades."""
    lb = np.where(rng.random(n) < 0.4, -np.inf, rng.standard_normal(n))
    ub = np.where(rng.random(n) < 0.4, np.inf, np.nan_to_num(lb, neginf=0.0) + rng.random(n))
    z = np.clip(rng.standard_normal(n) * 10.0 ** rng.integers(*z_exponents, n), lb, ub)
    f = rng.standard_normal(n) * 10.0 ** rng.integers(*f_exponents, n)
    return z, f, lb, ub


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("tol", [1e-6, 1e-300, 0.0, 1e300])
def test_compiled_min_map_test_gives_the_array_formula_verdict(seed, tol):
    from compass_sparse._merit_kernels import min_map_within
    from compass_sparse.merit import min_map

    rng, n = np.random.default_rng(seed), 400
    z, f, lb, ub = _random_point(rng, n, (-300, 10), (-320, 10))
    z[:4] = [np.inf, -np.inf, np.nan, 0.0]
    f[4:6] = [np.nan, -0.0]
    for k in range(n):  # every prefix: the first failing row moves along the vector
        zs, fs, ls, us = z[k:], f[k:], lb[k:], ub[k:]
        with np.errstate(invalid="ignore"):
            expected = bool((np.abs(min_map(zs, fs, ls, us)) <= tol).all())
        assert min_map_within(zs, fs, ls, us, tol) == expected
    # rows that pass: a near-solution of every bound kind
    zz = np.clip(rng.standard_normal(n), lb, ub)
    ff = np.where(zz == lb, np.abs(f), np.where(zz == ub, -np.abs(f), 0.0)) * 1e-9
    for t in (1e-6, 1e-12):
        assert min_map_within(zz, ff, lb, ub, t) == bool(
            (np.abs(min_map(zz, ff, lb, ub)) <= t).all())


def test_memo_key_is_a_copy_so_a_point_changed_in_place_is_evaluated_again():
    calls = []

    def F(x):
        calls.append(x.copy())
        return x - 1.0

    prob = MCP(F, lambda x: np.eye(2), -np.inf, np.inf, np.zeros(2))
    ev = prob.evaluator.fresh()
    calls.clear()  # (the problem's start check evaluated F once)
    x = np.array([3.0, 4.0])
    np.testing.assert_array_equal(ev.F(x), [2.0, 3.0])
    x[0] = 5.0  # the caller reuses its array
    np.testing.assert_array_equal(ev.F(x), [4.0, 3.0])
    np.testing.assert_array_equal(ev.F(np.array([5.0, 4.0])), [4.0, 3.0])  # memo hit
    assert len(calls) == 2
    assert ev.F(np.array([-0.0, 4.0])) is not None and len(calls) == 3
    np.testing.assert_array_equal(ev.F(np.array([0.0, 4.0])), [-1.0, 3.0])  # -0.0 == 0.0
    assert len(calls) == 3


@pytest.mark.parametrize("seed", range(4))
def test_scale_test_in_one_kernel_equals_diagonals_then_flat_step(seed):
    from compass_sparse._merit_kernels import flat_step_kernel, scale_test_kernel
    from compass_sparse.merit import fb_jacobian_diagonals

    rng, n = np.random.default_rng(seed), 40
    z, f, lb, ub = _random_point(rng, n, (-5, 5), (-12, 3))
    f[:3] = [0.0, -0.0, np.nan]
    J = without_duplicates(sp.random(n, n, density=0.15, random_state=seed, format="csc")
                   + sp.diags(rng.standard_normal(n)))
    J.data *= 10.0 ** rng.integers(-14, 3, J.nnz)
    phi = fb_phi(z, f, lb, ub)
    da, db = fb_jacobian_diagonals(z, f, lb, ub)
    two = flat_step_kernel(z, phi, da, db, J.indptr, J.indices, J.data, np.zeros(n),
                           np.empty(n), np.empty(n))
    one = scale_test_kernel(z, f, lb, ub, phi, J.indptr, J.indices, J.data)
    assert one[0] == two[0]
    for a, b in zip(one[1:], two[1:]):
        assert a == b or (np.isnan(a) and np.isnan(b))


def test_point_norm_by_math_sqrt_equals_the_numpy_square_root():
    from compass_sparse.nms.state import Point

    rng = np.random.default_rng(0)
    psis = np.concatenate([rng.random(2000) * 10.0 ** rng.integers(-320, 308, 2000),
                           [0.0, 5e-324, 1e308, np.inf, np.nan]])
    e = np.zeros(1)
    for psi in psis:
        got = Point(e, e, e, float(psi)).fbn
        ref = float(np.sqrt(2.0 * float(psi)))  # (Python floats overflow to inf silently)
        assert got == ref or (np.isnan(got) and np.isnan(ref))


def test_memo_never_stores_or_matches_a_point_with_a_nan():
    calls = []

    def F(x):
        calls.append(1)
        return np.nan_to_num(x) - 1.0

    prob = MCP(F, lambda x: np.eye(2), -np.inf, np.inf, np.zeros(2))
    ev = prob.evaluator.fresh()
    calls.clear()
    bad = np.array([np.nan, 1.0])
    ev.F(bad)
    ev.F(bad)  # NaN equals nothing: evaluated again
    ev.J(bad)
    ev.J(bad)
    assert len(calls) == 2 and ev.counters.njev == 2
    good = np.array([2.0, 1.0])
    ev.F(good)
    ev.F(good.copy())
    assert len(calls) == 3


def test_start_point_at_a_solution_runs_no_pass():
    """A solve started at a solution (a re-solve, a scenario that changed nothing) is
    judged on the user's problem before any pass: the preprocessor, which would reduce
    this CGE model (a fixed price and a column singleton), does not run, F and J are
    evaluated once, and the Result is the start point with its verdict."""
    from compass_sparse.generators.cge import size_for, static_cge

    p = static_cge(**size_for(90)).with_shock(output_tax=0.25).problem
    first = solve_mcp(p)
    assert first.success and first.passes["presolve"].ran  # it reduces this model
    again = solve_mcp(p.with_start(first.x))
    assert again.success and again.message == "the start point is a solution"
    assert again.nit == 0 and again.nfev == 1 and again.njev == 1
    assert not again.passes["presolve"].ran
    assert again.passes["presolve"].reason == "start point already solved"
    np.testing.assert_array_equal(again.x, first.x)
    f = p.F(again.x)
    assert np.max(np.abs(again.x - np.clip(again.x - f, p.lb, p.ub))) <= 1e-6
    # a start point that is not a solution still gets the preprocessor
    moved = solve_mcp(p.with_start(first.x * 1.01))
    assert moved.success and moved.passes["presolve"].ran


@pytest.mark.parametrize("seed", range(4))
def test_nan_and_finite_tests_by_one_dot_product_equal_numpy(seed):
    """The memo key's NaN flag and all_finite (the memo's and the evaluator's checks at
    every point, in one compiled pass for float vectors) give numpy's answers across
    magnitudes, with NaN, +-inf, subnormals, empty vectors, and on the numpy path for
    2-D and strided arrays."""
    from compass_sparse.problem.memo import Memo
    from compass_sparse.box import all_finite

    def has_nan(x):
        return Memo.probe(x)[2]

    rng = np.random.default_rng(seed)
    for n in (0, 1, 4, 50):
        for special in (None, np.nan, np.inf, -np.inf, 1e200, -1e300, 5e-324):
            x = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 150, n)
            if special is not None and n:
                x[rng.integers(n)] = special
            assert has_nan(x) == bool(np.isnan(x).any())
            assert all_finite(x) == bool(np.isfinite(x).all())
            for X in (np.vstack([x, x]) if n else np.zeros((2, 0)), x[::2]):
                assert has_nan(X) == bool(np.isnan(X).any())
                assert all_finite(X) == bool(np.isfinite(X).all())


@pytest.mark.parametrize("seed", range(3))
def test_acceptance_small_with_psi_gives_the_verdict_without_it(seed):
    """Acceptance.small decides "not small" from Psi alone on the user's unscaled problem
    (||Phi||_2 = sqrt(2 Psi) exactly); its answer is the full test's at points on both
    sides of the tolerance, and a scaled acceptance ignores Psi (it is of the scaled
    problem)."""
    from compass_sparse.nms.acceptance import Acceptance
    from compass_sparse.merit import fb_psi

    rng = np.random.default_rng(seed)
    n = 12
    lb, ub = np.zeros(n), np.full(n, np.inf)
    tol = 1e-6
    plain = Acceptance(lb, ub, tol)
    scaled = Acceptance(lb, ub, tol, np.full(n, 2.0), np.full(n, 0.5))
    seen = set()
    for size in (1e-9, 3e-7, 1e-6, 3e-6, 1e-2):
        z = np.abs(rng.standard_normal(n))
        f = size * rng.standard_normal(n) / np.sqrt(n)
        z[f > 0] = 0.0  # complementary up to the size of f
        phi = fb_phi(z, f, lb, ub)
        psi = fb_psi(phi)
        assert plain.small(z, f, phi, psi) == plain.small(z, f, phi)
        assert scaled.small(z, f, phi, psi) == scaled.small(z, f)
        seen.add(plain.small(z, f, phi))
    assert seen == {True, False}  # both sides of the tolerance were tried
