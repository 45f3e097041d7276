"""The stabilized Newton method's bookkeeping in compiled code (:meth:`NMSSolver._run`).

A major iteration of a small problem spent ~100 us of Python around ~15 us of the user's
F and J (double_root, round 13): the candidate point's merit, the best point, the
acceptance pre-test, the reference value, the d/m-step classification and its descent
test, the checkpoint and its memory, the watchdog's search, the stall rule.  Here all of
that runs in one compiled call between two requests to the Python driver
(``NMSSolver._run_compiled``), by reverse communication as the crash and the homotopy's
tracker do:

- NEED_NEWTON: the Newton point of the current iterate (rows W_CZ, W_CF, W_CX, the
  proximal eps in sf[S_EPS]).  The driver checks the limits.  On a small dense problem
  it brings J (A_J), and the call makes the linear MCP and its dense direct step; when
  the step fails it asks for the path (NEED_PATH).  Otherwise, or then, the driver runs
  the linear solve (``_newton_point``: its Jacobian, its path, its counts) and brings
  the path's end (z, w, v) in rows W_RZ, W_RW, W_RV with A_NEWTON (whether it is
  usable, solved the linear problem, reached t > 0: si[I_USABLE], si[I_RES_SOLVED],
  si[I_RES_MOVED]), or, when J failed there, the fallback's point with A_FRESH_J.
- NEED_F_CAND / NEED_F_TRIAL: F at the Newton point / at the watchdog's trial point
  W_TZ (the driver checks the time limit first for a trial point, as the search does);
  answered by A_F_GIVEN (F in ``ft``) or A_F_FAILED.
- JUDGE: the point in rows W_TZ, W_TF, W_TPHI (Psi in sf[S_TPSI]) passed the residual
  test: the driver applies the acceptance test (a solution ends the solve there) and
  answers A_JUDGED.
- NEED_FALLBACK: no step and no watchdog point: the driver runs the fallback from the
  best point and brings its point with A_FRESH (or ends the run).
- TIME_UP: the time limit passed at a considered point (``late``, which the driver sets
  on each call after an evaluation, as ``_consider`` reads the clock after its tests).
- STALLED: the stall rule ends the run.

A finished major iteration leaves its log record in si[I_LOG] (the step's letter) and
sf[S_LOG_FBN].  The best point lives in rows W_BZ, W_BF, W_BPHI while the kernel runs
(si[I_BEST_NEW] says it changed); the driver hands it to the solver before any Python
that reads it.  Every formula is the Python route's in its order (its norms as BLAS
products, numpy's max/min tie rules, Python's max and min over the memory), so the
points, steps and counts are the same bits; the Python route (option ``engine =
"reference"``, :mod:`compass_sparse.routes`) is the reference of the tests.
"""
from __future__ import annotations

import math

import numpy as np

from .._merit_kernels import np_max, np_min
from .._jit import njit
from .._merit_kernels import (fb_directional_kernel, fb_phi_kernel, max_abs_kernel, min_map_within,
                              normal_map_kernel)
from ..path.direct_step import dense_newton_direct

STALL_RTOL = 1e-3  # nms.STALL_RTOL (the stall rule's relative progress)
REFERENCE_WINDOW = 5  # nms.REFERENCE_WINDOW

# requests (returns)
NEED_NEWTON, NEED_F_CAND, NEED_F_TRIAL, JUDGE, NEED_FALLBACK, TIME_UP, STALLED, NEED_PATH = \
    range(8)
# answers (arg)
A_START, A_NEWTON, A_F_GIVEN, A_F_FAILED, A_JUDGED, A_FRESH, A_FRESH_J, A_J = range(8)
# log letters (si[I_LOG]); 0: no record pending
LOG_D, LOG_M, LOG_O, LOG_W = 1, 2, 3, 4
LETTERS = ("", "D", "M", "O", "W")

# W rows (length n): the current iterate and its normal-map point, the checkpoint's z and
# x, the checkpoint's Newton point, the path's end and its x, the point being tried, the
# best point, the box, two work rows, the linear MCP's q and r and its path's start
(W_CZ, W_CF, W_CPHI, W_CX, W_KZ, W_KX, W_NZ, W_NX, W_RZ, W_RW, W_RV, W_RX, W_TZ, W_TF,
 W_TPHI, W_TX, W_BZ, W_BF, W_BPHI, W_LB, W_UB, W_G, W_D, W_Q, W_R, W_LZ, W_LW,
 W_LV) = range(28)
W_ROWS = 28
# float scalars
(S_CPSI, S_KPSI, S_TPSI, S_BPSI, S_DELTA, S_EPS, S_BEST_SEEN, S_FBN_START, S_R, S_ALPHA,
 S_LOG_FBN, S_SIGMA, S_DELTA_SHRINK, S_DELTA_MIN, S_PROX_SHRINK, S_PROX_INCREASE,
 S_STEP_MIN, S_SHRINK, S_TOL, S_LOCAL, S_FEASIBILITY, S_RANK, S_RESIDUAL) = range(23)
S_SIZE = 23
# int scalars
(I_PHASE, I_ND, I_WATCHDOGS, I_STALL, I_NMEM, I_MEMSIZE, I_MONOTONE, I_MSTEP_FREQ,
 I_MAX_WATCHDOGS, I_STALL_LIMIT, I_NEWTON_SET, I_NEWTON_OK, I_CUR_IS_CKPT, I_LINE, I_LOG,
 I_USABLE, I_RES_SOLVED, I_RES_MOVED, I_BEST_NEW, I_HAS_WARM, I_BASIS_NEW, I_DIRECT,
 I_NF, I_SCATTER, I_GUESSED, I_PROGRESS, I_REFERENCE_RULE, I_SINCE_BEST) = range(28)
I_SIZE = 28
# rows of the int8 array B: the warm basis (the last path's), the start basis, its slack
B_WARM, B_BASIC, B_SLACK = range(3)
# phases: what the next call receives
_P_NEWTON, _P_CAND_F, _P_CAND_JUDGE, _P_TRIAL_F, _P_TRIAL_JUDGE, _P_FALLBACK = range(6)


@njit(cache=True, inline="always")
def _py_max(a, b):
    """Python's max(a, b): a unless b > a."""
    return b if b > a else a


@njit(cache=True, inline="always")
def _py_min(a, b):
    """Python's min(a, b): a unless b < a."""
    return b if b < a else a


@njit(cache=True)
def _memory_max(si, mem):
    """max(memory) as Python takes it over the list: the first largest."""
    m = mem[0]
    for j in range(1, si[I_NMEM]):
        if mem[j] > m:
            m = mem[j]
    return m


@njit(cache=True)
def _memory_min(si, mem):
    """min(memory), as Python takes it."""
    m = mem[0]
    for j in range(1, si[I_NMEM]):
        if mem[j] < m:
            m = mem[j]
    return m


@njit(cache=True)
def _reference(sf, si, mem, psi):
    """nms.reference_value(memory, psi, sqrt(2 psi), fbn_start): (R, large)."""
    R = _memory_max(si, mem)
    if math.sqrt(2.0 * psi) <= sf[S_LOCAL] * sf[S_FBN_START]:
        return _py_min(R, psi), 1.0
    return R, 100.0


@njit(cache=True)
def _copy(W, dst, src):
    for i in range(W.shape[1]):
        W[dst, i] = W[src, i]


@njit(cache=True)
def _make_current(sf, si, W, x_row):
    """The point in the T rows (its x in row ``x_row``) becomes the current iterate (not
    the checkpoint: _checkpoint says when it is)."""
    _copy(W, W_CZ, W_TZ)
    _copy(W, W_CF, W_TF)
    _copy(W, W_CPHI, W_TPHI)
    _copy(W, W_CX, x_row)
    sf[S_CPSI] = sf[S_TPSI]
    si[I_CUR_IS_CKPT] = 0


@njit(cache=True)
def _checkpoint(sf, si, W, mem, x_row):
    """NMSState.checkpoint of the point in the T rows (its x in row ``x_row``): it becomes
    the current iterate and the checkpoint, its merit enters the memory."""
    psi = sf[S_TPSI]
    _make_current(sf, si, W, x_row)
    k = si[I_NMEM]
    if k < si[I_MEMSIZE]:
        mem[k] = psi
        si[I_NMEM] = k + 1
    else:  # (memory + [psi])[-size:]
        for j in range(k - 1):
            mem[j] = mem[j + 1]
        mem[k - 1] = psi
    _copy(W, W_KZ, W_TZ)
    _copy(W, W_KX, x_row)
    sf[S_KPSI] = psi
    si[I_NEWTON_SET] = 0
    si[I_CUR_IS_CKPT] = 1


@njit(cache=True)
def _consider(sf, si, W):
    """NMSSolver._consider's tests of the point in rows W_TZ, W_TF: Phi and Psi, the best
    point, and the residual pre-test of Acceptance.small (whether it passed)."""
    phi = W[W_TPHI]
    fb_phi_kernel(W[W_TZ], W[W_TF], W[W_LB], W[W_UB], phi)
    sq = np.dot(phi, phi)  # (fb_psi's product; Acceptance.small's norm is its root)
    psi = 0.5 * sq
    sf[S_TPSI] = psi
    if psi < sf[S_BPSI]:
        sf[S_BPSI] = psi
        _copy(W, W_BZ, W_TZ)
        _copy(W, W_BF, W_TF)
        _copy(W, W_BPHI, W_TPHI)
        si[I_BEST_NEW] = 1
    tol = sf[S_TOL]
    if math.sqrt(2.0 * psi) > tol:
        return False
    if math.sqrt(sq) > tol:
        return False
    return min_map_within(W[W_TZ], W[W_TF], W[W_LB], W[W_UB], tol)


@njit(cache=True)
def _descent_ok(sf, W, R, indptr, indices, data):
    """NMSSolver._descent_ok of the candidate (T rows) from the current iterate."""
    psi = sf[S_TPSI]
    dd = fb_directional_kernel(W[W_CZ], W[W_CF], W[W_LB], W[W_UB], W[W_CPHI], indptr,
                               indices, data, W[W_TZ], W[W_G], W[W_D])
    if dd < 0:
        return psi <= R + sf[S_SIGMA] * dd
    return psi <= (1.0 - sf[S_SIGMA]) * R


@njit(cache=True)
def _end_major(sf, si):
    """The stall rule at the end of a major iteration (nms.NMSSolver._run's): progress is
    a 0.1% better best merit, or, where si[I_REFERENCE_RULE] (the restart rule), a
    checkpoint 0.1% below its reference value (si[I_PROGRESS], nms.below_reference) within
    REFERENCE_WINDOW major iterations of the best merit's last improvement."""
    progress = si[I_PROGRESS] != 0 and si[I_REFERENCE_RULE] != 0
    si[I_PROGRESS] = 0
    if sf[S_BPSI] < sf[S_BEST_SEEN] * (1.0 - STALL_RTOL):
        sf[S_BEST_SEEN] = sf[S_BPSI]
        si[I_STALL] = 0
        si[I_SINCE_BEST] = 0
    elif progress and si[I_SINCE_BEST] + 1 < REFERENCE_WINDOW:
        si[I_SINCE_BEST] += 1
        si[I_STALL] = 0
    else:
        si[I_SINCE_BEST] += 1
        si[I_STALL] += 1
        if si[I_STALL] >= si[I_STALL_LIMIT]:
            return STALLED
    si[I_PHASE] = _P_NEWTON
    return NEED_NEWTON


@njit(cache=True)
def _classify(sf, si, W, mem, indptr, indices, data):
    """The NMS test of the candidate (T rows; its x in W_RX), then the step or the
    watchdog (nms.classify_step and the loop's bookkeeping)."""
    psi = sf[S_TPSI]
    R, large = _reference(sf, si, mem, sf[S_CPSI])
    dist = max_abs_kernel(W[W_TZ], W[W_CZ], True)
    d_allowed = si[I_MONOTONE] == 0 and si[I_ND] < si[I_MSTEP_FREQ]
    step = 0
    if d_allowed and dist <= sf[S_DELTA] and psi <= large * _py_max(R, 1e-300):
        if psi < R * (1.0 - sf[S_SIGMA]) and _descent_ok(sf, W, R, indptr, indices, data):
            step = LOG_O
        else:
            step = LOG_D
    elif _descent_ok(sf, W, R, indptr, indices, data):
        step = LOG_M
    if step == 0:
        return _no_step(sf, si, W, mem)
    if step == LOG_M:
        si[I_ND] = 0
    else:
        si[I_ND] += 1
        sf[S_DELTA] = _py_max(sf[S_DELTA] * sf[S_DELTA_SHRINK], sf[S_DELTA_MIN])
    if step != LOG_D or psi < _memory_min(si, mem):
        si[I_PROGRESS] = psi < R * (1.0 - STALL_RTOL)
        _checkpoint(sf, si, W, mem, W_RX)
        si[I_WATCHDOGS] = 0
    else:  # the candidate becomes the current iterate only
        _make_current(sf, si, W, W_RX)
    sf[S_EPS] *= sf[S_PROX_SHRINK]
    si[I_LOG] = step
    sf[S_LOG_FBN] = math.sqrt(2.0 * psi)
    return _end_major(sf, si)


@njit(cache=True)
def _no_step(sf, si, W, mem):
    """No step from the Newton point: the proximal term grows, then the watchdog searches
    from the checkpoint towards its Newton point, or the fallback is asked for."""
    cur_fbn = math.sqrt(2.0 * sf[S_CPSI])
    usable = si[I_USABLE] != 0
    if usable and sf[S_EPS] == 0.0 and si[I_RES_SOLVED] == 0:
        sf[S_EPS] = 0.01 * _py_min(1.0, cur_fbn)
    elif not usable:
        sf[S_EPS] = _py_max(sf[S_EPS] * sf[S_PROX_INCREASE], 1e-6 * _py_min(1.0, cur_fbn))
    si[I_WATCHDOGS] += 1
    if (si[I_WATCHDOGS] <= si[I_MAX_WATCHDOGS] and si[I_NEWTON_SET] != 0
            and si[I_NEWTON_OK] != 0):
        sf[S_R] = _reference(sf, si, mem, sf[S_KPSI])[0]
        sf[S_ALPHA] = 1.0
        return _trial(sf, si, W)
    si[I_PHASE] = _P_FALLBACK
    return NEED_FALLBACK


@njit(cache=True)
def _trial(sf, si, W):
    """The watchdog's next trial point (NMSSolver._watchdog_search), or the fallback."""
    alpha = sf[S_ALPHA]
    if not alpha >= sf[S_STEP_MIN]:
        si[I_PHASE] = _P_FALLBACK
        return NEED_FALLBACK
    a = 1.0 - alpha
    lb, ub = W[W_LB], W[W_UB]
    for i in range(W.shape[1]):
        if si[I_LINE] != 0:
            t = a * W[W_KZ, i] + alpha * W[W_NZ, i]
        else:
            t = a * W[W_KX, i] + alpha * W[W_NX, i]
            W[W_TX, i] = t
        W[W_TZ, i] = np_min(np_max(t, lb[i]), ub[i])
    si[I_PHASE] = _P_TRIAL_F
    return NEED_F_TRIAL


@njit(cache=True)
def _trial_test(sf, si, W, mem):
    """The watchdog's acceptance of an evaluated trial point."""
    psi = sf[S_TPSI]
    alpha = sf[S_ALPHA]
    R = sf[S_R]
    if (psi <= (1.0 - sf[S_SIGMA] * alpha) * _py_min(R, _py_max(sf[S_KPSI], 1e-300) * 1e300)
            and psi < R):
        if si[I_LINE] != 0:
            normal_map_kernel(W[W_TZ], W[W_TF], W[W_LB], W[W_UB], W[W_TX], W[W_D])
        si[I_PROGRESS] = psi < R * (1.0 - STALL_RTOL)
        _checkpoint(sf, si, W, mem, W_TX)
        si[I_ND] = 0
        si[I_LOG] = LOG_W
        sf[S_LOG_FBN] = math.sqrt(2.0 * psi)
        return _end_major(sf, si)
    sf[S_ALPHA] = alpha * sf[S_SHRINK]
    return _trial(sf, si, W)


@njit(cache=True)
def _dense_newton(sf, si, W, B, mdata, indptr, indices, data, pos_j, pos_d, m_indptr,
                  m_indices):
    """The Newton point of a small dense problem from J (``indptr``, ``indices``,
    ``data``): the linear MCP (M's entries into ``mdata`` on the pattern ``m_indptr``,
    ``m_indices``, J's entries at ``pos_j`` when si[I_SCATTER], the diagonal at
    ``pos_d``: the linearizer's maps), its path's start and the dense direct step, as
    path.dense_newton_result makes them (direct_step.dense_newton_direct).  True when the
    start or the step ends the path (its end in the R rows, its basis the warm one,
    si[I_DIRECT]: whether the step was made, si[I_NF] its order); False when the path
    must run: q and r in rows W_Q, W_R, its start (z, w, v) in the L rows, its start
    basis in B[B_BASIC], and in B[B_SLACK] the basis before the inward guess when
    si[I_GUESSED]."""
    code, nf, accepted, guessed = dense_newton_direct(
        data, pos_j, si[I_SCATTER] != 0, pos_d, sf[S_EPS], m_indptr, m_indices, W[W_CZ],
        W[W_CF], W[W_CX], W[W_LB], W[W_UB], B[B_WARM], si[I_HAS_WARM] != 0, mdata, W[W_Q],
        W[W_R], W[W_LZ], W[W_LW], W[W_LV], B[B_BASIC], B[B_SLACK], W[W_RZ], W[W_RW],
        W[W_RV], sf[S_FEASIBILITY], sf[S_RANK], sf[S_RESIDUAL])
    si[I_NF] = nf
    si[I_DIRECT] = code
    si[I_GUESSED] = guessed
    if code == 0:  # r = 0: the start solves the linear problem
        _copy(W, W_RZ, W_LZ)
        _copy(W, W_RW, W_LW)
        _copy(W, W_RV, W_LV)
    elif not accepted:
        return False
    for i in range(W.shape[1]):
        B[B_WARM, i] = B[B_BASIC, i]
    si[I_HAS_WARM] = 1
    si[I_BASIS_NEW] = 1
    si[I_USABLE] = 1  # (a solved linear problem, t = 1)
    si[I_RES_SOLVED] = 1
    si[I_RES_MOVED] = 1
    return True


@njit(cache=True)
def nms_dense(sf, si, W, mem, B, mdata, ft, indptr, indices, data, pos_j, pos_d, m_indptr,
              m_indices, arg, late):
    """NMSSolver._run's major iterations from one request to the driver to the next (see
    the module's description of the requests and answers).  ``ft``: F at the point asked
    for (A_F_GIVEN); ``indptr``, ``indices``, ``data``: J of the current major iteration
    (its Newton point with A_J, its descent test); ``B``, ``mdata``, ``pos_j``,
    ``pos_d``, ``m_indptr``, ``m_indices``: the warm basis and the work of the dense
    Newton point (:func:`_dense_newton`); ``late``: the time limit passed (read after a
    considered point's tests)."""
    if arg == A_START:
        si[I_PHASE] = _P_NEWTON
        return NEED_NEWTON
    if arg == A_FRESH or arg == A_FRESH_J:
        # NMSState.fresh_checkpoint of the fallback's point (T rows, Psi in S_TPSI)
        normal_map_kernel(W[W_TZ], W[W_TF], W[W_LB], W[W_UB], W[W_TX], W[W_D])
        si[I_NMEM] = 0  # (the memory is [psi] after the checkpoint)
        _checkpoint(sf, si, W, mem, W_TX)
        if arg == A_FRESH_J:  # (after a failed J: no resets, no stall rule)
            si[I_PHASE] = _P_NEWTON
            return NEED_NEWTON
        si[I_ND] = 0
        si[I_WATCHDOGS] = 0
        return _end_major(sf, si)
    phase = si[I_PHASE]
    if arg == A_J and not _dense_newton(sf, si, W, B, mdata, indptr, indices, data, pos_j,
                                        pos_d, m_indptr, m_indices):
        return NEED_PATH
    if phase == _P_NEWTON:  # the path's end (z, w, v)
        for i in range(W.shape[1]):
            W[W_RX, i] = W[W_RZ, i] - W[W_RW, i] + W[W_RV, i]
        if si[I_CUR_IS_CKPT] != 0:
            _copy(W, W_NZ, W_RZ)
            _copy(W, W_NX, W_RX)
            si[I_NEWTON_SET] = 1
            si[I_NEWTON_OK] = 1 if si[I_RES_SOLVED] != 0 or si[I_RES_MOVED] != 0 else 0
        if si[I_USABLE] == 0:
            return _no_step(sf, si, W, mem)
        _copy(W, W_TZ, W_RZ)
        si[I_PHASE] = _P_CAND_F
        return NEED_F_CAND
    if phase == _P_CAND_F or phase == _P_TRIAL_F:
        if arg == A_F_FAILED:
            if phase == _P_CAND_F:
                return _no_step(sf, si, W, mem)
            sf[S_ALPHA] *= sf[S_SHRINK]
            return _trial(sf, si, W)
        for i in range(W.shape[1]):
            W[W_TF, i] = ft[i]
        if _consider(sf, si, W):
            si[I_PHASE] = _P_CAND_JUDGE if phase == _P_CAND_F else _P_TRIAL_JUDGE
            return JUDGE
        if late:
            return TIME_UP
        if phase == _P_CAND_F:
            return _classify(sf, si, W, mem, indptr, indices, data)
        return _trial_test(sf, si, W, mem)
    # A_JUDGED: the point was not a solution
    if late:
        return TIME_UP
    if phase == _P_CAND_JUDGE:
        return _classify(sf, si, W, mem, indptr, indices, data)
    return _trial_test(sf, si, W, mem)
