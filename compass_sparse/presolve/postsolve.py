"""The postsolve stack: reversible records of every reduction, replayed in reverse.

Each reduction the preprocessor makes is pushed as a record; every record type has its own
``undo(x, stack)``, which writes the values of the variables the reduction removed into
the full-length vector x.  A record may hold a *batch* of reductions of one kind made by
one pass in one round: the pass only batches reductions that touch disjoint rows and
columns, so they can be undone together with one evaluation of F (that keeps postsolve
cheap at n = 1e5).

Index maps: reduced variable k is original variable ``cols[k]``, reduced row k is original
row ``rows[k]`` (row k of the reduced problem is complementary to its variable k; the
preprocessor may re-pair a free variable with another equation, so ``rows`` need not equal
``cols``).  ``base`` holds, for every removed variable, the value fixed by presolve or a
placeholder (its start value) for variables whose value is computed in postsolve; no
remaining row depends on such a placeholder.

Postsolve: x = base; x[cols] = x_reduced; undo the records from the top of the stack down.
When record R is undone, every record pushed after it has been undone, so every variable
that was still present when R was made has its final value.
"""
from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ._onedim import solve_1d_vector

__all__ = [
    "PostsolveStack",
    "Record",
    "FixVariables",
    "FixByEquation",
    "EmptyColumns",
    "DiagonalColumnSingletons",
    "FreeColumnSingletons",
    "ForcingRows",
]


class Record(abc.ABC):
    """Base class of postsolve records: each reduction type undoes itself."""

    kind = "record"
    pass_name = ""

    @abc.abstractmethod
    def undo(self, x: np.ndarray, stack: "PostsolveStack") -> None:
        """Write the removed variables' values into the full-length x."""

    @property
    def removed_cols(self) -> np.ndarray:
        """Original indices of the variables this record removed (``cols`` by default)."""
        return self.cols


class _AssignValues:
    """Undo for records whose removed variables have values known at presolve time."""

    def undo(self, x, stack):
        x[self.cols] = self.values


@dataclass
class FixVariables(_AssignValues, Record):
    """Variables fixed at values known at presolve time (l = u, bound implied by the sign
    of F, the unique solution of a one-dimensional MCP, ...).  Their rows are removed; the
    F values of those rows are still reported (evaluated at the postsolved point)."""

    cols: np.ndarray
    values: np.ndarray
    reason: str
    pass_name: str = ""
    kind = "fix"


@dataclass
class FixByEquation(_AssignValues, Record):
    """Singleton row i: F_i = a z_j + c = 0 with row i's own variable z_p free, so z_j is
    fixed at -c/a (strictly inside its bounds) and z_p is re-paired with z_j's old row."""

    rows: np.ndarray
    cols: np.ndarray
    values: np.ndarray
    freed: np.ndarray  # the free variables z_p, kept in the problem
    repaired_rows: np.ndarray  # their new rows (the old rows of z_j)
    pass_name: str = ""
    kind = "fix_by_equation"


@dataclass
class EmptyColumns(Record):
    """A boxed variable z_j that no remaining row depends on: its row r is removed, and
    postsolve puts z_j at l_j if F_r > 0, at u_j if F_r < 0, and keeps it where it is
    (clipped into the box) if F_r = 0."""

    cols: np.ndarray
    rows: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    pass_name: str = ""
    kind = "empty_column"

    def undo(self, x, stack):
        f = stack.evaluate(x)[self.rows]
        v = np.clip(x[self.cols], self.lb, self.ub)
        v = np.where(f > 0, self.lb, np.where(f < 0, self.ub, v))
        x[self.cols] = v


@dataclass
class DiagonalColumnSingletons(Record):
    """z_j appears only in its own row i, with constant coefficient b:
    F_i = b z_j + g(other variables).  Postsolve solves the 1-D MCP
    l_j <= z_j <= u_j _|_ b z_j + g (always solvable since b > 0 or the box is bounded)."""

    rows: np.ndarray
    cols: np.ndarray
    coefs: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    pass_name: str = ""
    kind = "diagonal_column_singleton"

    def undo(self, x, stack):
        f = stack.evaluate(x)[self.rows]
        g = f - self.coefs * x[self.cols]
        x[self.cols] = solve_1d_vector(self.coefs, g, self.lb, self.ub, x[self.cols])


@dataclass
class FreeColumnSingletons(Record):
    """A free z_k appears only in row i (constant coefficient b), whose own variable z_p is
    free too: F_i = b z_k + g = 0 gives z_k = -g / b in postsolve; z_p is re-paired with z_k's
    old row (an equation, since z_k was free)."""

    rows: np.ndarray
    cols: np.ndarray
    coefs: np.ndarray
    freed: np.ndarray
    repaired_rows: np.ndarray
    pass_name: str = ""
    kind = "free_column_singleton"

    def undo(self, x, stack):
        f = stack.evaluate(x)[self.rows]
        g = f - self.coefs * x[self.cols]
        x[self.cols] = -g / self.coefs


@dataclass
class ForcingRows(Record):
    """Forcing rows (a batch; reduction k has row ``rows[k]``, dual variable
    ``dual_cols[k]`` and the entries of ``cols``/``dual_rows``/... with ``seg == k``).

    Linear row i's only complementary value is F_i = 0, reachable only with every variable
    of the row at a bound (``cols`` at ``values``).  Row i's own variable z_p has entries only
    in the rows ``dual_rows`` of those variables (constant coefficients ``dual_coefs``);
    postsolve moves z_p from its finite side towards its infinite bound (direction
    ``sigma``) just far enough that each of those rows gets the sign its variable's bound
    requires (``need``: +1 means F >= 0, -1 means F <= 0).  This is Theorem 4 of the thesis
    (§2.4) applied to one row, i.e. the dual postsolve of an LP forcing constraint."""

    rows: np.ndarray
    cols: np.ndarray
    values: np.ndarray
    seg: np.ndarray
    dual_cols: np.ndarray
    dual_rows: np.ndarray
    dual_coefs: np.ndarray
    need: np.ndarray
    sigma: np.ndarray
    dual_lb: np.ndarray
    dual_ub: np.ndarray
    pass_name: str = ""
    kind = "forcing_row"

    def undo(self, x, stack):
        x[self.cols] = self.values
        f = stack.evaluate(x)[self.dual_rows]
        d = self.dual_coefs
        g = f - d * x[self.dual_cols[self.seg]]
        t = -g / d  # need * (g + d z) >= 0 holds for z beyond t in direction sigma
        m = self.rows.size
        hi = np.full(m, -np.inf)
        lo = np.full(m, np.inf)
        np.maximum.at(hi, self.seg, t)
        np.minimum.at(lo, self.seg, t)
        x[self.dual_cols] = np.where(self.sigma > 0, np.maximum(self.dual_lb, hi),
                                     np.minimum(self.dual_ub, lo))

    @property
    def removed_cols(self):
        return np.append(self.cols, self.dual_cols)


@dataclass
class PostsolveStack:
    """Records of one presolve run and the maps from the reduced to the original problem.

    ``postsolve(x_reduced)`` returns the full-length point; ``reduce(x_full)`` restricts a
    full point to the reduced variables (e.g. to warm-start the reduced problem)."""

    n: int
    evaluate_F: Callable[[np.ndarray], np.ndarray]
    base: np.ndarray
    records: list = field(default_factory=list)
    cols: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    f_evals: int = 0

    def push(self, record: Record) -> None:
        self.records.append(record)

    def __len__(self):
        return len(self.records)

    def evaluate(self, x) -> np.ndarray:
        self.f_evals += 1
        return np.asarray(self.evaluate_F(x), dtype=float)

    def fill(self, x_reduced) -> np.ndarray:
        """The full point with removed variables at their presolve values/placeholders."""
        x = self.base.copy()
        x[self.cols] = x_reduced
        return x

    def reduce(self, x_full) -> np.ndarray:
        return np.asarray(x_full, dtype=float)[self.cols]

    def postsolve(self, x_reduced) -> np.ndarray:
        """Undo every reduction, last first; return x on the original variables."""
        x_reduced = np.asarray(x_reduced, dtype=float)
        if x_reduced.shape != (self.cols.size,):
            raise ValueError(
                f"postsolve expects {self.cols.size} reduced values, got shape {x_reduced.shape}")
        x = self.fill(x_reduced)
        for rec in reversed(self.records):
            rec.undo(x, self)
        return x

    def counts_by_kind(self) -> dict:
        out: dict = {}
        for rec in self.records:
            out[rec.kind] = out.get(rec.kind, 0) + int(np.size(rec.removed_cols))
        return out
