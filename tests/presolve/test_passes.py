"""One test (or a few) per reduction, on small problems built to contain it."""
import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.presolve import (PASS_NAMES, PresolveOptions, presolve, solve_1d,
                                     solve_with_presolve)
from compass_sparse.problem import MCP

from ._problems import linear_mcp
from ._ref_solver import ref_solve

INF = np.inf


def solve_ok(problem, **opts):
    sol = solve_with_presolve(problem, ref_solve, PresolveOptions(**opts) if opts else None)
    assert sol.infeasible is None
    assert sol.natural_residual <= 1e-8, sol.presolve.summary_line()
    return sol


def kinds(res):
    return [type(r).__name__ for r in res.stack.records]


def test_fixed_variable_removed_and_its_F_reported():
    M = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 5.0]])
    q = np.array([-1.0, 2.0, -3.0])
    p = linear_mcp(M, q, [0, 0.5, 0], [INF, 0.5, INF], declare=False)
    sol = solve_ok(p)
    assert sol.presolve.stats.passes["fixed_variables"].removed == 1
    assert sol.x[1] == 0.5
    # the fixed variable's F value is reported: F_1 = x0 + 3*0.5 + x2 + 2
    assert sol.F[1] == pytest.approx(sol.x[0] + 1.5 + sol.x[2] + 2.0)
    assert sol.F.shape == (3,)


@pytest.mark.parametrize("c, lb, ub, want", [(2.0, -1.0, 3.0, -1.0), (-2.0, -1.0, 3.0, 3.0)])
def test_empty_row_sends_variable_to_the_bound_its_sign_dictates(c, lb, ub, want):
    M = np.array([[0.0, 0.0], [1.0, 2.0]])
    M = sp.csc_matrix(M)
    p = linear_mcp(M, np.array([c, -1.0]), [lb, 0.0], [ub, INF])
    res = presolve(p)
    assert res.stats.passes["empty_rows"].removed >= 1
    sol = solve_ok(p)
    assert sol.x[0] == want


def test_empty_row_with_infinite_bound_is_infeasible_and_named():
    M = sp.csc_matrix(np.array([[0.0, 0.0], [1.0, 2.0]]))
    p = linear_mcp(M, np.array([2.0, -1.0]), [-INF, 0.0], [INF, INF],
                   names=["price", "output"])
    res = presolve(p)
    assert res.infeasible is not None
    assert "price" in res.infeasible.message and res.infeasible.variables == ["price"]
    assert res.infeasible.pass_name == "empty_rows"
    assert res.infeasible.rows == ["F(price)"]


def test_empty_row_zero_constant_keeps_variable_that_others_use():
    # F_0 = 0 (constant): z_0 is free within its bounds but row 1 depends on it -> kept
    M = sp.csc_matrix(np.array([[0.0, 0.0], [1.0, 2.0]]))
    p = linear_mcp(M, np.array([0.0, -1.0]), [0.0, 0.0], [1.0, INF])
    res = presolve(p, PresolveOptions(empty_columns=False, column_singletons=False))
    assert 0 in res.cols
    # with column singletons on, z_1 leaves first and then z_0 is in no row: fixed
    res = presolve(p)
    assert res.reduced is None and res.infeasible is None


def test_empty_column_boxed_variable_set_by_sign_in_postsolve():
    # column 0 empty (nothing depends on z_0); row 0 depends on z_1 (nonlinearly declared)
    M = np.array([[0.0, 1.0], [0.0, 2.0]])
    p = linear_mcp(M, np.array([0.0, -1.0]), [-1.0, 0.0], [1.0, INF],
                   cubic=np.array([0.0, 0.1]))
    res = presolve(p, PresolveOptions(singleton_rows=False, column_singletons=False,
                                      range_fixing=False))
    assert "EmptyColumns" in kinds(res)
    sol = solve_ok(p, singleton_rows=False, column_singletons=False, range_fixing=False)
    # F_0 = z_1 > 0 at the solution, so z_0 = l_0
    assert sol.F[0] > 0 and sol.x[0] == -1.0


def test_singleton_row_on_diagonal_fixes_the_unique_1d_solution():
    M = np.array([[2.0, 0.0, 0.0], [1.0, 3.0, 0.5], [0.0, 1.0, 4.0]])
    q = np.array([-3.0, -1.0, -2.0])
    p = linear_mcp(M, q, 0.0, INF)
    res = presolve(p, PresolveOptions(range_fixing=False))
    fx = [r for r in res.stack.records if getattr(r, "reason", "") == "singleton row"]
    assert fx and fx[0].cols[0] == 0 and fx[0].values[0] == pytest.approx(1.5)
    solve_ok(p)


def test_singleton_row_without_solution_is_infeasible():
    # F_0 = -z_0 - 1 < 0 for z_0 >= 0 and z_0 has no upper bound
    M = np.array([[-1.0, 0.0], [1.0, 1.0]])
    p = linear_mcp(M, np.array([-1.0, 0.0]), [0.0, 0.0], [INF, INF], names=["a", "b"])
    res = presolve(p)
    assert res.infeasible is not None
    assert res.infeasible.rows == ["F(a)"]


def test_singleton_row_with_several_solutions_not_fixed_when_others_depend_on_it():
    # F_0 = -z_0 + 1 on [0, 2]: solutions 0? F(0)=1>=0 yes; 2: F(2)=-1<=0 yes; 1 interior
    M = np.array([[-1.0, 0.0], [1.0, 2.0]])
    p = linear_mcp(M, np.array([1.0, -1.0]), [0.0, 0.0], [2.0, INF])
    res = presolve(p, PresolveOptions(range_fixing=False, column_singletons=False))
    assert 0 in res.cols
    assert solve_1d(-1.0, 1.0, 0.0, 2.0)[0] == "multiple"


def test_singleton_row_off_diagonal_with_free_partner_repairs():
    # row 0: -5 z_1 + 3.5 = 0 (z_0 free)  => z_1 = 0.7; z_0 re-paired with row 1
    M = np.array([[0.0, -5.0, 0.0], [5.0, 4.0, 1.0], [0.0, 1.0, 4.0]])
    q = np.array([3.5, -1.0, -2.0])
    p = linear_mcp(M, q, [-INF, 0.0, 0.0], [INF, INF, INF])
    res = presolve(p, PresolveOptions(max_rounds=1))
    assert "FixByEquation" in kinds(res)
    assert list(res.cols) == [0, 2] and list(res.rows) == [1, 2]
    assert res.reduced.eqn_names[0] == "F[1]" and res.reduced.var_names[0] == "x[0]"
    sol = solve_ok(p)
    assert sol.x[1] == pytest.approx(0.7)


def test_singleton_row_off_diagonal_outside_bounds_is_infeasible():
    M = np.array([[0.0, -5.0], [5.0, 4.0]])
    p = linear_mcp(M, np.array([-3.5, 0.0]), [-INF, 0.0], [INF, INF])  # z_1 = -0.7 < 0
    res = presolve(p)
    assert res.infeasible is not None and "outside its bounds" in res.infeasible.message


def test_singleton_row_off_diagonal_bounded_partner_does_nothing():
    M = np.array([[0.0, -5.0], [5.0, 4.0]])
    p = linear_mcp(M, np.array([3.5, 0.0]), [0.0, 0.0], [INF, INF])
    res = presolve(p, PresolveOptions(range_fixing=False, column_singletons=False,
                                      forcing_rows=False))
    assert res.stats.passes["singleton_rows"].removed == 0


def test_diagonal_column_singleton_with_nonlinear_row():
    # z_0 appears only in row 0 (coefficient 2); row 0 is nonlinear in z_1 (cubic)
    M = np.array([[2.0, 1.0, 0.0], [0.0, 3.0, 1.0], [0.0, 1.0, 4.0]])
    q = np.array([-1.0, -2.0, -1.0])
    cub = np.array([0.0, 0.3, 0.0])
    p = linear_mcp(M, q, [-INF, -INF, 0.0], [INF, INF, INF], cubic=cub)
    res = presolve(p, PresolveOptions(singleton_rows=False))
    assert "DiagonalColumnSingletons" in kinds(res)
    sol = solve_ok(p, singleton_rows=False)
    assert abs(sol.F[0]) <= 1e-10


def test_free_column_singleton_doubleton_equation():
    # row 0: 3 z_1 + 4 z_0 + z_2 - 1 = 0 (z_0 free); z_1 free appears only in row 0
    M = np.array([[4.0, 3.0, 1.0], [-3.0, 0.0, 0.0], [1.0, 0.0, 4.0]])
    M[1, 2] = 1.0
    q = np.array([-1.0, 2.0, -1.0])
    p = linear_mcp(M, q, [-INF, -INF, 0.0], [INF, INF, INF])
    res = presolve(p, PresolveOptions(singleton_rows=False))
    assert "FreeColumnSingletons" in kinds(res)
    sol = solve_ok(p, singleton_rows=False)
    ref = ref_solve(p)
    assert np.allclose(sol.x, ref.x, atol=1e-8)


def lp_kkt(A, b, c, Q=None):
    """KKT of min c'x + 0.5 x'Qx s.t. Ax >= b, x >= 0 as an MCP in (x, y) >= 0."""
    m, n = A.shape
    Q = sp.csr_matrix((n, n)) if Q is None else sp.csr_matrix(Q)
    A = sp.csr_matrix(A)
    M = sp.bmat([[Q, -A.T], [A, None]]).tocsc()
    return linear_mcp(M, np.concatenate([c, -b]), 0.0, INF)


def test_forcing_row_fixes_its_variables_and_postsolves_the_multiplier():
    # constraint 0: -x0 - 2 x1 >= 0 with x >= 0 forces x0 = x1 = 0; its multiplier y0 is
    # set in postsolve so that the reduced costs of x0, x1 have the right sign
    A = np.array([[-1.0, -2.0, 0.0], [1.0, 1.0, 1.0]])
    b = np.array([0.0, 1.0])
    c = np.array([-1.0, -3.0, 1.0])
    Q = np.diag([1.0, 1.0, 1.0])
    p = lp_kkt(A, b, c, Q)
    res = presolve(p)
    assert "ForcingRows" in kinds(res)
    sol = solve_ok(p)
    assert sol.x[0] == 0 and sol.x[1] == 0
    assert sol.F[0] >= -1e-12 and sol.F[1] >= -1e-12


def test_duplicate_rows_fix_the_weaker_constraints_multiplier():
    # x - 1 >= 0 and 2x - 1 >= 0: the second is implied strictly, so y2 = 0
    A = np.array([[1.0, 1.0], [2.0, 2.0], [1.0, 0.0]])
    b = np.array([1.0, 1.0, 0.2])
    c = np.array([1.0, 1.0])
    p = lp_kkt(A, b, c, np.eye(2))
    res = presolve(p, PresolveOptions(range_fixing=False, forcing_rows=False))
    assert res.stats.passes["duplicate_rows"].removed == 1
    fx = [r for r in res.stack.records if getattr(r, "reason", "") == "duplicate row"]
    assert fx[0].cols[0] == 3  # y for the row 2x1 + 2x2 >= 1
    solve_ok(p)


def test_duplicate_equations_are_reported():
    M = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [1.0, -1.0, 3.0]])
    p = linear_mcp(M, np.array([-1.0, -2.0, 0.0]), -INF, INF)
    res = presolve(p)
    assert any("proportional equations" in w for w in res.warnings)


def test_range_fixing_and_its_infeasibility():
    M = np.array([[4.0, 1.0, 2.0], [1.0, 3.0, 0.0], [0.0, 1.0, 4.0]])
    q = np.array([0.5, -1.0, -1.0])
    p = linear_mcp(M, q, 0.0, INF)
    res = presolve(p, PresolveOptions(singleton_rows=False))
    fx = [r for r in res.stack.records if getattr(r, "reason", "") == "range of F"]
    assert fx and 0 in fx[0].cols
    solve_ok(p)
    p2 = linear_mcp(M, q, [-INF, 0, 0], INF, names=["u", "v", "w"])
    res2 = presolve(p2, PresolveOptions(singleton_rows=False))
    # F_u >= 0.5 > 0 but u has no lower bound... unless u's range is unbounded (it is: u free)
    assert res2.infeasible is None
    M3 = np.array([[0.0, 1.0, 2.0], [1.0, 3.0, 0.0], [0.0, 1.0, 4.0]])
    p3 = linear_mcp(M3, q, [-INF, 0, 0], INF, names=["u", "v", "w"])
    res3 = presolve(p3, PresolveOptions(singleton_rows=False))
    assert res3.infeasible is not None and res3.infeasible.variables[0].startswith("u")
    assert "F(u)" in res3.infeasible.rows


def test_nonlinear_entries_are_never_used():
    # row 0 has one entry, declared nonlinear: no singleton-row fixing, no range fixing
    M = np.array([[1.0, 0.0], [1.0, 2.0]])
    p = linear_mcp(M, np.array([1.0, -1.0]), 0.0, INF, cubic=np.array([1.0, 0.0]))
    res = presolve(p, PresolveOptions(column_singletons=False))
    assert 0 in res.cols
    solve_ok(p)


def _falsely_declared(third_row: bool):
    """F_0 = z_0^2 + 1 - z_1 with the (0, 0) entry falsely declared constant; with
    ``third_row`` a correct linear singleton row F_2 = 3 z_2 - 1 that presolve removes."""
    n = 3 if third_row else 2
    calls = {"F": 0, "J": 0}

    def F(z):
        calls["F"] += 1
        f = [z[0] ** 2 + 1 - z[1], z[0] + 2 * z[1] - 1]
        return np.array(f + ([3 * z[2] - 1] if third_row else []))

    def J(z):
        calls["J"] += 1
        D = np.zeros((n, n))
        D[:2, :2] = [[2 * z[0], -1.0], [1.0, 2.0]]
        if third_row:
            D[2, 2] = 3.0
        return sp.csc_matrix(D)

    pattern = np.zeros((n, n))
    pattern[:2, :2] = 1.0
    if third_row:
        pattern[2, 2] = 1.0
    p = MCP(F, J, 0.0, INF, np.array([0.3, 0.2, 0.5][:n]), jac_sparsity=pattern,
            constant_jac=sp.csc_matrix(pattern))
    return p, calls


def test_wrong_linear_declaration_is_caught_by_verification():
    # a reduction rests on the declaration (row 2): the sample points are evaluated, the
    # wrong entry found, and the passes run again without it
    p, _ = _falsely_declared(third_row=True)
    res = presolve(p)
    assert res.warnings and "change value" in res.warnings[0]
    assert res.stats.removed == 1 and list(res.cols) == [0, 1]
    solve_ok(p)


def test_declared_linearity_is_verified_only_when_a_reduction_rests_on_it():
    # no reduction: no sample evaluations (only F at the start point and at the rounds'
    # base point), the same outcome as with the check
    p, calls = _falsely_declared(third_row=False)
    J0 = p.J(p.x0)
    calls["F"] = calls["J"] = 0
    res = presolve(p, J0=J0)
    assert res.stats.removed == 0 and calls["J"] == 0
    assert res.reduced is p
    checked = presolve(p, J0=J0, options=PresolveOptions(verify_linear=False))
    assert checked.stats.removed == 0


def test_pass_switches_and_counters():
    M = np.array([[2.0, 0.0, 0.0], [1.0, 3.0, 0.5], [0.0, 1.0, 4.0]])
    q = np.array([-3.0, -1.0, -2.0])
    p = linear_mcp(M, q, [0, 0, 1], [INF, INF, 1])
    off = PresolveOptions(**{k: False for k in PASS_NAMES})
    res = presolve(p, off)
    assert res.stats.removed == 0 and all(not s.enabled for s in res.stats.passes.values())
    res = presolve(p, PresolveOptions(singleton_rows=False))
    assert res.stats.passes["singleton_rows"].removed == 0
    assert res.stats.passes["fixed_variables"].removed == 1
    assert res.summary_line().startswith("Preprocessor removed ")
    with pytest.raises(ValueError):
        PresolveOptions.from_dict({"singleton_row": False})


def test_no_linear_structure_returns_the_problem_itself():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    p = linear_mcp(M, np.array([-1.0, -1.0]), 0.0, INF, declare=False)
    res = presolve(p)
    assert res.reduced is p and len(res.stack) == 0
    assert np.array_equal(res.postsolve(np.array([1.0, 2.0])), [1.0, 2.0])


def test_everything_removed():
    M = np.array([[2.0, 0.0], [0.0, 2.0]])
    p = linear_mcp(M, np.array([-1.0, 1.0]), 0.0, INF)
    sol = solve_with_presolve(p, ref_solve)
    assert sol.presolve.reduced is None and sol.inner is None
    assert np.allclose(sol.x, [0.5, 0.0]) and sol.natural_residual == 0


def test_jac_true_and_finite_difference_problems_are_wrapped():
    M = sp.csc_matrix(np.array([[2.0, 0.0, 0.0], [1.0, 3.0, 0.5], [0.0, 1.0, 4.0]]))
    q = np.array([-3.0, -1.0, -2.0])
    p1 = MCP(lambda z: (M @ z + q, M), True, 0.0, INF, np.zeros(3), constant_jac=M)
    p2 = MCP(lambda z: M @ z + q, None, 0.0, INF, np.zeros(3), jac_sparsity=M,
             constant_jac=M)
    for p in (p1, p2):
        sol = solve_with_presolve(p, ref_solve)
        assert sol.natural_residual <= 1e-8
        assert sol.presolve.stats.removed >= 1


def test_live_mask_is_shared_until_a_reduction_and_read_only():
    """The workspace's live-entry mask is computed once per state of the reduction (the
    passes ask for it before and after every call) and recomputed after one."""
    from compass_sparse.presolve._work import Workspace
    from compass_sparse.presolve.linear import declared_constant_mask

    M = np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]])
    p = linear_mcp(M, np.array([-1.0, -1.0, -1.0]), 0.0, np.inf)
    J0 = p.J(p.x0)
    opts = PresolveOptions()
    const = declared_constant_mask(p, J0, p.F(p.x0), opts, [], samples=[])
    ws = Workspace(p, opts, J0, const, [])
    a = ws.live_mask()
    assert ws.live_mask() is a and ws.live_nnz() == J0.nnz == 7
    with pytest.raises(ValueError):
        a[0] = False
    ws.fix(np.array([0]), np.array([0.0]), reason="test")
    b = ws.live_mask()
    assert b is not a and ws.live_nnz() == 7 - 3   # row 0 and column 0 leave
    np.testing.assert_array_equal(b, ws.row_active[ws.er] & ws.col_active[ws.ec])


@pytest.mark.parametrize("seed", range(5))
def test_compiled_recount_matches_the_array_formulas(seed):
    """The workspace's recount (counts, constants, activity bounds) runs in one compiled
    pass; it gives bit for bit what the bincounts and array formulas it replaces gave,
    with infinite bounds, entries below the zero tolerance, nonlinear entries and removed
    rows and columns."""
    from compass_sparse.presolve._work import Workspace

    rng = np.random.default_rng(seed)
    n = 40
    A = sp.random(n, n, density=0.15, random_state=seed, format="csc") + sp.identity(n)
    A = sp.csc_matrix(A)
    A.data *= rng.choice([-1.0, 1.0], A.nnz) * 10.0 ** rng.uniform(-3, 3, A.nnz)
    A.data[rng.random(A.nnz) < 0.05] = 1e-14  # below the zero tolerance
    q = rng.standard_normal(n)
    lb = np.where(rng.random(n) < 0.4, -INF, rng.uniform(-2, 0, n))
    ub = np.where(rng.random(n) < 0.4, INF, rng.uniform(0.5, 3, n))
    p = MCP(lambda z: A @ z + q + 0.1 * np.sin(z), lambda z: A, lb, ub,
            np.clip(rng.standard_normal(n), lb, ub))
    J0 = p.J(p.x0)
    const = rng.random(J0.nnz) < 0.7
    opts = PresolveOptions()
    ws = Workspace(p, opts, J0, const, [])
    for step in range(2):
        er, ec, ev = ws.er, ws.ec, ws.ev
        live = ws.live_mask()
        nz = live & ws.const & (np.abs(ev) > opts.zero_tolerance)
        nl = live & ~ws.const
        for got, want in ((ws.row_nnz, np.bincount(er[nz], minlength=n)),
                          (ws.row_nl, np.bincount(er[nl], minlength=n)),
                          (ws.col_nnz, np.bincount(ec[nz], minlength=n)),
                          (ws.col_nl, np.bincount(ec[nl], minlength=n))):
            np.testing.assert_array_equal(got, want)
            assert got.dtype == want.dtype
        f = p.F(ws.base)
        c = f - np.bincount(er[nz], weights=ev[nz] * ws.base[ec[nz]], minlength=n)
        a = ev[nz]
        lo_b, hi_b = ws.lb[ec[nz]], ws.ub[ec[nz]]
        tmin = np.where(a > 0, a * lo_b, a * hi_b)
        tmax = np.where(a > 0, a * hi_b, a * lo_b)
        rows = er[nz]
        mag = np.where(np.isfinite(tmin), np.abs(tmin), 0.0) + \
            np.where(np.isfinite(tmax), np.abs(tmax), 0.0)
        for got, want in ((ws.c, c),
                          (ws.fmin, c + np.bincount(rows, weights=tmin, minlength=n)),
                          (ws.fmax, c + np.bincount(rows, weights=tmax, minlength=n)),
                          (ws.scale, 1.0 + np.abs(c) + np.bincount(rows, weights=mag,
                                                                   minlength=n))):
            np.testing.assert_array_equal(got, want)
        # remove a few rows and columns, move the base point, and recount
        gone = rng.choice(np.flatnonzero(ws.col_active), 6, replace=False)
        ws.fix(gone, np.clip(np.zeros(6), lb[gone], ub[gone]), reason="test")
        ws.refresh()


def test_workspace_index_arrays_are_made_once_per_pattern_and_read_only():
    """The entry/row/column index arrays of the workspace depend on the pattern alone:
    two presolve runs of one model share them (read only); a J0 stored off the pattern
    gets its own."""
    from compass_sparse.presolve._work import Workspace

    M = np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]])
    p = linear_mcp(M, np.array([-1.0, -1.0, -1.0]), 0.0, np.inf)
    J0 = p.J(p.x0)
    opts = PresolveOptions()
    const = np.ones(J0.nnz, dtype=bool)
    a = Workspace(p, opts, J0, const, [])
    b = Workspace(p.with_start(np.ones(3)), opts, p.J(np.ones(3)), const, [])
    assert a.row_order is b.row_order and a.er is b.er and a.ec is b.ec
    with pytest.raises(ValueError):
        a.er[0] = 1
    np.testing.assert_array_equal(a.ec, [0, 0, 1, 1, 1, 2, 2])
    np.testing.assert_array_equal(a.row_ptr, [0, 2, 5, 7])
    # a J0 with a stored entry outside the pattern (a different structure): its own arrays
    J1 = sp.csc_matrix(M + np.diag([0.0, 0.0, 0.0]) + np.eye(3, k=2))
    c = Workspace(p, opts, J1, np.ones(J1.nnz, dtype=bool), [])
    assert c.er is not a.er and c.er.size == 8
