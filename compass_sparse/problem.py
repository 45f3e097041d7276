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

* ``jac=callable``: ``jac(x)`` returns any scipy.sparse matrix (or a dense array, which is
  only sensible for small problems since its pattern is the full matrix);
* ``jac=True``: ``F(x)`` returns the pair ``(f, J)``;
* ``jac=None`` with ``jac_sparsity``: J is approximated by forward differences, perturbing
  groups of structurally orthogonal columns together (greedy column colouring, as in
  Curtis–Powell–Reid), so one Jacobian costs (number of colours) extra F evaluations.

Evaluations go through :class:`MCP` methods, which pass *copies* of x to the user's
callbacks, count evaluations, check shapes and return J in canonical CSC form whose
``indptr``/``indices`` are those of the pattern recorded at the first call.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp

from .exceptions import (
    BoundsError,
    CompassError,
    EvaluationError,
    JacobianPatternError,
    ProblemError,
    ShapeError,
    StartPointError,
)

logger = logging.getLogger("compass_sparse")

INFINITY = 1e20
"""Bounds at or beyond this magnitude are infinite (PATH uses the same value)."""

__all__ = ["MCP", "INFINITY", "EvalCounters", "as_bounds"]


@dataclass
class EvalCounters:
    """Evaluations made through an :class:`MCP` (shared by every pass of one solve)."""

    nfev: int = 0  # F evaluations requested by the solver (finite-difference ones counted too)
    njev: int = 0  # Jacobian evaluations
    nfev_fd: int = 0  # of nfev: extra F calls spent on finite differences
    domain_errors: int = 0  # evaluations that raised or returned NaN/Inf


def as_bounds(lb, ub, n: int, names: Sequence[str] | None = None):
    """Broadcast and validate bounds; map |b| >= INFINITY to +-inf.

    Raises BoundsError naming the first offending variable."""
    lo = _broadcast_bound(lb, n, "lb")
    hi = _broadcast_bound(ub, n, "ub")
    # |b| >= INFINITY is infinite on either side: lb >= 1e20 is lb = +inf (an error below)
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


def _broadcast_bound(b, n, what):
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


def _keys(A: sp.csc_matrix) -> np.ndarray:
    """Sorted keys col * n + row of the stored entries of a canonical CSC matrix."""
    n = A.shape[0]
    return np.repeat(np.arange(A.shape[1], dtype=np.int64), np.diff(A.indptr)) * n + A.indices


def _canonical_csc(J, n: int) -> sp.csc_matrix:
    if sp.issparse(J):
        if J.shape != (n, n):
            raise ShapeError(f"the Jacobian has shape {J.shape}, expected ({n}, {n})")
        if np.iscomplexobj(J.data):
            raise EvaluationError("the Jacobian has complex entries; J must be real")
        C = sp.csc_matrix(J, dtype=float, copy=True)
    else:
        if np.iscomplexobj(J):
            raise EvaluationError("the Jacobian has complex entries; J must be real")
        A = np.asarray(J, dtype=float)
        if A.shape != (n, n):
            raise ShapeError(f"the Jacobian has shape {A.shape}, expected ({n}, {n})")
        # A dense array: its pattern is the full matrix, so zeros stay stored.
        C = sp.csc_matrix(np.ones((n, n)))
        C.data = A.T.ravel().copy()
        return C
    if not C.has_canonical_format:
        C.sum_duplicates()  # sorts indices too
    C.sort_indices()
    return C


class MCP:
    """A mixed complementarity problem  l <= z <= u  _|_  F(z), with a sparse Jacobian.

    Parameters
    ----------
    F : callable ``F(x) -> array (n,)`` (or ``(f, J)`` when ``jac=True``).
    jac : callable, True, or None
        See the module docstring.  None requires ``jac_sparsity``.
    lb, ub : scalar or array (n,)
        Bounds; +-inf (or |b| >= 1e20) for none.  Defaults: NCP bounds [0, inf).
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
        self._F = F
        self._jac = jac
        n = self._infer_n(n, x0, lb, ub, jac_sparsity)
        self.n = n
        self.var_names = self._check_names(var_names, "var_names")
        self.eqn_names = self._check_names(eqn_names, "eqn_names")
        self.lb, self.ub = as_bounds(lb, ub, n, self.var_names)
        if x0 is None:
            x0 = np.zeros(n)
        x0 = as_real(x0, "x0")
        if x0.ndim > 1 and x0.size == n:  # a column (n, 1) is accepted, as for the bounds
            x0 = x0.reshape(n)
        if x0.shape != (n,):
            raise ShapeError(f"x0 has shape {x0.shape}, expected ({n},)")
        bad = np.flatnonzero(~np.isfinite(x0))
        if bad.size:
            raise StartPointError(
                f"x0 is {x0[bad[0]]} for {_var_label(self.var_names, bad[0])}; the start point "
                "must be finite"
            )
        self.x0 = np.clip(x0, self.lb, self.ub)
        self.fd_step = float(fd_step)
        self.counters = EvalCounters()
        self._pattern: sp.csc_matrix | None = None
        self._colors: np.ndarray | None = None
        # A declared pattern is a contract: every J fits inside it (entries it lacks are
        # zeros) and a row without entries is constant.  A pattern recorded from the first
        # J is only an observation (a J built from arrays drops the zeros of that point),
        # so it grows when a later J has more entries.
        self.pattern_declared = jac_sparsity is not None
        self.pattern_growths = 0
        if jac_sparsity is not None:
            if sp.issparse(jac_sparsity):
                S = _canonical_csc(jac_sparsity, n)  # stored entries define the structure
            else:
                S = _canonical_csc(sp.csc_matrix(np.asarray(jac_sparsity) != 0), n)
            S.data[:] = 1.0
            self._pattern = S
        self._constant_spec = constant_jac
        self.constant_mask: np.ndarray | None = None
        if self._pattern is not None:  # declared: the pattern is known now
            self._set_constant_mask()
        if check:
            self.check_start()

    # -- construction helpers -------------------------------------------------------
    def _infer_n(self, n, x0, lb, ub, pattern) -> int:
        cands = []
        if n is not None:
            cands.append(("n", int(n)))
        if x0 is not None:
            cands.append(("x0", int(np.size(x0))))
        for arr, what in ((lb, "lb"), (ub, "ub")):
            if np.ndim(arr) > 0:
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
        return self.var_names[i] if self.var_names is not None else f"x[{i}]"

    def row_label(self, i: int) -> str:
        """Name of row i of F (paired with variable i)."""
        if self.eqn_names is not None:
            return self.eqn_names[i]
        if self.var_names is not None:
            return f"F({self.var_names[i]})"
        return f"F[{i}]"

    # -- evaluation -----------------------------------------------------------------
    def _call_F(self, x):
        out = self._F(np.array(x, dtype=float, copy=True))
        if self._jac is True:
            if not (isinstance(out, tuple) and len(out) == 2):
                raise ShapeError("with jac=True, F(x) must return the pair (f, J)")
            f, J = out
        else:
            f, J = out, None
        if np.iscomplexobj(f):
            raise EvaluationError("F(x) returned complex values; F must be real")
        f = np.asarray(f, dtype=float)
        if f.shape != (self.n,):
            if f.size == self.n:
                f = f.reshape(self.n)
            else:
                raise ShapeError(f"F(x) returned shape {f.shape}, expected ({self.n},)")
        return f, J

    def F_uncounted(self, x) -> np.ndarray:
        """F(x) without touching the counters (for independent residual checks)."""
        return self._call_F(x)[0]

    def J_uncounted(self, x) -> sp.csc_matrix:
        """J(x) without touching the counters (for wrappers that count on their own)."""
        saved = (self.counters.nfev, self.counters.njev, self.counters.nfev_fd)
        try:
            return self.J(x)
        finally:
            self.counters.nfev, self.counters.njev, self.counters.nfev_fd = saved

    def FJ_uncounted(self, x):
        """(F(x), J(x)) without touching the counters."""
        saved = (self.counters.nfev, self.counters.njev, self.counters.nfev_fd)
        try:
            return self.FJ(x)
        finally:
            self.counters.nfev, self.counters.njev, self.counters.nfev_fd = saved

    def F(self, x) -> np.ndarray:
        """F(x) as a float array of shape (n,).  Counts one evaluation."""
        self.counters.nfev += 1
        f, _ = self._call_F(x)
        return f

    def FJ(self, x) -> tuple[np.ndarray, sp.csc_matrix]:
        """F(x) and J(x) together (one F and one J evaluation)."""
        if self._jac is True:
            self.counters.nfev += 1
            self.counters.njev += 1
            f, J = self._call_F(x)
            return f, self._fix_pattern(_canonical_csc(J, self.n))
        f = self.F(x)
        return f, self._jac_given_f(x, f)

    def J(self, x) -> sp.csc_matrix:
        """J(x) in canonical CSC form with the problem's fixed pattern."""
        if self._jac is True:
            return self.FJ(x)[1]
        if self._jac is None:
            return self._jac_given_f(x, self.F(x))
        return self._jac_given_f(x, None)

    def _jac_given_f(self, x, f):
        self.counters.njev += 1
        if self._jac is None:
            return self._fd_jacobian(np.asarray(x, dtype=float), f)
        J = self._jac(np.array(x, dtype=float, copy=True))
        return self._fix_pattern(_canonical_csc(J, self.n))

    @property
    def pattern(self) -> sp.csc_matrix:
        """The structural pattern of J (CSC, data = 1).  Evaluates J at x0 if unknown."""
        if self._pattern is None:
            self.J(self.x0)
        P = self._pattern.copy()
        P.data = np.ones_like(P.data)
        return P

    def _fix_pattern(self, C: sp.csc_matrix) -> sp.csc_matrix:
        """C on the problem's pattern: entries of the pattern that C lacks are zeros; an
        entry outside a declared pattern is an error; an undeclared pattern grows."""
        if self._pattern is None:
            self._pattern = C.copy()
            self._set_constant_mask()
            return C
        P = self._pattern
        if (C.indptr.shape == P.indptr.shape and C.indices.shape == P.indices.shape
                and np.array_equal(C.indptr, P.indptr) and np.array_equal(C.indices, P.indices)):
            return C
        kp, kc = _keys(P), _keys(C)
        pos = np.searchsorted(kp, kc)
        inside = pos < kp.size
        inside[inside] = kp[pos[inside]] == kc[inside]
        if not inside.all():
            if self.pattern_declared:
                raise JacobianPatternError(self._outside_message(kc[~inside]))
            keys = np.union1d(kp, kc)
            rows, cols = keys % self.n, keys // self.n
            U = sp.csc_matrix((np.ones(keys.size), (rows, cols)), shape=P.shape)
            U.sort_indices()
            logger.info("the Jacobian has %d entries outside the pattern seen so far "
                        "(first at row %s, column %s): the pattern grows", int((~inside).sum()),
                        self.row_label(int(kc[~inside][0] % self.n)),
                        self.var_label(int(kc[~inside][0] // self.n)))
            self._pattern = P = U
            self.pattern_growths += 1
            self._set_constant_mask()
            kp = _keys(P)
            pos = np.searchsorted(kp, kc)
        data = np.zeros(P.nnz)
        data[pos] = C.data
        return sp.csc_matrix((data, P.indices.copy(), P.indptr.copy()), shape=P.shape)

    def on_pattern(self, J) -> sp.csc_matrix:
        """A J returned earlier, on the current pattern (which may have grown since)."""
        return self._fix_pattern(_canonical_csc(J, self.n))

    def _outside_message(self, keys) -> str:
        j, i = divmod(int(keys[0]), self.n)
        return (
            f"the Jacobian has an entry at (row {self.row_label(i)}, column "
            f"{self.var_label(j)}) outside the declared pattern jac_sparsity ({keys.size} such "
            "entries): jac_sparsity must contain every entry J can ever hold")

    def _set_constant_mask(self):
        spec = self._constant_spec
        if spec is None or self._pattern is None:
            return
        S = sp.csc_matrix(spec, copy=True)
        if S.shape != (self.n, self.n):
            raise ShapeError(f"constant_jac has shape {S.shape}, expected ({self.n}, {self.n})")
        S.sum_duplicates()  # canonical: column-major keys, sorted and unique
        S.sort_indices()
        P = self._pattern  # canonical CSC, so its keys are sorted and unique too
        n = self.n
        keys_p, keys_s = _keys(P), _keys(S)
        pos = np.searchsorted(keys_p, keys_s)
        inside = pos < keys_p.size
        inside[inside] = keys_p[pos[inside]] == keys_s[inside]
        if not inside.all():
            k = keys_s[~inside][0]
            j, i = divmod(int(k), n)
            raise ProblemError(
                f"constant_jac declares entry (row {self.row_label(i)}, column "
                f"{self.var_label(j)}) that is not in the Jacobian's pattern"
            )
        mask = np.zeros(P.nnz, dtype=bool)
        mask[pos] = True
        self.constant_mask = mask

    # -- finite differences -----------------------------------------------------------
    def _fd_jacobian(self, x, f):
        from ._coloring import color_columns

        P = self._pattern
        if self._colors is None:
            self._colors = color_columns(P.indptr, P.indices, self.n)
        if f is None:
            f = self.F(x)
        colors = self._colors
        ncol = int(colors.max()) + 1 if colors.size else 0
        h = self.fd_step * np.maximum(1.0, np.abs(x))
        # Step inward when an upper bound is near, so F is never evaluated outside the box.
        h = np.where(x + h > self.ub, -h, h)
        h = (x + h) - x  # the step actually taken in floating point
        data = np.empty(P.nnz)
        col_of_entry = np.repeat(np.arange(self.n), np.diff(P.indptr))
        for c in range(ncol):
            cols = colors == c
            xp = x.copy()
            xp[cols] += h[cols]
            self.counters.nfev_fd += 1
            fp = self.F(xp)
            diff = fp - f
            sel = cols[col_of_entry]
            data[sel] = diff[P.indices[sel]] / h[col_of_entry[sel]]
        J = sp.csc_matrix((data, P.indices.copy(), P.indptr.copy()), shape=(self.n, self.n))
        return J

    # -- validation -------------------------------------------------------------------
    def check_start(self):
        """Evaluate F and J at x0 and raise on wrong shapes or non-finite values."""
        x = self.x0
        try:
            f, J = self.FJ(x)
        except CompassError:  # our own diagnostics (shapes, pattern, ...) pass through
            raise
        except Exception as exc:  # the user's code failed at the start point
            hint = ""
            if self._n_source != "n":
                hint = (f" (the dimension n = {self.n} was taken from {self._n_source}; "
                        f"check that x0 and the bounds have one entry per variable)")
            raise EvaluationError(f"F or J raised at the start point: {exc!r}{hint}") from exc
        bad = np.flatnonzero(~np.isfinite(f))
        if bad.size:
            i = bad[0]
            raise EvaluationError(
                f"F is {f[i]} in row {self.row_label(i)} at the start point "
                f"({bad.size} non-finite rows)"
            )
        if not np.all(np.isfinite(J.data)):
            k = int(np.flatnonzero(~np.isfinite(J.data))[0])
            j = int(np.searchsorted(J.indptr, k, side="right") - 1)
            i = int(J.indices[k])
            raise EvaluationError(
                f"J is {J.data[k]} at (row {self.row_label(i)}, column {self.var_label(j)}) at "
                "the start point"
            )
        self._f0, self._J0 = f, J
        return f, J

    def with_start(self, x0) -> "MCP":
        """A shallow copy of this problem with another start point (pattern kept)."""
        import copy

        other = copy.copy(self)
        x0 = as_real(x0, "x0")
        if x0.ndim > 1 and x0.size == self.n:
            x0 = x0.reshape(self.n)
        if x0.shape != (self.n,):
            raise ShapeError(f"x0 has shape {x0.shape}, expected ({self.n},)")
        if not np.all(np.isfinite(x0)):
            raise StartPointError("the start point must be finite")
        other.x0 = np.clip(x0, self.lb, self.ub)
        other.counters = EvalCounters()
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
