"""The small-problem engine: the whole pivotal path in compiled code on a dense LU.

For small n the cost of a path is not arithmetic but the Python work around each pivot
and each factorization (slot tables, column specs, manager calls: 50-200 us per pivot and
~1 ms per path, measured on 4-variable problems).  :class:`DensePathEngine` stands where a
basis manager stands (the solve's basis factory hands it out for n <=
``compass_sparse.routes.DENSE_ENGINE_MAX_N``) and :meth:`PivotalPath.run` hands it the slot
table it set up; the initial factorization with artificial repair, every pivot (FTRAN,
Harris ratio test, column replacement, refactorization, complement rule, cycle rule) and
the final solution check then run in :mod:`compass_sparse.path._dense_kernels` with no
Python per pivot.
Results are returned through the same PivotalPath fields, so the algorithm, the codes and
the messages are those of the Python loop.

The factorization is a dense LU with partial pivoting; column replacements are
Forrest-Tomlin updates of its U (row etas, no explicit inverse), refreshed every
``factorization_update_limit`` pivots (see the kernels' docstring).  All work arrays
(L, U, row etas, breakpoints) are allocated once per engine and reused by every path of a
solve.

Tolerances: a column whose eliminated pivot is at most ``rank_tolerance`` (1e-9, the dense
reference basis' repair threshold) times
max(1, its inf-norm) is dependent and repaired by an artificial; a replacement with
``|d_s| <= pivot_tolerance * max(1, ||d||_inf)`` (1e-11) is refused and the basis
refactorized (the sparse manager's tests, same defaults).  An update whose two computations
of the new diagonal of U differ by more than ``stability_tolerance`` (1e-8, relative) or
whose row eta has a multiplier above ``growth_limit`` (100) is replaced by a
refactorization.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from . import _dense_kernels as K
from .._jit import NO_VALUES
from . import _kernels as PK
from ._dense_lu import allocate_factors
from ..linalg._csc_kernels import csc_to_dense
from ..basis.types import BasisStats
from .outcome import LinearCode

__all__ = ["DensePathEngine"]

PIVOT_CHUNK = 1000
"""Pivots per compiled call: the time limit is checked between calls."""

_NAMES = "zwvatS"

_NO_BASIS = np.empty(0, dtype=np.int8)  # start_path's slack basis when there is none
_NO_RECORDS = np.zeros((0, K.REC_COLUMNS), dtype=np.int64)  # a path that logs nothing

_UPDATES = {K.UPD_OK: "OK", K.UPD_REFUSED: "REFUSED"}
"""The Python loop's names (UpdateStatus) of the kernels' update outcomes; every other
outcome made the path refactorize: REFACTORED."""

_CODES = {K.SOLVED: LinearCode.SOLVED, K.RAY: LinearCode.RAY, K.CYCLE: LinearCode.CYCLE,
          K.MINOR_LIMIT: LinearCode.MINOR_LIMIT, K.SINGULAR: LinearCode.SINGULAR,
          K.TOLERANCE: LinearCode.TOLERANCE, K.ERROR: LinearCode.ERROR}
"""The kernels' path codes as :class:`compass_sparse.path.LinearCode`."""


class DensePathEngine:
    """Runs pivotal paths of a linear MCP with matrix M (n x n) in compiled code.

    Takes the place of the basis manager: ``set_matrix`` / ``set_dense_column`` / ``stats``
    as the managers, and :meth:`run_path` called by :meth:`PivotalPath.run`."""

    runs_paths = True

    def __init__(self, M, options=None, *, update_limit: int | None = None,
                 pivot_tolerance: float = 1e-11, rank_tolerance: float = 1e-9,
                 stability_tolerance: float = 1e-8, growth_limit: float = 100.0):
        if update_limit is None:
            update_limit = options.factorization_update_limit if options is not None else 50
        self.update_limit = max(1, int(update_limit))
        self.pivot_tolerance = float(pivot_tolerance)
        self.rank_tolerance = float(rank_tolerance)
        self.stability_tolerance = float(stability_tolerance)
        self.growth_limit = float(growth_limit)
        self.stats = BasisStats()
        self._dense = None
        self.set_matrix(M)
        self.L = None  # work areas: allocated by the first path (see _allocate)
        self._rec = None  # the pivot records of a minor log (see _records)
        self.r = np.zeros(self.n)

    def _allocate(self):
        """The factors' and the path's work areas, once per engine: a solve whose paths
        all end by the direct step (direct_step.py) never needs them."""
        n = self.n
        self.L, self.U, self.R, self.perm, self.fwork = allocate_factors(n, self.update_limit)
        self.work = np.zeros((8, n))
        self.n_breakpoints = max(1, min(200, 5_000_000 // max(n, 1)))
        self.bp_t = np.zeros(self.n_breakpoints)
        self.bp_x = np.zeros((self.n_breakpoints, n))
        self.best_x = np.zeros(n)
        self.enter_count = np.zeros((6, n), dtype=np.int64)
        self.displaced = np.full(n, -1, dtype=np.int64)

    def set_matrix(self, M):
        """Take M (sparse or dense); its dense column-major copy is made when a path
        first needs it (a path ended by the direct step never does)."""
        self.n = M.shape[0]
        self._pending = M

    @property
    def M(self):
        """The dense column-major copy of M, allocated once per order and refilled for
        every later linearization."""
        M = self._pending
        if M is not None:
            n = M.shape[0]
            A = self._dense
            if A is None or A.shape != (n, n):
                A = self._dense = np.zeros((n, n), order="F")
            if sp.issparse(M) and M.format == "csc":
                csc_to_dense(M.indptr, M.indices, M.data, A)
            else:
                A[...] = M.toarray() if sp.issparse(M) else np.asarray(M, dtype=float)
            self._pending = None
        return self._dense

    def set_dense_column(self, r):
        self.r = np.ascontiguousarray(r, dtype=float)

    # ------------------------------------------------------------------ the path
    def run_path(self, path, z, w, v, slack_basis):
        """Factor, pivot and check on ``path``'s slot table (set by PivotalPath.run).
        Leaves the path's fields as its own loop would and returns (LinearCode, message)."""
        if self.L is None:
            self._allocate()
        lb = np.ascontiguousarray(path.lb, dtype=float)
        ub = np.ascontiguousarray(path.ub, dtype=float)
        path.lb, path.ub = lb, ub
        q = path.q = np.ascontiguousarray(path.q, dtype=float)
        istate = np.empty(K.N_ISTATE, dtype=np.int64)
        fstate = np.empty(K.N_FSTATE)
        st = path.st  # the run's PathState: slot table set by PivotalPath.run
        opt = path.opt
        tolerances = (opt.pivot_tolerance, opt.ratio_tolerance, self.rank_tolerance,
                      self.pivot_tolerance, self.stability_tolerance, self.growth_limit,
                      int(path.minor_limit), int(opt.lemke_cycle_limit), PIVOT_CHUNK,
                      st.free_below, int(PK.BELOW_ZERO_PIVOTS), float(PK.T_PROGRESS))
        # the state's reset, the factorization (again on the slack basis when needed),
        # the first chunk of pivots and the solution check in one compiled call: a small
        # path's Python around three calls cost more than its pivots
        use_slack = slack_basis is not None
        log = path.log
        rec, rect = self._records() if log is not None else (_NO_RECORDS, NO_VALUES)
        factored, code, msg = K.start_path(
            self.M, q, self.r, lb, ub, st.sk, st.si, st.xb, st.zval, st.art_sign,
            self.displaced, self.enter_count, istate, fstate, self.L, self.U, self.R,
            self.perm, self.best_x, self.bp_t, self.bp_x, self.work, self.fwork, *tolerances,
            slack_basis if use_slack else _NO_BASIS, use_slack, z, w, v, rec, rect)
        if not factored:
            self._account(istate)
            return LinearCode.SINGULAR, self._message(msg, istate, fstate, path)
        if log is not None:
            _log_pivots(log, rec, rect, int(istate[K.I_PIV]))
        while code == K.RUNNING:
            if path.deadline is not None and time.perf_counter() > path.deadline:
                code, msg = K.MINOR_LIMIT, -1
                break
            done = int(istate[K.I_PIV])
            code, msg = K.run_pivots(
                self.M, q, self.r, lb, ub, st.sk, st.si, st.xb, st.zval,
                st.art_sign, self.displaced, self.enter_count, istate, fstate, self.L,
                self.U, self.R, self.perm, self.best_x, self.bp_t, self.bp_x, self.work,
                self.fwork, *tolerances, rec, rect)
            if log is not None:
                _log_pivots(log, rec, rect, int(istate[K.I_PIV]) - done)
        st.unbounded = msg == K.MSG_RAY_UNBOUNDED
        if st.unbounded:
            # z moves along dz: basic z's at their rates, an entering z at its direction
            # (the rates of the last pivot are still in the work area).
            ek, ei = int(istate[K.I_EK]), int(istate[K.I_EI])
            dz = np.zeros(self.n)
            m = st.sk == K.VAR_Z
            dz[st.si[m]] = self.work[7][m]
            if ek == K.VAR_Z:
                dz[ei] += fstate[K.F_ES]
            st.ray = (path.current_point()[0], dz)
        st.t = float(fstate[K.F_T])
        st.t_lower, st.below_from = float(fstate[K.F_TLOW]), int(istate[K.I_BELOW])
        st.t_slot = int(istate[K.I_TSLOT])
        st.pivots = int(istate[K.I_PIV])
        nbp = int(istate[K.I_NBP])
        st.breakpoints = [(float(self.bp_t[k]), self.bp_x[k].copy()) for k in range(nbp)]
        if fstate[K.F_BEST_T] > 0.0:
            st.best = (float(fstate[K.F_BEST_T]), self.best_x.copy())
        self._account(istate)
        return _CODES[int(code)], self._message(msg, istate, fstate, path)

    def _records(self):
        """The per-pivot record buffers of a logged path (made at its first log)."""
        if self._rec is None:
            self._rec = (np.zeros((PIVOT_CHUNK, K.REC_COLUMNS), dtype=np.int64),
                         np.zeros(PIVOT_CHUNK))
        return self._rec

    def _account(self, istate):
        self.stats.factorizations += int(istate[K.I_NFAC])
        self.stats.updates += int(istate[K.I_NUPD])
        self.stats.refused_updates += int(istate[K.I_REFUSED])
        self.stats.refactor_by_stability += int(istate[K.I_UNSTABLE] + istate[K.I_GROWTH])

    @staticmethod
    def _message(msg, istate, fstate, path) -> str:
        ek, ei = int(istate[K.I_EK]), int(istate[K.I_EI])
        if msg == -1:
            return "time limit during the path"
        if msg == K.MSG_NONE:
            return ""
        if msg == K.MSG_LIMIT:
            return f"{int(istate[K.I_PIV])} pivots: minor iteration limit"
        if msg == K.MSG_CYCLE:
            return f"{_NAMES[ek]}[{ei}] entered {path.opt.lemke_cycle_limit} times"
        if msg == K.MSG_RAY_UNBOUNDED:
            return f"ray: {_NAMES[ek]}[{ei}] unbounded"
        if msg == K.MSG_T_STALL:
            return f"t not above 0 after {int(istate[K.I_PIV])} pivots"
        if msg == K.MSG_TOL:
            return f"linear residual {fstate[K.F_RES]:.2e} after refactorization"
        return _MESSAGES[msg]


_MESSAGES = {
    K.MSG_T_ZERO: "t decreased to 0",
    K.MSG_SING_FACTOR: "the basis could not be factorized",
    K.MSG_SING_T: "the covering vector is dependent on the basis",
    K.MSG_SING_SLACK: "slack columns are dependent",
    K.MSG_SING_ART: "t reached 1 with nonzero artificial variables",
    K.MSG_NO_DISPLACED: "artificial without a displaced variable",
    K.MSG_LEAVE_KIND: "unexpected leaving kind",
    K.MSG_BOUNDED_SLACK: "bounded entering slack",
}


def _log_pivots(log, rec, rect, count):
    """The minor-log lines of ``count`` pivot records, as the Python loop writes them."""
    for k in range(count):
        pivots, kind, ek, ei, lk, li, upd = (int(v) for v in rec[k])
        if kind == K.REC_FLIP:
            log(f"minor {pivots:7d} t {rect[k]:.6e} z[{ei}] to its other bound")
        else:
            log(f"minor {pivots:7d} t {rect[k]:.6e} in {_NAMES[ek]}[{ei}] "
                f"out {_NAMES[lk]}[{li}] ({_UPDATES.get(upd, 'REFACTORED')})")
