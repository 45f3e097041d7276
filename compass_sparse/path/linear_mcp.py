"""One linear MCP of a major iteration solved: the pivotal path from the current point,
its Lemke-start retry, and the shortcuts that end a path before it pivots -- a start that
solves the linear problem (r = 0) and the direct Newton step
(:mod:`compass_sparse.path.direct_step`), for a small dense problem computed in one
compiled call with the linearization itself."""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..box import float_vectors
from ..linalg.csc import trusted_csc
from ..linalg.direct import DirectFactors
from .direct_step import (FEASIBILITY_TOLERANCE, RESIDUAL_TOLERANCE, dense_direct_path,
                          dense_newton_direct, failed_direct_start)
from .outcome import DIRECT_STEP_LINE, HAND_OVER_LINE, LinearCode, PathResult, WarmBasis
from .pivotal import PivotalPath

__all__ = ["dense_newton_result", "solve_handing_over", "solve_linear_mcp"]


def solve_linear_mcp(M, q, lb, ub, basis, options, x, *, warm: WarmBasis | None = None,
                     r=None, ray_start: bool = False, retry_below: float = np.inf,
                     keep_ray: bool = False, minor_limit=None, deadline=None,
                     log=None, direct: DirectFactors | None = None,
                     dense_start=None, hand_over: int | None = None) -> PathResult:
    """One linear MCP by the pivotal path from x (warm-started from ``warm``), retried
    from the Lemke ray start when ``options.lemke_start`` is "automatic", the first path
    failed and reached only t < ``retry_below``.  The retry's result is kept when it
    solves, reaches a larger t, or (``keep_ray``) ends in a genuine ray, which is what
    an infeasibility verdict needs; pivots and factorizations of both paths are counted.
    ``direct``: first try the path's end point by one sparse solve with these factors
    (:mod:`compass_sparse.path.direct_step`; the first path only, not the ray-start retry).
    ``dense_start``: what :func:`~compass_sparse.path.direct_step.dense_direct_path` returns
    for these arguments, when the caller has computed it (a failed step is not made
    again).  With ``options.engine = "reference"`` the path makes its start and its
    direct step itself (the reference of the one compiled call: the same bits).
    ``hand_over``: a path that makes this many pivots (below ``minor_limit``) stops there,
    and the result is returned at once with ``handed_over`` set, without the retry (the
    caller solves the linear MCP again on the compiled sparse engine; see
    :data:`compass_sparse.routes.HAND_OVER_MIN_PIVOTS`).
    """
    if hand_over is not None and minor_limit is not None and hand_over >= minor_limit:
        hand_over = None
    kw = dict(minor_limit=minor_limit if hand_over is None else hand_over,
              deadline=deadline, log=log)
    res = None
    if (direct is not None and direct.dense and not ray_start and r is not None
            and options.engine == "auto"):
        # A small problem's start and dense direct step in one compiled call (the
        # Python of a path's set-up cost more than the step); the path runs only when
        # the step fails, then without trying it again.
        res = _dense_direct_result(M, q, lb, ub, basis, options, x, r, warm, direct, kw,
                                   dense_start)
    if res is None:
        res = PivotalPath(M, q, lb, ub, basis, options, direct=direct, **kw).run(
            x, warm=warm, ray_start=ray_start, r=r)
    if _handed_over(res, hand_over):
        return res
    if (res.code is LinearCode.SOLVED or ray_start or options.lemke_start != "automatic"
            or res.t >= retry_below
            or (deadline is not None and time.perf_counter() > deadline)):
        return res  # (no retry after the time limit: its factorization alone may take long)
    res2 = PivotalPath(M, q, lb, ub, basis, options, **kw).run(x, ray_start=True)
    pivots = res.pivots + res2.pivots
    factorizations = res.factorizations + res2.factorizations
    if _handed_over(res2, hand_over):
        res2.pivots, res2.factorizations = pivots, factorizations
        return res2
    if (res2.code is LinearCode.SOLVED or res2.t > res.t
            or (keep_ray and res2.code is LinearCode.RAY and res2.unbounded)):
        res = res2
    res.pivots, res.factorizations = pivots, factorizations
    return res


def solve_handing_over(hand_over, M, q, lb, ub, basis, options, x, **kw):
    """:func:`solve_linear_mcp` on ``basis``; ``hand_over``: None, or (pivots(n),
    make_engine(M)) of :func:`compass_sparse.routes.basis_factory` (the route "sparse basis
    to engine"): a path that makes that many pivots stops, and the linear MCP is solved
    again, from its start, on a new compiled sparse engine, which counts on in the basis'
    stats (the pivots and factorizations of both are counted); a basis that is already an
    engine (``runs_paths``) never hands over.  Returns (the result, the basis that ended
    it: ``basis`` or the engine, the basis of the later paths)."""
    if hand_over is None or getattr(basis, "runs_paths", False):
        return solve_linear_mcp(M, q, lb, ub, basis, options, x, **kw), basis
    pivots_of, make_engine = hand_over
    res = solve_linear_mcp(M, q, lb, ub, basis, options, x,
                           hand_over=pivots_of(M.shape[0]), **kw)
    if not res.handed_over:
        return res, basis
    if kw.get("log") is not None:
        kw["log"](HAND_OVER_LINE)
    engine = make_engine(M)
    engine.stats = basis.stats
    kw.update(direct=None, dense_start=None)  # (tried on the manager, or not applicable)
    res2 = solve_linear_mcp(M, q, lb, ub, engine, options, x, **kw)
    res2.pivots += res.pivots
    res2.factorizations += res.factorizations
    return res2, engine


def _handed_over(res: PathResult, hand_over: int | None) -> bool:
    """Whether ``res`` stopped at the hand-over's pivots (and mark it so)."""
    if (hand_over is not None and res.code is LinearCode.MINOR_LIMIT
            and res.pivots >= hand_over):
        res.handed_over = True
    return res.handed_over


def _dense_direct_result(M, q, lb, ub, manager, options, x, r, warm, direct, kw, out=None):
    """What ``PivotalPath(..., direct=direct).run(x, warm=warm, r=r)`` returns, the same
    values and counts, with its start and direct step computed by
    :func:`~compass_sparse.path.direct_step.dense_direct_path` (``out``: its outcome, when
    the caller has it); None when that call does not apply."""
    t0 = time.perf_counter()
    M = M if (sp.issparse(M) and M.format == "csc") else sp.csc_matrix(M)
    if out is None:
        out = dense_direct_path(M, np.asarray(q, dtype=float), lb, ub, x, r, warm, direct)
    if out is None:
        return None
    kind, end, basic, nnz_lu = out
    if kind != "path":
        if kind == "direct" and kw["log"] is not None:
            kw["log"](DIRECT_STEP_LINE)
        return _decided_result(kind, end, basic, nnz_lu, manager, direct, t0)
    # the step failed: the path runs from the start the call computed
    if nnz_lu:
        manager.stats.record_direct_lu(nnz_lu, time.perf_counter() - t0, direct.method)
    res = PivotalPath(M, q, lb, ub, manager, options, **kw).run(x, warm=warm, r=r, start=end)
    # the failed step's factorization counts in the path's, as inside run()
    res.factorizations += 1 if nnz_lu else 0
    res.direct_lu_nnz = nnz_lu
    res.time = time.perf_counter() - t0
    return res


def _decided_result(kind, end, basic, nnz_lu, manager, direct, t0):
    """The PathResult of a path that its start ends (``kind`` "start": r = 0) or its dense
    direct step ends ("direct": the step's LU, ``nnz_lu`` entries, is counted)."""
    if kind == "start":
        res = PathResult(LinearCode.SOLVED, *end, 1.0, basis=WarmBasis(basic),
                         ray_start=False)
    else:
        if nnz_lu:
            manager.stats.record_direct_lu(nnz_lu, time.perf_counter() - t0, direct.method)
        res = PathResult(LinearCode.SOLVED, *end, 1.0, factorizations=1,
                         basis=WarmBasis(basic), ray_start=False, direct_lu_nnz=nnz_lu)
    res.time = time.perf_counter() - t0
    return res


def dense_newton_result(lin, J, eps, zk, fk, x, lb, ub, manager, warm, direct):
    """(M, q, r, res, start): the linear MCP of a major iteration, ``lin.linearize(J, eps,
    zk, fk, x)``, and what ``solve_linear_mcp(M, q, lb, ub, manager, ..., x, warm=warm,
    r=r, direct=direct)`` returns when the path's start or its dense direct step decides
    it, in one compiled call for a small dense problem
    (:func:`~compass_sparse.path.direct_step.dense_newton_direct`): the same values, counts and
    bits.  When the step fails, res is None and ``start`` is the outcome for that call's
    ``dense_start`` (the path runs from the start computed here).  All None when the
    arguments are not the compiled call's."""
    n = zk.shape[0]
    if not (direct.dense and J.data.dtype == np.float64 and J.data.shape[0] == J.nnz
            and float_vectors(n, zk, fk, x, lb, ub) and n == lin.n
            and (warm is None or warm.basic.shape == (n,))):
        return None, None, None, None, None
    t0 = time.perf_counter()
    P = lin.M
    mdata = np.empty(P.data.shape[0])
    q, r = np.empty((2, n))
    z, w, v, zt, wt, vt = np.empty((6, n))  # (rows of one allocation: C vectors)
    basic, slack = np.empty((2, n), dtype=np.int8)
    scatter = lin.pos_J is not None
    use_previous = warm is not None
    code, nf, accepted, guessed = dense_newton_direct(
        J.data, lin.pos_J if scatter else lin.pos_D, scatter, lin.pos_D, float(eps),
        P.indptr, P.indices, zk, fk, x, lb, ub, warm.basic if use_previous else basic,
        use_previous, mdata, q, r, z, w, v, basic, slack, zt, wt, vt, FEASIBILITY_TOLERANCE,
        direct.rank_tolerance, RESIDUAL_TOLERANCE)
    M = trusted_csc(mdata, P.indices, P.indptr, P.shape)
    if code == 0:
        return M, q, r, _decided_result("start", (z, w, v), basic, 0, manager, direct,
                                        t0), None
    nnz_lu = direct.dense_done(nf)
    if not accepted:
        return M, q, r, None, failed_direct_start(z, w, v, basic, slack, guessed, nnz_lu)
    return M, q, r, _decided_result("direct", (zt, wt, vt), basic, nnz_lu, manager, direct,
                                    t0), None
