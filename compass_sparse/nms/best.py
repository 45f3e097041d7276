"""The best point of a solve, and the acceptance of every point the solve evaluates.

Every loop that evaluates points (the crash, the major iterations, the watchdog's search,
the fallbacks, the homotopy) offers them to :meth:`BestPoint.consider`: the point with the
lowest merit Psi is kept through everything, and every exit of the solve returns it
(thesis §3.4: never lose the best point).  A point whose residuals are small is judged by
the acceptance test (:mod:`compass_sparse.nms.acceptance`): a solution ends the solve, a
flat tail is counted.  Since every evaluation passes through here, the time limit is
checked here too: it holds to within one evaluation.
"""
from __future__ import annotations

import time

from ..merit import fb_phi, fb_psi
from ..status import Status
from .state import NMSStop, Point

__all__ = ["FLAT_REJECTION_LIMIT", "BestPoint"]

FLAT_REJECTION_LIMIT = 10
"""Points with a residual below the tolerance that the scale test (see
:mod:`compass_sparse.nms.acceptance`) rejected before the solve stops with FLAT_RESIDUAL."""


class BestPoint:
    """The owner of the solve's best point (:attr:`point`) and of its verdicts.

    ``acceptance``: the solve's :class:`~compass_sparse.nms.acceptance.Acceptance`;
    ``evaluator``: the problem's, whose J the acceptance test may ask for; ``row_label``
    names rows in messages."""

    def __init__(self, acceptance, evaluator, lb, ub, deadline, row_label):
        self.acceptance = acceptance
        self.ev = evaluator
        self.lb, self.ub = lb, ub
        self.deadline = deadline
        self.row_label = row_label
        self.point: Point | None = None
        self.verdict = None  #: the verdict of ``point`` when it was judged a solution
        self.flat_rejections = 0

    def past_deadline(self) -> bool:
        return self.deadline is not None and time.perf_counter() > self.deadline

    def consider(self, z, f, phi, psi, verdict=None):
        """Every evaluated trial point may be the best (and a solution).  ``verdict``: the
        acceptance verdict of this point, when it is known already."""
        if self.point is None or psi < self.point.psi:
            self.point = Point(z.copy(), f.copy(), phi.copy(), psi)
        small = verdict.small_residual if verdict is not None else \
            self.acceptance.small(z, f, phi, psi)
        if small:
            self.judge(z, f, phi, psi, verdict)
        if self.past_deadline():
            raise NMSStop(Status.TIME_LIMIT, "time limit reached")

    def judge(self, z, f, phi, psi, verdict=None):
        """The acceptance test of a point whose residuals are small (``verdict``: its
        verdict, when known): a solution stops the solve; a flat tail is counted."""
        v = verdict if verdict is not None else self.acceptance.judge(
            z, f, jac=lambda y: self.ev.jac(y, f), phi=phi, small=True)
        if v.solved:
            self.point = Point(z.copy(), f.copy(), phi.copy(), psi)
            self.verdict = v
            raise NMSStop(Status.SOLVED, "solution found")
        if v.small_residual and v.flat_row >= 0:
            # A flat tail: keep going (a genuine solution may still be reached), but
            # not for ever along a tail that leads nowhere.
            self.flat_rejections += 1
            if self.flat_rejections >= FLAT_REJECTION_LIMIT:
                raise NMSStop(Status.FLAT_RESIDUAL, v.flat_message(self.row_label))

    def consider_trial(self, z, f):
        """A crash trial point (F evaluated there) may be the best point too."""
        phi = fb_phi(z, f, self.lb, self.ub)
        self.consider(z, f, phi, fb_psi(phi))
