"""The one-line progress display of long solves (``Options.progress``) and of scenario
batches (``solve_batch(progress=...)``).

A terminal feature, not a log: on a terminal it rewrites one line of the stream (carriage
return, no newline until the end), for a solve only once it has run longer than
``PROGRESS_AFTER`` seconds.  On any other stream it shows nothing, or (batches) logs the
line every few seconds.  Everything else the solver says goes through :mod:`logging`.
"""
from __future__ import annotations

import logging
import sys
import time

__all__ = ["PROGRESS_AFTER", "Progress", "pass_line", "solve_line"]

logger = logging.getLogger("compass_sparse")

PROGRESS_AFTER = 1.0
"""Seconds after which a solve's display starts."""


def stderr_is_terminal() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


def _is_terminal(stream) -> bool:
    if stream is sys.stderr:
        return stderr_is_terminal()
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


class Progress:
    """One line of progress on ``stream`` (default stderr): :meth:`show` redraws it on a
    terminal, from ``after`` seconds on (default ``PROGRESS_AFTER``); on another stream
    it logs the line every ``every`` seconds (never when ``every`` is None).  Nothing at
    all when not ``enabled``; :attr:`enabled` then says whether anything can be shown."""

    def __init__(self, enabled: bool = True, *, stream=None, after=None, every=None):
        self.stream = sys.stderr if stream is None else stream
        self.tty = bool(enabled) and _is_terminal(self.stream)
        self.periodic = bool(enabled) and not self.tty and every is not None
        self.enabled = self.tty or self.periodic
        self.after = PROGRESS_AFTER if after is None else after
        self.every = every
        self.t0 = self._last = time.perf_counter()
        self.shown = False

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def due(self, final=False) -> bool:
        """Whether :meth:`show` would show a line now (ask before formatting one)."""
        if self.tty:
            return self.elapsed >= self.after or (final and self.shown)
        return self.periodic and (final or time.perf_counter() - self._last >= self.every)

    def show(self, text: str, final=False):
        """Redraw the line (a terminal; a newline ends the last), or log it (periodic)."""
        if not self.due(final):
            return
        if self.tty:
            self.stream.write("\r" + text)
            self.shown = True
            if final:
                self.stream.write("\n")
            self.stream.flush()
        else:
            logger.info(text)
            self._last = time.perf_counter()


def solve_line(nit, pivots, residual, best, restarts, elapsed) -> str:
    """A solve's progress line."""
    return (f"[compass_sparse] major {nit:5d}  pivots {pivots:8d}  residual {residual:10.3e}  "
            f"best {best:10.3e}  restarts {restarts:3d}  {elapsed:8.1f} s")


def pass_line(phase, nfev, best, elapsed) -> str:
    """The progress line of a pass that runs before or between major iterations (the
    crash, the homotopy): its name, the F evaluations so far and the best residual."""
    return (f"[compass_sparse] {phase:8s}  F evaluations {nfev:8d}  best {best:10.3e}  "
            f"{elapsed:8.1f} s")
