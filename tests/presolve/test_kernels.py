"""The compiled candidate scans of the passes give the indices of the mask expressions
they replace (written out here as the reference), on random workspaces with infinite
bounds, infinite and NaN activity bounds, touched marks and inactive rows and columns."""
import numpy as np
import pytest

from compass_sparse.presolve import _kernels as K


def _state(seed, n=60):
    rng = np.random.default_rng(seed)
    lb = rng.choice([-np.inf, 0.0, -1.0, 2.0], n)
    ub = np.where(rng.random(n) < 0.3, lb, rng.choice([np.inf, 1.0, 3.0], n))
    ub = np.maximum(ub, lb)
    fmin = rng.choice([-np.inf, -1e-9, 0.0, 1e-9, 0.5, -2.0, np.nan], n)
    fmax = rng.choice([np.inf, 1e-9, 0.0, -1e-9, -0.5, 2.0, np.nan], n)
    return dict(
        n=n, lb=lb, ub=ub, fmin=fmin, fmax=fmax,
        scale=rng.choice([1.0, 10.0, 1e3], n),
        linear=rng.random(n) < 0.7, col_active=rng.random(n) < 0.8,
        touched_row=rng.random(n) < 0.2, touched_col=rng.random(n) < 0.2,
        row_nnz=rng.integers(0, 4, n), col_nnz=rng.integers(0, 3, n),
        col_nl=rng.integers(0, 2, n) * (rng.random(n) < 0.3),
        partner_var=rng.permutation(n))


@pytest.mark.parametrize("seed", range(20))
def test_candidate_scans_select_the_rows_and_columns_of_the_mask_expressions(seed):
    s = _state(seed)
    lb, ub, fmin, fmax = s["lb"], s["ub"], s["fmin"], s["fmax"]
    linear, tr, tc = s["linear"], s["touched_row"], s["touched_col"]
    act, rnnz, cnnz, cnl = s["col_active"], s["row_nnz"], s["col_nnz"], s["col_nl"]
    np.testing.assert_array_equal(K.fixed_columns(act, lb, ub, tc),
                                  np.flatnonzero(act & (lb == ub) & ~tc))
    for lo, hi in ((0, 0), (1, 1), (1, s["n"])):
        np.testing.assert_array_equal(K.linear_rows_with(linear, rnnz, tr, lo, hi),
                                      np.flatnonzero(linear & (rnnz >= lo) & (rnnz <= hi) & ~tr))
    np.testing.assert_array_equal(
        K.linear_columns_with(act, cnnz, cnl, tc, lb, ub, 0, True),
        np.flatnonzero(act & (cnnz == 0) & (cnl == 0) & np.isfinite(lb) & np.isfinite(ub)
                       & ~tc))
    np.testing.assert_array_equal(
        K.linear_columns_with(act, cnnz, cnl, tc, lb, ub, 1, False),
        np.flatnonzero(act & (cnnz == 1) & (cnl == 0) & ~tc))
    ftol = 1e-8
    t = ftol * s["scale"]
    p = s["partner_var"]
    cand = linear & (rnnz >= 1) & ~tr
    with np.errstate(invalid="ignore"):
        up = cand & (ub[p] == np.inf) & np.isfinite(fmax) & (np.abs(fmax) <= t)
        dn = cand & (lb[p] == -np.inf) & np.isfinite(fmin) & (np.abs(fmin) <= t)
        up_k = np.empty(s["n"], dtype=bool)
        np.testing.assert_array_equal(
            K.forcing_candidates(linear, rnnz, tr, p, lb, ub, fmin, fmax, s["scale"], ftol,
                                 up_k), np.flatnonzero(up | dn))
        np.testing.assert_array_equal(up_k, up)
        pos = linear & ~tr & (fmin > t)
        neg = linear & ~tr & (fmax < -t)
        low_k = np.empty(s["n"], dtype=bool)
        np.testing.assert_array_equal(
            K.range_candidates(linear, tr, fmin, fmax, s["scale"], ftol, low_k),
            np.flatnonzero(pos | neg))
        np.testing.assert_array_equal(low_k, pos)


@pytest.mark.parametrize("seed", range(10))
def test_touch_and_masks_and_duplicate_keys_give_the_array_formulas_bits(seed):
    import scipy.sparse as sp

    from compass_sparse.presolve._work import _index_arrays

    rng = np.random.default_rng(100 + seed)
    n = 40
    J = sp.random(n, n, density=0.15, random_state=rng, format="csc")
    J.data[rng.random(J.nnz) < 0.1] = 0.0  # stored zeros (below any tolerance)
    J.sum_duplicates()
    ec, er, col_ptr, row_order, row_ptr = _index_arrays(J)  # the workspace's index arrays
    ev = J.data.copy()

    # touch: rows of the columns' entries and columns of the rows' entries
    cols = rng.choice(n, 3, replace=False).astype(np.intp)
    rows = rng.choice(n, 2, replace=False).astype(np.intp)
    tc, tr = np.zeros(n, bool), np.zeros(n, bool)
    K.touch(cols, rows, col_ptr, er, row_ptr, row_order, ec, tc, tr)
    rc, rr = np.zeros(n, bool), np.zeros(n, bool)
    rc[cols] = rr[rows] = True
    for j in cols:
        rr[er[col_ptr[j]:col_ptr[j + 1]]] = True
    for i in rows:
        rc[ec[er == i]] = True
    np.testing.assert_array_equal(tc, rc)
    np.testing.assert_array_equal(tr, rr)

    live = rng.random(ev.size) < 0.8
    const = rng.random(ev.size) < 0.7
    nz, nl = np.empty(ev.size, bool), np.empty(ev.size, bool)
    K.refresh_masks(live, const, ev, 1e-3, nz, nl)
    np.testing.assert_array_equal(nz, live & const & (np.abs(ev) > 1e-3))
    np.testing.assert_array_equal(nl, live & ~const)

    # the duplicate-rows keys: bincount over the entries of the candidate rows
    cand = rng.random(n) < 0.6
    w1, w2 = rng.random(n) + 0.5, rng.random(n) + 0.5
    pos = row_order[nz[row_order] & cand[er[row_order]]]
    r, c, v = er[pos], ec[pos], ev[pos]
    first = np.ones(r.size, dtype=bool)
    first[1:] = r[1:] != r[:-1]
    lead = np.zeros(n)
    lead[r[first]] = v[first]
    h1_ref = np.bincount(r, weights=w1[c], minlength=n)
    h2_ref = np.bincount(r, weights=w2[c] * (v / lead[r]), minlength=n)
    h1, h2 = np.zeros(n), np.zeros(n)
    K.duplicate_row_keys(row_order, nz, er, ec, ev, cand, w1, w2, h1, h2)
    assert h1.tobytes() == h1_ref.tobytes()
    assert h2.tobytes() == h2_ref.tobytes()


def _screen_and_passes(problem):
    """(the screen's (fixed, singletons, rounds) or None, presolve result of the passes)."""
    from compass_sparse.presolve import core, presolve

    f0 = problem.F(problem.x0)
    J0 = problem.J(problem.x0)
    opts = core.PresolveOptions.coerce(None)
    const = core.declared_constant_mask(problem, J0, f0, opts, [], samples=[])
    simple = core._simple_reductions_only(problem, opts, J0, const)
    saved = core._simple_reductions_only
    core._simple_reductions_only = lambda *a: None  # the passes themselves
    try:
        full = presolve(problem, f0=f0, J0=J0, leave_simple_to_solver=True)
    finally:
        core._simple_reductions_only = saved
    return simple, full


def _feature_problems():
    from presolve._problems import ALL_FEATS, build

    for seed in range(12):
        yield build(seed, 40, ("fixed",))[0]          # fixing l = u is all there is
        yield build(seed, 40, ("fixed", "cubic"))[0]
        for feat in ALL_FEATS:                          # one reduction beside the fixed ones
            yield build(seed, 40, ("fixed", feat))[0]
        yield build(seed, 40)[0]


def _random_problems(count):
    """Sparse affine-plus-cubic problems with a few declared-constant entries (so a few
    linear rows), random bounds with some l = u, and a start point in the box: most of
    them give the passes nothing but the fixed variables, some a reduction."""
    from compass_sparse.problem import MCP
    import scipy.sparse as sp

    for seed in range(count):
        rng = np.random.default_rng(500 + seed)
        n = int(rng.integers(5, 40))
        A = sp.random(n, n, density=0.15, random_state=rng, format="csc") + sp.eye(n) * 3
        A = sp.csc_matrix(A)
        A.sum_duplicates()
        const = sp.csc_matrix((rng.random(A.nnz) < rng.choice([0.1, 0.5, 0.9]),
                               A.indices.copy(), A.indptr.copy()), shape=(n, n))
        cub = np.where(rng.random(n) < 0.5, 1.0, 0.0)
        q = rng.normal(size=n)
        lb = rng.choice([-np.inf, 0.0, -1.0], n)
        ub = rng.choice([np.inf, 2.0, 5.0], n)
        fix = rng.random(n) < 0.15
        ub[fix] = lb[fix] = np.where(np.isfinite(lb[fix]), lb[fix], 0.5)
        x0 = np.clip(rng.normal(size=n), lb, ub)
        # cubic terms on diagonal entries that are not declared constant
        dmask = np.asarray(const.diagonal(), dtype=bool)
        cub[dmask] = 0.0

        def F(x, A=A, q=q, cub=cub):
            return A @ x + q + cub * x ** 3

        def J(x, A=A, cub=cub):
            return sp.csc_matrix(A + sp.diags(3 * cub * x ** 2))

        yield MCP(F, J, lb, ub, x0, jac_sparsity=A, constant_jac=const)


def test_screen_of_simple_reductions_is_exact_against_the_passes():
    """The screen's answer "only fixed variables and diagonal column singletons" is exact:
    the passes find those (as many, in as many rounds) and nothing else -- checked on
    the preprocessor's feature problems (each with one reduction beside its fixed
    variables), random problems with a few linear rows, and CGE models; and it does
    answer on the Ramsey models (fixed numeraire) and the static ones (numeraire and a
    diagonal column singleton, two rounds)."""
    from compass_sparse.generators.cge import ramsey_cge, size_for, static_cge

    problems = list(_feature_problems()) + list(_random_problems(150))
    cge = [ramsey_cge(periods=T, sectors=s).with_shock(capital_tax=0.25).problem
           for T in (5, 11, 40) for s in (1, 2)]
    cge += [static_cge(**size_for(n)).problem for n in (91, 247, 759)]
    answered = 0
    for p in problems + cge:
        simple, full = _screen_and_passes(p)
        if simple is not None:
            answered += 1
            assert full.infeasible is None and full.reduced is p and full.warnings == []
            assert simple == (full.stats.kept_fixed, full.stats.kept_singletons,
                              full.stats.rounds)
        elif p in cge:
            pytest.fail(f"no answer on a CGE model: {full.summary_line()}")
    assert answered >= 20


def test_screened_presolve_returns_the_result_of_the_passes():
    """presolve with the screen returns what the passes return: the problem itself, the
    same kept counts, rounds and evaluations; the solve around it succeeds."""
    from compass_sparse import solve_mcp
    from compass_sparse.generators.cge import ramsey_cge, size_for, static_cge
    from compass_sparse.presolve import presolve

    for p in (ramsey_cge(periods=11, sectors=1).with_shock(capital_tax=0.25).problem,
              static_cge(**size_for(91)).with_shock(output_tax=0.25).problem):
        simple, full = _screen_and_passes(p)
        fast = presolve(p, f0=p.F(p.x0), J0=p.J(p.x0), leave_simple_to_solver=True)
        assert simple is not None and fast.reduced is p and full.reduced is p
        for k in ("kept_fixed", "kept_singletons", "rounds", "f_evals", "n_reduced",
                  "nnz_reduced", "n_original", "nnz_original"):
            assert getattr(fast.stats, k) == getattr(full.stats, k), k
        assert fast.summary_line().split(" in ")[0] == full.summary_line().split(" in ")[0]
        r = solve_mcp(p)
        assert r.success and r.passes["presolve"].ran
