"""Non-monotone stabilization (NMS): the major-iteration loop (thesis §3.4; Dirkse & Ferris
1995; Ferris, Kanzow & Munson 1999).

Each major iteration linearizes F at z_k = pi(x_k) with the proximal perturbation

    M = J(z_k) + eps I,   q = F(z_k) - M z_k,

and walks the pivotal path from x_k (warm-started from the previous basis) to the Newton
point x_N.  Acceptance (merit Psi = 0.5 ||Phi_FB||^2):

* d-step: ||z_N - z_k||_inf <= Delta (Delta shrinks by ``nms_delta_shrink_factor``) and at
  most ``nms_mstep_frequency`` consecutive d-steps: accept without a descent test (fast
  Newton progress);
* m-step: Psi(z_N) <= R - sigma max(0, -grad Psi^T (z_N - z_k)), or (1 - sigma) R, where
  the reference value R is the largest merit of the last ``nms_memory_size`` checkpoints;
  an accepted m-step (or a d-step that beats R) becomes a checkpoint;
* watchdog: otherwise return to the last checkpoint and search the segment towards the
  Newton point computed there (line: convex combination of the z's; arc: projection of
  the combination of the x's), shrinking by ``nms_shrink_factor``;
* fallback: when the watchdog fails, the path fails without a usable point, or the
  watchdog limit is reached, take a Levenberg–Marquardt step and/or projected-gradient
  steps on Psi from the best point found.

With ``nms = False`` the same loop is a monotone line search: no d-steps, a memory of one
checkpoint and the reference value Psi(z_k), so every accepted step decreases the merit.

Restarts when progress stops follow :mod:`compass_sparse.restarts`: PATH's three
configurations, then, as the thesis proposes, new points in the box and points near the
best one.
The best point is kept through everything and every exit returns it.

Major-iteration log (verbosity >= 2), fixed-width columns as in PATH:
``major minor func grad residual type prox inorm (label)`` — minor = pivots of this
path, func/grad = cumulative F/J evaluations, residual = ||Phi_FB||_2, type = two
letters: the path's code (S solved, R ray, C cycle, I pivot limit, N singular basis,
T tolerance lost, E error) and the step (D d-step, M m-step, O both tests passed,
W watchdog, G projected gradient, L Levenberg–Marquardt; ``-H``: a homotopy pass, counted
as one major iteration), prox = eps, inorm = ||Phi||_inf
with the worst row's name.  Crash lines: ``crash iter changes size residual step``.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from . import _nms_kernels as nk
from ._csc import trusted_csc
from ._jit import NO_INDICES, NO_VALUES, cold_start
from ._merit_kernels import csc_matvec, newton_linearization
from .acceptance import Acceptance
from .crash import crash
from .direct_step import (DIRECT_MIN_N, FEASIBILITY_TOLERANCE, RESIDUAL_TOLERANCE,
                          REUSE_BEATS_REFACTOR_NNZ, DirectFactors, direct_step_applies,
                          failed_direct_start)
from .evaluation import all_finite
from .exceptions import FactorBudgetError
from .fallback import gradient_steps, lm_step
from .merit import (_solver_vectors, fb_directional, fb_phi, fb_psi, max_abs_diff,
                    normal_map_at, project)
from .path import LinearCode, WarmBasis, dense_newton_result, solve_linear_mcp
from .progress import ProgressLine
from .restarts import FROM_RANDOM, FROM_START, RestartSchedule, near_point, random_point
from .result import Iteration, PassStats, Status
from .stationary import stationarity, worst_rows

logger = logging.getLogger("compass_sparse")

__all__ = ["NMSSolver", "Outcome", "Linearizer"]

LOCAL_FACTOR = 1e-3
"""Below this fraction of a run's starting residual the NMS accepts only steps that do not
raise the merit (d-steps included); larger steps go to the watchdog's backtracking."""

COMPILED_NMS = True
"""Run the major iterations' bookkeeping in compiled calls (:meth:`NMSSolver._run_compiled`)
where it applies; False keeps the Python loop (the reference of the tests)."""

COMPILED_NMS_MAX_N = 5000
"""Largest order whose major iterations run in compiled calls.  Their work area holds 28
vectors of length n (224 MB at n = 1e6), and above a few thousand variables the ~50 us
of Python a major iteration saves is a vanishing share of its factorizations."""

_NO_POSITIONS = np.zeros(0, dtype=np.int64)  # (the linearizer's maps before one is made)

FLAT_REJECTION_LIMIT = 10
"""Points with a residual below the tolerance that the scale test (see
:mod:`compass_sparse.acceptance`) rejected before the solve stops with FLAT_RESIDUAL."""

_DIAGNOSED = (Status.NO_PROGRESS, Status.MAJOR_ITERATION_LIMIT, Status.MINOR_ITERATION_LIMIT,
              Status.TIME_LIMIT)


class _Stop(Exception):
    def __init__(self, status: Status, message: str):
        self.status = status
        self.message = message


@dataclass
class Point:
    """An evaluated point: z, F(z), Phi_FB(z), Psi(z) and, when known, J(z)."""

    z: np.ndarray
    f: np.ndarray
    phi: np.ndarray
    psi: float
    J: sp.csc_matrix | None = None

    @property
    def fbn(self) -> float:
        # math.sqrt: the same correctly rounded square root as np.sqrt, without the
        # array machinery (read several times per major iteration)
        return math.sqrt(2.0 * self.psi)


@dataclass
class Outcome:
    status: Status
    message: str
    best: Point
    nit: int = 0
    minor: int = 0
    crash_iterations: int = 0
    restarts: int = 0
    gradient_steps: int = 0
    lm_steps: int = 0
    factorizations: int = 0
    updates: int = 0
    basis: WarmBasis | None = None
    passes: dict = field(default_factory=dict)
    #: the acceptance verdict of ``best`` on the user's problem when the solve stopped
    #: because best was judged a solution (None otherwise)
    verdict: object = None


class Linearizer:
    """M = J + eps I on the fixed pattern pattern(J) U diag, filled in place."""

    def __init__(self, J: sp.csc_matrix):
        n = J.shape[0]
        self.n = n
        self.nnz_J = J.nnz
        key_D = np.arange(n, dtype=np.int64) * (n + 1)
        if J.nnz == n * n:
            # A full pattern (a dense Jacobian) holds the diagonal: M has J's pattern.
            self._same_pattern(J, key_D)
            return
        # Structural union of pattern(J) and the diagonal, as sorted keys col * n + row
        # (values of J could cancel against the identity and vanish); built with array
        # operations, no sparse arithmetic: small problems build one per solve.
        col = np.repeat(np.arange(n, dtype=np.int64), np.diff(J.indptr))
        key_J = col * n + J.indices
        pos_D = np.searchsorted(key_J, key_D)
        if key_J.size and (pos_D < key_J.size).all() and (key_J[pos_D] == key_D).all():
            self._same_pattern(J, key_D, pos_D)  # the diagonal is stored already
            return
        # (a sort and a mask: numpy 2's hashing np.union1d took 0.6 s at n = 3e4, this 30 ms)
        keys = np.sort(np.concatenate((key_J, key_D)))
        keys = keys[np.concatenate(([True], keys[1:] != keys[:-1]))]
        indices = (keys % n).astype(np.int32)
        indptr = np.searchsorted(keys, np.arange(n + 1, dtype=np.int64) * n).astype(np.int32)
        self.M = trusted_csc(np.zeros(keys.size), indices, indptr, (n, n))
        # position of each J entry and each diagonal entry inside M's pattern
        self.pos_J = np.searchsorted(keys, key_J)
        self.pos_D = np.searchsorted(keys, key_D)

    def _same_pattern(self, J, key_D, pos_D=None):
        """M on J's own (canonical) pattern; ``pos_D``: the diagonal's positions in it
        (on a full pattern the diagonal of column j is entry j * (n + 1))."""
        n = self.n
        self.M = trusted_csc(np.zeros(J.nnz), J.indices.astype(np.int32),
                             J.indptr.astype(np.int32), (n, n))
        self.pos_J = None  # J's entries are M's, in the same order
        self.pos_D = key_D if pos_D is None else pos_D

    def linearize(self, J, eps: float, z, f, x):
        """(M, q, r) of the major iteration at z (F = f) from x: M = J + eps I, q = f - M z
        and r = f + x - z (the normal map of the linearization at x), in one compiled pass
        for the solver's float vectors (five array steps cost a small problem ~10 us per
        major iteration); the same bits either way."""
        n = self.n
        if (J.data.dtype == np.float64 and J.data.shape[0] == J.nnz
                and _solver_vectors(z, f, x, x) and z.shape[0] == n):
            data = np.empty(self.M.data.shape[0])
            q, r = np.empty(n), np.empty(n)
            scatter = self.pos_J is not None
            newton_linearization(J.data, self.pos_J if scatter else self.pos_D, scatter,
                                 self.pos_D, float(eps), self.M.indptr, self.M.indices,
                                 z, f, x, data, q, r)
            return trusted_csc(data, self.M.indices, self.M.indptr, self.M.shape), q, r
        z, f, x = (np.asarray(a, dtype=float) for a in (z, f, x))
        M = self(J, eps)
        Mz = np.empty(n)
        csc_matvec(M.indptr, M.indices, M.data, z, Mz)  # M @ z without scipy's dispatch
        return M, f - Mz, f + x - z

    def __call__(self, J, eps: float) -> sp.csc_matrix:
        if self.pos_J is None:
            data = J.data.copy()
        else:
            data = np.zeros_like(self.M.data)
            data[self.pos_J] = J.data  # canonical pattern: positions are distinct
        if eps:
            data[self.pos_D] += eps
        return trusted_csc(data, self.M.indices, self.M.indptr, self.M.shape)


def _linearizer_for(J, P):
    """A Linearizer of J when J is stored on the pattern P (None otherwise: not kept)."""
    if P is None or not (J.nnz == P.nnz and J.indptr.shape == P.indptr.shape
                         and np.array_equal(J.indptr, P.indptr)
                         and np.array_equal(J.indices, P.indices)):
        return None
    return Linearizer(J)


@dataclass
class NMSState:
    """The state of one NMS run from a start point (thesis §3.4)."""

    cur: Point  #: the current iterate z_k
    x: np.ndarray  #: its normal-map point, pi(x) = z_k
    memory: list  #: merits of the last checkpoints; R = max(memory)
    memory_size: int
    ckpt: tuple  #: (Point, x) of the last checkpoint
    delta: float  #: d-step radius
    eps: float  #: proximal perturbation of the next linearization
    best_seen: float  #: best merit when the stall count was last reset
    fbn_start: float  #: ||Phi|| at the run's start
    ckpt_newton: object = None  #: the path computed at the checkpoint, when it was
    n_d: int = 0  #: consecutive d-steps
    watchdogs: int = 0  #: watchdog returns since the last checkpoint
    stall: int = 0  #: major iterations without progress (see REFERENCE_PROGRESS)
    progress: bool = False  #: this major iteration set a checkpoint below its reference
    since_best: int = 0  #: major iterations since the best merit last improved by 0.1%

    def checkpoint(self, pt: Point, x):
        """pt becomes the current point and a checkpoint, its merit enters the memory."""
        self.cur, self.x = pt, x
        self.memory = (self.memory + [pt.psi])[-self.memory_size:]
        self.ckpt, self.ckpt_newton = (pt, x), None

    def fresh_checkpoint(self, pt: Point, x):
        """After a fallback step the new point starts a monotone phase: it is the only
        checkpoint and the reference value is its own merit."""
        self.cur, self.x = pt, x
        self.memory = [pt.psi]
        self.ckpt, self.ckpt_newton = (pt, x), None


def reference_value(memory, psi, fbn, fbn_start):
    """(R, large): the reference value R = max(memory) and the factor by which a d-step
    may exceed it (100).  Within ``LOCAL_FACTOR`` of the run's starting residual the
    iteration turns monotone: R <= Psi(z_k) and large = 1, so a Newton step that raises
    the merit there (a singular or non-Lipschitz Jacobian, e.g. a sector shutting down
    in a CGE model) goes to the watchdog's backtracking search instead of being accepted
    against old, large reference values."""
    R = max(memory)
    if fbn <= LOCAL_FACTOR * fbn_start:
        return min(R, psi), 1.0
    return R, 100.0


def classify_step(psi, R, large, dist, delta, d_allowed, sigma, descent_ok):
    """The NMS test of a Newton point with merit psi at distance dist (inf-norm):
    'D' d-step (d-steps allowed, dist <= delta, psi <= large R), 'O' a d-step that also
    passes the m-step test, 'M' m-step (``descent_ok()``: sufficient decrease against R),
    None: rejected (watchdog)."""
    if d_allowed and dist <= delta and psi <= large * max(R, 1e-300):
        if psi < R * (1.0 - sigma) and descent_ok():
            return "O"
        return "D"
    if descent_ok():
        return "M"
    return None


STALL_RTOL = nk.STALL_RTOL
"""A major iteration makes progress when it lowers the best merit, or (the restart rule)
sets a checkpoint below the reference value in force, by this fraction."""

REFERENCE_PROGRESS = True
"""The restart rule (restart_stationary_limit) counts from the reference value, as PATH's
does: a major iteration that sets a checkpoint below the reference value in force is
progress, like one that lowers the best merit (below_reference).  A non-monotone
excursion that the stabilization accepted and that came back below R is the method
working: counting it as "no progress" restarted the traffic equilibrium (n = 912: merit
21 -> 700 -> 214 by d-steps, then 56 -> 9.7 -> 0.68) after 3 major iterations and threw
505 pivots away (1098 pivots against 586).  The hand-over to the homotopy
(homotopy_stationary_limit) still watches the best merit alone: on the thesis families
(n <= 200, where the homotopy comes first) counting checkpoints there delayed it, every
instance still solved but with 6x the pivots on the 271 instances it changed."""


REFERENCE_WINDOW = nk.REFERENCE_WINDOW
"""... but only within this many major iterations (5) of the best merit's last 0.1%
improvement.  Without the window a run that oscillates, with checkpoints below a reference
value that the oscillation itself keeps high, makes such "progress" forever: F = (x_p^2 +
1, ...) (a stationary point of the merit, no zero; merit 1.0 <-> 2-5 every other
iteration) ran to the major iteration limit (500) where it had stalled after 3 major
iterations per restart; with a window of 10 it still used up the 500 before its 50
restarts (STATIONARY_POINT at 734f4f3 after 159).  The traffic excursion needs 4 (n =
2452: a watchdog return, a d-step, then a checkpoint below R, 4 major iterations after the
best merit's last improvement)."""


def below_reference(psi, R):
    """Whether a new checkpoint of merit psi is progress against the reference value R
    (REFERENCE_PROGRESS)."""
    return psi < R * (1.0 - STALL_RTOL)


class NMSSolver:
    """The stabilized Newton method on one MCP (after presolve)."""

    def __init__(self, problem, options, *, manager_factory, callback=None,
                 deadline=None, log_major=None, log_minor=None, acceptance=None):
        self.p = problem
        self.acceptance = acceptance or Acceptance(problem.lb, problem.ub,
                                                   options.convergence_tolerance)
        self.ev = problem.evaluator
        self.opt0 = options
        self.lb, self.ub = problem.lb, problem.ub
        self.n = problem.n
        self.manager_factory = manager_factory
        self.callback = callback
        self.deadline = deadline
        self.log_major = log_major
        self.history = []  # Iteration records, read by solve.py into Result.history
        self.log_minor = log_minor
        self.tol = options.convergence_tolerance
        self.best: Point | None = None
        self.nit = 0
        self.minor = 0
        self.crash_its = 0
        self.grad_steps = 0
        self.lm_steps = 0
        self.restarts = 0
        self.passes = {"crash": PassStats(), "path": PassStats(), "fallback": PassStats()}
        self.linearizer = None
        self.bm = None
        self._direct = None  # DirectFactors when Newton paths try the direct step
        self._crash_factors = None  # the crash's last LU, offered to the next basis
        self.basis: WarmBasis | None = None
        self._rng = None
        self.verdict = None  # set when a point is judged a solution
        self.flat_rejections = 0
        #: the caller's acceptance verdict of the start Point handed to solve(), when
        #: the solver works on the user's problem unscaled: the first run does not judge
        #: that point again
        self.start_verdict = None
        self._start0 = None  # the start Point of solve()

    @property
    def rng(self):
        """The random generator of the restarts from new points (made when first needed:
        most solves never restart, and making one costs ~20 us)."""
        if self._rng is None:
            self._rng = np.random.default_rng(self.opt0.seed)
        return self._rng

    # ------------------------------------------------------------------ bookkeeping
    def _past_deadline(self) -> bool:
        return self.deadline is not None and time.perf_counter() > self.deadline

    def _consider(self, z, f, phi, psi, verdict=None):
        """Every evaluated trial point may be the best (and a solution).  Every loop that
        evaluates points passes through here, so the time limit is checked here too: it
        holds to within one evaluation.  ``verdict``: the acceptance verdict of this
        point, when it is known already."""
        if self.best is None or psi < self.best.psi:
            self.best = Point(z.copy(), f.copy(), phi.copy(), psi)
        small = verdict.small_residual if verdict is not None else \
            self.acceptance.small(z, f, phi, psi)
        if small:
            self._judge(z, f, phi, psi, verdict)
        if self._past_deadline():
            raise _Stop(Status.TIME_LIMIT, "time limit reached")

    def _judge(self, z, f, phi, psi, verdict=None):
        """The acceptance test of a point whose residuals are small (``verdict``: its
        verdict, when known): a solution stops the solve; a flat tail is counted."""
        v = verdict if verdict is not None else self.acceptance.judge(
            z, f, jac=lambda y: self.ev.jac(y, f), phi=phi, small=True)
        if v.solved:
            self.best = Point(z.copy(), f.copy(), phi.copy(), psi)
            self.verdict = v
            raise _Stop(Status.SOLVED, "solution found")
        if v.small_residual and v.flat_row >= 0:
            # A flat tail: keep going (a genuine solution may still be reached), but
            # not for ever along a tail that leads nowhere.
            self.flat_rejections += 1
            if self.flat_rejections >= FLAT_REJECTION_LIMIT:
                raise _Stop(Status.FLAT_RESIDUAL, v.flat_message(self.p.row_label))

    def _consider_trial(self, z, f):
        """A crash trial point (F evaluated there) may be the best point too."""
        phi = fb_phi(z, f, self.lb, self.ub)
        self._consider(z, f, phi, fb_psi(phi))

    def _point(self, z, f=None, J=None):
        if f is None:
            f = self.ev.f(z)
            if f is None:
                return None
        phi = fb_phi(z, f, self.lb, self.ub)
        return Point(z, f, phi, fb_psi(phi), J)

    def _check_limits(self, opt):
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise _Stop(Status.TIME_LIMIT, "time limit reached")
        if self.nit >= opt.major_iteration_limit:
            raise _Stop(Status.MAJOR_ITERATION_LIMIT,
                        f"major iteration limit ({opt.major_iteration_limit}) reached")
        if self.minor >= opt.cumulative_limit(self.n):
            raise _Stop(Status.MINOR_ITERATION_LIMIT,
                        f"cumulative pivot limit ({opt.cumulative_limit(self.n)}) reached")

    def _progress(self, cur: Point, final=False):
        self.progress.update(self.nit, self.minor, cur.fbn, self.best.fbn, self.restarts,
                             final=final)

    def _callback(self, cur: Point):
        if self.callback is None:
            return
        from .result import IntermediateResult

        z, f = self.acceptance.user_point(cur.z, cur.f)  # the user's units
        a = self.acceptance
        info = IntermediateResult(x=np.array(z, copy=True), fun=np.array(f, copy=True),
                                  residual=float(np.linalg.norm(fb_phi(z, f, a.lb, a.ub))),
                                  nit=self.nit, minor_iterations=self.minor)
        try:
            stop = self.callback(info)
        except StopIteration:
            stop = True
        except Exception as exc:  # the user's callback failed: stop, keep the best point
            raise _Stop(Status.CALLBACK_STOP, f"the callback raised {exc!r}") from exc
        if stop:
            raise _Stop(Status.CALLBACK_STOP, "stopped by the callback")

    # ------------------------------------------------------------------ Newton point
    def _jacobian_at(self, cur: Point):
        """J at the current iterate (the run's start point brings its own), None when it
        cannot be evaluated; the linearizer made for its pattern."""
        J = cur.J if cur.J is not None else self.ev.jac(cur.z, cur.f)
        self._last_J = J
        if J is None:
            return J
        if self.linearizer is None:
            # M = J + eps I has the same pattern in every solve of this problem: its index
            # arrays are made once per Jacobian pattern; made when first needed (a solve
            # that the crash ends never needs them: 6% of a solve of cournot2).
            self.linearizer = self.ev.for_pattern(
                "linearizer", lambda: _linearizer_for(J, self.ev.pattern_ref))
        if self.linearizer is None or self.linearizer.nnz_J != J.nnz:
            self.linearizer = Linearizer(J)  # J off the pattern, or an undeclared one grew
        return J

    def _start_ray(self, opt) -> bool:
        return opt.lemke_start == "always" or (opt.lemke_start == "first" and self.nit == 0)

    def _dense_lane(self, opt) -> bool:
        """Whether a small dense problem's linear MCP and its dense direct step are one
        compiled call (from the second major iteration: the basis manager and the direct
        step's factors are made on the first)."""
        return (self.bm is not None and self._direct is not None and self._crash_factors is None
                and self.log_minor is None and not self._start_ray(opt))

    def _newton_point(self, cur: Point, x, eps, opt):
        J = self._jacobian_at(cur)
        if J is None:
            return None, None, LinearCode.ERROR
        t0 = time.perf_counter()
        M = res = start = None
        if self._dense_lane(opt):
            # A small dense problem's linear MCP and its dense direct step in one compiled
            # call; when the step ends the path, solve_linear_mcp below is not needed.
            M, q, r, res, start = dense_newton_result(
                self.linearizer, J, eps, cur.z, cur.f, x, self.lb, self.ub, self.bm,
                self.basis, self._direct)
        if M is None:
            # M = J + eps I, q = f - M z and r = f + x - z (r: the normal map of the
            # linearization at x)
            M, q, r = self.linearizer.linearize(J, eps, cur.z, cur.f, x)
        if res is not None:
            self.bm.set_matrix(M)
        else:
            res = self._solve_linear(M, q, r, x, self._start_ray(opt), opt, start)
        self._path_done(res, t0, opt)
        return res, J, res.code

    def _path_done(self, res, t0, opt):
        """The counts of a major iteration's linear solve (started at ``t0``), its basis."""
        if res.direct_lu_nnz >= REUSE_BEATS_REFACTOR_NNZ and opt.factor_reuse and \
                not getattr(self.bm, "runs_paths", False):
            # factors this large are cheaper to reuse (the sparse basis' GMRES) than to
            # compute afresh in every major iteration
            self._direct = None
        st = self.passes["path"]
        st.ran = True
        st.time += time.perf_counter() - t0
        st.pivots += res.pivots
        st.factorizations += res.factorizations
        st.iterations += 1
        self.minor += res.pivots
        if res.code is LinearCode.SOLVED or res.t > 0:
            self.basis = res.basis

    def _solve_linear(self, M, q, r, x, start_ray, opt, dense_start=None):
        """The pivotal path of the major iteration's linear MCP (M, q) from x (the basis
        manager made on the first one); ``dense_start``: as for solve_linear_mcp."""
        if self.bm is None:
            self.bm = self.manager_factory(M)
            if direct_step_applies(M, opt):
                self._direct = DirectFactors()
            elif self.n < DIRECT_MIN_N and getattr(self.bm, "runs_paths", False):
                # small problems on the compiled engine: the direct step's block is
                # solved densely in one compiled call (a path's set-up costs more)
                self._direct = DirectFactors(dense=True,
                                             rank_tolerance=self.bm.rank_tolerance)
            else:
                self._direct = None
        else:
            self.bm.set_matrix(M)
        if self._crash_factors is not None and hasattr(self.bm, "offer_factors"):
            self.bm.offer_factors(*self._crash_factors)
            if self.bm.holds_offer:
                # the basis will solve on the crash's factors, cheaper than the direct
                # step's factorization, and reuse its own factors after that
                self._direct = None
        self._crash_factors = None
        # A warm path that stalls before half-way is retried from the Lemke start.
        return solve_linear_mcp(M, q, self.lb, self.ub, self.bm, opt, x, warm=self.basis, r=r,
                                ray_start=start_ray, retry_below=0.5,
                                minor_limit=opt.minor_limit(self.n), deadline=self.deadline,
                                log=self.log_minor, direct=self._direct,
                                dense_start=dense_start)

    # ------------------------------------------------------------------ fallbacks
    def _fallback(self, opt):
        """LM step and projected-gradient steps from the best point: (the new point or
        None, its log letter 'L' or 'G')."""
        t0 = time.perf_counter()
        b = self.best
        out, letter = None, "G"
        if opt.lm_fallback:
            lm = lm_step(self.ev, b.z, b.f, None, self.lb, self.ub, opt, deadline=self.deadline,
                         on_point=self._consider)
            if lm is not None:
                self.lm_steps += 1
                out, letter = Point(lm[0], lm[1], lm[2], lm[3]), "L"
        if out is None:
            g = gradient_steps(self.ev, b.z, b.f, None, self.lb, self.ub, opt,
                               deadline=self.deadline,
                               on_point=self._consider)
            if g is not None:
                self.grad_steps += g[4]
                out = Point(g[0], g[1], g[2], g[3])
        st = self.passes["fallback"]
        st.ran = True
        st.time += time.perf_counter() - t0
        st.iterations += 1
        return out, letter

    # ------------------------------------------------------------------ one run
    def _run(self, start, opt, stall_limit=None):
        """Crash + NMS from ``start`` (a point of the box, or an evaluated Point) with
        options opt.  Returns when stuck (for a restart or the homotopy): when the best
        merit has not improved in ``stall_limit`` major iterations, or, for a restart
        (stall_limit None: opt.restart_stationary_limit), when in that many the best merit
        has not improved and no checkpoint has beaten its reference value
        (REFERENCE_PROGRESS)."""
        # The restart rule also counts checkpoints below their reference value as progress
        # (below_reference); the hand-over to the homotopy (its own stall_limit) watches
        # the best merit only: see REFERENCE_PROGRESS.
        reference_progress = stall_limit is None and REFERENCE_PROGRESS
        if stall_limit is None:
            stall_limit = opt.restart_stationary_limit
        lb, ub = self.lb, self.ub
        cur = start if isinstance(start, Point) else self._point(start)
        if cur is None:
            # only a restart's drawn point arrives unevaluated (the user's start was evaluated)
            return "F or J undefined at the last restart's point (not at the start point)"
        # the caller's verdict holds for the start Point itself, in the first run only
        v0 = self.start_verdict if start is self._start0 else None
        self.start_verdict = None
        self._consider(cur.z, cur.f, cur.phi, cur.psi, v0)
        x, _ = normal_map_at(cur.z, cur.f, lb, ub)
        # --- crash
        if (opt.crash_method == "pnewton" and self.n >= opt.crash_minimum_dimension
                and opt.crash_iteration_limit > 0):
            t0 = time.perf_counter()
            nf0, nj0 = self.p.counters.nfev, self.p.counters.njev
            st = self.passes["crash"]
            st.ran = True
            it0 = st.iterations
            try:  # (a solution found by the crash stops the solve from inside it)
                cr = crash(self.ev, cur.z, lb, ub, opt, f0=cur.f, J0=cur.J, tol=self.tol,
                           deadline=self.deadline,
                           log=self._crash_log if self.log_major is not None else None,
                           on_point=self._consider_trial, stats=st)
            finally:
                st.time += time.perf_counter() - t0
                st.nfev += self.p.counters.nfev - nf0
                st.njev += self.p.counters.njev - nj0
                self.crash_its += st.iterations - it0
            st.reason = cr.stop_reason  # (of the last run's crash; a skip's reason is stale)
            if cr.iterations > 0 and all_finite(cr.f):
                pt = self._point(cr.z, cr.f)
                self._consider(pt.z, pt.f, pt.phi, pt.psi)
                if pt.psi <= opt.nms_initial_reference_factor * cur.psi:
                    cur, x = pt, cr.x
                    self._crash_factors = cr.factors
        elif not self.passes["crash"].ran and self.passes["crash"].reason == "":
            self.passes["crash"].reason = (
                "crash_method none" if opt.crash_method == "none"
                else f"n < crash_minimum_dimension ({opt.crash_minimum_dimension})")
        # --- NMS
        # nms = False: a monotone line search -- no d-steps, and the reference value is
        # the merit of the current point (a memory of one checkpoint, no initial slack).
        monotone = not opt.nms
        st = NMSState(
            cur=cur, x=x, memory_size=1 if monotone else opt.nms_memory_size,
            memory=[cur.psi if monotone else opt.nms_initial_reference_factor * cur.psi],
            ckpt=(cur, x),
            delta=10.0 * max(1.0, float(np.max(np.abs(cur.z))) if cur.z.size else 1.0),
            eps=opt.proximal_perturbation, best_seen=self.best.psi, fbn_start=cur.fbn)
        if self._compiled_applies():
            return self._run_compiled(st, opt, stall_limit, reference_progress)
        while True:
            self._check_limits(opt)
            self._callback(st.cur)
            self._progress(st.cur)
            res, J, code = self._newton_point(st.cur, st.x, st.eps, opt)
            self.nit += 1
            st.progress = False
            if res is None:  # J could not be evaluated at z_k
                fb, letter = self._fallback(opt)
                if fb is None:
                    return "evaluation failure and no fallback progress"
                st.fresh_checkpoint(fb, normal_map_at(fb.z, fb.f, lb, ub)[0])
                self._log(code, letter, st.cur, st.eps, res)
                continue
            cur = st.cur
            if cur is st.ckpt[0]:
                st.ckpt_newton = res
            # A failed path that did not move (t ~ 0) offers no candidate point.
            usable = res.code is LinearCode.SOLVED or (
                res.t > 1e-8 and bool(np.any(res.z != cur.z)))
            step = None
            cand = self._point(res.z) if usable else None
            if cand is not None:
                self._consider(cand.z, cand.f, cand.phi, cand.psi)
                R, large = reference_value(st.memory, cur.psi, cur.fbn, st.fbn_start)
                dist = max_abs_diff(cand.z, cur.z)
                step = classify_step(
                    cand.psi, R, large, dist, st.delta,
                    not monotone and st.n_d < opt.nms_mstep_frequency, opt.nms_sigma,
                    lambda: self._descent_ok(cur, cand, R, opt))
                if step in ("D", "O"):
                    st.n_d += 1
                    st.delta = max(st.delta * opt.nms_delta_shrink_factor, opt.nms_delta_min)
                elif step == "M":
                    st.n_d = 0
            if step is not None:
                xN = res.x if cand.z is res.z else normal_map_at(cand.z, cand.f, lb, ub)[0]
                st.cur, st.x = cand, xN
                if step in ("M", "O") or cand.psi < min(st.memory):
                    st.progress = below_reference(cand.psi, R)
                    st.checkpoint(cand, xN)
                    st.watchdogs = 0
                st.eps *= opt.proximal_shrink_factor
                self._log(res.code, step, st.cur, st.eps, res)
            else:
                # Watchdog: back to the checkpoint, search towards its Newton point.
                if usable and st.eps == 0.0 and res.code is not LinearCode.SOLVED:
                    st.eps = 0.01 * min(1.0, cur.fbn)
                elif not usable:
                    st.eps = max(st.eps * opt.proximal_increase_factor,
                                 1e-6 * min(1.0, cur.fbn))
                st.watchdogs += 1
                found = None
                newton = st.ckpt_newton
                if st.watchdogs <= opt.nms_maximum_watchdogs and newton is not None and (
                        newton.code is LinearCode.SOLVED or newton.t > 0):
                    c = st.ckpt[0]
                    R = reference_value(st.memory, c.psi, c.fbn, st.fbn_start)[0]
                    found = self._watchdog_search(st.ckpt, newton, R, opt)
                if found is not None:
                    st.progress = below_reference(found[0].psi, R)
                    st.checkpoint(*found)
                    st.n_d = 0
                    self._log(res.code, "W", st.cur, st.eps, res)
                else:
                    fb, letter = self._fallback(opt)
                    if fb is None:
                        self._log(res.code, "G", self.best, st.eps, res)
                        return "no descent from the best point"
                    st.fresh_checkpoint(fb, normal_map_at(fb.z, fb.f, lb, ub)[0])
                    st.n_d = 0
                    st.watchdogs = 0
                    self._log(res.code, letter, st.cur, st.eps, res)
            # Stationarity: restart when neither the best merit nor (for a while after
            # the best merit's last improvement) the reference value has been beaten.
            if self.best.psi < st.best_seen * (1.0 - STALL_RTOL):
                st.best_seen = self.best.psi
                st.stall = 0
                st.since_best = 0
            elif (st.progress and reference_progress
                  and st.since_best + 1 < REFERENCE_WINDOW):
                st.since_best += 1
                st.stall = 0
            else:
                st.since_best += 1
                st.stall += 1
                if st.stall >= stall_limit:
                    return f"no progress in {st.stall} major iterations"

    def _compiled_applies(self) -> bool:
        """Whether the major iterations run in compiled calls (:meth:`_run_compiled`): on
        the user's problem unscaled, up to COMPILED_NMS_MAX_N variables, without a
        callback or a log of the iterations, and once numba is loaded (during the cold
        start the Python loop is the faster)."""
        return (COMPILED_NMS and self.callback is None and self.log_major is None
                and self.acceptance.row is None and 0 < self.n <= COMPILED_NMS_MAX_N
                and _solver_vectors(self.lb, self.ub, self.lb, self.ub)  # float vectors
                and not cold_start()["interpreting"])

    def _run_compiled(self, st, opt, stall_limit, reference_progress):
        """The major iterations of :meth:`_run` from the state ``st``, their bookkeeping
        in compiled calls (``_nms_kernels.nms_dense``, which says what it needs next);
        here the evaluations, the paths that the dense direct step does not end, the
        acceptance test, the fallback, the limits, the counts and the history.  The
        Python loop's steps in its order: the same points bit for bit, ~50 us faster per
        major iteration of a small problem (double_root: 1.28 -> 0.82 ms a solve)."""
        n = self.n
        W = np.empty((nk.W_ROWS, n))
        cur = st.cur
        for row, v in ((nk.W_CZ, cur.z), (nk.W_CF, cur.f), (nk.W_CPHI, cur.phi),
                       (nk.W_CX, st.x), (nk.W_KZ, cur.z), (nk.W_KX, st.x), (nk.W_LB, self.lb),
                       (nk.W_UB, self.ub)):
            W[row] = v
        mem = np.empty(st.memory_size)
        mem[:len(st.memory)] = st.memory
        sf = np.zeros(nk.S_SIZE)
        for k, v in ((nk.S_CPSI, cur.psi), (nk.S_KPSI, cur.psi), (nk.S_DELTA, st.delta),
                     (nk.S_EPS, st.eps), (nk.S_BEST_SEEN, st.best_seen),
                     (nk.S_FBN_START, st.fbn_start), (nk.S_SIGMA, opt.nms_sigma),
                     (nk.S_DELTA_SHRINK, opt.nms_delta_shrink_factor),
                     (nk.S_DELTA_MIN, opt.nms_delta_min),
                     (nk.S_PROX_SHRINK, opt.proximal_shrink_factor),
                     (nk.S_PROX_INCREASE, opt.proximal_increase_factor),
                     (nk.S_STEP_MIN, opt.nms_stepsize_minimum),
                     (nk.S_SHRINK, opt.nms_shrink_factor), (nk.S_TOL, self.acceptance.tol),
                     (nk.S_LOCAL, LOCAL_FACTOR), (nk.S_FEASIBILITY, FEASIBILITY_TOLERANCE),
                     (nk.S_RESIDUAL, RESIDUAL_TOLERANCE)):
            sf[k] = v
        si = np.zeros(nk.I_SIZE, dtype=np.int64)
        for k, v in ((nk.I_NMEM, len(st.memory)), (nk.I_MEMSIZE, st.memory_size),
                     (nk.I_MONOTONE, not opt.nms), (nk.I_MSTEP_FREQ, opt.nms_mstep_frequency),
                     (nk.I_MAX_WATCHDOGS, opt.nms_maximum_watchdogs),
                     (nk.I_STALL_LIMIT, stall_limit), (nk.I_CUR_IS_CKPT, 1),
                     (nk.I_REFERENCE_RULE, reference_progress),
                     (nk.I_LINE, opt.nms_searchtype == "line")):
            si[k] = v
        B = np.zeros((3, n), dtype=np.int8)  # the warm basis, the start basis and its slack
        owner = [True]  # whether the best point is the kernel's (rows W_B*) now

        def take_best():  # the solver's best point goes to the kernel
            b = self.best
            W[nk.W_BZ], W[nk.W_BF], W[nk.W_BPHI] = b.z, b.f, b.phi
            sf[nk.S_BPSI] = b.psi
            si[nk.I_BEST_NEW] = 0
            owner[0] = True

        def hand_best():  # ... and back to the solver, before Python reads it
            if owner[0] and si[nk.I_BEST_NEW]:
                self.best = Point(W[nk.W_BZ].copy(), W[nk.W_BF].copy(), W[nk.W_BPHI].copy(),
                                  float(sf[nk.S_BPSI]))
            owner[0] = False

        def take_basis():  # the last path's basis (the warm start of the next) ...
            if self.basis is not None:
                B[nk.B_WARM] = self.basis.basic
            si[nk.I_HAS_WARM] = self.basis is not None
            si[nk.I_BASIS_NEW] = 0

        def hand_basis():  # ... and back to the solver
            if si[nk.I_BASIS_NEW]:
                self.basis = WarmBasis(B[nk.B_WARM].copy())
                si[nk.I_BASIS_NEW] = 0

        def fallback():  # (from the solver's best point, which it may replace)
            hand_best()
            fb, letter = self._fallback(opt)
            if fb is not None:
                take_best()
                W[nk.W_TZ], W[nk.W_TF], W[nk.W_TPHI] = fb.z, fb.f, fb.phi
                sf[nk.S_TPSI] = fb.psi
            return fb, letter

        def path_end(res):  # a path's end for the kernel
            W[nk.W_RZ], W[nk.W_RW], W[nk.W_RV] = res.z, res.w, res.v
            solved = res.code is LinearCode.SOLVED
            si[nk.I_USABLE] = solved or (res.t > 1e-8 and bool(np.any(res.z != W[nk.W_CZ])))
            si[nk.I_RES_SOLVED] = solved
            si[nk.I_RES_MOVED] = res.t > 0
            return res.code, res.pivots

        take_best()
        take_basis()
        kernel = nk.nms_dense
        jx = mdata = NO_VALUES  # (the arguments a call leaves unused)
        ip = ix = mp = mi = NO_INDICES
        pj = pd = _NO_POSITIONS

        def answer(arg, ft=NO_VALUES, late=False):  # the kernel's next call
            return kernel(sf, si, W, mem, B, mdata, ft, ip, ix, jx, pj, pd, mp, mi, arg, late)

        cur_J, f = cur.J, None
        code_res = pivots = None  # the last linear solve's code and pivots (the log's)
        try:
            code = answer(nk.A_START)
            while True:
                if si[nk.I_LOG]:  # a finished major iteration
                    self._record(code_res, nk.LETTERS[si[nk.I_LOG]], float(sf[nk.S_LOG_FBN]),
                                 pivots, float(sf[nk.S_EPS]))
                    si[nk.I_LOG] = 0
                if code == nk.NEED_NEWTON:
                    self._check_limits(opt)
                    if self.progress.enabled:
                        self.progress.update(self.nit, self.minor, math.sqrt(2.0 * sf[nk.S_CPSI]),
                                             math.sqrt(2.0 * sf[nk.S_BPSI]), self.restarts)
                    J_given, cur_J = cur_J, None  # (only the run's start comes with its J)
                    res = J = None
                    code_res = LinearCode.ERROR
                    direct = self._dense_lane(opt) and self._direct.dense
                    if direct:
                        J = self._jacobian_at(Point(W[nk.W_CZ], W[nk.W_CF], None, 0.0, J_given))
                        if J is not None and not (J.data.dtype == np.float64
                                                  and J.data.shape[0] == J.nnz):
                            direct, J_given = False, J  # (the Python route, with this J)
                    if direct and J is not None:  # the linear MCP and its direct step
                        lin = self.linearizer
                        if mdata.shape[0] != lin.M.data.shape[0]:
                            mdata = np.empty(lin.M.data.shape[0])
                        si[nk.I_SCATTER] = lin.pos_J is not None
                        pj, pd = (lin.pos_J if lin.pos_J is not None else lin.pos_D), lin.pos_D
                        mp, mi = lin.M.indptr, lin.M.indices
                        ip, ix, jx = J.indptr, J.indices, J.data
                        sf[nk.S_RANK] = self._direct.rank_tolerance
                        t0 = time.perf_counter()
                        code = answer(nk.A_J)
                        self.nit += 1
                        if code != nk.NEED_PATH:
                            self._dense_step_done(si[nk.I_DIRECT], si[nk.I_NF], t0)
                            code_res, pivots = LinearCode.SOLVED, 0
                            continue
                        # the step failed: the path, on the call's linear MCP and from
                        # its start (dense_direct_path's outcome)
                        P = lin.M
                        start = failed_direct_start(
                            W[nk.W_LZ].copy(), W[nk.W_LW].copy(), W[nk.W_LV].copy(),
                            B[nk.B_BASIC].copy(), B[nk.B_SLACK].copy(), si[nk.I_GUESSED],
                            self._direct.dense_done(int(si[nk.I_NF])))
                        hand_basis()
                        res = self._solve_linear(
                            trusted_csc(mdata.copy(), P.indices, P.indptr, P.shape),
                            W[nk.W_Q].copy(), W[nk.W_R].copy(), W[nk.W_CX].copy(), False, opt,
                            start)
                        self._path_done(res, t0, opt)
                        take_basis()
                    elif direct:  # (J could not be evaluated)
                        self.nit += 1
                    else:
                        hand_basis()
                        cur = Point(W[nk.W_CZ].copy(), W[nk.W_CF].copy(),
                                    W[nk.W_CPHI].copy(), float(sf[nk.S_CPSI]), J_given)
                        res, J, code_res = self._newton_point(cur, W[nk.W_CX].copy(),
                                                              float(sf[nk.S_EPS]), opt)
                        self.nit += 1
                        take_basis()
                    if res is None:  # J could not be evaluated at z_k
                        fb, letter = fallback()
                        if fb is None:
                            return "evaluation failure and no fallback progress"
                        self._record(code_res, letter, fb.fbn, 0, float(sf[nk.S_EPS]))
                        code = answer(nk.A_FRESH_J)
                        continue
                    code_res, pivots = path_end(res)
                    ip, ix, jx = J.indptr, J.indices, J.data
                    code = answer(nk.A_NEWTON)
                elif code == nk.NEED_F_CAND or code == nk.NEED_F_TRIAL:
                    if code == nk.NEED_F_TRIAL and self._past_deadline():
                        raise _Stop(Status.TIME_LIMIT, "time limit reached")
                    f = self.ev.f(W[nk.W_RZ] if code == nk.NEED_F_CAND else W[nk.W_TZ])
                    code = (answer(nk.A_F_FAILED) if f is None else
                            answer(nk.A_F_GIVEN, f, self._past_deadline()))
                elif code == nk.JUDGE:
                    hand_best()  # (a solution found here becomes the best point)
                    self._judge(W[nk.W_TZ].copy(), f, W[nk.W_TPHI].copy(),
                                float(sf[nk.S_TPSI]))
                    owner[0] = True
                    code = answer(nk.A_JUDGED, late=self._past_deadline())
                elif code == nk.NEED_FALLBACK:
                    fb, letter = fallback()
                    if fb is None:
                        self._record(code_res, "G", self.best.fbn, pivots, float(sf[nk.S_EPS]))
                        return "no descent from the best point"
                    self._record(code_res, letter, fb.fbn, pivots, float(sf[nk.S_EPS]))
                    code = answer(nk.A_FRESH)
                elif code == nk.TIME_UP:
                    raise _Stop(Status.TIME_LIMIT, "time limit reached")
                else:  # STALLED
                    return f"no progress in {int(si[nk.I_STALL])} major iterations"
        finally:
            hand_best()
            hand_basis()

    def _dense_step_done(self, direct, nf, t0):
        """The counts of a major iteration's linear MCP that the compiled call solved (its
        path's start, or its dense direct step on a block of order ``nf`` when
        ``direct``), as :meth:`_path_done` counts the same PathResult."""
        st = self.passes["path"]
        st.ran = True
        dt = time.perf_counter() - t0
        st.time += dt
        st.iterations += 1
        if direct:
            st.factorizations += 1
            nnz = self._direct.dense_done(int(nf))
            if nnz:
                self.bm.stats.record_direct_lu(nnz, dt, self._direct.method)

    def _descent_ok(self, cur, cand, R, opt):
        # The directional derivative of Psi at z_k uses the Jacobian of this major iteration.
        J = self._last_J
        if J is not None:
            dd = fb_directional(cur.z, cur.f, J, self.lb, self.ub, cur.phi, cand.z)
            if dd < 0:
                return cand.psi <= R + opt.nms_sigma * dd
        return cand.psi <= (1.0 - opt.nms_sigma) * R

    def _watchdog_search(self, ckpt, newton, R, opt):
        c, xc = ckpt
        lb, ub = self.lb, self.ub
        zN = newton.z
        xN = newton.x
        alpha = 1.0
        while alpha >= opt.nms_stepsize_minimum:
            if self._past_deadline():
                raise _Stop(Status.TIME_LIMIT, "time limit reached")
            if opt.nms_searchtype == "line":
                # (projected: the combination of two points at one bound can round to a
                # unit in the last place beyond it, and a returned point must lie in the box)
                zt = project((1.0 - alpha) * c.z + alpha * zN, lb, ub)
            else:
                zt = project((1.0 - alpha) * xc + alpha * xN, lb, ub)
            pt = self._point(zt)
            if pt is not None:
                self._consider(pt.z, pt.f, pt.phi, pt.psi)
                if pt.psi <= (1.0 - opt.nms_sigma * alpha) * min(R, max(c.psi, 1e-300) * 1e300) \
                        and pt.psi < R:
                    if opt.nms_searchtype == "line":
                        x, _ = normal_map_at(pt.z, pt.f, lb, ub)
                    else:
                        x = (1.0 - alpha) * xc + alpha * xN
                    return pt, x
            alpha *= opt.nms_shrink_factor
        return None

    # ------------------------------------------------------------------ logging
    def _crash_log(self, line):
        if self.log_major is not None:
            self.log_major("crash " + line)

    def _record(self, code, step, fbn, pivots, eps):
        """The history's record of this major iteration; returns the path's code letter."""
        c = code.value if hasattr(code, "value") else str(code)
        self.history.append(Iteration(self.nit, fbn, f"{c}{step}", pivots, eps,
                                      time.perf_counter() - self._t_start))
        return c

    def _log(self, code, step, cur, eps, res):
        pivots = res.pivots if res is not None else 0
        c = self._record(code, step, cur.fbn, pivots, eps)
        if self.log_major is None:
            return
        idx = int(np.argmax(np.abs(cur.phi))) if cur.phi.size else 0
        inorm = np.abs(cur.phi[idx]) if cur.phi.size else 0.0
        self.log_major(
            f"{self.nit:5d} {pivots:7d} {self.p.counters.nfev:6d} {self.p.counters.njev:5d} "
            f"{cur.fbn:12.4e} {c}{step} {eps:9.2e} {inorm:10.3e}"
            f" ({self.p.row_label(idx)})")

    # ------------------------------------------------------------------ driver
    def solve(self, start: Point) -> Outcome:
        """Run from ``start``, the evaluated start point (in the box, with F and J)."""
        opt = self.opt0
        self.progress = ProgressLine(opt.progress)
        self._t_start = time.perf_counter()
        start0, z0 = start, start.z
        self._start0 = start
        status, message = Status.NO_PROGRESS, ""
        schedule = RestartSchedule(self.opt0)
        self._last_J = None
        pattern = start.J if start.J is not None else self.ev.pattern_ref
        homotopy_after = self.opt0.restarts_before_homotopy(
            self.n, pattern.nnz if pattern is not None else self.n * self.n)
        try:
            if self.opt0.homotopy == "only":
                self._consider(start.z, start.f, start.phi, start.psi)
                raise _Stop(Status.NO_PROGRESS, self._homotopy(z0))
            while True:
                homotopy_next = (self.opt0.homotopy == "auto" and "homotopy" not in self.passes
                                 and self.restarts >= min(homotopy_after,
                                                          self.opt0.restart_limit))
                why = self._run(start, opt, stall_limit=self.opt0.homotopy_stationary_limit
                                if homotopy_next else None)
                if homotopy_next:
                    why = self._homotopy(z0)
                if self.restarts >= self.opt0.restart_limit:
                    status, message = Status.NO_PROGRESS, f"{why}; restart limit reached"
                    break
                self.restarts += 1
                if self.log_major is not None:
                    self.log_major(f"restart {self.restarts}: {why}")
                opt, where = schedule.plan(self.restarts - 1, self.best.fbn)
                if where == FROM_START:
                    start = start0
                elif where == FROM_RANDOM:
                    start = random_point(self.rng, z0, self.lb, self.ub)
                else:
                    start = near_point(self.rng, self.best.z, self.lb, self.ub)
                self.basis = None
        except _Stop as stop:
            status, message = stop.status, stop.message
        except FactorBudgetError as exc:
            status = Status.TIME_LIMIT if exc.kind == "time" else Status.MEMORY_LIMIT
            message = f"factorization not started: {exc}"
        except KeyboardInterrupt:
            status, message = Status.USER_INTERRUPT, "interrupted by the user (Ctrl-C)"
        status, message = self._diagnose(status, message)
        if self.best is not None:
            self._progress(self.best, final=True)
        bm = self.bm
        return Outcome(
            status, message, self.best, nit=self.nit, minor=self.minor,
            crash_iterations=self.crash_its, restarts=self.restarts,
            gradient_steps=self.grad_steps, lm_steps=self.lm_steps,
            factorizations=(bm.stats.factorizations if bm is not None else 0)
            + self.passes["crash"].factorizations
            + self.passes.get("homotopy", PassStats()).factorizations,
            updates=bm.stats.updates if bm is not None else 0,
            basis=self.basis, passes=self.passes,
            verdict=self.verdict if status is Status.SOLVED else None,
        )

    def _homotopy(self, start):
        """The homotopy pass (a solution stops the solve from inside): its first path from
        ``start`` (the user's start point), or with homotopy_start = 'best' after a stall
        from the best point; later paths from random points around ``start``."""
        from .homotopy import HomotopyStatus, homotopy_pass

        polish = None if self.opt0.homotopy == "only" else (lambda z: self._run(z, self.opt0))
        first = start
        if self.opt0.homotopy == "auto" and self.opt0.homotopy_start == "best":
            first = self.best.z
        self.nit += 1  # the pass is one major iteration of the log and the history
        try:
            out = homotopy_pass(self, first, polish=polish, center=start)
        finally:
            self.history.append(Iteration(self.nit, self.best.fbn, "-H", 0, 0.0,
                                          time.perf_counter() - self._t_start))
        if out.status is HomotopyStatus.TIME_LIMIT:
            raise _Stop(Status.TIME_LIMIT, "time limit reached on the homotopy path")
        return f"homotopy {out.status.value} ({out.message})"

    def _diagnose(self, status, message):
        """A failed solve names the rows that keep the merit up; one that converged to a
        stationary point of the merit function says so (see
        :mod:`compass_sparse.stationary`)."""
        if status not in _DIAGNOSED or self.best is None:
            return status, message
        try:
            J = self.ev.jac(self.best.z, self.best.f)
        except KeyboardInterrupt:
            return status, message
        st = stationarity(self.best.z, self.best.f, J, self.lb, self.ub)
        a = self.acceptance
        if a.row is not None:
            # The verdict is the scaled problem's (better conditioned); the rows are named
            # with the user's |Phi_i| at the user's point (the Result's residual report
            # reads the same values), not the scaled ones.
            zu, fu = a.user_point(self.best.z, self.best.f)
            st.rows = worst_rows(fb_phi(zu, fu, a.lb, a.ub))
        text = st.message(self.p.row_label)
        if status is Status.NO_PROGRESS and st.stationary:
            return Status.STATIONARY_POINT, text
        return status, f"{message}; {text}"
