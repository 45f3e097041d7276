"""The compiled route of the crash: a problem whose blocks are all dense (n <=
``DENSE_SOLVE_MAX_N``) runs everything between two evaluations of the user's F or J in one
compiled call (:func:`compass_sparse.crash._kernels.crash_dense`, which says what it needs
next); here only the evaluations, the trial points offered to the caller, the time limit,
the counts and the log.  The Python route's steps (:mod:`compass_sparse.crash.projected_newton`)
in its order: the same points bit for bit."""
from __future__ import annotations

import time

import numpy as np

from .._jit import NO_INDICES, NO_VALUES
from ..linalg.csc import float_csc
from . import _kernels as ck
from .outcome import (CRASH_START_FACTOR, CRASH_STEP_LIMIT, EPS_SCALE, PERTURB_ATTEMPTS,
                      RAISED, CrashResult, offer_point)

__all__ = ["crash_compiled"]


_REASONS = ("iteration limit", "converged", "domain error in J", "no basis change",
            "singular reduced Jacobian", "no progress", "time limit",
            RAISED)  # (ck.R_* order)


_SETTINGS: dict = {}  # id(options) -> (options, tol, sf, si): see _dense_settings


def _dense_settings(opt, tol):
    """Fresh copies of the compiled crash's settings arrays (sf, si) for options ``opt``
    and tolerance ``tol``, made from arrays kept per options object: a loop of solves
    with the same options sets them up once (a dozen item assignments, ~3 us a solve).
    The entry holds the options object itself, so its id is not reused while kept."""
    hit = _SETTINGS.get(id(opt))
    if hit is None or hit[0] is not opt or hit[1] != tol:
        sf = np.zeros(ck.CF_SIZE)
        sf[ck.CF_SIGMA] = opt.crash_sigma
        sf[ck.CF_MIN_STEP] = opt.crash_stepsize_minimum
        sf[ck.CF_TOL] = tol
        sf[ck.CF_EPS_SCALE] = EPS_SCALE
        sf[ck.CF_STEP_LIMIT] = CRASH_STEP_LIMIT
        sf[ck.CF_START_FACTOR] = CRASH_START_FACTOR
        si = np.zeros(ck.CI_SIZE, dtype=np.int64)
        si[ck.CI_LIMIT] = opt.crash_iteration_limit
        si[ck.CI_NBCHANGE] = opt.crash_nbchange_limit
        si[ck.CI_PERTURB] = bool(opt.crash_perturb)
        si[ck.CI_ATTEMPTS] = PERTURB_ATTEMPTS
        si[ck.CI_LINE] = opt.crash_searchtype == "line"
        if len(_SETTINGS) >= 32:
            _SETTINGS.clear()
        hit = _SETTINGS[id(opt)] = (opt, tol, sf, si)
    return hit[2].copy(), hit[3].copy()


def crash_compiled(evalr, z, f0, J0, lb, ub, opt, tol, deadline, log, on_point, stats, t0):
    """:func:`crash` of a problem whose blocks are all dense: everything between two
    evaluations of the user's F or J in one compiled call (``crash._kernels.crash_dense``,
    which says what it needs next); here only the evaluations, the trial points offered
    to ``on_point``, the time limit, the counts and the log.  The Python route's steps in
    its order: the same points bit for bit."""
    n = z.size
    W = np.empty((ck.CW_ROWS, n))
    W[ck.CW_Z] = z
    W[ck.CW_F] = f0
    W[ck.CW_LB] = lb
    W[ck.CW_UB] = ub
    prev_free = np.zeros(n, dtype=np.bool_)
    sf, si = _dense_settings(opt, tol)
    rows = []
    seen = [0, 0]  # accepted steps and factorizations already counted in stats

    def late():
        return deadline is not None and time.perf_counter() > deadline

    step = ck.crash_dense
    none, no_index = NO_VALUES, NO_INDICES
    if late():
        code = step(sf, si, W, prev_free, none, no_index, no_index, none, ck.STOP)
    elif J0 is not None:
        J = float_csc(J0)
        code = step(sf, si, W, prev_free, none, J.indptr, J.indices, J.data, ck.J_GIVEN)
    else:
        code = step(sf, si, W, prev_free, none, no_index, no_index, none, ck.NOTHING)
    while True:
        # what the call did: factorizations made, a step accepted (counted as they happen,
        # so that a stop raised by on_point reports them)
        if stats is not None and si[ck.CI_NFACT] != seen[1]:
            stats.factorizations += int(si[ck.CI_NFACT]) - seen[1]
            seen[1] = int(si[ck.CI_NFACT])
        if si[ck.CI_ACCEPTED] != seen[0]:
            seen[0] = int(si[ck.CI_ACCEPTED])
            row = (int(si[ck.CI_ROW_IT]), int(si[ck.CI_CHANGES]), int(si[ck.CI_NINACT]),
                   float(sf[ck.CF_NMT]), float(sf[ck.CF_ALPHA]))
            rows.append(row)
            if stats is not None:
                stats.iterations += 1
            if log is not None:
                log(f"{row[0]:5d} {row[1]:8d} {row[2]:9d} {row[3]:12.4e} {row[4]:9.2e}")
        if code == ck.DONE:
            break
        if late():
            code = step(sf, si, W, prev_free, none, no_index, no_index, none, ck.STOP)
        elif code == ck.NEED_J:
            J = evalr.jac(W[ck.CW_Z], W[ck.CW_F])
            if J is None:
                code = step(sf, si, W, prev_free, none, no_index, no_index, none,
                            ck.J_FAILED)
            else:
                J = float_csc(J)
                code = step(sf, si, W, prev_free, none, J.indptr, J.indices, J.data,
                            ck.J_GIVEN)
        else:  # NEED_F at the trial point
            zt = W[ck.CW_ZT].copy()
            ft = evalr.f(zt)
            if ft is None:
                code = step(sf, si, W, prev_free, none, no_index, no_index, none,
                            ck.F_FAILED)
                continue
            offer_point(on_point, stats, zt, ft)
            code = step(sf, si, W, prev_free, ft, no_index, no_index, none, ck.F_GIVEN)
    return CrashResult(W[ck.CW_Z].copy(), W[ck.CW_F].copy(), W[ck.CW_X].copy(),
                       max(int(si[ck.CI_IT]), 0), float(sf[ck.CF_FB]),
                       _REASONS[int(si[ck.CI_REASON])], time.perf_counter() - t0,
                       int(si[ck.CI_NFACT]), rows)
