"""The scaling pass: row/column equilibration of J(x0) (compass_sparse.scaling)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import Status, solve_mcp
from compass_sparse.linalg.csc import without_duplicates
from compass_sparse.problem import MCP
from compass_sparse.scaling import (
    SPREAD_TRIGGER,
    _maxnorms,
    _spread,
    equilibrate,
    scale_problem,
    spread,
)


def _monotone(n, seed):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=0.2, random_state=seed).toarray()
    M = B - B.T + np.diag(rng.uniform(1, 2, n))  # positive definite
    q = rng.normal(size=n)
    return M, q


@pytest.mark.parametrize("k", [2, 4, 6, 8])
def test_equilibration_brings_row_and_column_norms_together(k):
    rng = np.random.default_rng(k)
    M, _ = _monotone(30, k)
    R = 10.0 ** rng.uniform(-k, k, 30)
    C = 10.0 ** rng.uniform(-k, k, 30)
    J = sp.csc_matrix(R[:, None] * M * C[None, :])
    sc = equilibrate(J)
    assert sc.spread_before > 10.0 ** k
    assert sc.spread_after <= 16.0  # powers of two, a few sweeps: within a small factor
    assert np.all(np.log2(sc.row) == np.round(np.log2(sc.row)))  # exact power-of-two factors


def test_scaled_problem_has_the_same_solutions_in_the_users_units():
    M, q = _monotone(12, 0)
    p = MCP(lambda z: M @ z + q, lambda z: sp.csc_matrix(M), 0.0, np.inf, np.ones(12))
    sc = equilibrate(sp.diags(10.0 ** np.arange(12)) @ sp.csc_matrix(M))
    g = scale_problem(p, sc)
    y = np.linspace(0, 1, 12)
    np.testing.assert_allclose(g.F(y), sc.row * (M @ (sc.col * y) + q))
    np.testing.assert_allclose(g.J(y).toarray(), sc.row[:, None] * M * sc.col[None, :])
    np.testing.assert_array_equal(g.lb, p.lb / sc.col)


def test_badly_row_scaled_problem_is_solved_with_the_scaling_pass_and_reported():
    n = 20
    M, q = _monotone(n, 3)
    rng = np.random.default_rng(5)
    S = 10.0 ** rng.uniform(-8, 2, n)  # rows in very different units
    ref = solve_mcp(lambda z: M @ z + q, lambda z: sp.csc_matrix(M), 0.0, np.inf, np.zeros(n),
                    options={"convergence_tolerance": 1e-12})
    assert ref.success

    def F(z):
        return S * (M @ z + q)

    def J(z):
        return sp.csc_matrix(S[:, None] * M)

    r = solve_mcp(F, J, 0.0, np.inf, np.zeros(n))
    assert r.passes["scaling"].ran and "spread" in r.passes["scaling"].reason
    assert r.status is Status.SOLVED
    assert np.max(np.abs(r.x - ref.x)) <= 1e-6
    nat = np.max(np.abs(r.x - np.clip(r.x - F(r.x), 0, np.inf)))
    assert nat <= 1e-6
    off = solve_mcp(F, J, 0.0, np.inf, np.zeros(n), options={"scaling": False})
    assert not off.passes["scaling"].ran and off.passes["scaling"].reason == "scaling off"


def test_scaling_pass_stays_off_for_a_well_scaled_jacobian():
    M, q = _monotone(10, 1)
    assert spread(sp.csc_matrix(M)) <= SPREAD_TRIGGER
    r = solve_mcp(lambda z: M @ z + q, lambda z: sp.csc_matrix(M), 0.0, np.inf, np.zeros(10))
    assert r.success and not r.passes["scaling"].ran


@pytest.mark.parametrize("n,density", [(1, 1.0), (6, 0.6), (50, 0.1)])
def test_compiled_scaling_passes_match_the_array_formulas(n, density):
    """The compiled max-norms of R A C and the entrywise R J C agree bit for bit with the
    array formulas they replace ((|a| r) c and (a r) c; a NaN entry poisons its row and
    column maxima as np.maximum does)."""
    from compass_sparse.linalg._csc_kernels import csc_scale, csc_scaled_abs_maxima

    rng = np.random.default_rng(n)
    A = sp.csc_matrix(sp.random(n, n, density=density, format="csc", random_state=n)
                      - 0.5 * sp.random(n, n, density=density, format="csc",
                                        random_state=n + 1))
    A.sum_duplicates()
    if A.nnz and n > 1:
        A.data[A.nnz // 2] = np.nan
    row = 2.0 ** rng.integers(-20, 20, n)
    col = 2.0 ** rng.integers(-20, 20, n)
    ecol = np.repeat(np.arange(n), np.diff(A.indptr))  # column of each stored entry
    rows, cols = np.zeros(n), np.zeros(n)
    csc_scaled_abs_maxima(A.indptr, A.indices, A.data, row, col, rows, cols)
    a = np.abs(A.data) * row[A.indices] * col[ecol]
    ref_r, ref_c = np.zeros(n), np.zeros(n)
    np.maximum.at(ref_r, A.indices, a)
    np.maximum.at(ref_c, ecol, a)
    assert np.array_equal(rows, ref_r, equal_nan=True)
    assert np.array_equal(cols, ref_c, equal_nan=True)
    out = np.empty(A.nnz)
    csc_scale(A.indptr, A.indices, A.data, row, col, out)
    assert np.array_equal(out, A.data * row[A.indices] * col[ecol], equal_nan=True)


def test_scale_entries_is_the_diagonal_products_and_undoes_itself():
    """diag(r) J diag(c) entry by entry, bit for bit what the two sparse products give;
    with power-of-two factors scaling by 1/r, 1/c restores J exactly (the acceptance test
    judges the user's J this way)."""
    from compass_sparse.scaling import scale_entries

    rng = np.random.default_rng(3)
    n = 40
    J = sp.csc_matrix(sp.random(n, n, density=0.1, random_state=3, format="csc")
                      + sp.identity(n))
    r = 2.0 ** rng.integers(-30, 30, n)
    c = 2.0 ** rng.integers(-30, 30, n)
    S = scale_entries(J, r, c)
    ref = sp.csc_matrix(sp.diags(r) @ J @ sp.diags(c))
    assert np.array_equal(S.indptr, J.indptr) and np.array_equal(S.indices, J.indices)
    assert np.array_equal(S.toarray(), ref.toarray())
    back = scale_entries(S, 1.0 / r, 1.0 / c)
    assert np.array_equal(back.data, J.data) and back.data is not S.data


def test_a_loop_of_scaled_solves_builds_the_newton_linearizer_once(monkeypatch):
    """The scaled evaluator shares the user evaluator's pattern object and its store of
    pattern-derived objects: R J C has J's pattern, so a loop of solves of one badly
    scaled model builds the linearizer's index arrays once (every solve did), with the
    same results."""
    import compass_sparse.nms.newton as nms

    n = 20
    M, q = _monotone(n, 3)
    S = 10.0 ** np.random.default_rng(5).uniform(-8, 2, n)
    p = MCP(lambda z: S * (M @ z + q), lambda z: sp.csc_matrix(S[:, None] * M), 0.0, np.inf,
            np.zeros(n))
    built = []
    real = nms.linearizer_for
    monkeypatch.setattr(nms, "linearizer_for", lambda J, P: built.append(1) or real(J, P))
    # (no crash: it solves this model, and a solve that the crash ends needs no linearizer)
    opt = {"crash_method": "none"}
    first = solve_mcp(p, options=opt)
    assert first.passes["scaling"].ran and first.status is Status.SOLVED and first.nit > 0
    for _ in range(3):
        again = solve_mcp(p.with_start(np.zeros(n)), options=opt)
        np.testing.assert_array_equal(again.x, first.x)
        assert (again.nit, again.minor_iterations) == (first.nit, first.minor_iterations)
    assert len(built) == 1
    sc = equilibrate(p.J(p.x0))
    g = scale_problem(p, sc)
    assert g.evaluator.pattern_ref is p.evaluator.pattern_ref


@pytest.mark.parametrize("seed", range(6))
def test_compiled_ruiz_sweeps_match_the_array_formulas(seed):
    """The Ruiz sweeps of equilibrate run in one compiled call; they give bit for bit the
    factors of the array formulas they replace (max-norms of R A C, then
    row /= sqrt(where(r > 0, r, 1)), the same for the columns), zero and NaN entries
    included."""
    from compass_sparse.linalg.csc import without_duplicates
    from compass_sparse.scaling import SWEEPS, _maxnorms, _ruiz_sweeps

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 80))
    A = sp.random(n, n, density=rng.uniform(0.02, 0.5), random_state=seed, format="csc")
    A.data *= 10.0 ** rng.uniform(-12, 12, A.nnz)
    if A.nnz > 2:
        A.data[0], A.data[-1] = np.nan, 0.0
    A = without_duplicates(A)
    row, col = np.ones(n), np.ones(n)
    for _ in range(SWEEPS):
        r, c = _maxnorms(A, row, col)
        row /= np.sqrt(np.where(r > 0, r, 1.0))
        col /= np.sqrt(np.where(c > 0, c, 1.0))
    got_r, got_c = np.ones(n), np.ones(n)
    _ruiz_sweeps(A.indptr, A.indices, A.data, got_r, got_c, SWEEPS)
    assert np.array_equal(got_r, row, equal_nan=True)
    assert np.array_equal(got_c, col, equal_nan=True)


def test_the_scaled_problem_keeps_the_problems_name_lists():
    """The scaled MCP names rows and variables with the user problem's own (checked)
    lists, not converted copies."""
    M, q = _monotone(5, 1)
    p = MCP(lambda z: M @ z + q, lambda z: sp.csc_matrix(M), 0.0, np.inf, np.ones(5),
            var_names=[f"v{i}" for i in range(5)], eqn_names=[f"e{i}" for i in range(5)])
    g = scale_problem(p, equilibrate(sp.diags(10.0 ** np.arange(5)) @ sp.csc_matrix(M)))
    assert g.var_names is p.var_names and g.eqn_names is p.eqn_names
    assert g.var_label(3) == "v3" and g.row_label(4) == "e4"


def test_scaled_jacobian_follows_a_pattern_that_grows_after_the_scaling():
    """The scaled evaluator shares the user evaluator's pattern; when an undeclared
    pattern grows (an entry that was zero at the start point and dropped), the scaled J
    still carries the new entry, with its value R J C."""
    S = np.array([1e4, 1.0, 1e-4])

    def J(z):
        D = S[:, None] * np.array([[3.0 * z[0] ** 2, 1.0, 0.0],
                                   [1.0, 2.0, 0.0],
                                   [0.0, 1.0, 1.0]])
        return sp.csc_matrix(D)  # drops the zero entry (0, 0) at z0 = 0

    p = MCP(lambda z: S * np.array([z[0] ** 3 + z[1], z[0] + 2 * z[1], z[1] + z[2]]), J,
            -np.inf, np.inf, np.zeros(3))
    J0 = p.J(p.x0)
    assert J0.nnz == 5
    sc = equilibrate(J0)
    g = scale_problem(p, sc)
    y = np.array([0.5, 0.2, -0.1]) / sc.col
    got = g.J(y).toarray()
    want = sc.row[:, None] * J(sc.col * y).toarray() * sc.col[None, :]
    np.testing.assert_array_equal(got, want)
    assert got[0, 0] != 0.0 and g.evaluator.pattern_ref.nnz == 6


def test_equilibrate_takes_the_spread_the_caller_has():
    """``before`` is spread(J), reported as is (the pass computed it already); the factors
    do not depend on it."""
    M, _ = _monotone(10, 2)
    J = sp.diags(10.0 ** np.arange(10)) @ sp.csc_matrix(M)
    a, b = equilibrate(J), equilibrate(J, before=spread(J))
    assert a.spread_before == b.spread_before == spread(J)
    np.testing.assert_array_equal(a.row, b.row)
    np.testing.assert_array_equal(a.col, b.col)


def test_scaling_keeps_a_large_finite_bound_that_the_scaled_problem_would_read_as_infinite():
    """J = diag(1e12, 1) is equilibrated with the column factor 2^-20 on x1, so the
    scaled problem's bound is u1 / 2^-20 = 1.05e21 for the user's u1 = 1e15.  The scaled
    problem was built through the bounds' validation, which reads |b| >= 1e20 as
    infinite: the upper bound vanished, the solve ran to the unconstrained root x1 = 2e15
    (outside the box) and failed, where the unscaled solve finds x1 = 1e15.  The scaled
    bounds are now exactly l / C and u / C."""
    def F(x):
        return np.array([1e12 * (x[0] - 2e15), x[1] - 1.0])

    def J(x):
        return sp.csc_matrix(np.diag([1e12, 1.0]))

    lb, ub = np.array([0.0, -np.inf]), np.array([1e15, np.inf])
    r = solve_mcp(F, J, lb, ub, np.array([1.0, 0.0]))
    assert r.passes["scaling"].ran
    assert r.success and r.x[0] == 1e15 and abs(r.x[1] - 1.0) <= 1e-9
    assert np.all(r.x >= lb) and np.all(r.x <= ub)
    p = MCP(F, J, lb, ub, np.array([1.0, 0.0]))
    s = equilibrate(J(p.x0))
    q = scale_problem(p, s)
    assert s.col[0] < 1e-5                                # the factor that lifts u1
    assert np.array_equal(q.ub, p.ub / s.col) and np.array_equal(q.lb, p.lb / s.col)
    assert np.isfinite(q.ub[0]) and q.ub[0] > 1e20


def test_failure_message_names_rows_with_the_users_residuals_not_the_scaled_ones():
    """F_0 = 1e6 (x_0^2 + 1) has no root: the solve ends at a stationary point with
    |Phi_0| = 1e6 at x_0 = 0, which the Result's residual report says.  The message,
    built by the solver on the scaled problem (J spread 2e6, so the scaling pass ran),
    named 'F[0] (|Phi| 9.77e+02)', the scaled row's value; it now names the user's."""
    import re

    def F(x):
        return np.array([1e6 * (x[0] ** 2 + 1.0), x[1] - 1.0])

    def J(x):
        return sp.csc_matrix(np.diag([2e6 * x[0], 1.0]))

    r = solve_mcp(F, J, np.full(2, -np.inf), np.full(2, np.inf), np.array([1.0, 0.0]))
    assert r.passes["scaling"].ran and not r.success
    named = dict(re.findall(r"(F\[\d+\]) \(\|Phi\| ([0-9.e+-]+)\)", r.message))
    worst_name, worst_phi, _ = r.residual.worst[0]
    assert worst_name in named
    assert float(named[worst_name]) == pytest.approx(worst_phi, rel=1e-2)


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


def test_maxnorms_equal_scipy_row_and_column_max_of_scaled_matrix():
    from compass_sparse import scaling

    rng = np.random.default_rng(11)
    for n in (1, 4, 25):
        A = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        A.data *= 10.0 ** rng.uniform(-9, 9, A.nnz) * rng.choice([-1.0, 1.0], A.nnz)
        row, col = 2.0 ** rng.integers(-6, 6, n), 2.0 ** rng.integers(-6, 6, n)
        r, c = scaling._maxnorms(A, row, col)
        B = abs(sp.diags(row) @ A @ sp.diags(col))
        np.testing.assert_array_equal(r, B.max(axis=1).toarray().ravel())
        np.testing.assert_array_equal(c, B.max(axis=0).toarray().ravel())


def test_maxnorm_spread_sums_duplicate_entries_first():
    from compass_sparse.scaling import spread

    # two stored entries (1, 1) of 3 and -3 cancel: the matrix is diag(1, 0) plus a
    # 1e-4 entry in row 1, column 0 -> row norms 1 and 1e-4
    A = sp.csc_matrix((np.array([1.0, 1e-4, 3.0, -3.0]), np.array([0, 1, 1, 1]),
                       np.array([0, 2, 4])), shape=(2, 2))
    assert spread(A) == pytest.approx(1e4)


def test_spread_of_positive_entries():
    from compass_sparse import scaling

    assert scaling._spread(np.array([0.0, 4.0, np.nan, 0.5, -3.0])) == 8.0
    assert scaling._spread(np.array([0.0, -1.0])) == 1.0


def test_scaled_solve_judges_its_result_on_the_user_problem_again():
    """When the scaling pass changed the problem the solver works on, its verdict (taken
    on the scaled problem) is not handed to the Result: the Result's verdict is a fresh
    judgement of the returned point on the user's problem, and agrees with one."""
    from compass_sparse import MCP, solve_mcp
    from compass_sparse.nms.acceptance import judge

    d = np.array([1e-5, 1.0, 1e5])
    q = np.array([-1e-5, 2.0, -3e5])
    F = lambda x: d * x + q  # noqa: E731
    J = lambda x: sp.diags(d, format="csc")  # noqa: E731
    res = solve_mcp(MCP(F, J, np.zeros(3), np.full(3, np.inf), np.ones(3)))
    assert res.passes["scaling"].ran
    assert res.success
    v = judge(res.x, F(res.x), res.lb, res.ub, res.tolerance, jac=J)
    assert v.solved
    np.testing.assert_allclose(res.x, [1.0, 0.0, 3.0], atol=1e-6)

