"""The preprocessor driver: passes iterated to a fixed point, then the reduced problem.

Round structure (thesis §2.4, Ferris & Munson 2001): phase one -- fixed variables, empty
rows, empty columns, singleton rows, column singletons (incl. doubleton rows with a
column singleton), forcing rows, duplicate rows -- is repeated while it reduces anything;
when a round of phase one finds nothing, phase two (fixing by the range of F) runs, and
if it fixes something phase one starts again.  Every round starts by recomputing the
remaining problem's counts and the constants of its linear rows (one F evaluation).

``presolve`` never changes the user's problem: it returns a reduced MCP that wraps it and
a postsolve stack.  A problem without declared linear entries still gets the passes that
need none (fixed variables; rows and columns without pattern entries).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..box import all_finite
from ..merit import natural_residual
from ..problem.isolated import isolated_pairs as isolated_indices
from ..problem.isolated import solved_exactly
from . import (column_singletons, duplicate_rows, empty_columns, empty_rows, fixed, forcing,
               isolated_pairs, range_fixing, singleton_rows)
from ._kernels import simple_reductions_screen
from ._work import InfeasibilityDiagnostic, PresolveInfeasible, Workspace, pattern_index
from .linear import declared_constant_mask, empty_row_status, sample_evaluations
from .options import PresolveOptions
from .postsolve import PostsolveStack
from .reduced import build_reduced
from .structural import StructuralReport, structural_rank_check

logger = logging.getLogger("compass_sparse.presolve")

__all__ = ["presolve", "PresolveResult", "PresolveStats", "ReductionStats", "solve_with_presolve",
           "PostsolvedSolution"]

PHASE_ONE = (fixed, empty_rows, empty_columns, isolated_pairs, singleton_rows,
             column_singletons, forcing, duplicate_rows)
PHASE_TWO = (range_fixing,)


@dataclass
class ReductionStats:
    """Counters of one reduction of the preprocessor: calls, calls that reduced something,
    what it removed, its time (the solver's passes are :class:`compass_sparse.PassStats`)."""

    name: str
    enabled: bool = True
    calls: int = 0
    applied: int = 0  # calls that removed something
    removed: int = 0  # rows/cols (pairs) removed
    nnz_removed: int = 0
    time: float = 0.0


@dataclass
class PresolveStats:
    n_original: int = 0
    n_reduced: int = 0
    nnz_original: int = 0
    nnz_reduced: int = 0
    rounds: int = 0
    time: float = 0.0
    f_evals: int = 0
    passes: dict = field(default_factory=dict)
    kept_fixed: int = 0  #: l = u variables left in the problem (``leave_simple_to_solver``)
    kept_singletons: int = 0  #: diagonal column singletons left in it (the same)

    @property
    def removed(self) -> int:
        return self.n_original - self.n_reduced

    @property
    def nnz_removed(self) -> int:
        return self.nnz_original - self.nnz_reduced

    def table(self) -> str:
        lines = [f"{'pass':20s} {'on':>3s} {'calls':>6s} {'removed':>8s} {'nnz':>9s} "
                 f"{'time[s]':>8s}"]
        for s in self.passes.values():
            lines.append(f"{s.name:20s} {'yes' if s.enabled else 'no':>3s} {s.calls:6d} "
                         f"{s.removed:8d} {s.nnz_removed:9d} {s.time:8.4f}")
        return "\n".join(lines)


@dataclass
class PresolveResult:
    """What :func:`presolve` returns.

    ``reduced``: the MCP on the remaining variables (None when presolve removed everything,
    the problem itself when it removed nothing).  ``stack``: the postsolve stack.
    ``stats``: per-pass counters.  ``infeasible``: an :class:`InfeasibilityDiagnostic`
    when a reduction proved that the MCP has no solution (the reductions made before it
    are kept).  ``warnings``: messages (unverifiable linear declarations, duplicate
    equations).  ``structural``: the structural-rank report of the reduced problem.
    """

    original: object
    reduced: object
    stack: PostsolveStack
    stats: PresolveStats
    options: PresolveOptions
    infeasible: InfeasibilityDiagnostic | None = None
    warnings: list = field(default_factory=list)
    structural: StructuralReport | None = None

    @property
    def cols(self) -> np.ndarray:
        return self.stack.cols

    @property
    def rows(self) -> np.ndarray:
        return self.stack.rows

    def postsolve(self, x_reduced) -> np.ndarray:
        return self.stack.postsolve(x_reduced)

    def summary_line(self) -> str:
        s = self.stats
        line = (f"Preprocessor removed {s.removed} rows/cols and {s.nnz_removed} non-zeros; "
                f"preprocessed size {s.n_reduced} (nnz {s.nnz_reduced}) from {s.n_original} "
                f"(nnz {s.nnz_original}) in {s.rounds} rounds, {s.time:.3f} s")
        if s.kept_fixed:
            line += f"; {s.kept_fixed} fixed variables (l = u) left to the solver"
        if s.kept_singletons:
            line += (f"; {s.kept_singletons} diagonal column singletons left to the "
                     "solver")
        if self.infeasible is not None:
            line += f"; INFEASIBLE: {self.infeasible.message}"
        return line

    def counters_line(self) -> str:
        """PATH-style per-reduction counters."""
        return "Presolve: " + " ".join(
            f"{name}={ps.removed}" for name, ps in self.stats.passes.items() if ps.removed)


def _has_structure(problem, J0) -> bool:
    if np.any(problem.lb == problem.ub):
        return True
    if problem.constant_mask is not None and problem.constant_mask.any():
        return True
    counts_r = np.bincount(J0.indices, minlength=problem.n)
    if np.any(counts_r == 0) or np.any(np.diff(J0.indptr) == 0):
        return True
    return problem.pattern_declared and bool(
        isolated_indices(J0.indptr, J0.indices, problem.n).size)


def _solved_isolated_pair(problem, J0, removed, base, f) -> bool:
    """Whether the declared pattern, without the ``removed`` indices, has an isolated pair
    that the base point solves exactly (the isolated-pairs pass would fix it)."""
    if not problem.pattern_declared:
        return False
    idx = isolated_indices(J0.indptr, J0.indices, problem.n, removed)
    idx = idx[problem.lb[idx] < problem.ub[idx]]
    return bool(solved_exactly(base[idx], f[idx], problem.lb[idx], problem.ub[idx]).any())


def presolve(problem, options: PresolveOptions | dict | None = None, *, f0=None,
             J0=None, leave_simple_to_solver: bool = False) -> PresolveResult:
    """Reduce ``problem`` (an :class:`~compass_sparse.problem.MCP`); see the module docs.
    ``f0``, ``J0``: F and J at ``problem.x0`` when the caller has them.

    ``leave_simple_to_solver``: when every reduction found is one the solver does as well
    on the whole problem -- fixing l = u variables (it keeps them at their value) and
    diagonal column singletons (a variable that appears in its own row only, linearly:
    one Newton step settles it) -- return the problem itself (an identity stack;
    ``stats.kept_fixed`` and ``stats.kept_singletons`` count them): a reduced problem's
    set-up and restricted evaluations cost a small model more than they save (a static
    CGE model at n = 91 with one of each: 7.9 ms per solve against 3.5 ms without the
    preprocessor, measured).  The declared linearity is then not checked at sample points:
    the check only ever withdraws reductions, and none is made."""
    opts = PresolveOptions.coerce(options)
    t0 = time.perf_counter()
    warnings: list = []
    if J0 is None:
        J0 = problem.J(problem.x0)
    nnz = int(J0.indptr[-1])
    stats = PresolveStats(n_original=problem.n, nnz_original=nnz)
    if not _has_structure(problem, J0):
        _reset_passes(stats, opts)
        stack = _identity_stack(problem)
        stats.n_reduced, stats.nnz_reduced = problem.n, nnz
        structural = _structural_report(problem) if opts.structural_check else None
        if structural is not None and not structural.ok:
            logger.warning("presolve: %s", structural.message)
        stats.time = time.perf_counter() - t0
        return PresolveResult(problem, problem, stack, stats, opts, warnings=warnings,
                              structural=structural)
    if f0 is None:
        f0 = problem.F(problem.x0)
    # The passes first run on the declared linear structure; the check of the declaration
    # at sample points (``verify_linear``, two more F and J evaluations) only matters when
    # a reduction or a verdict rests on it, and then the passes run again when the check
    # withdrew anything.  The result is the same as checking first (the check only ever
    # removes linear information), at no evaluation cost when nothing rests on it.
    declared = problem.constant_mask is not None and problem.constant_mask.any()
    const = declared_constant_mask(problem, J0, f0, opts, warnings, samples=[])
    if leave_simple_to_solver:
        simple = _simple_reductions_only(problem, opts, J0, const)
        if simple is not None:
            # what the passes would end with, without them: the simple reductions left to
            # the solver, the problem itself (see _simple_reductions_only)
            _reset_passes(stats, opts)
            stats.kept_fixed, stats.kept_singletons, stats.rounds = simple
            stats.f_evals = stats.rounds  # the passes' refreshes: one per round
            stats.n_reduced, stats.nnz_reduced = problem.n, nnz
            return _finish_presolve(problem, problem, _identity_stack(problem), stats, opts,
                                    None, warnings, t0)
    ws, infeasible = _reduce(problem, opts, J0, const, warnings, stats)
    kept = _left_to_solver(ws.stack) if leave_simple_to_solver and infeasible is None \
        else None
    if kept is None and declared and opts.verify_linear and \
            _rests_on_linearity(stats, infeasible):
        samples = sample_evaluations(problem, opts)
        J0v = J0
        if J0.nnz != problem.pattern.nnz:  # an undeclared pattern grew at the sample points
            J0v = problem.evaluator.on_pattern(J0)
            stats.nnz_original = nnz = int(J0v.indptr[-1])
        checked = []
        const_v = declared_constant_mask(problem, J0v, f0, opts, checked, samples)
        if J0v is not J0 or not np.array_equal(const_v, const):
            warnings[:] = checked
            stats.rounds = 0
            ws, infeasible = _reduce(problem, opts, J0v, const_v, warnings, stats)
            if leave_simple_to_solver and infeasible is None:
                kept = _left_to_solver(ws.stack)
        else:
            warnings.extend(checked)
    stats.kept_fixed = stats.kept_singletons = 0
    if kept is not None and len(ws.stack):
        stats.kept_fixed, stats.kept_singletons = kept
        _reset_passes(stats, opts)
    if len(ws.stack) == 0 or kept is not None:
        reduced = problem
        ws.stack = _identity_stack(problem)
        stats.n_reduced, stats.nnz_reduced = problem.n, nnz
    else:
        reduced = build_reduced(ws)
        stats.n_reduced = int(ws.stack.cols.size)
        stats.nnz_reduced = ws.live_nnz()
    stats.f_evals = ws.f_evals
    return _finish_presolve(problem, reduced, ws.stack, stats, opts, infeasible, warnings, t0)


def _finish_presolve(problem, reduced, stack, stats, opts, infeasible, warnings, t0):
    warnings[:] = list(dict.fromkeys(warnings))
    structural = None
    if opts.structural_check and reduced is not None:
        structural = _structural_report(reduced)
        if not structural.ok:
            logger.warning("presolve: %s", structural.message)
    stats.time = time.perf_counter() - t0
    res = PresolveResult(problem, reduced, stack, stats, opts, infeasible=infeasible,
                         warnings=warnings, structural=structural)
    if logger.isEnabledFor(logging.INFO):
        logger.info(res.summary_line())
    return res


def _simple_reductions_only(problem, opts, J0, const):
    """(fixed variables, diagonal column singletons, rounds) when these are provably all
    the passes would reduce -- then they are left to the solver and the problem is kept
    (see ``presolve``'s ``leave_simple_to_solver``) -- else None.  One compiled replay of
    the rounds on the workspace's counts (:func:`._kernels.simple_reductions_screen`) in
    place of the workspace and the passes: on small CGE models whose only reductions are
    their fixed numeraire (and a diagonal column singleton) these cost ~0.6-1.2 ms of a
    3-5 ms solve, measured with the solve around them.  None also when the fixed
    variables' pass is switched off or F is not finite at the base point (the passes
    report that)."""
    if not opts.fixed_variables or opts.max_rounds < 1:
        return None
    lb, ub = problem.lb, problem.ub
    fixed = lb == ub
    base = problem.x0.copy()
    base[fixed] = lb[fixed]
    f = np.asarray(problem.F(base), dtype=np.float64)
    if not all_finite(f):
        return None
    if opts.isolated_pairs and _solved_isolated_pair(problem, J0, fixed, base, f):
        return None  # (a reduction the solver does not make: the passes make it)
    ec, er, col_ptr, row_order, row_ptr = pattern_index(problem, J0)
    w1, w2 = duplicate_rows.hash_weights(problem.n)
    code, rounds, singletons = simple_reductions_screen(
        er, ec, J0.data[:er.size].astype(np.float64), const, col_ptr, row_ptr, row_order, lb,
        ub, base, f, float(opts.zero_tolerance), float(opts.feasibility_tolerance),
        bool(problem.pattern_declared), w1, w2, int(opts.max_rounds))
    if code != 0 or (singletons and not opts.column_singletons):
        return None
    return int(np.count_nonzero(fixed)), int(singletons), int(rounds)


_STRUCTURAL_KEPT = 4
"""Structural reports kept per Jacobian pattern (one per set of fixed variables)."""


def _structural_report(problem) -> StructuralReport:
    """:func:`structural_rank_check` of ``problem``, made once per Jacobian pattern and set
    of fixed variables (l = u): the matching reads nothing else, and a loop of solves of
    one model ran it in every solve (0.1-0.2 ms of a 5 ms solve at n = 100-1000,
    measured).  The report is shared between those solves: read only.  It names rows and
    variables: it is reused only by a problem with the same name lists (copies of one
    problem share them; two problems on one evaluator may not)."""
    keep = np.packbits(problem.lb < problem.ub).tobytes()
    store = problem.evaluator.pattern_cache.structural_reports
    hit = store.get(keep)
    if hit is not None and hit[0] is problem.var_names and hit[1] is problem.eqn_names:
        return hit[2]
    rep = structural_rank_check(problem)
    store.pop(keep, None)
    if len(store) >= _STRUCTURAL_KEPT:
        store.pop(next(iter(store)))
    store[keep] = (problem.var_names, problem.eqn_names, rep)
    return rep


def _identity_stack(problem):
    return PostsolveStack(n=problem.n, evaluate_F=problem.F, base=problem.x0.copy(),
                          cols=np.arange(problem.n), rows=np.arange(problem.n))


def _reset_passes(stats, opts):
    for mod in PHASE_ONE + PHASE_TWO:
        stats.passes[mod.NAME] = ReductionStats(mod.NAME, enabled=getattr(opts, mod.NAME))


def _reduce(problem, opts, J0, const, warnings, stats):
    """The rounds of passes on a fresh workspace: (workspace, infeasibility or None)."""
    _reset_passes(stats, opts)
    certain, nonlinear = empty_row_status(problem, J0)
    ws = Workspace(problem, opts, J0, const, warnings, certain_rows=certain,
                   nonlinear_rows=nonlinear, refresh=False)
    infeasible = None
    try:
        # Fixed variables first, on their own: every other pass of the first round would
        # skip the rows and columns they touch (often all of a model's rows through one
        # fixed price) and a second round would be needed only to look at them again.
        # That pass reads no counts or constants: the workspace's first refresh follows it.
        _run_phase(ws, (fixed,), stats, opts)
        ws.refresh()
        for rnd in range(opts.max_rounds):
            if rnd > 0:
                ws.refresh()
            stats.rounds = rnd + 1
            changed = _run_phase(ws, PHASE_ONE, stats, opts)
            if not changed:
                changed = _run_phase(ws, PHASE_TWO, stats, opts)
            if not changed:
                break
    except PresolveInfeasible as exc:
        infeasible = exc.diagnostic
        logger.warning("presolve: %s", infeasible.message)
    return ws, infeasible


def _left_to_solver(stack):
    """(fixed variables, diagonal column singletons) when these are all the records on
    the stack (the reductions the solver does as well itself), else None."""
    counts = [0, 0]
    for rec in stack.records:
        if rec.kind == "fix" and rec.pass_name == fixed.NAME:
            counts[0] += int(np.size(rec.cols))
        elif rec.kind == "diagonal_column_singleton":
            counts[1] += int(np.size(rec.cols))
        else:
            return None
    return tuple(counts)


def _fixed_only(stats) -> bool:
    """Whether fixing l = u variables is all the passes did."""
    return all(ps.removed == 0 for name, ps in stats.passes.items() if name != fixed.NAME)


def _rests_on_linearity(stats, infeasible) -> bool:
    """Whether a reduction or the verdict may rest on declared-constant entries: anything
    but fixing l = u variables (conservative: empty rows and columns are included)."""
    return infeasible is not None or not _fixed_only(stats)


def _run_phase(ws, passes, stats, opts) -> int:
    total = 0
    for mod in passes:
        if not getattr(opts, mod.NAME):
            continue
        ps = stats.passes[mod.NAME]
        ws.current_pass = mod.NAME
        before = ws.changed
        t = time.perf_counter()
        nnz_before = None
        try:
            nnz_before = ws.live_nnz()
            mod.run(ws)
        finally:
            ps.calls += 1
            k = ws.changed - before
            if k:
                ps.applied += 1
                ps.removed += k
                ps.nnz_removed += nnz_before - ws.live_nnz()
            ps.time += time.perf_counter() - t
        total += k
    return total


@dataclass
class PostsolvedSolution:
    """What :func:`solve_with_presolve` returns: the full point ``x``, ``F`` = F(x) on the
    original problem (fixed and removed variables' F values included), its natural
    residual, the presolve result and the inner solver's return value (None when presolve
    removed everything or proved infeasibility)."""

    x: np.ndarray
    F: np.ndarray
    natural_residual: float
    presolve: PresolveResult
    inner: object = None

    @property
    def infeasible(self):
        return self.presolve.infeasible


def solve_with_presolve(problem, solve: Callable, options=None) -> PostsolvedSolution:
    """Presolve, ``solve(reduced_problem)`` (must return an object with ``.x``), postsolve.

    When presolve proves infeasibility the solver is not called and ``x`` is the
    postsolved start point."""
    pre = presolve(problem, options)
    inner = None
    if pre.reduced is None:
        xr = np.zeros(0)
    elif pre.infeasible is not None:
        xr = pre.reduced.x0
    else:
        inner = solve(pre.reduced)
        xr = np.asarray(inner.x, dtype=float)
    x = pre.postsolve(xr)
    f = problem.F(x)
    return PostsolvedSolution(x=x, F=f, natural_residual=natural_residual(x, f, problem.lb,
                                                                          problem.ub),
                              presolve=pre, inner=inner)
