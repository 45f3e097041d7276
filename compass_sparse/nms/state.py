"""The state of the stabilized Newton method: evaluated points, one run's state (iterate,
checkpoint, memory of merits, d-step radius, proximal term), the acceptance rules of a
Newton point (d-step, m-step, watchdog; thesis §3.4) and what a solve returns."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..path.outcome import WarmBasis
from ..status import Status, WorkCounts
from . import _kernels as nk

__all__ = ["LOCAL_FACTOR", "NMSState", "NMSStop", "Outcome", "Point", "classify_step",
           "reference_value"]

LOCAL_FACTOR = 1e-3
"""Below this fraction of a run's starting residual the NMS accepts only steps that do not
raise the merit (d-steps included); larger steps go to the watchdog's backtracking."""


class NMSStop(Exception):
    """Ends the solve from wherever it is decided (a solution, a limit, the callback)."""

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
    """What :meth:`compass_sparse.nms.solver.NMSSolver.solve` returns."""

    status: Status
    message: str
    best: Point
    counts: WorkCounts = field(default_factory=WorkCounts)
    basis: WarmBasis | None = None
    passes: dict = field(default_factory=dict)
    #: the start point, every logged major iteration, and the final point when the solve
    #: stopped inside a major iteration (:class:`~compass_sparse.status.Iteration`)
    history: list = field(default_factory=list)
    #: the acceptance verdict of ``best`` on the user's problem when the solve stopped
    #: because best was judged a solution (None otherwise)
    verdict: object = None


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
restarts.  The traffic excursion needs 4 (n = 2452: a watchdog return, a d-step, then a
checkpoint below R, 4 major iterations after the best merit's last improvement)."""


def below_reference(psi, R):
    """Whether a new checkpoint of merit psi is progress against the reference value R
    (REFERENCE_PROGRESS)."""
    return psi < R * (1.0 - STALL_RTOL)


def stall_update(st: "NMSState", best_psi: float, reference_progress: bool) -> None:
    """The stall count after a major iteration: reset by a 0.1% better best merit, or
    (``reference_progress``: the restart rule) by a checkpoint below its reference value
    within REFERENCE_WINDOW major iterations of the best merit's last improvement."""
    if best_psi < st.best_seen * (1.0 - STALL_RTOL):
        st.best_seen = best_psi
        st.stall = 0
        st.since_best = 0
    elif st.progress and reference_progress and st.since_best + 1 < REFERENCE_WINDOW:
        st.since_best += 1
        st.stall = 0
    else:
        st.since_best += 1
        st.stall += 1


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
