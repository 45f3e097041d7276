"""The acceptance test of a point (compass_sparse.nms.acceptance): both residuals within the
tolerance and no flat tail of F (the Newton step still to go), read on the user's
problem when the solver works on a scaled one."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.nms.acceptance import FLAT_STEP_RTOL, judge

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
    from compass_sparse.problem.evaluator import Evaluator
    from compass_sparse.scaling import Scaling
    from compass_sparse.problem.evaluator import ScaledEvaluator
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
    from compass_sparse.nms.acceptance import _scale_test
    from compass_sparse.merit import fb_phi

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
    from compass_sparse.nms.acceptance import residuals_small
    from compass_sparse.merit import fb_phi, min_map

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
