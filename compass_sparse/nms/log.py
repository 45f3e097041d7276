"""The one log of a solve, and the history of its major iterations.

The log is written through one callable (``logger.info`` of the ``compass_sparse`` logger,
at verbosity >= 2) in sections, as PATH writes its own: each pass that iterates has a
title line and a header of fixed-width columns, written when the pass starts writing
(again after another section, e.g. the crash of a restart):

``Crash Log``            ``crash changes size residual step`` -- one line per accepted
                         projected-Newton step (:mod:`compass_sparse.crash`): the changes
                         of its active set, the size of its free set, the normal map's
                         norm after the step, the step length;
``Major Iteration Log``  ``major minor func grad residual type prox inorm (label)`` -- one
                         line per major iteration (:mod:`compass_sparse.nms`), the pivots of
                         its path before it at verbosity 3;
``Homotopy Log``         ``step lambda h |x| func`` -- one line per accepted step of the
                         path tracker (:mod:`compass_sparse.homotopy`), and one per path's
                         end.

Lines of no section (the preprocessor's and the scaling's reports, restarts, a crash's
end) are written as they come.  Every major iteration also leaves an
:class:`~compass_sparse.status.Iteration` in the history (``Result.history``); both routes
of the major iterations (the Python loop and the compiled one) report through here, so
they log the same lines.
"""
from __future__ import annotations

import time

import numpy as np

from ..box import dot_norm
from ..status import Iteration

__all__ = ["CRASH_HEADER", "HEADER", "HOMOTOPY_HEADER", "MajorLog", "SectionLog"]

HEADER = (f"{'major':>5} {'minor':>7} {'func':>6} {'grad':>5} {'residual':>12} "
          f"type {'prox':>9} {'inorm':>10} (label)")
"""The major-iteration log's header line."""

CRASH_HEADER = f"{'crash':>5} {'changes':>8} {'size':>9} {'residual':>12} {'step':>9}"
"""The crash log's header line (the crash writes its lines in these columns)."""

HOMOTOPY_HEADER = f"{'step':>6} {'lambda':>10} {'h':>9} {'|x|':>9} {'func':>6}"
"""The homotopy log's header line."""

SECTIONS = {"crash": ("Crash Log", CRASH_HEADER),
            "major": ("Major Iteration Log", HEADER),
            "homotopy": ("Homotopy Log", HOMOTOPY_HEADER)}
"""Each section's title and header."""


class SectionLog:
    """A log callable written in sections (see the module docstring): :meth:`writer` gives
    the callable of one section, which writes the section's title and header before its
    first line and whenever another section wrote in between."""

    def __init__(self, log):
        self.log = log
        self.section = None

    def enter(self, name):
        """Start section ``name`` (its title and header, unless it is the current one)."""
        if self.log is not None and self.section != name:
            self.section = name
            for line in SECTIONS[name]:
                self.log(line)

    def writer(self, name):
        """The log callable of section ``name`` (None when nothing is logged)."""
        if self.log is None:
            return None

        def write(line):
            self.enter(name)
            self.log(line)
        return write


class MajorLog:
    """The history and the log lines of one solve's major iterations (``log``: the log
    callable, or None; ``counters``: the evaluator's counters; ``row_label`` names rows)."""

    def __init__(self, log, counters, row_label):
        self.log = log
        self.sections = SectionLog(log)
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
        self.sections.enter("major")
        self.log(f"{nit:5d} {pivots:7d} {self.counters.nfev:6d} {self.counters.njev:5d} "
                 f"{fbn:12.4e} {c}{step} {eps:9.2e} {inorm:10.3e}"
                 f" ({self.row_label(idx)})")

    def homotopy(self, nit, fbn):
        """The homotopy pass, one major iteration of the history and of the log (type
        ``-H``, the residual of the best point after it)."""
        self.history.append(Iteration(nit, fbn, "-H", 0, 0.0, self.elapsed()))
        if self.log is not None:
            self.sections.enter("major")
            self.log(f"{nit:5d} {'':7s} {self.counters.nfev:6d} {self.counters.njev:5d} "
                     f"{fbn:12.4e} -H")

    def note(self, text):
        """A line of the log in no section (a restart, the end of a crash)."""
        if self.log is not None:
            self.log(text)

    def writer(self, name):
        """The log callable of section ``name`` ("crash", "major", "homotopy"), or None."""
        return self.sections.writer(name)

    def minor(self, log_minor):
        """The pivots' log callable (verbosity 3): its lines belong to the major
        iterations' section, whose header comes before the first."""
        if log_minor is None:
            return None

        def write(line):
            self.sections.enter("major")
            log_minor(line)
        return write

    def full_history(self, start_phi, nit, best) -> list:
        """The start point, every logged major iteration, and the final point when the
        solve stopped inside a major iteration (a solution found during a search: empty
        type)."""
        hist = [Iteration(0, dot_norm(start_phi), "", 0, 0.0, 0.0)] + self.history
        if best is not None and hist[-1].nit < nit:
            hist.append(Iteration(nit, best.fbn, "", 0, 0.0, self.elapsed()))
        return hist
