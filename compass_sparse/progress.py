"""The one-line progress display of long solves (``Options.progress``).

A terminal feature, not a log: it rewrites one line of stderr (carriage return, no
newline until the end) and is shown only when stderr is a terminal, and only for solves
that have run longer than ``PROGRESS_AFTER`` seconds.  Everything else the solver says
goes through :mod:`logging`.
"""
from __future__ import annotations

import sys
import time

__all__ = ["ProgressLine", "PROGRESS_AFTER"]

PROGRESS_AFTER = 1.0
"""Seconds after which the display starts."""


def stderr_is_terminal() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


class ProgressLine:
    """``update`` redraws the line; ``close`` ends it with a newline (if it was shown)."""

    def __init__(self, enabled: bool):
        self.enabled = bool(enabled) and stderr_is_terminal()
        self.t0 = time.perf_counter()
        self.shown = False

    def update(self, nit, pivots, residual, best, restarts, *, final=False):
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.t0
        if elapsed < PROGRESS_AFTER and not (final and self.shown):
            return
        stream = sys.stderr
        stream.write(f"\r[compass_sparse] major {nit:5d}  pivots {pivots:8d}  "
                     f"residual {residual:10.3e}  best {best:10.3e}  "
                     f"restarts {restarts:3d}  {elapsed:8.1f} s")
        self.shown = True
        if final:
            stream.write("\n")
        stream.flush()
