"""The crash pass's entry point: :func:`crash` runs the compiled route or the Python loop,
as the solve's routes chose, inside one BLAS block for problems whose reduced systems are
factored densely."""
from __future__ import annotations

import contextlib
import time

import numpy as np

from ..basis.backends import DENSE_SOLVE_MAX_N
from ..box import solver_vectors
from ..linalg.blas import BLAS_LIMIT_MIN_N, single_threaded_blas
from .compiled import crash_compiled
from .outcome import CrashResult
from .projected_newton import crash_python

__all__ = ["crash"]


def crash(evalr, z0, lb, ub, options, *, f0=None, J0=None, tol=None, deadline=None,
          log=None, on_point=None, stats=None, compiled=True) -> CrashResult:
    """Projected-Newton crash from z0, a point of the box.  ``evalr`` is the problem's
    :class:`~compass_sparse.problem.evaluator.Evaluator`; ``f0``, ``J0``: F and J at z0 when
    known.  ``on_point(z, f)`` sees every trial point where F was evaluated (the caller's
    best point may be among them, and it may stop the crash by raising).  ``stats`` (a
    :class:`~compass_sparse.status.PassStats`) counts the accepted steps and the
    factorizations as they happen, so that they are reported when ``on_point`` stops the
    crash at a solution.  ``compiled``: the solve's crash route
    (:attr:`compass_sparse.routes.Routes.crash`); a problem whose blocks are all dense
    (n <= ``DENSE_SOLVE_MAX_N``), given F at z0 as the solver's float vectors, then runs
    in compiled calls (the same points bit for bit), every other one in the Python loop."""
    t0 = time.perf_counter()
    tol = options.convergence_tolerance if tol is None else tol
    z = np.asarray(z0, dtype=float)
    # Its reduced systems are factored densely, each in a single-threaded BLAS block; one
    # block around the whole crash makes those free (see compass_sparse.linalg.blas).
    # (Below BLAS_LIMIT_MIN_N OpenBLAS keeps such small kernels on one thread itself.)
    with (single_threaded_blas() if BLAS_LIMIT_MIN_N <= z.size <= DENSE_SOLVE_MAX_N
          else contextlib.nullcontext()):
        if (compiled and f0 is not None and 0 < z.size <= DENSE_SOLVE_MAX_N
                and solver_vectors(z, f0, lb, ub)):
            return crash_compiled(evalr, z, f0, J0, lb, ub, options, tol, deadline, log,
                                  on_point, stats, t0)
        return crash_python(evalr, z, f0, J0, lb, ub, options, tol, deadline, log, on_point,
                            stats, t0)
