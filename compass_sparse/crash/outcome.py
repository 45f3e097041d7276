"""What a crash returns (:class:`CrashResult`) and the settings both of its routes share."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CRASH_MEMORY", "CRASH_START_FACTOR", "CRASH_STEP_LIMIT", "EPS_SCALE",
           "PERTURB_ATTEMPTS", "RAISED", "CrashResult", "offer_point"]

RAISED = "raised the merit"
"""The stop reason of a crash whose next step would raise the solver's merit, the
Fischer-Burmeister norm ||Phi||, above its value at the crash's start: a point the
watchdog, searching from that start as its checkpoint, would not accept.  The crash's
own search measures the normal map (and accepts rises up to twice the start's at first),
which can fall while ||Phi|| climbs: on the static CGE model with a 50% output tax
(n = 2024) the crash went 181 -> 184 -> 145 -> 255 -> ... and handed on a point
(||Phi|| 175) whose linearizations the paths then walked for 1500-4000 pivots each (17705
pivots in all, 60 s), where Newton from the start solves it in 5 major iterations without
a pivot; on the traffic equilibrium (n = 912) it climbed 21.1 -> 36.8 over 6 steps for
37 of the solve's 76 factorizations and then handed on its start.  The step is not taken;
the crash hands on its best point so far."""

CRASH_MEMORY = 4
"""Residuals of the last accepted steps the next full step is tried against (the
non-monotone reference: the largest of them)."""

CRASH_START_FACTOR = 2.0
"""The reference of the first step: this times the start's ||F_B||."""

EPS_SCALE = 1e-8
"""The first perturbation of a singular J_II is this times max(1, ||F_B||)."""


@dataclass
class CrashResult:
    z: np.ndarray
    f: np.ndarray
    x: np.ndarray  # normal-map point with pi(x) = z of least ||F_B||
    iterations: int
    fb_norm: float
    stop_reason: str
    time: float
    factorizations: int
    log: list
    #: (labels, HeldLU): the factors of the last reduced Jacobian J[labels, labels]
    #: (None if not kept), for the first Newton step's basis (a preconditioner)
    factors: tuple | None = None
    reused: int = 0  #: steps solved on the previous step's factors (no factorization)


CRASH_STEP_LIMIT = 10.0
"""Largest ||d||_inf / (1 + ||z||_inf) of a crash step solved on a PERTURBED J_II + eps I.
On a singular J_II a tiny eps leaves the matrix nearly singular, and the step has length
~1/eps along the null space: at the start x0 = 0 of kojshin (J_II has a zero column)
eps = 1e-7 gave ||d|| ~ 1e7, and the search spent 13 F evaluations to reject it.  A longer
step is refused as a singular matrix would be, and eps grows tenfold (eps ~ 1 gave a crash
step to a third of the start residual there)."""


PERTURB_ATTEMPTS = 8
"""Factorizations of J_II (+ eps I) per crash step: eps = 0 (when J_II is structurally
regular), then eps0 = 1e-8 max(1, ||F_B||) growing tenfold, so up to eps0 * 1e6 or 1e7.
(Jumping straight to the eps that brings a runaway step to the limit, ~eps ||d|| / limit,
was tried: at kojshin's start it stopped at eps ~ 0.1, whose step the search rejects, where
tenfold growth passes on to eps ~ 1.)"""


def offer_point(on_point, stats, zt, ft):
    """A trial point where F was evaluated, offered to the caller (who may stop the crash
    by raising: the step that reached the point is counted then)."""
    if on_point is not None:
        try:
            on_point(zt, ft)
        except BaseException:
            if stats is not None:
                stats.iterations += 1
            raise
