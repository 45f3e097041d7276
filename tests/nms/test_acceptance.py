"""The acceptance test of a point (compass_sparse.nms.acceptance): both residuals within the
tolerance and no flat tail of F (the Newton step still to go), read on the user's
problem when the solver works on a scaled one."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import MCP, merit, solve_mcp
from compass_sparse.linalg.csc import without_duplicates
from compass_sparse.merit import fb_phi
from compass_sparse.nms.acceptance import FLAT_STEP_RTOL, judge, live_rows

TOL = 1e-6


# ------------------------------------------------------------------ defect: flat tails
FLAT = {
    "exp(-x)": (lambda x: np.exp(-x), lambda x: sp.csc_matrix([[-np.exp(-x[0])]])),
    "-1/(1+x)": (lambda x: -1 / (1 + x), lambda x: sp.csc_matrix([[1 / (1 + x[0]) ** 2]])),
    "atan(x)-pi/2": (lambda x: np.arctan(x) - np.pi / 2,
                     lambda x: sp.csc_matrix([[1 / (1 + x[0] ** 2)]])),
}


@pytest.mark.parametrize("x", [14.0, 30.0, 100.0, 500.0])
def test_flat_step_threshold_rejects_exp_tail_at_every_distance(x):
    F, J = FLAT["exp(-x)"]
    v = judge(np.array([x]), F(np.array([x])), np.zeros(1), np.full(1, np.inf), TOL,
              jac=J)
    assert v.small_residual and not v.solved
    assert v.step == pytest.approx(1.0)  # the Newton step still to go: 1 / (1 + x) > 1e-3


@pytest.mark.parametrize("scale, accepted", [(1.0, True), (1e-3, True), (1e-6, True),
                                             (1e-7, False), (1e-8, False)])
def test_flat_step_threshold_separates_converged_rows_from_flat_ones(scale, accepted):
    # F = scale * (x - 2), free, residual r = 1e-9 at x = 2 + r / scale: the Newton step
    # still to go is d = r / scale, accepted iff d <= FLAT_STEP_RTOL * (1 + |x|) ~ 3e-3
    lb, ub = np.full(1, -np.inf), np.full(1, np.inf)
    J = sp.csc_matrix([[scale]])
    x = np.array([2.0 + 1e-9 / scale])
    v = judge(x, scale * (x - 2.0), lb, ub, TOL, jac=lambda y: J)
    assert v.small_residual and v.solved is accepted
    assert bool(1e-9 / scale <= FLAT_STEP_RTOL * (1 + x[0])) is accepted




# --------------------------------------------------- verdicts of a scaled solve
def _scaled_acceptance(J_user, f_user=None, raise_J=False):
    """An Acceptance of a 3-variable problem scaled by powers of two, with the scaled
    evaluator's guarded jac (the old route) and the user's J read directly."""
    from compass_sparse.nms.acceptance import Acceptance
    from compass_sparse.problem.evaluator import Evaluator, ScaledEvaluator
    from compass_sparse.scaling import Scaling
    from compass_sparse.solve import _UserJacobian

    n = 3

    def jac(x):
        if raise_J:
            raise ValueError("no J here")
        return J_user

    parent = Evaluator(lambda x: np.zeros(n), jac, n, pattern=sp.csc_matrix(np.ones((n, n))))
    sc = Scaling(np.array([4.0, 0.5, 2.0 ** 600]), np.array([0.25, 8.0, 1.0]), 1.0, 1.0)
    scaled = ScaledEvaluator(parent, sc)
    lb, ub = np.zeros(n), np.full(n, np.inf)
    direct = Acceptance(lb, ub, 1e-6, sc.row, sc.col, user_jac=_UserJacobian(parent, scaled, sc))
    old = Acceptance(lb, ub, 1e-6, sc.row, sc.col)
    return parent, scaled, sc, direct, old


@pytest.mark.parametrize("case", ["solved", "flat", "J fails", "R J C overflows"])
def test_scaled_verdict_reads_the_users_jacobian_as_the_scaled_route_did(case):
    """With a scaling, the verdict reads the user's J itself (no R^-1 (R J C) C^-1): the
    same verdict, evaluations, counts and rejections as through the scaled evaluator; it
    says it may stand for the Result's verdict exactly when J was read and obtained."""
    J = sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [0.0, 3.0, 0.0], [1.0, 0.0, 5.0]]))
    if case == "flat":
        J = sp.csc_matrix(J * 1e-9)
    if case == "R J C overflows":  # finite J, but row 2's factor 2^600 overflows it
        J = sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [0.0, 3.0, 0.0], [1e300, 0.0, 5.0]]))
    outs = []
    for route in ("direct", "old"):
        parent, scaled, sc, direct, old = _scaled_acceptance(J, raise_J=case == "J fails")
        acc = direct if route == "direct" else old
        zu = np.array([1.0, 2.0, 0.5])
        fu = np.array([1e-8, -2e-8, 1e-8]) if case != "flat" else np.array([1e-8, 0, 0])
        z, f = zu / sc.col, fu * sc.row
        v = acc.judge(z, f, jac=lambda y: scaled.jac(y, f), small=True)
        outs.append((v, parent.counters.njev, parent.counters.domain_errors, v.reusable))
    (vd, nd, dd, rd), (vo, no, do, ro) = outs
    assert vd == vo and nd == no and dd == do
    assert not ro  # the old route read J through the scaling
    assert rd is (case in ("solved", "flat"))
    if case == "flat":
        assert not vd.solved and vd.small_residual and vd.flat_row >= 0
    if case == "solved":
        assert vd.solved


def test_scale_test_of_a_non_canonical_jacobian_is_that_of_its_canonical_form():
    """The compiled canonical test lets a canonical J straight through; an unsorted one,
    one with duplicates (summed) or with int64 indices gets the verdict of its canonical
    form, unchanged."""
    from compass_sparse.merit import fb_phi
    from compass_sparse.nms.acceptance import _scale_test

    n = 3
    z, f = np.array([1.0, 2.0, 0.0]), np.array([1e-8, -1e-8, 2e-8])
    lb, ub = np.zeros(n), np.full(n, np.inf)
    phi = fb_phi(z, f, lb, ub)
    ref = sp.csc_matrix(np.array([[1e-9, 1.0, 0.0], [0.0, 2e-9, 0.0], [1.0, 0.0, 3.0]]))
    dup = sp.csc_matrix((np.array([1e-9, 0.5, 0.5, 1.0, 2e-9, 3.0]),
                         np.array([0, 2, 2, 0, 1, 2], np.int32),
                         np.array([0, 3, 5, 6], np.int32)), shape=(n, n))
    uns = sp.csc_matrix((np.array([1.0, 1e-9, 2e-9, 1.0, 3.0]), np.array([2, 0, 1, 0, 2], np.int32),
                         np.array([0, 2, 4, 5], np.int32)), shape=(n, n))
    i64 = ref.copy()
    i64.indices, i64.indptr = i64.indices.astype(np.int64), i64.indptr.astype(np.int64)
    want = _scale_test(z, f, lb, ub, phi, ref)
    for J in (dup, uns, i64):
        assert _scale_test(z, f, lb, ub, phi, J) == want
    assert not want.solved  # the flat row 1 decides: the forms must agree on it
    assert dup.nnz == 6  # the caller's matrix is not summed in place


def test_residual_test_asks_the_natural_residual_first_with_the_same_answer():
    """Without Phi at hand the natural residual is tested first: the answer is still the
    conjunction of both tests, on points where either, both or none fails (NaN too)."""
    from compass_sparse.merit import fb_phi, min_map
    from compass_sparse.nms.acceptance import residuals_small

    rng = np.random.default_rng(1)
    n = 20
    lb = np.where(rng.random(n) < 0.5, 0.0, -np.inf)
    ub = np.where(rng.random(n) < 0.3, 1.0, np.inf)
    seen = set()
    for trial in range(400):
        z = np.clip(rng.standard_normal(n), lb, ub)
        f = rng.standard_normal(n) * 10.0 ** rng.uniform(-12, -5)
        if trial % 50 == 0:
            f[3] = np.nan
        tol = 10.0 ** rng.uniform(-10, -4)
        phi = fb_phi(z, f, lb, ub)
        a = not float(np.sqrt(np.dot(phi, phi))) > tol
        b = bool((np.abs(min_map(z, f, lb, ub)) <= tol).all())
        seen.add((a, b))
        assert residuals_small(z, f, lb, ub, tol) == (a and b)
        assert residuals_small(z, f, lb, ub, tol, phi=phi) == (a and b)
    assert len(seen) >= 3


def _cournot():
    def F(q):
        return np.array([1.0, 2.0]) - (10.0 - q.sum()) + q

    return MCP(F, lambda q: np.array([[2.0, 1.0], [1.0, 2.0]]), 0.0, np.inf, np.zeros(2))


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
    two = flat_step_kernel(z, f, lb, ub, phi, da, db, J.indptr, J.indices, J.data,
                           np.zeros(n), np.empty(n), np.empty(n))
    one = scale_test_kernel(z, f, lb, ub, phi, J.indptr, J.indices, J.data)
    assert one[0] == two[0]
    for a, b in zip(one[1:], two[1:]):
        assert a == b or (np.isnan(a) and np.isnan(b))


@pytest.mark.parametrize("seed", range(3))
def test_acceptance_small_with_psi_gives_the_verdict_without_it(seed):
    """Acceptance.small decides "not small" from Psi alone on the user's unscaled problem
    (||Phi||_2 = sqrt(2 Psi) exactly); its answer is the full test's at points on both
    sides of the tolerance, and a scaled acceptance ignores Psi (it is of the scaled
    problem)."""
    from compass_sparse.merit import fb_psi
    from compass_sparse.nms.acceptance import Acceptance

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


def _random_box(rng, n):
    lb = np.where(rng.random(n) < 0.5, -np.inf, rng.standard_normal(n))
    ub = np.where(rng.random(n) < 0.5, np.inf, np.nan_to_num(lb, neginf=0.0)
                  + np.abs(rng.standard_normal(n)))
    return lb, ub


def test_flat_tail_verdict_same_for_duplicate_csr_and_canonical_csc_jacobian():
    from compass_sparse.nms.acceptance import judge

    z = np.array([1.0, 2.0])
    f = np.array([1e-9, -1e-9])
    canonical = sp.csc_matrix(np.array([[1e-12, 0.0], [0.0, 2.0]]))
    # the same matrix with the (0, 0) entry split in two stored parts, as CSR
    dup = sp.csr_matrix((np.array([3e-12, -2e-12, 2.0]), np.array([0, 0, 1]),
                         np.array([0, 2, 3])), shape=(2, 2))
    a = judge(z, f, np.zeros(2), np.full(2, np.inf), 1e-6, jac=lambda _: canonical)
    b = judge(z, f, np.zeros(2), np.full(2, np.inf), 1e-6, jac=lambda _: dup)
    assert not a.solved and a.small_residual and a.flat_row == 0
    assert (b.solved, b.small_residual, b.flat_row) == (a.solved, a.small_residual, a.flat_row)
    assert b.step == pytest.approx(a.step, rel=1e-9)


def test_verdict_shared_by_the_solver_and_the_result_agrees_with_a_fresh_judgement():
    """The acceptance verdict that stops the solve is reused by the Result (not taken
    twice); on every known problem it is the verdict a fresh judgement of the returned
    point gives on the user's problem."""
    import known_problems as kp

    from compass_sparse import MCP, solve_mcp
    from compass_sparse.nms.acceptance import judge

    makers = dict(kp.ALL_SOLVABLE)
    makers.update(sqrt_ncp=kp.sqrt_ncp, billups=kp.billups)
    for name, make in makers.items():
        p = make()
        res = solve_mcp(MCP(p.F, p.J, p.lb, p.ub, p.x0))
        f = np.asarray(p.F(res.x), dtype=float)
        v = judge(res.x, f, res.lb, res.ub, res.tolerance, jac=lambda y: sp.csc_matrix(p.J(y)))
        assert v.solved == res.success, name
        assert res.success, name


@pytest.mark.parametrize("seed", range(6))
def test_compiled_scale_test_gives_the_array_formula_verdict(seed):
    """The compiled flat-step test returns the verdict, the row and the step of the array
    formulas, on random sparse Jacobians with rows of every scale (flat rows included)
    and points at and between bounds."""
    from compass_sparse.nms.acceptance import _scale_test, _scale_test_arrays

    rng = np.random.default_rng(seed)
    n = 30
    lb, ub = _random_box(rng, n)
    z = np.clip(rng.standard_normal(n) * 10.0, lb, ub)
    at = rng.random(n) < 0.3
    z[at] = np.where(np.isfinite(lb), lb, z)[at]
    f = rng.standard_normal(n) * 10.0 ** rng.uniform(-12, -6, n)
    f[rng.random(n) < 0.2] = 0.0
    J = sp.random(n, n, density=0.2, random_state=seed, format="csc")
    J.data *= 10.0 ** rng.uniform(-9, 3, J.nnz)
    J = (J + sp.diags(rng.standard_normal(n) * (rng.random(n) < 0.7))).tocsc()
    # rows scaled down to 1e-14: F flat there, a Newton step would still move far
    J = (sp.diags(10.0 ** rng.uniform(-14 if seed % 2 else -2, 0, n)) @ J).tocsc()
    J.sort_indices()
    phi = merit.fb_phi(z, f, lb, ub)
    got = _scale_test(z, f, lb, ub, phi, J)
    ref = _scale_test_arrays(z, f, lb, ub, phi, J)
    assert (got.solved, got.flat_row) == (ref.solved, ref.flat_row)
    assert got.step == ref.step or np.isclose(got.step, ref.step, rtol=1e-15)
    assert got.solved == (seed % 2 == 0)  # both verdicts occur



@pytest.mark.parametrize("fmt", ["csc", "csr", "coo", "lil"])
def test_live_rows_are_the_rows_with_a_nonzero_entry_in_every_format(fmt):
    """Rows with a nonzero stored entry: explicit zeros do not count, NaN does, and
    duplicate entries are summed first (two that cancel leave their row dead)."""
    n = 8
    rows = np.array([0, 1, 2, 3, 5, 5, 6])
    cols = np.array([1, 2, 3, 4, 7, 7, 0])
    vals = np.array([1.0, 0.0, np.nan, -2.0, 1.0, -1.0, 3.0])
    J = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).asformat(fmt)
    expected = np.zeros(n, dtype=bool)
    expected[[0, 2, 3, 6]] = True
    assert np.array_equal(live_rows(J), expected)
