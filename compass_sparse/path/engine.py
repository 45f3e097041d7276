"""The compiled path engines: the whole pivotal path of a linear MCP in compiled code.

A path engine stands where a basis manager stands (``set_matrix`` /
``set_dense_column`` / ``stats``) and :meth:`PivotalPath.run` hands it the slot table it
set up (``runs_paths``); the initial factorization with artificial repair, every pivot
(FTRAN, Harris ratio test, column replacement, refactorization, complement and cycle
rules, t's lower-bound rules, best point) and the final solution check
then run in :mod:`compass_sparse.path._path_kernels` with no Python per pivot, in chunks
of at most ``chunk`` pivots between which the time limit is checked.  Results are
returned through the same PivotalPath fields, so the algorithm, the codes and the
messages are those of the Python loop.

There is one loop and two factor kinds: :class:`~compass_sparse.path.dense_engine.
DensePathEngine` (dense LU, small problems) and :class:`~compass_sparse.path.
sparse_engine.SparsePathEngine` (sparse LU, the rest); :class:`PathEngine` is what they
share: the call of the kernels, the minor log from their record buffer, the path's state
read back, the counts.
"""
from __future__ import annotations

import time

import numpy as np

from .._jit import NO_VALUES
from . import _kernels as PK
from . import _path_kernels as K
from ..basis.types import BasisStats
from .outcome import LinearCode

__all__ = ["DEFAULT_UPDATE_LIMIT", "PIVOT_CHUNK", "PathEngine", "UPDATE_LIMIT_FLOOR",
           "resolve_update_limit"]

PIVOT_CHUNK = 1000
"""Pivots per compiled call at most: the time limit is checked between calls."""

UPDATE_LIMIT_FLOOR = 50
"""factorization_update_limit is capped at max(n, this) (the bases preallocate the updates)."""

DEFAULT_UPDATE_LIMIT = 50
"""The update limit of the dense engine and the basis managers when
factorization_update_limit is None (automatic): PATH's default."""


def resolve_update_limit(requested, automatic: int, n: int) -> int:
    """The update limit of a basis of order n: ``requested`` (``factorization_update_limit``,
    an integer the user set: a hard limit on every basis) or, when it is None (automatic),
    the basis' own ``automatic`` (:data:`DEFAULT_UPDATE_LIMIT`; the sparse engine's
    ``AUTO_UPDATE_LIMIT`` above its refactorization rule).  Every basis preallocates room
    for its updates, and past max(n, UPDATE_LIMIT_FLOOR) updates applying them costs more
    than a fresh factorization, so a larger limit is capped there.  The one place the
    limit is decided: the routes and the engines built directly call it."""
    limit = automatic if requested is None else int(requested)
    return max(1, min(limit, max(int(n), UPDATE_LIMIT_FLOOR)))

_NAMES = "zwvatS"

_NO_BASIS = np.empty(0, dtype=np.int8)  # start_path's slack basis when there is none
_NO_RECORDS = np.zeros((0, K.REC_COLUMNS), dtype=np.int64)  # a path that logs nothing

_UPDATES = {0: "OK", 3: "REFUSED"}
"""The Python loop's names (UpdateStatus) of the kernels' update outcomes (UPD_OK,
UPD_REFUSED); every other outcome made the path refactorize: REFACTORED."""

_CODES = {K.SOLVED: LinearCode.SOLVED, K.RAY: LinearCode.RAY, K.CYCLE: LinearCode.CYCLE,
          K.MINOR_LIMIT: LinearCode.MINOR_LIMIT, K.SINGULAR: LinearCode.SINGULAR,
          K.TOLERANCE: LinearCode.TOLERANCE, K.ERROR: LinearCode.ERROR}
"""The kernels' path codes as :class:`compass_sparse.path.LinearCode`."""


class PathEngine:
    """What the two engines share.  A subclass sets ``kind`` (K.FAC_DENSE / FAC_SPARSE),
    the tolerances, ``stats`` and ``n``, and provides :meth:`prepare` (the factors and
    the problem bundle of a path, after ``_allocate``) and :meth:`_grow` (more storage
    for the factors: the sparse kind)."""

    runs_paths = True
    kind = K.FAC_DENSE
    chunk = PIVOT_CHUNK

    automatic_update_limit = DEFAULT_UPDATE_LIMIT
    """The engine's update limit when factorization_update_limit is None."""

    def init_common(self, update_limit, options, pivot_tolerance, rank_tolerance,
                    stability_tolerance, growth_limit, fill_factor=2.0):
        """The tolerances and limits of the engine (``update_limit``: the caller's, else
        the options' factorization_update_limit, resolved by :func:`resolve_update_limit`)."""
        if update_limit is None and options is not None:
            update_limit = options.factorization_update_limit
        self.update_limit = resolve_update_limit(update_limit, self.automatic_update_limit,
                                                 self.n)
        self.pivot_tolerance = float(pivot_tolerance)
        self.rank_tolerance = float(rank_tolerance)
        self.stability_tolerance = float(stability_tolerance)
        self.growth_limit = float(growth_limit)
        self.fill_factor = float(fill_factor)
        self.pivot_threshold = 1.0  # the sparse LU's diagonal preference (sparse_engine.py)
        self.stats = BasisStats()
        self._rec = None  # the pivot records of a minor log (see _records)
        self.r = np.zeros(self.n)
        self.work = None

    def _allocate_path(self):
        """The path's work areas, once per engine: a solve whose paths all end by the
        direct step (direct_step.py) never needs them."""
        n = self.n
        # (rows 8, 9: the slots' bounds; row 10: the ratio test's candidates' rooms)
        self.work = np.zeros((11, n))
        self.best_x = np.zeros(n)
        self.enter_count = np.zeros((6, n), dtype=np.int64)
        self.displaced = np.full(n, -1, dtype=np.int64)

    def set_dense_column(self, r):
        self.r = np.ascontiguousarray(r, dtype=float)

    # ------------------------------------------------------------------ the path
    def run_path(self, path, z, w, v, slack_basis):
        """Factor, pivot and check on ``path``'s slot table (set by PivotalPath.run).
        Leaves the path's fields as its own loop would and returns (LinearCode, message)."""
        if self.work is None:
            self._allocate_path()
        lb = np.ascontiguousarray(path.lb, dtype=float)
        ub = np.ascontiguousarray(path.ub, dtype=float)
        path.lb, path.ub = lb, ub
        q = path.q = np.ascontiguousarray(path.q, dtype=float)
        istate = np.empty(K.N_ISTATE, dtype=np.int64)
        fstate = np.empty(K.N_FSTATE)
        st = path.st  # the run's PathState: slot table set by PivotalPath.run
        opt = path.opt
        tol = np.array([opt.pivot_tolerance, opt.ratio_tolerance, self.rank_tolerance,
                        self.pivot_tolerance, self.stability_tolerance, self.growth_limit,
                        float(PK.T_PROGRESS), self.fill_factor, self.pivot_threshold])
        lim = np.array([int(path.minor_limit), int(opt.lemke_cycle_limit), self.chunk,
                        int(bool(st.free_below)), int(PK.BELOW_ZERO_PIVOTS)], dtype=np.int64)
        tab = (st.sk, st.si, st.xb, st.zval, st.art_sign, self.displaced, self.enter_count)
        state = (istate, fstate, self.best_x, self.work)
        use_slack = slack_basis is not None
        log = path.log
        rec, rect = self._records() if log is not None else (_NO_RECORDS, NO_VALUES)
        table0 = tuple(a.copy() for a in tab[:5]) if self.kind == K.FAC_SPARSE else None
        logged = 0  # pivots logged (a path run again after GROW does not log them twice)
        while True:
            prob, D, S = self.prepare(q, lb, ub)
            # the state's reset, the factorization (again on the slack basis when needed),
            # the first chunk of pivots and the solution check in one compiled call
            factored, code, msg = K.start_path(
                self.kind, prob, tab, state, D, S, tol, lim,
                slack_basis if use_slack else _NO_BASIS, use_slack, z, w, v, rec, rect)
            if log is not None and factored:
                logged = _log_pivots(log, rec, rect, int(istate[K.I_PIV]), logged)
            while code == K.RUNNING:
                if path.deadline is not None and time.perf_counter() > path.deadline:
                    code, msg = K.MINOR_LIMIT, -1
                    break
                done = int(istate[K.I_PIV])
                code, msg = K.run_pivots(self.kind, prob, tab, state, D, S, tol, lim, rec,
                                         rect)
                if log is not None:
                    logged = _log_pivots(log, rec, rect, int(istate[K.I_PIV]) - done,
                                         logged)
            if code != K.GROW:
                break
            # the sparse factors did not fit: more storage, and the path again from its
            # start (the same pivots: it is deterministic)
            self._grow()
            for a, a0 in zip(tab[:5], table0):
                a[...] = a0
        if not factored:
            self._account(istate)
            return LinearCode.SINGULAR, self._message(msg, istate, fstate, path)
        self._read_back(path, st, istate, fstate, msg)
        self._account(istate)
        return _CODES[int(code)], self._message(msg, istate, fstate, path)

    def _read_back(self, path, st, istate, fstate, msg):
        """The path's fields from the kernels' state, as the Python loop leaves them."""
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
        if fstate[K.F_BEST_T] > 0.0:
            st.best = (float(fstate[K.F_BEST_T]), self.best_x.copy())

    def _grow(self):  # pragma: no cover - the dense factors never grow
        raise RuntimeError("these factors have a fixed size")

    def _records(self):
        """The per-pivot record buffers of a logged path (made at its first log)."""
        if self._rec is None:
            self._rec = (np.zeros((self.chunk, K.REC_COLUMNS), dtype=np.int64),
                         np.zeros(self.chunk))
        return self._rec

    def _account(self, istate):
        s = self.stats
        s.factorizations += int(istate[K.I_NFAC])
        s.updates += int(istate[K.I_NUPD])
        s.refused_updates += int(istate[K.I_REFUSED])
        s.refactor_by_stability += int(istate[K.I_UNSTABLE] + istate[K.I_GROWTH])
        s.refactor_by_fill += int(istate[K.I_FILL])

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


def _log_pivots(log, rec, rect, count, logged):
    """The minor-log lines of ``count`` pivot records, as the Python loop writes them,
    but those of pivots already logged (numbers up to ``logged``); returns the last
    pivot number logged."""
    for k in range(min(count, rec.shape[0])):
        pivots, kind, ek, ei, lk, li, upd = (int(v) for v in rec[k])
        if pivots <= logged:
            continue
        logged = pivots
        if kind == K.REC_FLIP:
            log(f"minor {pivots:7d} t {rect[k]:.6e} z[{ei}] to its other bound")
        else:
            log(f"minor {pivots:7d} t {rect[k]:.6e} in {_NAMES[ek]}[{ei}] "
                f"out {_NAMES[lk]}[{li}] ({_UPDATES.get(upd, 'REFACTORED')})")
    return logged
