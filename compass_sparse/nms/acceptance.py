"""When a point counts as a solution of MCP(F, [l, u]).

Three tests, at the user's ``convergence_tolerance`` tol:

1. *Residuals.*  ||Phi_FB(z)||_2 <= tol **and** the natural residual
   ||z - pi(z - F(z))||_inf <= tol.  Neither bounds the other tightly (|Phi_i| can be
   as small as (2 - sqrt 2) |min-map_i|), so both are required: a solution meets the
   documented tolerance on both residuals.

2. *Scale.*  A small residual means little where F is flat: F = exp(-x) on [0, inf) has
   residual 8e-7 at x = 14, far from its solution x = 0.  With H = Da + Db J an element of
   the generalized Jacobian of Phi (see :mod:`.merit`), the Newton step on row i would move
   the point by about

       d_i = |Phi_i| / ||H_i||_inf,

   so the point is accepted only when, for every row with Phi_i != 0,

       d_i <= FLAT_STEP_RTOL * (1 + |z_i|).

   At a genuine solution d_i is of the order of the residual divided by the row's scale;
   in a flat tail it is the distance still to go (1 for exp(-x), x for -1/(1+x)).  A row
   with H_i = 0 and Phi_i != 0 fails.

   At a bound the FB row is mostly the bound's (z_i = l_i, F_i < 0: H_i ~ -e_i), so its
   step is ~|Phi_i| whatever F does: F = 1e-9 (x - 1) on x >= 0 looked solved at x = 0.
   So d_i is also, where the natural map's F-piece is active (z_i - u_i < F_i < z_i - l_i,
   the min-map's value is F_i and its Newton row is J_i), the larger of that and

       |F_i| / ||J_i||_inf,

   the step of the natural map's Newton row.  Where the bound's piece is active instead
   the natural map's step is |z_i - l_i| (or |z_i - u_i|), at most tol by test (1).  The
   verdict is then the same at every small-residual point of a flat F, whatever the start.

3. *Vanished rows.*  Far enough down a flat tail F underflows: F = a exp(-z) (M z + q)
   is exactly 0, and so is its Jacobian, at z ~ 3e4, where every residual is 0 and test
   (2) has nothing to divide.  A row strictly inside its bounds whose F value and
   Jacobian row are both exactly 0 at z, although its F was not 0 at the solve's start
   point, is such a tail: the point is not accepted (its d_i is reported as inf).  A row
   whose F was 0 at the start too may be identically 0 (a variable nothing depends on,
   whose every value solves its row, as PATH treats it), and a row at a bound is
   complementary whatever F's sign below the underflow.  The price: a degenerate root
   hit exactly (F_i = (x - 1)^2 at x = 1, from a start where it was not 0) is not
   accepted either; the solve goes on and ends FLAT_RESIDUAL at that point.  J is read
   for this test only where such a row exists.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..linalg.csc import without_duplicates
from .._merit_kernels import flat_step_kernel, min_map_within, scale_test_kernel
from ..box import dot_norm, max_abs
from ..merit import fb_jacobian_diagonals, fb_phi, min_map
from ..merit import fb_jacobian_diagonals_arrays
from ..box import float_vectors
from ..scaling import scale_entries

__all__ = ["FLAT_STEP_RTOL", "Verdict", "judge", "live_rows", "residuals_small",
           "Acceptance"]

FLAT_STEP_RTOL = 1e-3
"""Largest Newton displacement d_i, relative to 1 + |z_i|, of an accepted point."""


@dataclass
class Verdict:
    solved: bool
    small_residual: bool  #: test (1) passed
    flat_row: int = -1  #: when (1) passed but (2) failed: the row with the largest d_i / (1+|z_i|)
    step: float = 0.0  #: that row's d_i
    #: of a verdict of :meth:`Acceptance.judge` on a scaled problem: whether it is the
    #: verdict :func:`judge` gives on the user's problem at this point with the user's J
    #: (read from the evaluator's memo), so that the solve's Result may take it instead of
    #: judging again.  False when test (2) read J through the scaling (R^-1 (R J C) C^-1)
    #: or J could not be evaluated there (judging again would ask the user once more).
    #: (Not compared: two verdicts with the same findings are equal.)
    reusable: bool = field(default=True, compare=False)

    def flat_message(self, row_label) -> str:
        if math.isinf(self.step):
            return (f"the residual is 0 only because F vanished: F and its Jacobian are "
                    f"exactly 0 in row {row_label(self.flat_row)}, whose F was not 0 at the "
                    "start point (F underflowed in a flat tail)")
        return (f"the residual is below the tolerance only because F is flat: a Newton step "
                f"would still move the point by {self.step:.3g} in row "
                f"{row_label(self.flat_row)}")


def residuals_small(z, f, lb, ub, tol, phi=None) -> bool:
    """Test (1): both residuals at most tol (``phi``: fb_phi(z, f), when already known)."""
    if phi is None:
        # The answer is the conjunction of the two tests; without Phi at hand the
        # natural residual, one compiled pass without an array, is asked first, and
        # away from a solution (most points asked) it alone says no.
        if float_vectors(np.size(z), z, f, lb, ub):
            if not min_map_within(z, f, lb, ub, float(tol)):
                return False
            phi = fb_phi(z, f, lb, ub)
            return not dot_norm(phi) > tol
        phi = fb_phi(z, f, lb, ub)
    if dot_norm(phi) > tol:  # (np.dot's product, a correctly rounded root)
        return False
    if float_vectors(np.size(z), z, f, lb, ub):  # the solver's points: one compiled pass
        return bool(min_map_within(z, f, lb, ub, float(tol)))
    mm = min_map(z, f, lb, ub)
    return bool((np.abs(mm) <= tol).all())


def live_rows(J) -> np.ndarray:
    """The rows of J with a nonzero stored entry (NaN counts as nonzero; duplicates are
    summed first).  Read off the canonical CSC's row indices: through CSR, abs and a row
    maximum it cost ~0.1 ms a call on the traffic model at n = 912."""
    J = without_duplicates(J)
    live = np.zeros(J.shape[0], dtype=bool)
    live[J.indices[J.data != 0.0]] = True
    return live


def judge(z, f, lb, ub, tol, jac=None, phi=None, small=False, start_f=None) -> Verdict:
    """The three tests.  ``jac(z)`` returns J(z) (sparse) or None when it cannot be
    evaluated; without a Jacobian only test (1) is applied.  ``phi``: fb_phi(z, f) when
    known; ``small``: test (1) is known to pass (the caller has just applied it);
    ``start_f``: F at the solve's start point (None: test (3) is skipped)."""
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    if phi is None:
        phi = fb_phi(z, f, lb, ub)
    if not (small or residuals_small(z, f, lb, ub, tol, phi)):
        return Verdict(False, False)
    if jac is None:
        return Verdict(True, True)
    vanished = None
    if start_f is not None and not f.all():  # (rare: a row's F exactly 0)
        vanished = (f == 0.0) & (np.asarray(start_f) != 0.0) & (lb < z) & (z < ub)
        if not vanished.any():
            vanished = None
    if max_abs(phi) == 0.0 and vanished is None:  # (phi.any() via numpy's wrapper: ~2 us)
        return Verdict(True, True)
    J = jac(z)
    if J is None:
        return Verdict(True, True)
    v = _scale_test(z, f, lb, ub, phi, J)
    if v.solved and vanished is not None:
        dead = np.flatnonzero(vanished & ~live_rows(J))
        if dead.size:
            return Verdict(False, True, flat_row=int(dead[0]), step=math.inf)
    return v


def _scale_test(z, f, lb, ub, phi, J) -> Verdict:
    """Test (2) at a point that passed test (1), with J = J(z): ||H_i||_inf over the row
    is max(|db_i| max_j |J_ij|, |da_i + db_i J_ii|), read off the stored entries of the
    canonical CSC in one compiled pass (no sparse matrix built per solve)."""
    J = without_duplicates(J)  # (the evaluator's J already is: then J itself)
    if float_vectors(np.size(z), z, f, lb, ub, phi) and J.data.dtype == np.float64:
        # the solver's points: diagonals and test in one compiled call
        row, d, ratio = scale_test_kernel(z, f, lb, ub, phi, J.indptr, J.indices, J.data)
    else:
        da, db = fb_jacobian_diagonals(z, f, lb, ub)
        n = z.size
        row, d, ratio = flat_step_kernel(z, f, lb, ub, phi, da, db, J.indptr, J.indices,
                                         J.data, np.zeros(n), np.empty(n), np.empty(n))
    if row < 0 or ratio <= FLAT_STEP_RTOL:
        return Verdict(True, True)
    return Verdict(False, True, flat_row=int(row), step=float(d))


def _scale_test_arrays(z, f, lb, ub, phi, J) -> Verdict:
    """_scale_test with array operations (the reference of the compiled kernel)."""
    da, db = fb_jacobian_diagonals_arrays(z, f, lb, ub)
    J = sp.csc_matrix(J)
    rows = np.flatnonzero(phi)
    if rows.size == 0:
        return Verdict(True, True)
    row_max = np.asarray(abs(J).max(axis=1).todense()).ravel()
    h = np.maximum(np.abs(db) * row_max, np.abs(da + db * J.diagonal()))[rows]
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(h > 0, np.abs(phi[rows]) / h, np.inf)
        fr, zr, rm = f[rows], z[rows], row_max[rows]
        active = (zr - np.broadcast_to(ub, z.shape)[rows] < fr) & \
            (fr < zr - np.broadcast_to(lb, z.shape)[rows])
        dn = np.where(rm > 0, np.abs(fr) / rm, np.inf)
        d = np.where(active & (dn > d), dn, d)
    ratio = d / (1.0 + np.abs(z[rows]))
    k = int(np.argmax(ratio))
    if ratio[k] <= FLAT_STEP_RTOL:
        return Verdict(True, True)
    return Verdict(False, True, flat_row=int(rows[k]), step=float(d[k]))


class Acceptance:
    """Both tests for the points of a solve that may work on a scaled problem
    (z_user = col * z, F_user = f / row; see :mod:`compass_sparse.scaling`): the verdict is
    always on the user's problem, at the user's tolerance."""

    def __init__(self, lb, ub, tol, row=None, col=None, user_jac=None, start_f=None):
        self.lb, self.ub, self.tol = lb, ub, tol
        self.start_f = start_f  #: test (3)'s F at the start point, unscaled (or None)
        self.row, self.col = row, col
        #: with a scaling: ``user_jac(z_user)``, the user's J at the user's point (None
        #: when it cannot be evaluated), which the caller guarantees to be evaluated,
        #: counted and rejected exactly as the ``jac`` handed to :meth:`judge` would be
        #: (through the same evaluator's memo), while ``user_jac.applies()``.  The verdict
        #: then reads the user's J itself, as the verdict on the user's problem (solve's
        #: Result) does, instead of R^-1 (R J C) C^-1 -- the same entries unless a
        #: power-of-two factor under- or overflowed -- and two scalings of J per verdict
        #: are saved.
        self.user_jac = user_jac

    def user_point(self, z, f):
        """(z, F) in the user's units."""
        if self.row is None:
            return z, f
        return self.col * z, f / self.row

    def small(self, z, f, phi=None, psi=None) -> bool:
        """Test (1) only (cheap: no Jacobian).  ``phi``, ``psi``: Phi(z) and Psi(z) of the
        problem being solved, when known (used only when that problem is the user's,
        unscaled: then ||Phi||_2 = sqrt(2 Psi) exactly, and the common answer "not small"
        costs one square root)."""
        if self.row is None and psi is not None and math.sqrt(2.0 * psi) > self.tol:
            return False
        zu, fu = self.user_point(z, f)
        return residuals_small(zu, fu, self.lb, self.ub, self.tol,
                               phi if self.row is None else None)

    def judge(self, z, f, jac=None, phi=None, small=False) -> Verdict:
        """Both tests; ``jac(z)`` evaluates the Jacobian of the problem being solved at z;
        ``phi`` as in :meth:`small`; ``small``: :meth:`small` has just passed at z."""
        zu, fu = self.user_point(z, f)
        if self.row is None:
            return judge(zu, fu, self.lb, self.ub, self.tol, jac=jac, phi=phi, small=small,
                         start_f=self.start_f)
        read = []  # whether J was asked for, and obtained
        if jac is not None and self.user_jac is not None and self.user_jac.applies():
            def direct(y):
                J = self.user_jac(y)
                read.append(J is not None)
                return J

            v = judge(zu, fu, self.lb, self.ub, self.tol, jac=direct, small=small,
                      start_f=self.start_f)
            v.reusable = all(read)
            return v

        def user_jac(_):
            read.append(False)
            J = jac(z)
            if J is None:
                return J
            # R^-1 J C^-1 (power-of-two factors: exact) in one compiled pass: two sparse
            # products cost a small model ~0.5 ms per verdict
            return scale_entries(J, 1.0 / self.row, 1.0 / self.col)

        v = judge(zu, fu, self.lb, self.ub, self.tol,
                  jac=None if jac is None else user_jac, small=small, start_f=self.start_f)
        v.reusable = not read
        return v
