"""The mixed complementarity problem and its sparse-Jacobian API.

MCP(F, [l, u]): find z with l <= z <= u such that for every i

    l_i < z_i < u_i  and  F_i(z) = 0,   or
    z_i = l_i        and  F_i(z) >= 0,  or
    z_i = u_i        and  F_i(z) <= 0.

Row i of F is paired with (complementary to) variable z_i, so the system is square.
Bounds may be infinite; an entry with |bound| >= ``INFINITY`` (1e20, PATH's convention) is
treated as infinite.

The Jacobian J(z) = dF/dz is sparse with a *structural pattern*, the set of entries J
can ever hold.  ``jac_sparsity=`` declares it (with any form of ``jac``): every returned J
must fit inside it, entries it lacks are zeros, and a row without entries is constant
(the preprocessor relies on that).  Without a declaration the pattern is the union of the
entries seen so far: a J built from arrays that drop zeros at one point may add entries
later, and the pattern grows (so nothing is concluded from an entry's absence).  Three
ways to give J:

* ``jac=callable``: ``jac(x)`` returns any scipy.sparse matrix or array, in any format
  (csc, csr, coo, dok, lil, bsr, dia: converted to CSC), or a dense array, which is only
  sensible for small problems since its pattern is the full matrix;
* ``jac=True``: ``F(x)`` returns the pair ``(f, J)``;
* ``jac=None`` with ``jac_sparsity``: J is approximated by forward differences, perturbing
  groups of structurally orthogonal columns together (greedy column colouring, as in
  Curtis–Powell–Reid), so one Jacobian costs (number of colours) extra F evaluations.

Evaluations go through the problem's :class:`~compass_sparse.problem.evaluator.Evaluator`
(``MCP.evaluator``), the only code that calls the user's functions: it passes *copies* of
x, counts evaluations, memoizes the last point, checks shapes and returns J in canonical
CSC form on the pattern.
"""
from __future__ import annotations

import copy
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp

from ..box import all_finite, project  # (project: np.clip's values, at 40% of its cost)
from ..exceptions import BoundsError, EvaluationError, ProblemError, ShapeError, StartPointError
from ._kernels import clean_bounds
from .evaluator import Evaluator
from .memo import EvalCounters

_SIZE_WORDS = ("shape", "dimension", "size", "broadcast", "index", "mismatch", "aligned")
"""Words of a user's exception at the start point that suggest a wrong-length x0."""

INFINITY = 1e20
"""Bounds at or beyond this magnitude are infinite (PATH uses the same value)."""

__all__ = ["MCP", "INFINITY", "EvalCounters", "as_bounds"]


def as_bounds(lb, ub, n: int, names: Sequence[str] | None = None):
    """Broadcast and validate bounds; map |b| >= INFINITY to +-inf.

    Raises BoundsError naming the first offending variable."""
    lo = _broadcast_bound(lb, n, "lb")
    hi = _broadcast_bound(ub, n, "ub")
    # |b| >= INFINITY is infinite on either side: lb >= 1e20 is lb = +inf (an error below).
    # Valid bounds (every solve's) are mapped and checked in one compiled pass; the
    # array operations below name the first offending variable otherwise.
    if clean_bounds(lo, hi, INFINITY):
        return lo, hi
    lo[lo <= -INFINITY] = -np.inf
    lo[lo >= INFINITY] = np.inf
    hi[hi >= INFINITY] = np.inf
    hi[hi <= -INFINITY] = -np.inf

    def name(i):
        return _var_label(names, int(i))

    for arr, what in ((lo, "lb"), (hi, "ub")):
        bad = np.flatnonzero(np.isnan(arr))
        if bad.size:
            raise BoundsError(f"{what} is NaN for {name(bad[0])} ({bad.size} NaN entries in {what})")
    bad = np.flatnonzero(lo == np.inf)
    if bad.size:
        raise BoundsError(f"lb = +inf for {name(bad[0])}: a lower bound must be below +inf")
    bad = np.flatnonzero(hi == -np.inf)
    if bad.size:
        raise BoundsError(f"ub = -inf for {name(bad[0])}: an upper bound must be above -inf")
    bad = np.flatnonzero(lo > hi)
    if bad.size:
        i = bad[0]
        raise BoundsError(
            f"lb > ub for {name(i)}: lb = {lo[i]:g}, ub = {hi[i]:g} ({bad.size} such variables)"
        )
    return lo, hi


def as_real(value, what: str) -> np.ndarray:
    """``value`` as a float array; complex input is an error, never truncated silently."""
    arr = np.asarray(value)
    if np.iscomplexobj(arr):
        raise ProblemError(f"{what} is complex; compass_sparse solves real problems "
                           "(pass the real part explicitly if that is what you mean)")
    try:
        return np.asarray(arr, dtype=float)
    except (TypeError, ValueError):
        raise ProblemError(f"{what} must be numeric, got {type(value).__name__}") from None


def _as_start(x0, n) -> np.ndarray:
    """x0 real of shape (n,) (a column (n, 1) is accepted, as for the bounds)."""
    x0 = as_real(x0, "x0")
    if x0.ndim > 1 and x0.size == n:
        x0 = x0.reshape(n)
    if x0.shape != (n,):
        raise ShapeError(f"x0 has shape {x0.shape}, expected ({n},)")
    return x0


def _broadcast_bound(b, n, what):
    if b.__class__ is np.ndarray and b.dtype == np.float64 and b.shape == (n,):
        return b.copy()  # the common cases, without the general route's ~8 us
    if b.__class__ is float or b.__class__ is int:
        return np.full(n, float(b))
    arr = as_real(b, what)
    if arr.ndim > 1 and arr.size == n:
        arr = arr.reshape(n)
    try:
        return np.array(np.broadcast_to(arr, (n,)), dtype=float)
    except ValueError:
        raise ShapeError(f"{what} has shape {arr.shape}, expected ({n},) or a scalar") from None


def _var_label(names, i: int) -> str:
    if names is not None:
        return f"variable {names[i]!r} (index {i})"
    return f"variable {i}"



def var_label(var_names, i: int) -> str:
    """The name of variable i under ``var_names`` (``x[i]`` when there are none)."""
    return var_names[i] if var_names is not None else f"x[{i}]"


def row_label(var_names, eqn_names, i: int) -> str:
    """The name of row i of F: its equation's name, else ``F(<variable i>)``, else
    ``F[i]``."""
    if eqn_names is not None:
        return eqn_names[i]
    if var_names is not None:
        return f"F({var_names[i]})"
    return f"F[{i}]"

class MCP:
    """A mixed complementarity problem  l <= z <= u  _|_  F(z), with a sparse Jacobian.

    Parameters
    ----------
    F : callable ``F(x) -> array (n,)`` (or ``(f, J)`` when ``jac=True``).
    jac : callable, True, or None
        See the module docstring.  None requires ``jac_sparsity``.
    lb, ub : scalar or array (n,)
        Bounds; +-inf (or ``|b| >= 1e20``) for none.  Defaults: NCP bounds [0, inf).
    x0 : array (n,), optional
        Start point; projected onto [lb, ub].  Default: the projection of 0.
    n : int, optional
        Dimension, needed only when neither x0 nor array bounds give it.
    jac_sparsity : sparse matrix or array, optional
        Structural pattern of J (nonzero structure is used, values ignored).
    var_names, eqn_names : sequences of str, optional
        Names used in messages and logs; ``eqn_names[i]`` names row i (paired with
        variable i).  When only var_names is given, rows are named ``F(<var>)``.
    constant_jac : sparse matrix, optional
        Entries of J declared constant (linear); its nonzero *structure* marks them.  The
        preprocessor only acts on declared (or conservatively detected) linear entries.
    fd_step : float
        Relative forward-difference step for ``jac=None`` (default sqrt(machine eps)).
    check : bool
        Evaluate F and J at x0 now and raise on non-finite values or wrong shapes.
    """

    def __init__(
        self,
        F: Callable,
        jac=None,
        lb=0.0,
        ub=np.inf,
        x0=None,
        *,
        n: int | None = None,
        jac_sparsity=None,
        var_names: Sequence[str] | None = None,
        eqn_names: Sequence[str] | None = None,
        constant_jac=None,
        fd_step: float = float(np.sqrt(np.finfo(float).eps)),
        check: bool = True,
    ):
        if not callable(F):
            raise ProblemError("F must be callable: F(x) -> array of shape (n,)")
        if jac is not None and jac is not True and not callable(jac):
            raise ProblemError("jac must be a callable, True (F returns (f, J)), or None")
        if jac is None and jac_sparsity is None:
            raise ProblemError(
                "no Jacobian: give jac=callable, jac=True, or a jac_sparsity pattern for "
                "finite differences"
            )
        n = self._infer_n(n, x0, lb, ub, jac_sparsity)
        self.n = n
        self.var_names = self._check_names(var_names, "var_names")
        self.eqn_names = self._check_names(eqn_names, "eqn_names")
        self.lb, self.ub = as_bounds(lb, ub, n, self.var_names)
        if x0 is None:
            x0 = np.zeros(n)
        x0 = _as_start(x0, n)
        if not all_finite(x0):
            bad = np.flatnonzero(~np.isfinite(x0))
            raise StartPointError(
                f"x0 is {x0[bad[0]]} for {_var_label(self.var_names, bad[0])}; the start point "
                "must be finite"
            )
        self.x0 = project(x0, self.lb, self.ub)
        pattern = None
        if jac_sparsity is not None:
            # The stored entries of jac_sparsity (or the nonzeros of an array) are the
            # declared pattern, known now (with any form of jac).
            pattern = (jac_sparsity if sp.issparse(jac_sparsity)
                       else sp.csc_matrix(np.asarray(jac_sparsity) != 0))
        self.evaluator = Evaluator(F, jac, n, pattern=pattern, constant_jac=constant_jac,
                                   fd_step=fd_step, ub=self.ub, row_label=self.row_label,
                                   var_label=self.var_label)
        if check:
            self.check_start()

    @classmethod
    def from_evaluator(cls, evaluator: Evaluator, lb, ub, x0, *, var_names=None,
                       eqn_names=None, exact_bounds: bool = False) -> "MCP":
        """An MCP whose F and J are those of an existing evaluator (e.g. the restriction
        built by :meth:`Evaluator.restrict` for the preprocessor's reduced problem).

        ``exact_bounds``: lb and ub are float vectors of length n derived exactly from a
        validated problem's bounds (the scaling's l / C, u / C) and are taken as they are:
        no validation, and in particular no reading of |b| >= INFINITY as infinite -- a
        finite user bound of 1e15 divided by a column factor 2^-20 is 1.05e21 there, and
        read as infinite it vanished from the scaled problem (the solve then ran past it)."""
        self = cls.__new__(cls)
        self.n = evaluator.n
        self.var_names = self._check_names(var_names, "var_names")
        self.eqn_names = self._check_names(eqn_names, "eqn_names")
        if exact_bounds:
            self.lb, self.ub = lb, ub
        else:
            self.lb, self.ub = as_bounds(lb, ub, self.n, self.var_names)
        self.x0 = project(np.asarray(x0, dtype=float), self.lb, self.ub)
        self.evaluator = evaluator
        return self

    # -- construction helpers -------------------------------------------------------
    def _infer_n(self, n, x0, lb, ub, pattern) -> int:
        cands = []
        if n is not None:
            cands.append(("n", int(n)))
        if x0 is not None:
            cands.append(("x0", x0.size if x0.__class__ is np.ndarray else int(np.size(x0))))
        for arr, what in ((lb, "lb"), (ub, "ub")):
            # (an array's own attributes: np.ndim and np.size cost ~1 us each)
            if arr.__class__ is np.ndarray:
                if arr.ndim > 0:
                    cands.append((what, arr.size))
            elif np.ndim(arr) > 0:
                cands.append((what, int(np.size(arr))))
        if pattern is not None:
            shp = np.shape(pattern) if not sp.issparse(pattern) else pattern.shape
            if len(shp) != 2 or shp[0] != shp[1]:
                raise ShapeError(
                    f"jac_sparsity has shape {shp}: an MCP is square (row i of F is paired "
                    "with variable i)"
                )
            cands.append(("jac_sparsity", int(shp[0])))
        if not cands:
            raise ShapeError("cannot infer the dimension: give x0, array bounds or n")
        first = cands[0]
        self._n_source = first[0]
        for c in cands[1:]:
            if c[1] != first[1]:
                raise ShapeError(
                    f"inconsistent sizes: {first[0]} has {first[1]} entries but {c[0]} has {c[1]}"
                )
        if first[1] < 1:
            raise ShapeError("the problem has no variables")
        return first[1]

    def _check_names(self, names, what):
        if names is None:
            return None
        names = [str(s) for s in names]
        if len(names) != self.n:
            raise ShapeError(f"{what} has {len(names)} entries, expected {self.n}")
        return names

    # -- names ----------------------------------------------------------------------
    def var_label(self, i: int) -> str:
        """Name of variable i (its index when unnamed)."""
        return var_label(self.var_names, i)

    def row_label(self, i: int) -> str:
        """Name of row i of F (paired with variable i)."""
        return row_label(self.var_names, self.eqn_names, i)

    # -- evaluation (delegated to the evaluation layer) ------------------------------
    @property
    def counters(self) -> EvalCounters:
        """Calls of the user's F and J so far (an
        :class:`~compass_sparse.problem.memo.EvalCounters`)."""
        return self.evaluator.counters

    @property
    def constant_mask(self) -> np.ndarray | None:
        """Mask over the pattern entries (CSC order) declared constant, or None."""
        return self.evaluator.constant_mask

    @property
    def pattern_declared(self) -> bool:
        """True when the pattern was declared (``jac_sparsity``): a row without entries is
        then constant; a pattern only observed in returned Jacobians may still grow."""
        return self.evaluator.pattern_declared

    @property
    def fd_step(self) -> float:
        return self.evaluator.fd_step

    def F(self, x) -> np.ndarray:
        """F(x) as a float array of shape (n,)."""
        return self.evaluator.F(x)

    def J(self, x) -> sp.csc_matrix:
        """J(x) in canonical CSC form with the problem's fixed pattern."""
        return self.evaluator.J(x)

    def FJ(self, x) -> tuple[np.ndarray, sp.csc_matrix]:
        """F(x) and J(x) together."""
        return self.evaluator.FJ(x)

    def F_uncounted(self, x) -> np.ndarray:
        """F(x) outside the counters and the memo (for independent residual checks)."""
        return self.evaluator.F_uncounted(x)

    @property
    def pattern(self) -> sp.csc_matrix:
        """The structural pattern of J (CSC, data = 1).  Evaluates J at x0 if unknown."""
        P = self.evaluator.pattern
        if P is None:
            self.evaluator.J(self.x0)
            P = self.evaluator.pattern
        return P

    # -- validation -------------------------------------------------------------------
    def check_start(self):
        """Evaluate F and J at x0 and raise on wrong shapes or non-finite values.  The
        values stay in the evaluator's memo, so the solve does not ask for them again."""
        try:
            return self.evaluator.check_at(self.x0)
        except EvaluationError as exc:
            source = getattr(self, "_n_source", "n")
            cause = str(exc.__cause__).lower()
            if source == "n" or not any(w in cause for w in _SIZE_WORDS):
                raise
            # a wrong-length x0 with scalar bounds surfaces as the user's own shape error
            raise EvaluationError(
                f"{exc} (the dimension n = {self.n} was taken from {source}; check that x0 "
                "and the bounds have one entry per variable)") from exc.__cause__

    def with_start(self, x0) -> "MCP":
        """A shallow copy of this problem with another start point (pattern kept)."""
        other = copy.copy(self)
        x0 = _as_start(x0, self.n)
        if not np.all(np.isfinite(x0)):
            raise StartPointError("the start point must be finite")
        other.x0 = project(x0, self.lb, self.ub)
        other.evaluator = self.evaluator.fresh()
        return other

    def __repr__(self):
        kinds = bound_kinds(self.lb, self.ub)
        counts = np.bincount(kinds, minlength=4)
        return (
            f"MCP(n={self.n}, free={counts[0]}, lower={counts[1]}, upper={counts[2]}, "
            f"boxed={counts[3]})"
        )


def bound_kinds(lb, ub) -> np.ndarray:
    """0 free, 1 lower bound only, 2 upper bound only, 3 both (boxed or fixed)."""
    return np.isfinite(lb).astype(np.int8) + 2 * np.isfinite(ub).astype(np.int8)
