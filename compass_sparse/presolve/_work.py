"""The preprocessor's working state: the problem as reduced so far.

Jacobian entries are kept in the CSC order of the problem's pattern (``er``, ``ec``,
``ev``: row, column, value at the start point; ``const``: declared constant).  The
remaining problem is described by masks (``row_active``, ``col_active``) and by the pairing
``partner_var[row]`` / ``partner_row[var]`` (row i is complementary to variable
``partner_var[i]``; the identity until a free variable is re-paired).

Linear information.  Row i is *linear* when every remaining entry of it is declared
constant; then, exactly,

    F_i(z) = c_i + sum_j a_ij z_j     (remaining j),

because a function whose partial derivatives are constant on the box is affine, and
entries outside the pattern are structurally zero.  c_i is obtained from one evaluation
of F at ``base`` (removed variables at their values, remaining ones at the start point):
c_i = F_i(base) - sum_j a_ij base_j.  Constant entries with |a_ij| <= zero_tolerance are
treated as zero (their term is frozen at its base value).

Each round recomputes the counts and constants with vectorized code (O(nnz)) and one F
evaluation.  Inside a round a reduction marks every row and column whose counts or
constant it changes as *touched*; later reductions of the round skip touched rows and
columns, so reductions in one round never depend on each other (this is what lets a
record hold a batch of reductions).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..linalg._csc_kernels import csc_same_pattern
from . import _kernels
from ._kernels import recount as _recount
from .postsolve import FixVariables, PostsolveStack, Record

logger = logging.getLogger("compass_sparse.presolve")


class PresolveInfeasible(Exception):
    """Raised inside a pass when a reduction proves the MCP has no solution."""

    def __init__(self, diagnostic):
        super().__init__(diagnostic.message)
        self.diagnostic = diagnostic


@dataclass
class InfeasibilityDiagnostic:
    """Why presolve proved the MCP has no solution, in the user's names."""

    message: str
    pass_name: str
    rows: list = field(default_factory=list)
    variables: list = field(default_factory=list)

    def __str__(self):
        return self.message


def _index_arrays(J0):
    """(ec, er, col_ptr, row_order, row_ptr): column and row of every entry (CSC
    order), the column pointers, the entries in row-major order and the row pointers."""
    n = J0.shape[0]
    ec = np.repeat(np.arange(n), np.diff(J0.indptr)).astype(np.intp)
    er = J0.indices.astype(np.intp)
    col_ptr = J0.indptr.astype(np.intp)
    row_order = np.argsort(er, kind="stable")
    row_ptr = np.zeros(n + 1, dtype=np.intp)
    np.cumsum(np.bincount(er, minlength=n), out=row_ptr[1:])
    out = (ec, er, col_ptr, row_order, row_ptr)
    for a in out:  # read only: shared by the workspaces of one pattern
        a.flags.writeable = False
    return out


def pattern_index(problem, J0):
    """The index arrays of J0's structure (:func:`_index_arrays`), made once per Jacobian
    pattern when J0 is stored on the problem's pattern (a loop of solves of one model
    made them in every solve: an argsort and five array passes over the entries)."""
    ev = getattr(problem, "evaluator", None)
    P = ev.pattern_ref if ev is not None else None
    if P is None or not csc_same_pattern(J0.indptr, J0.indices, P.indptr, P.indices):
        return _index_arrays(J0)
    cache = ev.pattern_cache
    if cache.presolve_index is None:
        cache.presolve_index = _index_arrays(P)
    return cache.presolve_index


class Workspace:
    def __init__(self, problem, options, J0, const_mask, warnings, certain_rows=None,
                 nonlinear_rows=None, refresh=True):
        """``refresh``: compute the counts and constants now (one F evaluation).  The
        driver passes False: the first pass it runs (fixed variables) reads only the
        bounds and the activity and touched masks, and it refreshes after that pass in
        any case (a refresh here was recomputed, with a second F evaluation, as soon as a
        model had one fixed price)."""
        P = problem
        none = np.zeros(P.n, dtype=bool)
        # rows without entries: constant by declaration (an infeasibility verdict may rest
        # on them) / not known to be constant (never linear); see presolve.linear
        self.certain_rows = none if certain_rows is None else certain_rows
        self.nonlinear_rows = none if nonlinear_rows is None else nonlinear_rows
        n = P.n
        self.problem = P
        self.opts = options
        self.n = n
        self.warnings = warnings
        self.ec, self.er, self.col_ptr, self.row_order, self.row_ptr = pattern_index(P, J0)
        self.ev = J0.data.astype(float).copy()
        self.const = const_mask.copy()
        self.lb = P.lb.copy()
        self.ub = P.ub.copy()
        self.col_active = np.ones(n, dtype=bool)
        self.row_active = np.ones(n, dtype=bool)
        self.partner_var = np.arange(n, dtype=np.intp)
        self.partner_row = np.arange(n, dtype=np.intp)
        self.base = P.x0.copy()
        self.f_evals = 0
        self.stack = PostsolveStack(n=n, evaluate_F=P.F, base=self.base)
        self.nnz_total = self.er.size
        self.current_pass = ""
        self.changed = 0
        self._live = None  # (changed, live mask, its count) -- see live_mask
        self._refreshed = False
        if refresh:
            self.refresh()
        else:
            self.touched_row = np.zeros(n, dtype=bool)
            self.touched_col = np.zeros(n, dtype=bool)

    # -- snapshot ----------------------------------------------------------------------
    def evaluate(self, x):
        self.f_evals += 1
        return self.problem.F(x)

    def live_mask(self):
        """Entries whose row and column remain (read only: shared until the next
        reduction, which is the only thing that changes it and counts in ``changed``)."""
        if self._live is None or self._live[0] != self.changed:
            mask = self.row_active[self.er] & self.col_active[self.ec]
            mask.flags.writeable = False
            self._live = (self.changed, mask, int(np.count_nonzero(mask)))
        return self._live[1]

    def live_nnz(self) -> int:
        self.live_mask()
        return self._live[2]

    def refresh(self):
        """Recompute counts, constants and activity bounds of the remaining problem."""
        n = self.n
        er, ec, ev = self.er, self.ec, self.ev
        nz = np.empty(ev.shape[0], dtype=bool)
        nl = np.empty(ev.shape[0], dtype=bool)
        _kernels.refresh_masks(self.live_mask(), self.const, ev,
                               float(self.opts.zero_tolerance), nz, nl)
        self.nz = nz
        self.nl = nl
        f = self.evaluate(self.base)
        # the first refresh checks every row, as when it ran before any pass (the fixed
        # variables' rows included), the later ones the remaining rows
        checked = self.row_active if self._refreshed else np.ones(n, dtype=bool)
        self._refreshed = True
        if not np.all(np.isfinite(f[checked])):
            bad = np.flatnonzero(~np.isfinite(f) & checked)
            raise FloatingPointError(
                f"F is not finite in row {self.problem.row_label(int(bad[0]))} at the "
                "presolve base point")
        self.f_base = f
        # counts, constants c = F(base) - A base and the activity bounds of the linear
        # rows over the remaining box, in one compiled pass (see _recount)
        counts = np.zeros((4, n), dtype=np.intp)
        vals = np.empty((4, n))
        _recount(er, ec, ev, nz, nl, self.base, self.lb, self.ub,
                 np.asarray(f, dtype=np.float64), counts, vals)
        self.row_nnz, self.row_nl, self.col_nnz, self.col_nl = counts
        self.c, self.fmin, self.fmax, self.scale = vals
        self.linear = self.row_active & (self.row_nl == 0) & ~self.nonlinear_rows
        self.touched_row = np.zeros(n, dtype=bool)
        self.touched_col = np.zeros(n, dtype=bool)

    # -- access ------------------------------------------------------------------------
    def row_entries(self, i: int):
        """(columns, values) of the remaining nonzero constant entries of row i."""
        pos = self.row_order[self.row_ptr[i]:self.row_ptr[i + 1]]
        pos = pos[self.nz[pos]]
        return self.ec[pos], self.ev[pos]

    def col_entries(self, j: int):
        """(rows, values) of the remaining nonzero constant entries of column j."""
        pos = np.arange(self.col_ptr[j], self.col_ptr[j + 1])
        pos = pos[self.nz[pos]]
        return self.er[pos], self.ev[pos]

    def free(self, j) -> bool:
        # (comparisons with inf: np.isneginf / np.isposinf on a scalar cost ~5 us each)
        return bool(self.lb[j] == -np.inf and self.ub[j] == np.inf)

    def tol(self, i) -> float:
        return self.opts.feasibility_tolerance * self.scale[i]

    def untouched_rows(self, rows) -> bool:
        return not self.touched_row[rows].any()

    def untouched_cols(self, cols) -> bool:
        return not self.touched_col[cols].any()

    # -- mutation ------------------------------------------------------------------------
    def _touch(self, cols, rows):
        _kernels.touch(np.asarray(cols, dtype=np.intp), np.asarray(rows, dtype=np.intp),
                       self.col_ptr, self.er, self.row_ptr, self.row_order, self.ec,
                       self.touched_col, self.touched_row)

    def touch(self, cols=(), rows=()):
        """Mark rows/columns as used by a reduction of this round (no removal)."""
        self._touch(np.asarray(cols, dtype=np.intp), np.asarray(rows, dtype=np.intp))

    def remove(self, cols, rows):
        """Remove variables ``cols`` and rows ``rows`` (same count; pairing handled by
        the caller) and mark everything they touch."""
        cols = np.asarray(cols, dtype=np.intp)
        rows = np.asarray(rows, dtype=np.intp)
        assert cols.size == rows.size
        assert self.col_active[cols].all() and self.row_active[rows].all()
        self._touch(cols, rows)
        self.col_active[cols] = False
        self.row_active[rows] = False
        self.changed += cols.size

    def fix(self, cols, values, reason: str):
        """Fix variables at presolve-time values; remove them and their rows."""
        cols = np.asarray(cols, dtype=np.intp)
        if cols.size == 0:
            return
        values = np.asarray(values, dtype=float)
        assert cols.size < 2 or np.unique(cols).size == cols.size
        rows = self.partner_row[cols]
        self.remove(cols, rows)
        self.base[cols] = values
        self.push(FixVariables(cols=cols.copy(), values=values.copy(), reason=reason))

    def repair(self, free_var, new_row):
        """Pair the (free) variable ``free_var`` with row ``new_row``."""
        self.partner_var[new_row] = free_var
        self.partner_row[free_var] = new_row

    def remove_and_re_pair(self, j, i, p):
        """Remove z_j with row i, whose own variable z_p is free, and pair z_p with row r,
        z_j's old row (which must be an equation: z_j was free or interior).  A free
        variable with an equation is a valid MCP pair.  Returns r, or None (nothing done)
        when row r was already used by a reduction of this round."""
        r = int(self.partner_row[j])
        if self.touched_row[r]:
            return None
        self.remove([j], [i])
        self.repair(p, r)
        self.touch(cols=[p], rows=[r])
        return r

    def push(self, record: Record):
        record.pass_name = self.current_pass
        self.stack.push(record)

    def infeasible(self, message, rows=(), variables=()):
        """Raise the verdict, saying what it rests on: the rows' entries declared constant
        (``constant_jac``, checked at more points when ``verify_linear``) and, for entries
        absent from the pattern, the declared pattern (``jac_sparsity``)."""
        P = self.problem
        if "because" not in message:
            basis = ["Jacobian entries declared constant (constant_jac)"]
            basis.append("the declared pattern (jac_sparsity)" if P.pattern_declared else
                         "the entries J returned at the start point")
            message += f" [this rests on {' and '.join(basis)}]"
        diag = InfeasibilityDiagnostic(
            message=message,
            pass_name=self.current_pass,
            rows=[P.row_label(int(i)) for i in rows],
            variables=[P.var_label(int(j)) for j in variables],
        )
        raise PresolveInfeasible(diag)

    # -- labels ------------------------------------------------------------------------
    def rl(self, i) -> str:
        return self.problem.row_label(int(i))

    def vl(self, j) -> str:
        return self.problem.var_label(int(j))
