"""The Newton point of each major iteration: J at z_k, the linear MCP M = J + eps I,
q = F - M z_k with covering vector r (:mod:`compass_sparse.path.linearize`), and its
pivotal path warm-started from the last path's basis
(:func:`~compass_sparse.path.solve_linear_mcp`).

:class:`NewtonStep` owns what the paths of a solve share: the linearizer (made once per
Jacobian pattern), the basis of the paths (made on the first linear MCP by the solve's
basis factory: the route's engine or manager; on the route "sparse basis to engine" the
manager until a path hands the paths to the engine), the direct step's factors, the crash's last
factors offered to the first basis, and the warm basis handed from path to path (and to
the Result).
"""
from __future__ import annotations

import time

from ..linalg.direct import DirectFactors
from ..path.direct_step import (DIRECT_MIN_N, REUSE_BEATS_REFACTOR_NNZ, direct_step_applies,
                                direct_step_worth_trying)
from ..path.linear_mcp import dense_newton_result, solve_handing_over
from ..path.linearize import Linearizer, linearizer_for
from ..path.outcome import DIRECT_STEP_LINE, LinearCode, WarmBasis

__all__ = ["NewtonStep"]


class NewtonStep:
    """The Newton points of one solve (see the module docstring).

    ``make_basis(M)``: the basis of the paths (the solve's
    :func:`~compass_sparse.routes.basis_factory`); ``stats``: the path pass's
    :class:`~compass_sparse.status.PassStats`; ``counts``: the solve's
    :class:`~compass_sparse.status.WorkCounts` (its pivots); ``warm``: the first path's
    warm basis (a previous solve's, or None); ``log``: the minor log (verbosity 3)."""

    def __init__(self, evaluator, lb, ub, *, make_basis, stats, counts, deadline=None,
                 log=None, warm: WarmBasis | None = None):
        self.ev = evaluator
        self.lb, self.ub = lb, ub
        self.n = lb.shape[0]
        self.make_basis = make_basis
        self.stats = stats
        self.counts = counts
        self.deadline = deadline
        self.log = log
        self.warm = warm  #: the basis of the last path that moved (the next one's start)
        self.linearizer = None
        self.basis = None  #: the paths' basis (engine or manager), made on the first path
        self.direct = None  #: DirectFactors when Newton paths try the direct step
        self.last_pivots = None  #: the pivots of the last path (None before the first)
        self.crash_factors = None  #: the crash's last LU, offered to the next basis
        self.last_J = None  #: J of the last major iteration (the descent test's)

    def jacobian_at(self, z, f, J=None):
        """J at the current iterate (``J``: the run's start point brings its own), None
        when it cannot be evaluated; the linearizer made for its pattern."""
        J = J if J is not None else self.ev.jac(z, f)
        self.last_J = J
        if J is None:
            return J
        if self.linearizer is None:
            # M = J + eps I has the same pattern in every solve of this problem: its index
            # arrays are made once per Jacobian pattern; made when first needed (a solve
            # that the crash ends never needs them: 6% of a solve of cournot2).
            cache = self.ev.pattern_cache
            if cache.linearizer is None:
                cache.linearizer = linearizer_for(J, cache.pattern)
            self.linearizer = cache.linearizer
        if self.linearizer is None or self.linearizer.nnz_J != J.nnz:
            self.linearizer = Linearizer(J)  # J off the pattern, or an undeclared one grew
        return J

    @staticmethod
    def start_ray(opt, first: bool) -> bool:
        """Whether the path starts from the Lemke ray (``first``: the first major iteration)."""
        return opt.lemke_start == "always" or (opt.lemke_start == "first" and first)

    def dense_lane(self, opt, first: bool) -> bool:
        """Whether a small dense problem's linear MCP and its dense direct step are one
        compiled call (from the second major iteration: the basis and the direct step's
        factors are made on the first; never with ``engine = "reference"``)."""
        return (self.basis is not None and self.direct is not None
                and self.crash_factors is None and not self.start_ray(opt, first)
                and opt.engine == "auto")

    def point(self, cur, x, eps, opt, first: bool):
        """(PathResult or None, J, its code) of the major iteration at ``cur`` (a
        :class:`~compass_sparse.nms.state.Point`) from x with proximal term eps."""
        J = self.jacobian_at(cur.z, cur.f, cur.J)
        if J is None:
            return None, None, LinearCode.ERROR
        t0 = time.perf_counter()
        M = res = start = None
        if self.dense_lane(opt, first):
            # A small dense problem's linear MCP and its dense direct step in one compiled
            # call; when the step ends the path, solve_linear_mcp below is not needed.
            M, q, r, res, start = dense_newton_result(
                self.linearizer, J, eps, cur.z, cur.f, x, self.lb, self.ub, self.basis,
                self.warm, self.direct)
            if res is not None and res.direct_lu_nnz and self.log is not None:
                self.log(DIRECT_STEP_LINE)
        if M is None:
            # M = J + eps I, q = f - M z and r = f + x - z (r: the normal map of the
            # linearization at x)
            M, q, r = self.linearizer.linearize(J, eps, cur.z, cur.f, x)
        if res is not None:
            self.basis.set_matrix(M)
        else:
            res = self.solve_linear(M, q, r, x, self.start_ray(opt, first), opt, start)
        self.path_done(res, t0, opt)
        return res, J, res.code

    def path_done(self, res, t0, opt):
        """The counts of a major iteration's linear solve (started at ``t0``), its basis."""
        if res.direct_lu_nnz >= REUSE_BEATS_REFACTOR_NNZ and opt.factor_reuse and \
                not getattr(self.basis, "runs_paths", False):
            # factors this large are cheaper to reuse (the sparse basis' GMRES) than to
            # compute afresh in every major iteration
            self.direct = None
        st = self.stats
        st.ran = True
        st.time += time.perf_counter() - t0
        st.pivots += res.pivots
        st.factorizations += res.factorizations
        st.iterations += 1
        self.counts.minor_iterations += res.pivots
        self.last_pivots = res.pivots
        if res.code is LinearCode.SOLVED or res.t > 0:
            self.warm = res.basis

    def dense_step_done(self, direct, nf, t0):
        """The counts of a major iteration's linear MCP that a compiled call solved (its
        path's start, or its dense direct step on a block of order ``nf`` when
        ``direct``), as :meth:`path_done` counts the same PathResult."""
        st = self.stats
        st.ran = True
        dt = time.perf_counter() - t0
        st.time += dt
        st.iterations += 1
        if direct:
            if self.log is not None:
                self.log(DIRECT_STEP_LINE)
            st.factorizations += 1
            nnz = self.direct.dense_done(int(nf))
            if nnz:
                self.basis.stats.record_direct_lu(nnz, dt, self.direct.method)

    def solve_linear(self, M, q, r, x, start_ray, opt, dense_start=None):
        """The pivotal path of the major iteration's linear MCP (M, q) from x (the basis
        made on the first one); ``dense_start``: as for solve_linear_mcp."""
        if self.basis is None:
            self.basis = self.make_basis(M)
            if direct_step_applies(M, opt):
                self.direct = DirectFactors()
            elif self.n < DIRECT_MIN_N and getattr(self.basis, "runs_paths", False):
                # small problems on the compiled engine: the direct step's block is
                # solved densely in one compiled call (a path's set-up costs more)
                self.direct = DirectFactors(dense=True,
                                            rank_tolerance=self.basis.rank_tolerance)
            else:
                self.direct = None
        else:
            self.basis.set_matrix(M)
        if self.crash_factors is not None and hasattr(self.basis, "offer_factors"):
            self.basis.offer_factors(*self.crash_factors)
            if self.basis.holds_offer:
                # the basis will solve on the crash's factors, cheaper than the direct
                # step's factorization, and reuse its own factors after that
                self.direct = None
        self.crash_factors = None
        direct = self.direct if direct_step_worth_trying(self.direct, self.basis,
                                                         self.last_pivots) else None
        # A warm path that stalls before half-way is retried from the Lemke start.
        res, self.basis = solve_handing_over(
            self.make_basis.hand_over, M, q, self.lb, self.ub, self.basis,
            opt, x, warm=self.warm, r=r, ray_start=start_ray, retry_below=0.5,
            minor_limit=opt.minor_limit(self.n), deadline=self.deadline, log=self.log,
            direct=direct, dense_start=dense_start)
        return res
