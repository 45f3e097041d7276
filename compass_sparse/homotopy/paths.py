"""The homotopy pass: paths from the start and from random points of the box, followed by
one tracker that counts the pass's work, every accepted point offered to the caller."""
from __future__ import annotations

import contextlib
import time

import numpy as np

from ..box import project, random_point
from ..linalg.blas import BLAS_LIMIT_MIN_N, single_threaded_blas
from ..status import PassStats
from .outcome import HomotopyOutcome, HomotopyStatus
from .tracker import HomotopyStop, Tracker

__all__ = ["homotopy_pass", "track_paths"]


def track_paths(evalr, lb, ub, z_start, opt, *, center=None, on_point=None, rng,
                deadline=None, tol=1e-6, polish=None, log=None,
                compiled=True) -> HomotopyOutcome:
    """Follow up to ``opt.homotopy_path_limit`` homotopy paths, the first from ``z_start``,
    the others from random points of the box drawn around ``center`` (default z_start; the
    user's start point when the first path starts from the best point found:
    :func:`~compass_sparse.box.random_point`).

    ``rng``: the random generator of those points, or a callable that returns it (called
    when the second path starts).  ``on_point(z, f, phi, psi)`` receives every accepted
    path point and every end-game point and may raise to stop the pass (the stabilized
    Newton method raises when a point is a solution); ``polish(z)`` (optional) is called
    with the end point of a path (lam = 1) whose Newton end game missed the tolerance.
    ``compiled``: the tracker's route (see :class:`~compass_sparse.homotopy.tracker.Tracker`)."""
    tr = Tracker(evalr, lb, ub, opt, deadline=deadline, on_point=on_point, tol=tol, log=log,
                 compiled=compiled)
    return _follow_paths(tr, z_start, opt, center, rng, polish, log)


def _follow_paths(tr, z_start, opt, center, rng, polish, log) -> HomotopyOutcome:
    """:func:`track_paths` with the tracker ``tr``."""
    lb = tr.lb
    ub = tr.ub
    statuses = []
    status, message, y = HomotopyStatus.STEP_LIMIT, "no path followed", None
    a = project(np.asarray(z_start, float), lb, ub)
    center = np.asarray(z_start if center is None else center, float)
    for k in range(opt.homotopy_path_limit):
        if k > 0:
            if callable(rng):  # made now: most passes end on their first path
                rng = rng()
            a = random_point(rng, center, lb, ub)
        try:
            status, message, y = tr.follow(a, polish=polish)
        except HomotopyStop as stop:
            status, message = stop.status, stop.message
        statuses.append(status)
        if log is not None:
            log(f"path {k + 1}: {status.value} ({message}); "
                f"{tr.steps} steps so far, {tr.factorizations} factorizations")
        if status is HomotopyStatus.SOLVED:
            break
        if status is HomotopyStatus.TIME_LIMIT:
            break
    z = tr.best[0] if tr.best is not None else None
    return HomotopyOutcome(
        status=status, message=message, z=z, lam=float(y[-1]) if y is not None else 0.0,
        paths=len(statuses), steps=tr.steps, rejected=tr.rejected,
        turning_points=tr.turning_points, newton_iterations=tr.newton_iterations,
        factorizations=tr.factorizations, path_status=statuses)


def homotopy_pass(evalr, lb, ub, z_start, opt, *, stats: PassStats, on_point, rng,
                  deadline=None, tol=1e-6, polish=None, center=None, log=None,
                  compiled=True) -> HomotopyOutcome:
    """The homotopy as a pass of the stabilized Newton method: :func:`track_paths` with its
    evaluator ``evalr``, its best-point bookkeeping ``on_point`` (which raises at a
    solution), its random stream ``rng`` and its deadline.  The first path starts from
    ``z_start``, the others around ``center``.  The work done is added to ``stats`` (the
    pass's :class:`~compass_sparse.status.PassStats`) whether the pass ends normally or by
    a stop raised from ``on_point``."""
    counters = evalr.counters
    nf0, nj0 = counters.nfev, counters.njev
    t0 = time.perf_counter()
    out = None
    stopped = ""
    tr = Tracker(evalr, lb, ub, opt, deadline=deadline, on_point=on_point, tol=tol, log=log,
                 compiled=compiled)
    try:
        # dense LU of the bordered system: one BLAS thread (a multithreaded BLAS ran these
        # factorizations 10x slower on a loaded machine: 150 ms against 15 ms at n = 500);
        # below BLAS_LIMIT_MIN_N OpenBLAS keeps such small kernels on one thread itself
        with (single_threaded_blas() if tr.n >= BLAS_LIMIT_MIN_N
              else contextlib.nullcontext()):
            out = _follow_paths(tr, z_start, opt, center, rng, polish, log)
        return out
    except BaseException as exc:  # a solution or a limit of the solve, raised through us
        stopped = getattr(exc, "message", type(exc).__name__)
        raise
    finally:
        stats.ran = True
        stats.time += time.perf_counter() - t0
        stats.nfev += counters.nfev - nf0
        stats.njev += counters.njev - nj0
        stats.iterations += tr.steps
        stats.factorizations += tr.factorizations
        stats.reason = (f"{out.status.value}: {out.message} ({out.paths} paths, "
                        f"{out.steps} steps, {out.turning_points} turning points)"
                        if out is not None else f"stopped on the path: {stopped}")
