"""The major-iteration log and history of a solve.

Every major iteration leaves an :class:`~compass_sparse.status.Iteration` in the history
(``Result.history``) and, with a log callable (verbosity >= 2), a line with PATH's
fixed-width columns: ``major minor func grad residual type prox inorm (label)`` -- see
:mod:`compass_sparse.nms`.  Both routes of the major iterations (the Python loop and the
compiled one) report through here, so they log the same lines.
"""
from __future__ import annotations

import time

import numpy as np

from ..box import dot_norm
from ..status import Iteration

__all__ = ["MajorLog"]

HEADER = (f"{'major':>5} {'minor':>7} {'func':>6} {'grad':>5} {'residual':>12} "
          f"type {'prox':>9} {'inorm':>10} (label)")
"""The major-iteration log's header line."""


class MajorLog:
    """The history and the log lines of one solve's major iterations (``log``: the log
    callable, or None; ``counters``: the evaluator's counters; ``row_label`` names rows)."""

    def __init__(self, log, counters, row_label):
        self.log = log
        self.counters = counters
        self.row_label = row_label
        self.history = []
        self.t_start = time.perf_counter()

    def elapsed(self) -> float:
        return time.perf_counter() - self.t_start

    def record(self, nit, code, step, fbn, pivots, eps) -> str:
        """The history's record of major iteration ``nit``; returns the path's code letter."""
        c = code.value if hasattr(code, "value") else str(code)
        self.history.append(Iteration(nit, fbn, f"{c}{step}", pivots, eps, self.elapsed()))
        return c

    def iteration(self, nit, code, step, point, eps, pivots, fbn=None):
        """The record and the log line of a major iteration that ends at ``point`` (``fbn``:
        its ||Phi||_2 as the caller computed it, when the caller did)."""
        fbn = point.fbn if fbn is None else fbn
        c = self.record(nit, code, step, fbn, pivots, eps)
        if self.log is None:
            return
        phi = point.phi
        idx = int(np.argmax(np.abs(phi))) if phi.size else 0
        inorm = np.abs(phi[idx]) if phi.size else 0.0
        self.log(f"{nit:5d} {pivots:7d} {self.counters.nfev:6d} {self.counters.njev:5d} "
                 f"{fbn:12.4e} {c}{step} {eps:9.2e} {inorm:10.3e}"
                 f" ({self.row_label(idx)})")

    def homotopy(self, nit, fbn):
        """The homotopy pass, one major iteration of the history."""
        self.history.append(Iteration(nit, fbn, "-H", 0, 0.0, self.elapsed()))

    def note(self, text):
        """A line of the log that is no major iteration (crash steps, restarts)."""
        if self.log is not None:
            self.log(text)

    def crash_line(self, line):
        self.log("crash " + line)

    def full_history(self, start_phi, nit, best) -> list:
        """The start point, every logged major iteration, and the final point when the
        solve stopped inside a major iteration (a solution found during a search: empty
        type)."""
        hist = [Iteration(0, dot_norm(start_phi), "", 0, 0.0, 0.0)] + self.history
        if best is not None and hist[-1].nit < nit:
            hist.append(Iteration(nit, best.fbn, "", 0, 0.0, self.elapsed()))
        return hist
