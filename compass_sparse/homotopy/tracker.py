"""The path tracker of the homotopy pass: predictor-corrector on H_a(x, lam) = 0 in
arclength, its step control and the normal-map Newton end game (see
:mod:`compass_sparse.homotopy` for the mathematics).  A dense problem's path runs in
compiled calls between two evaluations (:meth:`Tracker.follow` when the solve's routes
chose the compiled tracker); the array route is the reference, and the route of every
other problem."""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from .._jit import NO_INDICES, NO_VALUES
from ..box import all_finite, dot_norm, float_vector, float_vectors, max_abs, project
from ..linalg.csc import csc_times, float_csc
from ..merit import fb_phi, fb_psi
from ..options import HOMOTOPY_DENSE_DENSITY, HOMOTOPY_DENSE_MAX_N
from . import _kernels as hk
from ._kernels import (bordered_values, chord_step, homotopy_values, smoothed_projection,
                       unit_tangent)
from .bordered import Bordered, dense_copy, solve_square
from .outcome import HomotopyStatus
from .smoothing import SmoothedNormalMap

__all__ = ["HomotopyStop", "Tracker", "compiled_tracker_available"]

CORRECTOR_ITERATIONS = 6
"""Chord iterations allowed per step before the step is halved."""
CONTRACTION_MAX = 0.5
"""A corrector whose correction shrinks by less than this factor is rejected."""
DISTANCE_MAX = 0.5
"""A first correction longer than this times the step rejects the step (the predictor
left the curve's neighbourhood)."""
KAPPA_NOMINAL = 0.3
DISTANCE_NOMINAL = 0.2
STEP_GROWTH_MAX = 2.0
"""Step control: the next step is h / f with f = max(kappa / KAPPA_NOMINAL,
delta_1 / (DISTANCE_NOMINAL h)) clipped to [1 / STEP_GROWTH_MAX, 2] (Allgower & Georg's
nominal contraction and distance).  0.3 and 0.2 (with homotopy_initial_step 0.1) took 24%
fewer steps, 17% fewer J and 7% fewer F evaluations than 0.2 and 0.1 (with 0.01) on the
106 thesis instances that reach the homotopy, all solved either way
(benchmarks/homotopy_steps.py)."""
CORRECTOR_TOLERANCE = 1e-4
"""Relative distance to the curve (to 1 + ||y||) at which the corrector stops (see
CORRECTOR_ESTIMATE).  The
path only has to be followed closely enough not to jump to another branch; the end game
gets the solution's accuracy.  On the thesis families 1e-4 took half the steps and a
quarter of the evaluations of 1e-8 and found the same solutions."""
CORRECTOR_ESTIMATE = True
"""Stop the corrector when the estimated distance of its point to the curve, theta d /
(1 - theta) with theta the ratio of the last two corrections and d the last one, is below
the tolerance (True), or only when the last correction itself is (False; the last
correction bounds the distance of the point *before* it, so that test asks one chord
iteration more whenever the contraction is good).  On the 106 thesis instances that reach
the homotopy (benchmarks/homotopy_steps.py): all solved either way, 11% fewer F
evaluations, 2% fewer steps; at n = 500 (21 instances): 21/21 either way, 11% fewer F,
9% fewer steps and 6% fewer J evaluations."""
DENSE_DENSITY = HOMOTOPY_DENSE_DENSITY
"""Bordered systems whose Jacobian is at least this dense, or small (n <= DENSE_MAX_N),
are factorized densely (the option ``homotopy_after_restarts`` reads the same rule)."""
DENSE_MAX_N = HOMOTOPY_DENSE_MAX_N
NEWTON_ITERATIONS = 20
"""Iterations of the normal-map Newton end game per attempt."""
END_GAP = 1e-10
"""A path point with lam >= 1 - END_GAP is the end of the path."""
NEWTON_STEP_MAX = 1.0
"""Longest end-game Newton step, relative to 1 + ||x||_inf."""


# ------------------------------------------------------------------ the tracker
_DENSE_ENDS = {hk.SINGULAR: HomotopyStatus.SINGULAR,
               hk.STEP_TOO_SMALL: HomotopyStatus.STEP_TOO_SMALL,
               hk.DIVERGED: HomotopyStatus.DIVERGED, hk.RETURNED: HomotopyStatus.RETURNED,
               hk.STEP_LIMIT: HomotopyStatus.STEP_LIMIT}


def compiled_tracker_available() -> bool:
    """Whether this numba binds LAPACK's getrf, which the compiled tracker calls (through
    numba's internal interface: a numba without it leaves the tracker on its Python
    route).  Asked by the routes when a solve starts; it loads numba."""
    return hk.bind_lapack()


class HomotopyStop(Exception):
    """Raised through the tracker to end the pass: a solution, the time limit, an
    evaluation error at a path's start."""

    def __init__(self, status: HomotopyStatus, message: str):
        self.status = status
        self.message = message


class Tracker:
    """Follows the zero curves of H_a for one problem; counts its own work.  ``compiled``:
    the solve's tracker route (:attr:`compass_sparse.routes.Routes.homotopy`): a problem of
    order at most ``DENSE_MAX_N`` then follows its paths in compiled calls (the same points
    bit for bit), where numba binds LAPACK's getrf; any other in the array route."""

    def __init__(self, evalr, lb, ub, opt, *, deadline, on_point, tol, log, compiled=True):
        self.ev = evalr
        self.lb, self.ub = np.asarray(lb, float), np.asarray(ub, float)
        self.n = self.lb.size
        self.opt = opt
        self.deadline = deadline
        self.on_point = on_point
        self.tol = tol
        self.log = log
        self.compiled = compiled
        self.smooth = SmoothedNormalMap(lb, ub)
        self.factorizations = 0
        self.steps = 0
        self.rejected = 0
        self.turning_points = 0
        self.newton_iterations = 0
        self.dense = None
        self._dx, self._dmu = np.empty(self.n), np.empty(self.n)  # the corrector's work
        #: (y, p) of the dense corrector's converged point: p = p_mu(x), and dp/dx and
        #: dp/dmu there in the work arrays above, until the next projection
        self._corrected = None
        self.best = None  # (z, psi) of the lowest merit seen
        width = self.ub - self.lb
        width = np.sort(width[np.isfinite(width)])
        # the median of the finite widths: np.median's value (the middle one, or the mean
        # of the two middle ones), without its ~25 us of dispatch on a short vector
        k = width.size // 2
        scale = (1.0 if width.size == 0 else float(width[k]) if width.size % 2
                 else float((width[k - 1] + width[k]) / 2.0))
        self.mu0 = opt.homotopy_smoothing * max(scale, 1e-8)

    # -------------------------------------------------------------- evaluations
    def _check_time(self):
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise HomotopyStop(HomotopyStatus.TIME_LIMIT, "time limit reached on the path")

    def _offer(self, z, f):
        phi = fb_phi(z, f, self.lb, self.ub)
        psi = fb_psi(phi)
        if self.best is None or psi < self.best[1]:
            self.best = (z.copy(), psi)
        if self.on_point is not None:
            # the caller's acceptance test decides what a solution is (it raises then)
            self.on_point(z, f, phi, psi)
        elif np.sqrt(2.0 * psi) <= self.tol:
            raise HomotopyStop(HomotopyStatus.SOLVED, "solution found on the homotopy pass")

    def _mu(self, lam):
        """The smoothing mu(lam) = mu0 (1 - lam), 0 from lam = 1 on."""
        return self.mu0 * max(1.0 - lam, 0.0)

    def residual(self, y, a, want_jac):
        """H(y), and with want_jac the pieces of DH: (H, Hx, Hlam).  Points where the
        Jacobian is evaluated (the accepted ones) are offered as candidate best points."""
        x, lam = y[:-1], y[-1]
        if want_jac and self._corrected is not None and self._corrected[0] is y:
            # the corrector's last chord step projected this point already (chord_step:
            # the same kernel with the same mu(lam)) into p and the work arrays
            p, dx, dmu = self._corrected[1], self._dx, self._dmu
        else:
            p, dx, dmu = self.smooth.project(x, self._mu(lam))
        if want_jac:
            f, J = self.ev.fj(p)
        else:
            f, J = self.ev.f_once(p), None  # (the corrector's iterates: no memo)
        if f is None:
            return None
        if want_jac:
            self._offer(p, f)
        lam = float(lam)
        floats = float_vectors(self.n, f, x, p, a)
        n = self.n
        if want_jac:
            if J is None:
                return None
            J = float_csc(J)
            if self.dense is None:
                self.dense = n <= DENSE_MAX_N or J.nnz >= DENSE_DENSITY * n * n
            if self.dense and floats and float_vectors(n, dx, dmu):
                # the map's values, H_x and H_lam in one compiled call, the latter two as
                # views of the bordered matrix that factor() completes with the tangent's
                # row and factors in place (column-major for getrf)
                G, H = np.empty(n), np.empty(n)
                B = np.empty((n + 1, n + 1), order="F")
                bordered_values(f, x, p, a, lam, G, H, J.indptr, J.indices, J.data, dx, dmu,
                                self.mu0, B, np.empty(n))
                return H, B[:n, :n], B[:n, n]
        if floats:
            G, H = np.empty(n), np.empty(n)
            homotopy_values(f, x, p, a, lam, G, H)
        else:
            G = f + x - p
            H = lam * G + (1.0 - lam) * (x - a)
        if not want_jac:
            return H, None, None
        # H_x = lam (J D + I - D) + (1 - lam) I = lam J D + I - lam D
        # dH/dlam = G - (x - a) + lam (J - I) dp/dmu * dmu/dlam,  dmu/dlam = -mu0
        if self.dense:
            Hx = dense_copy(J)
            Hx *= lam * dx  # scales column j by lam dx_j
            Hx.flat[::n + 1] += 1.0 - lam * dx  # the diagonal
        else:
            Hx = (lam * (J @ sp.diags(dx)) + sp.diags(1.0 - lam * dx)).tocsc()
        dGdmu = csc_times(J, dmu) - dmu
        Hlam = G - (x - a) - lam * self.mu0 * dGdmu
        return H, Hx, Hlam

    def factor(self, Hx, Hlam, v):
        """The factors of [[Hx, Hlam], [v^T]] (dense Hx and Hlam from :meth:`residual` are
        views of that matrix, which the factorization overwrites)."""
        self.factorizations += 1
        B = Hx.base if isinstance(Hx, np.ndarray) else None
        if B is not None and Hlam.base is B:
            B[-1, :] = v  # residual()'s bordered matrix: its last row, then factored
            return Bordered(B, None, None, True)
        return Bordered(Hx, np.append(Hlam, 0.0), v, self.dense)

    # -------------------------------------------------------------- one path
    def _end(self, status, y, h=0.0, bound=0.0):
        """(status, message, y) of a path that ended without reaching lam = 1 (both
        routes' messages)."""
        S = HomotopyStatus
        if status is S.SINGULAR:
            text = f"singular augmented Jacobian at lam = {y[-1]:.6f}"
        elif status is S.STEP_TOO_SMALL:
            text = f"corrector failed at step {h:.1e} (lam = {y[-1]:.6f})"
        elif status is S.DIVERGED:
            text = f"||x|| exceeded {bound:.3g} at lam = {y[-1]:.6f}"
        elif status is S.RETURNED:
            text = "the path returned below lam = 0"
        elif status is S.EVALUATION_ERROR:
            text = "F or J undefined on the path"
        else:
            text = f"{self.opt.homotopy_step_limit} steps without reaching lam = 1"
        return status, text, y

    def _log_step(self, lam, h, x):
        """The log line of an accepted step (:data:`compass_sparse.nms.log.HOMOTOPY_HEADER`:
        steps so far, lambda, the next step length, ||x||_inf, F evaluations so far)."""
        if self.log is not None:
            self.log(f"{self.steps:6d} {lam:10.6f} {h:9.2e} {np.linalg.norm(x, np.inf):9.2e} "
                     f"{self.ev.counters.nfev:6d}")

    def follow(self, a, polish=None):
        """Track gamma_a from (a, 0).  Returns (status, message, last point (x, lam))."""
        if self.compiled and self.n <= DENSE_MAX_N and hk.bind_lapack():
            return self._follow_dense(a, polish)
        opt = self.opt
        n = self.n
        y = np.append(a, 0.0)
        self._y = y
        v = np.zeros(n + 1)
        v[-1] = 1.0
        a_max = max_abs(a)
        bound = opt.homotopy_divergence_bound * (1.0 + a_max)
        out = self.residual(y, a, True)
        if out is None:
            raise HomotopyStop(HomotopyStatus.EVALUATION_ERROR,
                               "F or J undefined at the start of the path")
        H, Hx, Hlam = out
        lam_end = opt.homotopy_end_lambda
        h = opt.homotopy_initial_step * (1.0 + a_max)
        hmin = opt.homotopy_step_minimum * (1.0 + a_max)
        for _ in range(opt.homotopy_step_limit):
            self._check_time()
            # --- tangent at y, from the factorization that also serves the corrector
            try:
                Bf = self.factor(Hx, Hlam, v)
                tau, turned = self._tangent(Bf, v)
            except (np.linalg.LinAlgError, RuntimeError):
                return self._end(HomotopyStatus.SINGULAR, y)
            self.turning_points += turned
            # --- predictor-corrector with step control
            retried = False
            while True:
                self._check_time()
                yp = y + h * tau
                if yp[-1] > 1.0:  # do not step past the end: mu(lam) must stay >= 0
                    hh = (1.0 - y[-1]) / tau[-1] if tau[-1] > 0 else h
                    yp = y + min(h, hh) * tau
                yn, ok = self._correct(yp, a, Bf, v)
                if ok:
                    break
                self.rejected += 1
                retried = True
                h *= 0.5
                if h < hmin:
                    return self._end(HomotopyStatus.STEP_TOO_SMALL, y, h=h)
            yn, factor = yn
            if retried:  # do not grow right after a rejection (avoids oscillating)
                factor = max(factor, 1.0)
            self.steps += 1
            x_max = max_abs(yn[:-1])  # (the divergence test's too, below)
            h = min(max(h, dot_norm(yn - y)) / factor,
                    opt.homotopy_maximum_step * (1.0 + x_max))
            y, v = yn, tau
            self._y = y
            lam = y[-1]
            self._log_step(lam, h, y[:-1])
            if not all_finite(y) or x_max > bound:
                return self._end(HomotopyStatus.DIVERGED, y, bound=bound)
            if lam < -0.5:
                return self._end(HomotopyStatus.RETURNED, y)
            out = self.residual(y, a, True)
            if out is None:
                return self._end(HomotopyStatus.EVALUATION_ERROR, y)
            H, Hx, Hlam = out
            if lam >= lam_end or lam >= 1.0 - END_GAP:
                z_end = self.end_game(y[:-1])  # raises HomotopyStop(SOLVED) on success
                if lam >= 1.0 - END_GAP:
                    return self._end_reached(z_end, polish, y)
                lam_end = 1.0 - 0.1 * (1.0 - lam)
        return self._end(HomotopyStatus.STEP_LIMIT, y)

    def _end_reached(self, z_end, polish, y):
        if polish is not None and z_end is not None:
            polish(z_end)
        return (HomotopyStatus.END_REACHED,
                "lam = 1 reached; Newton's method missed the tolerance", y)

    def _follow_dense(self, a, polish):
        """:meth:`follow` of a dense problem: everything between two evaluations of the
        user's functions in one compiled call (``_kernels.follow_dense``, which
        says what it needs next); here only the evaluations, the candidate points, the
        time limit, the log and the end game.  The Python route's steps in its order: the
        same points bit for bit, without its ~50 us of Python per accepted step."""
        opt, n = self.opt, self.n
        self.dense = True
        W = np.zeros((hk.W_ROWS, n + 1))
        W[hk.W_Y, :n] = a  # y = (a, 0)
        W[hk.W_V, n] = 1.0
        W[hk.W_A, :n] = a
        W[hk.W_LB, :n] = self.lb
        W[hk.W_UB, :n] = self.ub
        B = np.empty((n + 1, n + 1), order="F")  # (getrf factors it in place)
        piv = np.empty(n + 1, dtype=np.int32)
        a_max = max_abs(a)
        sf = np.zeros(hk.F_SIZE)
        sf[hk.F_H] = opt.homotopy_initial_step * (1.0 + a_max)
        sf[hk.F_HMIN] = opt.homotopy_step_minimum * (1.0 + a_max)
        sf[hk.F_BOUND] = bound = opt.homotopy_divergence_bound * (1.0 + a_max)
        sf[hk.F_LAM_END] = opt.homotopy_end_lambda
        sf[hk.F_MU0] = self.mu0
        sf[hk.F_HMAX] = opt.homotopy_maximum_step
        # the module's constants as they are now (a test may change them)
        sf[hk.F_TOL] = CORRECTOR_TOLERANCE
        sf[hk.F_CONTRACTION] = CONTRACTION_MAX
        sf[hk.F_DISTANCE] = DISTANCE_MAX
        sf[hk.F_KAPPA_NOM] = KAPPA_NOMINAL
        sf[hk.F_DISTANCE_NOM] = DISTANCE_NOMINAL
        sf[hk.F_GROWTH] = STEP_GROWTH_MAX
        sf[hk.F_END_GAP] = END_GAP
        si = np.zeros(hk.I_SIZE, dtype=np.int64)
        si[hk.I_STEP_LIMIT] = opt.homotopy_step_limit
        si[hk.I_CORRECTOR_ITERATIONS] = CORRECTOR_ITERATIONS
        si[hk.I_ESTIMATE] = CORRECTOR_ESTIMATE
        keys = (hk.I_STEPS, hk.I_REJECTED, hk.I_TURNS, hk.I_FACTORIZATIONS)
        synced = [0, 0, 0, 0]  # si's counts already added to the tracker's
        p_row = W[hk.W_P, :n]
        y = W[hk.W_Y]
        follow = hk.follow_dense
        none, no_index = NO_VALUES, NO_INDICES
        logged, log = 0, self.log

        def sync():  # the tracker's counts (the end game's factorizations too) get the path's
            d = [int(si[k]) - c for k, c in zip(keys, synced)]
            synced[:] = [int(si[k]) for k in keys]
            self.steps += d[0]
            self.rejected += d[1]
            self.turning_points += d[2]
            self.factorizations += d[3]

        try:
            code = follow(sf, si, W, B, piv, none, no_index, no_index, none, False)
            while True:
                if log is not None and si[hk.I_STEPS] != logged:  # a step was accepted
                    logged = si[hk.I_STEPS]
                    sync()  # (the log reads the count; else it is synced at the end)
                    self._log_step(y[n], sf[hk.F_H], y[:n])
                if code == hk.NEED_F:
                    self._check_time()
                    f = self.ev.f_once(p_row)  # (the user's F gets a copy: _call_F)
                    code = (follow(sf, si, W, B, piv, none, no_index, no_index, none, True)
                            if f is None else
                            follow(sf, si, W, B, piv, f, no_index, no_index, none, False))
                elif code == hk.NEED_FJ:
                    self._check_time()
                    p = p_row.copy()
                    f, J = self.ev.fj(p)
                    if f is None:
                        if si[hk.I_AT_START]:
                            raise HomotopyStop(HomotopyStatus.EVALUATION_ERROR,
                                        "F or J undefined at the start of the path")
                        return self._end(HomotopyStatus.EVALUATION_ERROR, y.copy())
                    self._offer(p, f)
                    J = float_csc(J)
                    code = follow(sf, si, W, B, piv, f, J.indptr, J.indices, J.data, False)
                elif code == hk.END_GAME:
                    lam = y[n]
                    z_end = self.end_game(y[:n].copy())  # raises HomotopyStop(SOLVED) on success
                    if lam >= 1.0 - END_GAP:
                        return self._end_reached(z_end, polish, y.copy())
                    sf[hk.F_LAM_END] = 1.0 - 0.1 * (1.0 - lam)
                    code = follow(sf, si, W, B, piv, none, no_index, no_index, none, False)
                elif code == hk.LAPACK_ERROR:
                    raise ValueError("illegal argument of getrf")
                else:
                    return self._end(_DENSE_ENDS[code], y.copy(), h=sf[hk.F_H], bound=bound)
        finally:
            sync()

    def _tangent(self, Bf, v):
        """(tau, 1 if lam turned else 0): the unit tangent at the last accepted point from
        the factors Bf of its bordered matrix, oriented by the previous tangent v."""
        if Bf.dense and float_vector(v):  # one compiled call
            tau = np.empty(v.size)
            turned = unit_tangent(*Bf.lu, v, tau)
            if turned < 0:
                raise np.linalg.LinAlgError("non-finite tangent")
            return tau, turned
        e = np.zeros(v.size)
        e[-1] = 1.0
        w = Bf.solve(e)
        tau = w / dot_norm(w)
        if tau @ v < 0:  # keep the orientation
            tau = -tau
        return tau, int(tau[-1] * v[-1] < 0)  # lam changed direction: a turning point

    def _correct(self, yp, a, Bf, v):
        """Chord iterations with the factorization Bf.  Returns ((y, step factor), ok): the
        factor by which the next step is divided, from the contraction ratio kappa and the
        first correction delta relative to the step h (both grow like h)."""
        self._corrected = None  # (the work arrays are about to change)
        y = yp.copy()
        h = max(dot_norm(yp - self._y), 1e-300)
        first = prev = None
        kappa = 0.0
        tol_y = CORRECTOR_TOLERANCE * (1.0 + dot_norm(yp))
        rhs = np.empty(yp.size)
        # a dense problem's iterations in compiled calls (the same formulas; the solves'
        # last bits may differ from the array route's, which remains for the others)
        fast = Bf.dense and float_vectors(self.n, a, self.lb, self.ub) and float_vector(y) \
            and float_vector(v)
        p = None
        if fast:  # p = p_mu(x) of the first iterate; each chord step makes the next one's
            n = self.n
            p = np.empty(n)
            smoothed_projection(y[:n], self._mu(float(y[n])), self.lb, self.ub, p, self._dx,
                                self._dmu)
        for _ in range(CORRECTOR_ITERATIONS):
            if fast:
                # one chord iteration of a dense problem: F, then one compiled call (y += d
                # in place, and p at the new point)
                f = self.ev.f_once(p)
                if f is None:  # F undefined at the point
                    return None, False
                dn = chord_step(f, y, yp, p, a, v, *Bf.lu, rhs, self.mu0, self.lb, self.ub,
                                self._dx, self._dmu)
                if dn < 0.0:  # a non-finite correction
                    return None, False
            else:
                r = self.residual(y, a, False)
                if r is None:
                    return None, False
                np.negative(r[0], out=rhs[:-1])
                rhs[-1] = -(v @ (y - yp))
                try:
                    d = Bf.solve(rhs)
                except np.linalg.LinAlgError:  # a non-finite correction: a shorter step
                    return None, False
                dn = dot_norm(d)
                y = y + d
            if prev is not None:
                kappa = max(kappa, dn / max(prev, 1e-300))
                if kappa > CONTRACTION_MAX:
                    return None, False
            else:
                first = dn
                # The base point itself is only on the curve to the tracking tolerance:
                # a correction of that size is not the predictor's error.
                if first > max(DISTANCE_MAX * h, 10.0 * tol_y):
                    return None, False
            if dn <= tol_y or (CORRECTOR_ESTIMATE and prev is not None
                               and dn * dn <= tol_y * (prev - dn)):
                factor = max(kappa / KAPPA_NOMINAL, first / (DISTANCE_NOMINAL * h))
                self._corrected = (y, p) if fast else None
                return (y, min(max(float(factor), 1.0 / STEP_GROWTH_MAX), 2.0)), True
            prev = dn
        return None, False

    # -------------------------------------------------------------- end game
    def end_game(self, x):
        """Newton on F_B from x.  Returns its last point pi(x) when it missed the tolerance
        (a solution raises through ``_offer``)."""
        lb, ub = self.lb, self.ub
        z = project(x, lb, ub)
        f = self.ev.f(z)
        if f is None:
            return None
        self._offer(z, f)
        fb = f + x - z
        nrm = dot_norm(fb)
        for _ in range(NEWTON_ITERATIONS):
            self._check_time()
            J = self.ev.jac(z, f)
            if J is None:
                break
            d = ((x > lb) & (x < ub)).astype(float)
            J = float_csc(J)
            if self.dense:
                A = dense_copy(J)
                A *= d  # J D + I - D, entry by entry as the sparse sum
                A.flat[::self.n + 1] += 1.0 - d  # the diagonal
            else:
                A = J @ sp.diags(d) + sp.diags(1.0 - d)
            try:
                self.factorizations += 1
                dx = solve_square(A, -fb, self.dense)
            except (np.linalg.LinAlgError, RuntimeError, ValueError):
                break
            if not all_finite(dx):
                break
            # The end game is local: a step much longer than the point is a singular
            # Jacobian's, not Newton's convergence (it once jumped from 1 to 1e7).
            # (the ratio only when it is below 1: at |x| ~ 1e17 and |dx| ~ 1e-300 it
            # overflowed, with a RuntimeWarning, to a min() that took 1 anyway)
            cap = NEWTON_STEP_MAX * (1.0 + max_abs(x))
            size = max_abs(dx)
            alpha = 1.0 if size <= cap else cap / size
            accepted = False
            while alpha >= 1e-3:
                xt = x + alpha * dx
                zt = project(xt, lb, ub)
                ft = self.ev.f(zt)
                if ft is not None:
                    self._offer(zt, ft)  # raises in the caller when zt is a solution
                    fbt = ft + xt - zt
                    nt = dot_norm(fbt)
                    if nt < (1.0 - 1e-4 * alpha) * nrm:
                        x, z, f, fb, nrm, accepted = xt, zt, ft, fbt, nt, True
                        break
                alpha *= 0.5
            self.newton_iterations += 1
            if not accepted:
                break
        return z


