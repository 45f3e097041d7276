"""The pivotal path: solve the linear MCP of one major iteration (thesis §3.2–3.3).

Linear MCP(M, q, [l, u]): find a valid triple (z, w, v) — l <= z <= u, w, v >= 0,
w_i (z_i - l_i) = 0, v_i (u_i - z_i) = 0 — with

    M z + q - w + v = 0.

Start at a point x_k with components z_k = pi(x_k), w_k = (z_k - x_k)+, v_k = (x_k - z_k)+
and residual r = M z_k + q - w_k + v_k (= the normal map of the linearization at x_k).
The path is the set of valid triples and t in [0, 1] with

    M z - w + v + t r = r - q,                                              (*)

starting at t = 0 in (z_k, w_k, v_k) and ending at t = 1 in a solution, the Newton point.
Each index i has one basic variable: z_i when l_i < z_i < u_i, w_i when z_i = l_i, v_i when
z_i = u_i (a free z_i is always basic; a fixed variable's slack w_i - v_i is a free basic
variable).  With t entering first, (*) has n + 1 unknowns on a basis of n columns; each
pivot moves the entering variable until a basic one hits a bound (ratio test), and that
variable leaves.  The complement rule picks the next entering variable:

    w_i leaves -> z_i enters at l_i;   v_i leaves -> z_i enters at u_i;
    z_i leaves at l_i -> w_i enters;   z_i leaves at u_i -> v_i enters;
    an artificial leaves -> the z it displaced enters (direction: increase t);
    t reaches 1 -> solved.

The basis is owned by the basis manager (sparse LU + Forrest–Tomlin updates).  A singular
start basis or a refused update is repaired with artificial columns (thesis §3.3.1): a z
column that cannot stay is moved to the right-hand side at its current value and an
artificial unit column takes its slot at value 0.

The ratio test is a two-pass (Harris) test: pass 1 finds the largest step that keeps every
basic variable within its bound plus a small tolerance; pass 2 picks, among the variables
that block within that step, the one with the largest |pivot|, so near-ties never force a
tiny pivot.  Values that end slightly outside their bounds are projected back (thesis
§4.2.2).  t reaching 1 wins every tie.

t may decrease along the path (thesis §3.3: "the value of t can also decrease during the
procedure").  With s = 1 - t, (*) reads M z - w + v = s r - q: Lemke's system with
covering vector r and covering variable s, whose only bound is s >= 0 (t <= 1); the normal
map of the linearization is s r along the path, so t < 0 is a point where that residual
is larger than at the start, not an end of the path.  PATH's paths do go below t = 0.
Here t's lower bound is 0, with one exception.  On a path from the current point that has
not yet been above t = 0 (above T_PROGRESS = 1e-9: smaller values are rounding of zero
steps), t blocking at 0 lifts the bound instead of ending the path, and from then on the
path may make at most BELOW_ZERO_PIVOTS (8) pivots before t gets above 0; once it has,
0 is t's bound again.  A path that comes back to its bound ends in a ray ("t decreased to
0"), one that uses up the pivots as well ("t not above 0"), and either is retried from the
Lemke start.  This matters at a degenerate start vertex (basic variables at their bounds,
so the first pivots make zero steps): t >= 0 ended such paths where they began although
they go on through t < 0 to t = 1 (PATH's path on thesis family 2, n = 10, seed 1 goes to
t = -0.97).  The bound is lifted only when t blocks, not from the start: a path that walks
through degenerate bases at t = 0 without t blocking (duplicated columns) is as before.
The pivot budget ends the paths that go below 0 and do not come back (without it they
ran on to the cycle limit).
Paths that have been above 0 keep the bound: letting them go below as well solved more
first paths (benchmarks/small.md, "Degenerate ties at the start vertex"), but a path
through t < 0 can end at a distant solution of the linearization and the sector-shutdown
CGE test then failed.  The Lemke ray start keeps t >= 0 throughout: its t = 0 is Lemke's
start at infinity (lambda = inf), and a path that returns there ends in a secondary ray.
A path that never gets above t = 0 returns its start point.

Ray termination (§3.3.2): the entering variable can grow without bound.  The Lemke (ray)
start is the classical Lemke method in this parametrization: with z at bounds and the
covering vector r_i = F_i(z0) -+ delta_i, the slack values are w(t) = t q' + (1 - t) delta,
which is Lemke's w = q' + lambda delta scaled by t (lambda = (1 - t)/t), so the
copositive-plus theory applies: a ray from the Lemke start proves infeasibility.

Cycling (§3.3.3): a variable that enters more than ``lemke_cycle_limit`` times stops the
path; the point with the largest t is returned.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..basis import KIND_DENSE, KIND_M, KIND_UNIT, FactorReuseFailed, UpdateStatus
from ..box import float_vectors, max_abs
from ..exceptions import SingularBasisError
from ..linalg.csc import csc_times
from ..linalg.direct import DirectFactors
from . import _kernels as _PK
from ._kernels import VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z, project_slots, ratio_test
from ._slot_kernels import lemke_start, slot_basis, slot_point, slot_table
from .direct_step import direct_step
from .outcome import DIRECT_STEP_LINE, LinearCode, PathResult, WarmBasis
from .warm import components, default_basis, start_basis_with_guess

_VAR_NAMES = "zwvatS"

PATH_ATTEMPTS = 3
"""Runs of one path when the basis manager reports that a singular basis changed its slot
table (each run starts again from fresh factors); after the last, the path ends SINGULAR."""


@dataclass
class PathState:
    """Everything one run of :meth:`PivotalPath.run` changes, set afresh by every run."""

    art_sign: np.ndarray | None = None  #: sign of the artificial unit column of each row
    sk: np.ndarray | None = None  #: slot table: kind (VAR_*) of each slot's basic variable
    si: np.ndarray | None = None  #: slot table: index of each slot's basic variable
    xb: np.ndarray | None = None  #: values of the basic variables, by slot
    zval: np.ndarray | None = None  #: values of z (basic ones refreshed from xb)
    r: np.ndarray | None = None  #: the covering vector
    displaced: dict = field(default_factory=dict)  #: artificial row -> z index it displaced
    t: float = 0.0  #: the path parameter
    t_lower: float = 0.0  #: t's lower bound now: 0, or -inf once t went below 0 (see above)
    free_below: bool = False  #: t may go below 0 (a path from the current point)
    below_from: int = -1  #: the pivot at which t's lower bound was lifted (-1: not lifted)
    start: tuple | None = None  #: (z, w, v) at t = 0: returned by a path that never reaches t > 0
    t_slot: int = -1  #: the slot holding t (-1: t nonbasic)
    best: tuple = (0.0, None)  #: (largest t, its x), for a path that does not reach t = 1
    pivots: int = 0
    unbounded: bool = False  #: RAY because the entering variable grows without bound
    ray: tuple | None = None  #: (base z, direction dz) of that ray


class PivotalPath:
    """One linear MCP solved by a pivotal path on a basis manager.

    Parameters
    ----------
    M : sparse (n, n)
    q, lb, ub : arrays (n,)
    manager : a :class:`~compass_sparse.basis.protocol.Basis` (the sparse BasisManager or
        the DenseBasis)
    options : compass_sparse.Options
    """

    def __init__(self, M, q, lb, ub, manager, options, *, minor_limit=None, deadline=None,
                 log=None, direct: DirectFactors | None = None):
        # No copy when M is already CSC (every major iteration builds a new path).
        self.M = M if (sp.issparse(M) and M.format == "csc") else sp.csc_matrix(M)
        self.n = self.M.shape[0]
        self.q = np.asarray(q, dtype=float)
        self.lb = lb
        self.ub = ub
        self.bm = manager
        self.opt = options
        self.minor_limit = minor_limit or options.minor_limit(self.n)
        self.deadline = deadline
        self.log = log
        self.direct = direct
        self.direct_lu_nnz = 0  # entries of the direct step's LU (0: not tried)

    # ------------------------------------------------------------------ set-up
    def _times_M(self, z):
        """M z (every path asks one or two)."""
        return csc_times(self.M, z)

    def _columns_for(self, kinds, idx):
        """Basis-manager column specs of slot variables."""
        n = kinds.size
        ck = np.empty(n, dtype=np.int64)
        ci = idx.astype(np.int64).copy()
        cs = np.ones(n, dtype=np.int64)
        isz = kinds == VAR_Z
        ck[isz] = KIND_M
        ck[~isz] = KIND_UNIT
        cs[(kinds == VAR_W) | (kinds == VAR_S)] = -1
        cs[kinds == VAR_A] = self.st.art_sign[idx[kinds == VAR_A]] if (kinds == VAR_A).any() else 1
        ist = kinds == VAR_T
        ck[ist] = KIND_DENSE
        ci[ist] = 0
        return ck, ci, cs

    def _col_of(self, kind, index):
        if kind == VAR_Z:
            return KIND_M, index, 1
        if kind == VAR_T:
            return KIND_DENSE, 0, 1
        if kind in (VAR_W, VAR_S):
            return KIND_UNIT, index, -1
        if kind == VAR_A:
            return KIND_UNIT, index, int(self.st.art_sign[index])
        return KIND_UNIT, index, 1

    def run(self, x_start, *, warm: WarmBasis | None = None, ray_start: bool = False,
            r=None, start=None) -> PathResult:
        """The path from x_start (or from the Lemke start).  ``start``: (z, w, v, basic,
        slack basis or None) of x_start, as this method computes them (the components of
        x_start, the start basis with the inward guess, and the basis before the guess
        when it changed something), when the caller has them already."""
        t0 = time.perf_counter()
        st0 = self._stats0()  # (the counts include a first attempt on reused factors)
        for attempt in range(PATH_ATTEMPTS):
            try:
                return self._run(x_start, warm, ray_start, r, t0, st0, start)
            except FactorReuseFailed:
                # The basis (solved on the factors of an older one, or found inaccurate by
                # a residual check) is singular and its repair changed the manager's slot
                # table: the path starts again on fresh factors, repairing its own basis
                # as usual.
                if attempt == PATH_ATTEMPTS - 1:
                    return self._finish(LinearCode.SINGULAR, 0.0, t0, st0, ray_start,
                                        "the basis kept turning singular in its solves")

    def _run(self, x_start, warm, ray_start, r, t0, st0, start=None) -> PathResult:
        lb, ub = self.lb, self.ub
        slack_basis = None
        if ray_start:
            z, w, v, r, basic = self._lemke_start()
        elif start is not None and r is not None:
            z, w, v, basic, slack_basis = start
        else:
            z, w, v = components(np.asarray(x_start, dtype=float), lb, ub)
            if r is None:
                r = self._times_M(z) + self.q - w + v
            basic, slack_basis = start_basis_with_guess(z, w, v, r, lb, ub, warm)
        if max_abs(r) == 0.0:  # (a NaN in r is not 0: the path meets it)
            # Already a solution of the linear problem: nothing to pivot.
            res = PathResult(LinearCode.SOLVED, z, w, v, 1.0, basis=WarmBasis(basic.copy()),
                             ray_start=ray_start)
            res.time = time.perf_counter() - t0
            return res
        if self.direct is not None and not ray_start:
            # A path without pivots ends where one sparse solve says (path/direct_step.py).
            td = time.perf_counter()
            end, self.direct_lu_nnz = direct_step(self.M, self.q, lb, ub, z, basic,
                                                  self.direct)
            if self.direct_lu_nnz:
                self.bm.stats.record_direct_lu(self.direct_lu_nnz, time.perf_counter() - td,
                                               self.direct.method)
            if end is not None:
                if self.log is not None:
                    self.log(DIRECT_STEP_LINE)
                res = PathResult(LinearCode.SOLVED, *end, 1.0, factorizations=1,
                                 basis=WarmBasis(basic.copy()), ray_start=False,
                                 direct_lu_nnz=self.direct_lu_nnz)
                res.time = time.perf_counter() - t0
                return res
        # The path's state, made afresh by every run (a path may run again), only now: a
        # solved start or a direct step needs none (~5 us of a small major iteration).
        # (_reset_slots sets the slot table, z's values and the artificials' signs)
        self.st = PathState()
        self.st.r = r
        self.st.t_lower, self.st.below_from = 0.0, -1
        self.st.free_below = not ray_start
        self.st.start = (z, w, v)
        self._reset_slots(basic, z, w, v)
        self.bm.set_dense_column(r)
        if getattr(self.bm, "runs_paths", False):
            # The small-problem engine (path/dense_engine.py): factorization, pivots and the
            # solution check in compiled code, on this slot table.
            code, msg = self.bm.run_path(self, z, w, v, slack_basis)
            return self._finish(code, self.st.t, t0, st0, ray_start, msg)
        code, msg = self._factor()
        if slack_basis is not None and (
                code is not None or (self.st.sk == VAR_A).any()):
            self._reset_slots(slack_basis, z, w, v)
            code, msg = self._factor()
        if code is not None:
            return self._finish(code, 0.0, t0, st0, ray_start, msg)
        self.st.t = 0.0
        self.st.t_slot = -1
        self.st.best = (0.0, None)
        code, msg = self._pivot_loop()
        if code is LinearCode.SOLVED:
            code, msg = self._verify_solution()
        return self._finish(code, self.st.t, t0, st0, ray_start, msg)

    def _verify_solution(self):
        """t reached 1: the point solves the linear MCP only if no artificial is left
        nonzero and the equation holds to working accuracy (else never report 'S')."""
        art = self.st.sk == VAR_A
        tol = 1e-9 * (1.0 + float(np.max(np.abs(self.q))) + float(np.max(np.abs(self.st.r))))
        if art.any() and np.max(np.abs(self.st.xb[art])) > tol:
            return LinearCode.SINGULAR, "t reached 1 with nonzero artificial variables"
        for attempt in range(2):
            z, w, v = self.current_point()
            Mz = self._times_M(z)
            res = float(np.max(np.abs(Mz + self.q - w + v)))
            scale = 1.0 + float(np.max(np.abs(Mz))) + float(np.max(np.abs(self.q)))
            if res <= 1e-9 * scale:
                return LinearCode.SOLVED, ""
            if attempt == 0:
                code, msg = self._factor()
                if code is not None:
                    return code, msg
        return LinearCode.TOLERANCE, f"linear residual {res:.2e} after refactorization"

    def _reset_slots(self, basic, z, w, v):
        """Slot table: slot i holds index i's basic variable at its value in (z, w, v)."""
        n = self.n
        if float_vectors(n, z, w, v):
            self.st.sk = np.empty(n, dtype=np.int64)  # slot variable kind (VAR_*)
            self.st.si = np.empty(n, dtype=np.int64)  # slot variable index
            self.st.xb = np.empty(n)
            slot_table(basic, z, w, v, self.st.sk, self.st.si, self.st.xb)
        else:
            self.st.sk = basic.astype(np.int64)
            self.st.si = np.arange(n, dtype=np.int64)
            xb = np.where(basic == VAR_Z, z, np.where(basic == VAR_W, w, v))
            xb = np.where(basic == VAR_S, w - v, xb)
            self.st.xb = xb.astype(float)
        self.st.zval = z.copy()  # values of z (basic or not); basic ones refreshed from xb
        self.st.art_sign = np.ones(n, dtype=np.int64)
        self.st.displaced = {}  # artificial row -> z index it displaced

    def _stats0(self):
        s = self.bm.stats
        return (s.factorizations, s.updates)

    def _lemke_start(self):
        """(z, w, v, r, basic) of the Lemke start: every bounded variable at a bound with
        its slack basic, the covering vector making them feasible at t = 0 (one compiled
        pass for float data; :meth:`_lemke_start_arrays` otherwise, and its reference)."""
        n, M = self.n, self.M
        if M.data.dtype == np.float64 and float_vectors(n, self.q, self.lb, self.ub):
            z, w, v, r = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
            basic = np.empty(n, dtype=np.int8)
            lemke_start(M.indptr, M.indices, M.data, self.q, self.lb, self.ub, z, w, v, r,
                        basic)
            return z, w, v, r, basic
        return self._lemke_start_arrays()

    def _lemke_start_arrays(self):
        n, lb, ub = self.n, self.lb, self.ub
        z = np.where(np.isfinite(lb), lb, np.where(np.isfinite(ub), ub, 0.0))
        f = self._times_M(z) + self.q
        basic = np.full(n, VAR_Z, dtype=np.int8)
        has_l = np.isfinite(lb)
        has_u = np.isfinite(ub) & ~has_l
        basic[has_l] = VAR_W
        basic[has_u] = VAR_V
        basic[lb == ub] = VAR_S
        # Covering vector: slacks start at delta > 0 (all slacks strictly positive at t = 0).
        delta = np.maximum(1.0, np.abs(f))
        r = f.copy()
        r[has_l] = f[has_l] - delta[has_l]
        r[has_u] = f[has_u] + delta[has_u]
        w = np.where(basic == VAR_W, delta, 0.0)
        v = np.where(basic == VAR_V, delta, 0.0)
        # Rows of fixed variables: the free slack absorbs f - r; keep r = f there.
        return z, w, v, r, basic

    # ------------------------------------------------------------------ factorization
    def _factor(self):
        """Factor the current slot table; the basis repairs singularity with artificials
        (one factorization repairs every dependent column)."""
        ck, ci, cs = self._columns_for(self.st.sk, self.st.si)
        try:
            rep = self.bm.factor(ck, ci, cs)
        except SingularBasisError:
            return LinearCode.SINGULAR, "the basis could not be factorized or repaired"
        if not rep.ok:
            return LinearCode.SINGULAR, "the basis could not be factorized"
        code, msg = self._apply_repairs(rep.replaced)
        if code is not None:
            return code, msg
        self._recompute_values()
        return None, ""

    def _apply_repairs(self, replaced):
        """Follow the basis' repair in the slot table: a z column that could not stay is
        moved to the right-hand side at its current value and an artificial takes its
        slot (thesis §3.3.1)."""
        for (slot, _okind, _oidx, _osign, new_row) in replaced:
            vk = self.st.sk[slot]
            if vk == VAR_T:
                return LinearCode.SINGULAR, "the covering vector is dependent on the basis"
            if vk != VAR_Z and vk != VAR_A:
                return LinearCode.SINGULAR, "slack columns are dependent"
            if vk == VAR_Z:
                j = int(self.st.si[slot])
                self.st.zval[j] = self.st.xb[slot]  # stranded on the right-hand side
                self.st.displaced[int(new_row)] = j
            else:
                j = self.st.displaced.pop(int(self.st.si[slot]), None)
                if j is not None:
                    self.st.displaced[int(new_row)] = j
            self.st.sk[slot] = VAR_A
            self.st.si[slot] = new_row
            self.st.art_sign[new_row] = 1
        return None, ""

    def _recompute_values(self):
        """x_B = B^{-1} (r - q - M_N z_N - t r) for the nonbasic values (no drift)."""
        zn = self.st.zval.copy()
        zb = self.st.sk == VAR_Z
        zn[self.st.si[zb]] = 0.0
        t_nb = 0.0 if self.st.t_slot >= 0 else self.st.t
        rhs = self.st.r * (1.0 - t_nb) - self.q - self._times_M(zn)
        xb = self.bm.ftran(rhs)
        # Artificials whose value is ~0 are exactly 0: they were placed there.
        self.st.xb = xb
        ts = np.flatnonzero(self.st.sk == VAR_T)
        if ts.size:
            self.st.t = float(xb[ts[0]])
        self._project()

    # ------------------------------------------------------------------ pivoting
    def _project(self):
        project_slots(self.st.sk, self.st.si, self.st.xb, self.lb, self.ub, self.st.t_lower)

    def _pivot_loop(self):
        opt = self.opt
        entering = (VAR_T, 0, 1.0, 0.0)  # (kind, index, direction, start value)
        enter_count = {}
        pivots = 0
        self.st.pivots = 0
        cycle_limit = opt.lemke_cycle_limit
        while True:
            if pivots >= self.minor_limit:
                return LinearCode.MINOR_LIMIT, f"{pivots} pivots: minor iteration limit"
            if self.deadline is not None and time.perf_counter() > self.deadline:
                return LinearCode.MINOR_LIMIT, "time limit during the path"
            if self.st.below_from >= 0:
                if self.st.best[0] > _PK.T_PROGRESS:
                    self.st.t_lower = 0.0  # above 0 now: 0 is t's bound again
                elif pivots - self.st.below_from >= _PK.BELOW_ZERO_PIVOTS:
                    return LinearCode.RAY, f"t not above 0 after {pivots} pivots"
            ek, ei, es, ev = entering
            key = (ek, ei)
            enter_count[key] = enter_count.get(key, 0) + 1
            if enter_count[key] > cycle_limit:
                return LinearCode.CYCLE, f"{_VAR_NAMES[ek]}[{ei}] entered {cycle_limit} times"
            col = self._col_of(ek, ei)
            d = self.bm.ftran_column(*col)
            # rates at most piv_tol are zero (the ratio test's pivot tolerance)
            piv_tol = self.opt.pivot_tolerance * (max(1.0, float(np.max(np.abs(d))))
                                                  if d.size else 1.0)
            if ek == VAR_Z and es == 0.0:
                # direction free (after an artificial left): increase t; when t does not
                # move with it (a rate within rounding), increase the variable.
                if self.st.t_slot >= 0 and abs(d[self.st.t_slot]) > piv_tol:
                    es = -np.sign(d[self.st.t_slot])
                else:
                    es = 1.0
                entering = (ek, ei, es, ev)
            rate = -es * d  # d xb / d theta
            theta_self = self._entering_room(ek, ei, es, ev)
            leave, theta, leave_up = self._ratio_test(rate, piv_tol)
            if (leave >= 0 and theta < theta_self and self.st.sk[leave] == VAR_T
                    and not leave_up and self.st.free_below and self.st.below_from < 0
                    and self.st.best[0] <= _PK.T_PROGRESS):
                # t blocks at 0 before the path has been above 0: lift its bound.
                self.st.t_lower, self.st.below_from = -np.inf, pivots
                leave, theta, leave_up = self._ratio_test(rate, piv_tol)
            if leave < 0 and not np.isfinite(theta_self):
                return self._ray(ek, ei, es, rate)
            if leave < 0 or theta_self <= theta:
                # The entering variable reaches its own bound first.
                theta = theta_self
                self.st.xb += theta * rate
                self._project()
                if ek == VAR_T:
                    # t reaches 1 with the basis unchanged: no pivot was made.
                    self.st.t = 1.0
                    return LinearCode.SOLVED, ""
                pivots += 1
                self.st.pivots = pivots
                if ek == VAR_Z:
                    entering = self._bound_flip(ei, es, pivots)
                    continue
                return LinearCode.ERROR, "bounded entering slack"  # cannot happen
            # A basic variable blocks: update values and exchange columns.
            self.st.xb += theta * rate
            new_val = ev + es * theta
            lk, li = int(self.st.sk[leave]), int(self.st.si[leave])
            leave_at_upper = bool(leave_up)
            leave_val = self._bound_of(lk, li, leave_at_upper)
            status = self.bm.replace(leave, *col)
            pivots += 1
            self.st.pivots = pivots
            self._set_slot(leave, ek, ei, new_val, lk, li, leave_val)
            if status is UpdateStatus.REFUSED or status is UpdateStatus.REPAIRED:
                # Tiny pivot, or the basis lost its regularity: factorize the path's
                # table afresh, repairing it with artificials.
                code, msg = self._factor()
            elif status is UpdateStatus.REFACTORED:
                self._recompute_values()  # fresh factors: basic values without drift
                code = None
            else:
                code = None
            if code is not None:
                self._log_exchange(pivots, ek, ei, lk, li, status)
                return code, msg
            self._project()
            self._update_t()
            self._log_exchange(pivots, ek, ei, lk, li, status)
            if lk == VAR_T:
                if leave_at_upper:
                    return LinearCode.SOLVED, ""
                return LinearCode.RAY, "t decreased to 0"
            self._record()
            entering, code, msg = self._complement(lk, li, leave_at_upper)
            if code is not None:
                return code, msg

    def _log_exchange(self, pivots, ek, ei, lk, li, status):
        """The minor-log line of pivot ``pivots``: (ek, ei) entered, (lk, li) left."""
        if self.log is not None:
            self.log(f"minor {pivots:7d} t {self.st.t:.6e} in {_VAR_NAMES[ek]}[{ei}] "
                     f"out {_VAR_NAMES[lk]}[{li}] ({status.name})")

    def _complement(self, lk, li, leave_at_upper):
        """The complement rule: (the next entering variable, None, "") after variable
        (lk, li) left the basis (at its upper bound: ``leave_at_upper``), or (None, code,
        message) when there is none."""
        if lk == VAR_W:
            return (VAR_Z, li, 1.0, self.lb[li]), None, ""
        if lk == VAR_V:
            return (VAR_Z, li, -1.0, self.ub[li]), None, ""
        if lk == VAR_Z:
            return ((VAR_V, li, 1.0, 0.0) if leave_at_upper else (VAR_W, li, 1.0, 0.0)), \
                None, ""
        if lk == VAR_A:
            j = self.st.displaced.pop(li, None)
            if j is None:
                return None, LinearCode.ERROR, "artificial without a displaced variable"
            return (VAR_Z, j, 0.0, self.st.zval[j]), None, ""
        return None, LinearCode.ERROR, f"unexpected leaving kind {lk}"

    def _ray(self, ek, ei, es, rate):
        """Ray termination: the entering variable grows without bound; z moves along dz
        (basic z's at their rates, an entering z at its direction)."""
        self.st.unbounded = True
        dz = np.zeros(self.n)
        m = self.st.sk == VAR_Z
        dz[self.st.si[m]] = rate[m]
        if ek == VAR_Z:
            dz[ei] += es
        self.st.ray = (self.current_point()[0], dz)
        return LinearCode.RAY, f"ray: {_VAR_NAMES[ek]}[{ei}] unbounded"

    def _bound_flip(self, ei, es, pivots):
        """z_i moves to its other bound (pivot ``pivots``); returns its other slack, the
        next entering variable."""
        newv = self.ub[ei] if es > 0 else self.lb[ei]
        self.st.zval[ei] = newv
        entering = (VAR_V, ei, 1.0, 0.0) if es > 0 else (VAR_W, ei, 1.0, 0.0)
        self._update_t()
        self._record()
        if self.log is not None:
            self.log(f"minor {pivots:7d} t {self.st.t:.6e} z[{ei}] to its other bound")
        return entering

    def _bound_of(self, kind, index, upper):
        """The bound a leaving basic variable stops at."""
        if kind == VAR_Z:
            return float(self.ub[index] if upper else self.lb[index])
        if kind == VAR_T:
            return 1.0 if upper else 0.0
        return 0.0

    def _set_slot(self, slot, ek, ei, new_val, lk, li, leave_val):
        if lk == VAR_Z:
            self.st.zval[li] = leave_val
        if lk == VAR_T:
            self.st.t = leave_val
            self.st.t_slot = -1
        self.st.sk[slot] = ek
        self.st.si[slot] = ei
        self.st.xb[slot] = new_val
        if ek == VAR_T:
            self.st.t_slot = slot
        if ek == VAR_Z:
            self.st.zval[ei] = new_val

    def _update_t(self):
        if self.st.t_slot >= 0:
            self.st.t = float(self.st.xb[self.st.t_slot])

    def _entering_room(self, ek, ei, es, ev):
        if ek == VAR_T:
            return max(0.0, 1.0 - self.st.t)
        if ek == VAR_Z:
            bound = self.ub[ei] if es > 0 else self.lb[ei]
            return abs(bound - ev) if np.isfinite(bound) else np.inf
        return np.inf

    def _ratio_test(self, rate, piv_tol):
        """Two-pass (Harris) ratio test.  Returns (slot, theta, leaves_at_upper)."""
        return ratio_test(self.st.sk, self.st.si, self.st.xb, rate, self.lb, self.ub,
                          piv_tol, self.opt.ratio_tolerance, self.st.t_lower)

    def _record(self):
        if self.st.t > self.st.best[0] + 1e-15:
            x = self._current_x()
            self.st.best = (self.st.t, x)

    def current_point(self):
        if float_vectors(self.n, self.st.zval, self.st.xb, self.lb, self.ub):
            z, w, v = np.empty(self.n), np.empty(self.n), np.empty(self.n)
            slot_point(self.st.sk, self.st.si, self.st.xb, self.st.zval, self.lb, self.ub,
                       z, w, v)
            return z, w, v
        z = self.st.zval.copy()
        w = np.zeros(self.n)
        v = np.zeros(self.n)
        sk, si, xb = self.st.sk, self.st.si, self.st.xb
        m = sk == VAR_Z
        z[si[m]] = xb[m]
        m = sk == VAR_W
        w[si[m]] = np.maximum(xb[m], 0.0)
        m = sk == VAR_V
        v[si[m]] = np.maximum(xb[m], 0.0)
        m = sk == VAR_S
        s = xb[m]
        w[si[m]] = np.maximum(s, 0.0)
        v[si[m]] = np.maximum(-s, 0.0)
        z = np.minimum(np.maximum(z, self.lb), self.ub)
        return z, w, v

    def _current_x(self):
        z, w, v = self.current_point()
        return z - w + v

    def _finish(self, code, t, t0, st0, ray_start, msg):
        s = self.bm.stats
        if (code is not LinearCode.SOLVED and self.st.best[1] is None
                and self.st.start is not None and not ray_start):
            # The path never got above t = 0 (it may have gone below): its start is its
            # best point (thesis §3.3.2: no point of such a path is a candidate).
            z, w, v = (c.copy() for c in self.st.start)
            t = 0.0
        elif code is LinearCode.SOLVED or self.st.best[1] is None:
            z, w, v = self.current_point() if self.st.xb is not None else (self.st.zval, 0, 0)
        else:
            # Not solved: return the point with the largest t (PATH's return-best-point).
            if self.st.t >= self.st.best[0]:
                z, w, v = self.current_point()
            else:
                x = self.st.best[1]
                z, w, v = components(x, self.lb, self.ub)
                t = self.st.best[0]
        if not isinstance(w, np.ndarray):
            w = np.zeros(self.n)
            v = np.zeros(self.n)
        if self.st.sk is not None and float_vectors(self.n, z, self.lb, self.ub):
            basic = np.empty(self.n, dtype=np.int8)  # (slot_basis sets every entry)
            slot_basis(z, self.lb, self.ub, self.st.sk, self.st.si, basic)
        elif self.st.sk is not None:
            basic = default_basis(z, self.lb, self.ub)
            for kind in (VAR_Z, VAR_W, VAR_V, VAR_S):
                m = self.st.sk == kind
                basic[self.st.si[m]] = kind
        else:
            basic = np.full(self.n, VAR_Z, dtype=np.int8)
        res = PathResult(
            code, z, w, v, float(t if code is not LinearCode.SOLVED else 1.0),
            pivots=self.st.pivots,
            factorizations=s.factorizations - st0[0], updates=s.updates - st0[1],
            artificials=(int(np.count_nonzero(self.st.sk == VAR_A))
                         if self.st.sk is not None else 0),
            basis=WarmBasis(basic), ray_start=ray_start, message=msg,
        )
        res.direct_lu_nnz = self.direct_lu_nnz
        res.unbounded = code is LinearCode.RAY and self.st.unbounded
        if res.unbounded and self.st.ray is not None:
            res.ray_base, res.ray = self.st.ray
        res.time = time.perf_counter() - t0
        return res
