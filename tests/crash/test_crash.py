"""The projected-Newton crash pass (compass_sparse.crash) on small constructed problems."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.crash import crash
from compass_sparse.crash.outcome import RAISED
from compass_sparse.merit import normal_map_at


def _norm_nm(p, z):
    return float(np.linalg.norm(normal_map_at(z, p.F(z), p.lb, p.ub)[1]))


def test_crash_returns_its_best_iterate_when_a_nonmonotone_step_climbs():
    """Newton on arctan from 1.5 overshoots to -1.69 where |F| is larger (1.037 against
    0.983); the non-monotone reference (twice the start's residual) accepts the step, so
    the crash ended on a worse point than its start, and the solve continued from there
    (on the dynamic CGE model at n = 3e4 this turned a 4-iteration solve into a
    time-limit failure)."""
    n = 3
    p = cs.MCP(lambda x: np.arctan(x), lambda x: sp.diags(1.0 / (1.0 + x * x), format="csc"),
               -np.inf, np.inf, np.full(n, 1.5))
    z0 = p.x0
    cr = crash(p.evaluator, z0, p.lb, p.ub, cs.Options())
    # the crash hands on its best point: here the start (since crash.RAISED the climbing
    # step is not even taken: its ||Phi|| is above the start's)
    assert _norm_nm(p, cr.z) <= min([_norm_nm(p, z0)] + [row[3] for row in cr.log])
    np.testing.assert_array_equal(cr.z, z0)
    np.testing.assert_allclose(cr.f, p.F(cr.z))


def test_crash_stops_before_a_step_that_raises_the_merit_above_its_start():
    """Regression: the crash's search measures the normal map and accepts rises (twice the
    start's at first), so it went on through points whose ||Phi|| (the solver's merit)
    was above its start's: on the traffic equilibrium (n = 912) six steps 21.1 -> 36.8
    for 37 of 76 factorizations, then its start handed on; on the static CGE model with a
    50% output tax (n = 2024) sixteen steps through ||Phi|| up to 255 to a point from which
    the paths took 17705 pivots.  It now stops before such a step (crash.RAISED).  Newton
    on arctan from 1.5 overshoots to -1.69, where |F| is 1.037 against 0.983 (and the old
    crash went on climbing for 17 steps before it came back); with every basis change
    allowed, the crash now takes no step."""
    n = 3
    p = cs.MCP(lambda x: np.arctan(x), lambda x: sp.diags(1.0 / (1.0 + x * x), format="csc"),
               -np.inf, np.inf, np.full(n, 1.5))
    cr = crash(p.evaluator, p.x0, p.lb, p.ub, cs.Options(crash_nbchange_limit=0))
    assert cr.stop_reason == RAISED
    assert cr.iterations == 0 and cr.log == []
    np.testing.assert_array_equal(cr.z, p.x0)  # the start handed on
    # a crash whose steps lower ||Phi|| is not stopped: from 0.5 Newton converges
    p2 = cs.MCP(lambda x: np.arctan(x), lambda x: sp.diags(1.0 / (1.0 + x * x), format="csc"),
                -np.inf, np.inf, np.full(n, 0.5))
    cr2 = crash(p2.evaluator, p2.x0, p2.lb, p2.ub, cs.Options(crash_nbchange_limit=0))
    assert cr2.stop_reason != RAISED and cr2.iterations >= 1
    assert np.linalg.norm(np.arctan(cr2.z)) < np.linalg.norm(np.arctan(p2.x0))


def test_crash_perturbs_a_structurally_singular_reduced_jacobian_without_factoring_it():
    """J_II with an empty column is singular for every value of its entries: the crash
    goes straight to J_II + eps I (one factorization, not a failing one first -- at
    n = 3e4 that failing factorization alone took 40 s)."""
    n = 12

    def F(x):
        f = x - 2.0
        f[0] = x[1] - 2.0          # x[0] appears nowhere: an empty column
        return f

    def J(x):
        A = sp.lil_matrix((n, n))
        for i in range(1, n):
            A[i, i] = 1.0
        A[0, 1] = 1.0
        return A.tocsc()

    p = cs.MCP(F, J, -np.inf, np.inf, np.zeros(n))
    cr = crash(p.evaluator, p.x0, p.lb, p.ub, cs.Options(crash_iteration_limit=1))
    assert cr.iterations == 1
    assert cr.factorizations == 1
    assert _norm_nm(p, cr.z) < _norm_nm(p, p.x0)


def test_crash_steps_and_factorizations_are_reported_when_the_crash_finds_the_solution():
    """A crash trial point that solves the problem stops the solve from inside the crash;
    its steps and factorizations were then reported as 0 (the dynamic CGE model at
    n = 1e4: 'crash its 0, factorizations 0' after eight crash steps)."""
    n = 20
    rng = np.random.default_rng(5)
    A = sp.csc_matrix(np.eye(n) * 4.0 + rng.uniform(-1, 1, (n, n)) * 0.3)
    b = rng.uniform(1.0, 2.0, n)
    # affine on a box: the first crash step lands on the solution
    r = cs.solve_mcp(lambda x: A @ x - b, lambda x: A, -10.0, 10.0, np.zeros(n),
                     options={"crash_minimum_dimension": 1})
    assert r.success and r.nit == 0     # solved inside the crash
    st = r.passes["crash"]
    assert st.ran and st.iterations >= 1 and r.crash_iterations == st.iterations
    assert st.factorizations >= st.iterations and r.factorizations >= st.factorizations


def _dynamic_cge_crash(monkeypatch, **consts):
    import compass_sparse.crash.reduced as reduced
    from compass_sparse.generators.cge import ramsey_cge

    monkeypatch.undo()                    # the module's own constants, then these
    # the default LU whatever COMPASS_SPARSE_LU asks: the reuse holds SuperLU's factors
    # (the UMFPACK route keeps none), and another ordering takes other crash steps
    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    # this model's blocks (n = 1281, 6e3 entries) are small enough for KLU, which keeps
    # no factors (a KLU refactorization costs less than GMRES on old factors there: the
    # crash 9-13 ms against 21 ms); the reuse is that of the larger blocks, on SuperLU
    monkeypatch.setattr(reduced, "klu_suits", lambda J, lu: False)
    for k, v in consts.items():
        monkeypatch.setattr(reduced, k, v)
    p = ramsey_cge(periods=20, sectors=10, seed=0).with_shock(capital_tax=0.25).problem
    return crash(p.evaluator, p.x0, p.lb, p.ub, cs.Options())


def test_crash_steps_reuse_the_previous_factors_when_the_inactive_set_barely_moves(
        monkeypatch):
    """Each crash step factored its reduced Jacobian afresh; with a few indices changing
    (here 20 of 1281) GMRES on the previous factors gives the step (one factorization
    instead of three here, five of six at n = 3e4)."""
    fresh = _dynamic_cge_crash(monkeypatch, REUSE_MAX_CHANGES=-1)
    assert fresh.reused == 0 and fresh.factorizations == fresh.iterations >= 3
    cr = _dynamic_cge_crash(monkeypatch)
    assert cr.reused >= 1 and cr.factorizations + cr.reused == cr.iterations
    assert cr.iterations == fresh.iterations
    # the inexact steps (forcing term min(1e-4, ||nm||)) follow the exact ones closely
    for a, b in zip(cr.log, fresh.log):
        assert a[1:3] == b[1:3]                        # the same active-set changes
        assert abs(a[3] - b[3]) <= 1e-2 * b[3] + 1e-6   # residuals
    assert cr.fb_norm <= 2.0 * fresh.fb_norm + 1e-8


def test_crash_factors_afresh_when_gmres_on_the_old_factors_does_not_converge(monkeypatch):
    # one GMRES step cannot reach the forcing term: every step falls back to a fresh
    # factorization and the crash is the exact one
    fresh = _dynamic_cge_crash(monkeypatch, REUSE_MAX_CHANGES=-1)
    cr = _dynamic_cge_crash(monkeypatch, REUSE_ITERATIONS=1)
    assert cr.reused == 0 and cr.factorizations == fresh.factorizations
    assert [r[3] for r in cr.log] == [r[3] for r in fresh.log]


def test_crash_step_on_a_singular_reduced_jacobian_does_not_run_away():
    """At kojshin's start x0 = 0, J has a zero column.  The perturbed J_II + eps I with
    the first eps (~1e-7) gave a step of length ~1e7 that the search rejected through 13 F
    evaluations; such a step is now refused and eps grows until the step is at most
    CRASH_STEP_LIMIT (1 + max|z|) long."""

    import known_problems as kp

    from compass_sparse.crash.outcome import CRASH_STEP_LIMIT
    from compass_sparse.crash.reduced import solve_reduced as _solve_reduced

    p = kp.kojima_shindo()
    z = p.x0.astype(float)
    f = p.F(z)
    J = sp.csc_matrix(p.J(z))
    eps0 = 1e-8 * max(1.0, float(np.linalg.norm(f)))
    limit = CRASH_STEP_LIMIT * (1.0 + float(np.max(np.abs(z))))
    d, eps, nf, why, _ = _solve_reduced(J, f, True, eps0, step_limit=limit)
    assert why is None and np.max(np.abs(d)) <= limit and eps > eps0 and nf > 1
    # the step solves the perturbed system it was taken on
    np.testing.assert_allclose((J + eps * sp.identity(4)) @ d, f, rtol=1e-10, atol=1e-10)
    # without the limit, the first perturbation's step is the runaway one
    d0, eps_0, _, _, _ = _solve_reduced(J, f, True, eps0)
    assert eps_0 == eps0 and np.max(np.abs(d0)) > 1e5
    # in a solve: the crash takes steps, and the whole solve a handful of F evaluations
    r = cs.solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    assert r.success and r.passes["crash"].iterations >= 1
    assert r.nfev <= 15 and r.restarts == 0


def test_compiled_crash_active_set_matches_the_array_formulas():
    """The crash's active set and target in one compiled pass: the same sets and the same
    d as the array formulas it replaced, with zero and NaN diagonal entries, infinite
    bounds, points at their bounds and a NaN F."""
    from compass_sparse.crash._kernels import crash_active_set

    rng = np.random.default_rng(7)
    n = 400
    z = rng.normal(size=n)
    f = rng.normal(size=n) * 3
    lb = np.where(rng.random(n) < 0.3, -np.inf, z - rng.random(n))
    ub = np.where(rng.random(n) < 0.3, np.inf, z + rng.random(n))
    z[:20] = lb[:20] if np.all(np.isfinite(lb[:20])) else z[:20]
    dg = rng.normal(size=n)
    dg[::7] = 0.0
    dg[::11] = np.nan
    f[5] = np.nan
    g = np.abs(dg)
    g = np.where(g > 0, g, 1.0)
    xm = z - f / g
    act_l = xm <= lb
    act_u = (xm >= ub) & ~act_l
    d_ref = np.zeros(n)
    d_ref[act_l] = z[act_l] - lb[act_l]
    d_ref[act_u] = z[act_u] - ub[act_u]
    free = np.empty(n, dtype=bool)
    d = np.empty(n)
    crash_active_set(z, f, lb, ub, dg, free, d)
    np.testing.assert_array_equal(free, ~(act_l | act_u))
    np.testing.assert_array_equal(d, d_ref)


def test_dense_solve_of_the_crash_gives_the_bits_of_scipy_lu_factor_and_lu_solve():
    """The crash's reduced systems up to DENSE_SOLVE_MAX_N are solved by LAPACK's getrf and
    getrs (through the compiled gesv); the result must be bitwise that of
    scipy.linalg.lu_factor + lu_solve (the same two calls), and an exactly singular matrix
    must still raise."""
    import scipy.linalg as sla

    from compass_sparse.basis.backends import SingularFactorError, solve_sparse

    rng = np.random.default_rng(4)
    for n in (1, 7, 60, 150):
        A = sp.random(n, n, 0.1, format="csc", random_state=n) + 2.0 * sp.identity(
            n, format="csc")
        for b in (rng.standard_normal(n), rng.standard_normal((n, 2))):
            want = sla.lu_solve(sla.lu_factor(A.toarray()), b)
            got, held = solve_sparse(A, b, keep=True)
            assert held is None
            np.testing.assert_array_equal(got, want)
        D = A.toarray()
        np.testing.assert_array_equal(solve_sparse(D, b), want)  # a dense A: not modified
        np.testing.assert_array_equal(D, A.toarray())
    S = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]]))
    try:
        solve_sparse(S, np.ones(3))
    except SingularFactorError:
        pass
    else:
        raise AssertionError("a singular matrix was solved")
    assert solve_sparse(sp.csc_matrix((0, 0)), np.zeros(0)).shape == (0,)


def test_crash_norm_is_numpys_two_norm_bit_for_bit():
    """The crash's ||v||_2 (the square root of v.v, box.dot_norm, which the homotopy's
    corrector uses too) gives np.linalg.norm's bits, from underflowing to overflowing
    magnitudes."""
    from compass_sparse.box import dot_norm as _norm

    rng = np.random.default_rng(0)
    for n in (0, 1, 2, 5, 17, 1000):
        for e in (-200, -100, 0, 100, 200):
            v = rng.normal(size=n) * 10.0 ** e
            with np.errstate(over="ignore"):  # (1e200 squared: both give inf)
                assert _norm(v) == float(np.linalg.norm(v))


def test_crash_report_of_a_solve_whose_restart_ran_it_is_not_a_skip_reason():
    """With crash_method none the first run skips the crash and billups' restarts run it
    (their schedule turns it on); the report said ran=True with the reason
    'crash_method none'.  It now gives the stop reason of the crash that ran."""

    import known_problems as kp

    p = kp.billups()
    # (the restarts first: by default a problem this small goes to the homotopy at once)
    r = cs.solve_mcp(p.F, p.J, p.lb, p.ub, p.x0,
                     options={"crash_method": "none", "homotopy_after_restarts": 3})
    st = r.passes["crash"]
    assert r.restarts > 0 and st.ran and st.iterations > 0
    assert st.reason and "none" not in st.reason and "dimension" not in st.reason
    skipped = cs.solve_mcp(p.F, p.J, p.lb, p.ub, p.x0,
                           options={"crash_method": "none", "major_iteration_limit": 2})
    assert not skipped.passes["crash"].ran
    assert skipped.passes["crash"].reason == "crash_method none"


def test_structural_singularity_reads_nonzero_entries_only():
    """The crash's structural test: a block is structurally singular exactly when a
    maximum matching of its NONZERO entries (stored zeros dropped) leaves a column
    unmatched -- compared with the matching of scipy's copy without stored zeros (the
    test it replaced) on random patterns with stored zeros."""
    from compass_sparse.crash._kernels import structurally_singular
    from compass_sparse.linalg.matching import column_matching

    rng = np.random.default_rng(5)
    seen = set()
    for trial in range(300):
        n = int(rng.integers(1, 30))
        A = sp.random(n, n, density=float(rng.uniform(0.02, 0.3)), random_state=rng,
                      format="csc")
        A.data[rng.random(A.nnz) < 0.3] = 0.0   # stored zeros
        B = A.copy()
        B.eliminate_zeros()
        ref = bool(np.any(column_matching(B) < 0))
        assert structurally_singular(A.indptr, A.indices, A.data, n) == ref
        seen.add(ref)
    assert seen == {True, False}
    # a diagonal of stored zeros is singular however many entries are stored
    Z = sp.csc_matrix((np.zeros(3), (np.arange(3), np.arange(3))), shape=(3, 3))
    assert Z.nnz == 3 and structurally_singular(Z.indptr, Z.indices, Z.data, 3)


def test_crash_factors_small_sparse_blocks_by_klu_and_large_ones_by_superlu(monkeypatch):
    """A sparse block above the dense order (200) whose LU could not reach the size the
    basis reuses is factored by KLU, with the same steps (to working accuracy) and the
    same perturbations as SuperLU's route; a block with more entries, a chosen LU backend
    or the environment's choice keeps SuperLU (and its factors, for reuse)."""
    import compass_sparse.crash.reduced as crash_module
    from compass_sparse.crash.reduced import klu_suits as _klu_suits
    from compass_sparse.crash.reduced import solve_reduced as _solve_reduced
    from compass_sparse.linalg.direct import klu_available

    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    rng = np.random.default_rng(3)
    n = 400
    A = sp.random(n, n, density=3.0 / n, random_state=rng, format="csc")
    A = sp.csc_matrix(A + sp.identity(n) * 2.0)
    assert _klu_suits(A, ("auto", "auto")) == klu_available()
    assert not _klu_suits(A, ("superlu", "auto")) and not _klu_suits(A, ("auto", "amd"))
    dense_ish = sp.csc_matrix(sp.random(n, n, density=0.1, random_state=rng) +
                              sp.identity(n))
    assert not _klu_suits(dense_ish, ("auto", "auto"))  # its LU may be worth keeping
    assert not _klu_suits(sp.csc_matrix(sp.identity(150)), ("auto", "auto"))  # dense order
    monkeypatch.setenv("COMPASS_SPARSE_LU", "superlu:colamd")
    assert not _klu_suits(A, ("auto", "auto"))
    monkeypatch.delenv("COMPASS_SPARSE_LU")
    B = A.tolil()
    B[:, 7] = 0.0                                   # structurally singular: shifted
    B = sp.csc_matrix(B)
    b = rng.normal(size=n)
    for M, eps0 in ((A, 1e-8), (B, 1e-3)):
        d, eps, nf, why, held = _solve_reduced(M, b, True, eps0)
        monkeypatch.setattr(crash_module, "klu_suits", lambda J, lu: False)
        d_s, eps_s, nf_s, why_s, held_s = _solve_reduced(M, b, True, eps0)
        monkeypatch.undo()
        monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
        assert why is None and why_s is None and (eps, nf) == (eps_s, nf_s)
        np.testing.assert_allclose(d, d_s, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose((M + eps * sp.identity(n)) @ d, b, atol=1e-9)
        assert held_s is not None and (held is None) == klu_available()


@pytest.mark.parametrize("n, blocks", [(4, 0), (20, 1)])
def test_crash_limits_blas_threads_only_from_the_size_where_blas_could_use_threads(
        monkeypatch, n, blocks):
    """Below BLAS_LIMIT_MIN_N the crash leaves the BLAS thread count alone (OpenBLAS keeps
    kernels that small on one thread itself); from there on one block spans the crash."""
    import numpy as np

    from compass_sparse import solve_mcp
    from compass_sparse.crash import driver as C

    opened = []
    real = C.single_threaded_blas
    monkeypatch.setattr(C, "single_threaded_blas", lambda: opened.append(1) or real())
    rng = np.random.default_rng(3)
    A = rng.normal(size=(n, n)) * 0.1 + 3 * np.eye(n)
    b = rng.normal(size=n)
    r = solve_mcp(lambda x: A @ x + b, lambda x: A, np.zeros(n), np.full(n, np.inf),
                  np.ones(n), options={"crash_minimum_dimension": 1})
    assert r.success and r.passes["crash"].ran
    assert len(opened) == blocks

