"""The evaluation layer: the one owner of the user's F and J.

Every value of F(x) and J(x) the solver uses comes from an :class:`Evaluator`.  It

* passes a *copy* of x to the user's callbacks (they may keep or change their argument);
* checks shapes and puts J on its structural pattern, returned in canonical CSC form.  A
  declared pattern (``jac_sparsity``) is a contract: entries a returned J lacks are zeros,
  an entry outside it is the error.  An undeclared pattern is the union of the entries
  seen so far and grows when a later J has more (a J assembled from arrays drops the zeros
  of the point where it was built);
* counts the user's calls in one :class:`EvalCounters` (F, J, the F calls spent on
  finite differences, and the rejected evaluations);
* memoizes the last point of F and of J separately, so a value already computed at x
  (the start point checked when the problem was built, a trial point whose Jacobian the
  next major iteration needs) is never asked of the user again;
* offers two flavours of every evaluation: ``F``/``J``/``FJ`` raise (bad input is the
  caller's error: the start point check, the preprocessor), while the guarded ``f``/
  ``jac``/``fj`` turn an exception or a NaN/Inf into ``None`` -- a rejected trial point
  that the caller answers by a shorter step, as PATH does with evaluation errors -- and
  count it in ``counters.domain_errors``.  Our own diagnostics (a wrong shape, a changed
  pattern) and KeyboardInterrupt always propagate.

Jacobians come in three ways (see :mod:`compass_sparse.problem`): a callable ``jac(x)``;
``jac=True``, where ``F(x)`` returns ``(f, J)`` (the J of an F call is kept in the memo and
counted as a Jacobian evaluation only when it is used); or forward differences on the
pattern, perturbing groups of structurally orthogonal columns together (Curtis-Powell-Reid
colouring), with relative step ``fd_step * max(1, |x_j|)`` taken inwards near an upper bound
so F is never evaluated outside the box.

:meth:`Evaluator.restrict` gives the evaluator of a restriction of the problem,
``F_R(y) = F(fill(y))[rows]``, ``J_R(y) = J(fill(y))[rows, cols]`` (the reduced problem of
the preprocessor): F and a given J are taken from the parent (through its memo, so the
start point evaluated once serves both problems) and the counters are shared, so every
user call is counted exactly once, whichever problem asked for it.
:class:`ScaledEvaluator` is the evaluator of the scaling pass's problem G(y) = R F(C y)
(:mod:`compass_sparse.scaling`), built on the user's evaluator the same way.
"""
from __future__ import annotations

import copy
import logging
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..box import F64, all_finite, float_vector
from ..exceptions import (CompassError, EvaluationError, JacobianPatternError, ProblemError,
                          ShapeError)
from ..linalg._csc_kernels import csc_copy_on_pattern, csc_same_pattern
from ..linalg.coloring import color_columns
from ..linalg.csc import I32, canonical_csc, dense_csc, is_csc, pattern_keys, trusted_csc
from .memo import EvalCounters, Memo
from .pattern_cache import PatternCache

__all__ = ["Evaluator", "ScaledEvaluator"]

logger = logging.getLogger("compass_sparse")


def _default_row_label(i):
    return f"F[{i}]"


def _default_var_label(j):
    return f"x[{j}]"


class Evaluator:
    """The user's F and J behind copies, checks, counters and a one-point memo.

    Parameters
    ----------
    F : callable ``F(x) -> (n,)`` (``(f, J)`` when ``jac is True``).
    jac : callable, True or None (finite differences on ``pattern``).
    n : int
    pattern : CSC pattern of J when known in advance (required for ``jac=None``).
    constant_jac : matrix whose structure marks entries of J declared constant.
    fd_step : relative forward-difference step.
    ub : upper bounds (finite differences step inwards near them).
    row_label, var_label : callables naming rows and variables in messages.
    """

    def __init__(self, F: Callable, jac, n: int, *, pattern=None, constant_jac=None,
                 fd_step: float = float(np.sqrt(np.finfo(float).eps)), ub=None,
                 row_label=_default_row_label, var_label=_default_var_label,
                 counters: EvalCounters | None = None):
        self._user_F = F
        self._user_jac = jac
        self.n = int(n)
        self.fd_step = float(fd_step)
        self.ub = np.full(self.n, np.inf) if ub is None else ub
        self.row_label = row_label
        self.var_label = var_label
        self.counters = counters if counters is not None else EvalCounters()
        self.last_error = ""
        self._pattern: sp.csc_matrix | None = None
        self._colors: np.ndarray | None = None
        self._constant_spec = constant_jac
        self.constant_mask: np.ndarray | None = None
        self._mf = Memo()  # F: value f
        self._mj = Memo()  # J: value (J, counted?)
        self.pattern_declared = pattern is not None
        self.pattern_growths = 0
        # [the PatternCache of the last pattern asked], shared with the fresh() copies
        # and the scaled problem's evaluator, which keep the pattern (pattern_cache)
        self._cache = [None]
        if pattern is not None:
            P = canonical_csc(pattern, self.n)
            P.data[:] = 1.0
            self._set_pattern(P)

    # ------------------------------------------------------------------ structure
    @property
    def jac_mode(self):
        """The user's ``jac`` argument kind: a callable, True, or None (differences)."""
        return self._user_jac

    @property
    def pattern(self) -> sp.csc_matrix | None:
        """The structural pattern (CSC, data = 1), None until the first Jacobian."""
        if self._pattern is None:
            return None
        P = self._pattern
        return trusted_csc(np.ones(P.nnz), P.indices.copy(), P.indptr.copy(), P.shape)

    @property
    def pattern_cache(self) -> PatternCache:
        """The :class:`~compass_sparse.problem.pattern_cache.PatternCache` of the current
        pattern: a loop of solves of one problem (:meth:`fresh` copies share it) fills it
        once.  A pattern that grows (a new object) gets a new one; without a pattern yet,
        a new cache that is not kept."""
        P = self._pattern
        cache = self._cache[0]
        if P is None:
            return PatternCache(None)
        if cache is None or cache.pattern is not P:
            cache = self._cache[0] = PatternCache(P)
        return cache

    @property
    def pattern_ref(self) -> sp.csc_matrix | None:
        """The stored pattern itself (not a copy: read only)."""
        return self._pattern

    def _set_pattern(self, C):
        # C is canonical (every caller passes canonical_csc's or the union's matrix): its
        # arrays copied into a trusted matrix (scipy's copy re-checks them, ~35 us)
        self._pattern = trusted_csc(C.data.copy(), C.indices.copy(), C.indptr.copy(),
                                    C.shape)
        self._set_constant_mask()

    def _fix_pattern(self, C: sp.csc_matrix) -> sp.csc_matrix:
        """C on the pattern: entries of the pattern that C lacks are zeros; an entry outside
        a declared pattern is an error; an undeclared pattern grows to hold it."""
        if self._pattern is None:
            self._set_pattern(C)
            return C
        P = self._pattern
        if C.nnz == P.nnz == self.n * self.n:
            return C  # two canonical full patterns are the same pattern
        if C.indices.shape == P.indices.shape and csc_same_pattern(C.indptr, C.indices,
                                                                    P.indptr, P.indices):
            return C
        kp, kc = pattern_keys(P), pattern_keys(C)
        pos = np.searchsorted(kp, kc)
        inside = pos < kp.size
        inside[inside] = kp[pos[inside]] == kc[inside]
        if not inside.all():
            out = kc[~inside]
            j, i = divmod(int(out[0]), self.n)
            if self.pattern_declared:
                raise JacobianPatternError(
                    f"the Jacobian has an entry at (row {self.row_label(i)}, column "
                    f"{self.var_label(j)}) outside the declared pattern jac_sparsity "
                    f"({out.size} such entries): jac_sparsity must contain every entry J can "
                    "ever hold")
            keys = np.union1d(kp, kc)
            U = sp.csc_matrix((np.ones(keys.size), (keys % self.n, keys // self.n)),
                              shape=P.shape)
            U.sort_indices()
            logger.info("the Jacobian has %d entries outside the pattern seen so far (first "
                        "at row %s, column %s): the pattern grows", out.size,
                        self.row_label(i), self.var_label(j))
            self._set_pattern(U)
            self.pattern_growths += 1
            P = self._pattern
            pos = np.searchsorted(pattern_keys(P), kc)
        data = np.zeros(P.nnz)
        data[pos] = C.data
        return sp.csc_matrix((data, P.indices.copy(), P.indptr.copy()), shape=P.shape)

    def on_pattern(self, J) -> sp.csc_matrix:
        """A Jacobian returned earlier, on the current pattern (which may have grown)."""
        return self._fix_pattern(canonical_csc(J, self.n))

    def _user_J_on_pattern(self, J) -> sp.csc_matrix:
        """A J the user returned, checked, copied and on the pattern:
        ``_fix_pattern(canonical_csc(J, n))``.  The common case -- a float64 CSC with int32
        index arrays holding exactly the stored pattern (canonical: so is J then) -- is
        recognised and copied in one compiled pass, where the general route (canonical
        test, three copies, two array comparisons) costs ~20 us per evaluation of a small
        model; it gives that route's matrix: J's values on the pattern's index arrays,
        which are J's own."""
        P = self._pattern
        n = self.n
        if J.__class__ is np.ndarray and J.dtype == np.float64:
            # a dense float array (small problems): no sparse tests, no complex check
            C = dense_csc(J, n)
            if P is not None and P.indices.shape[0] == n * n:
                return C  # on the full pattern stored already: nothing to check
            return self._fix_pattern(C)
        # (the dtypes by identity: a tenth of ``==``'s cost; a non-native byte order
        # takes the general route)
        if (P is not None and is_csc(J) and J.shape == (n, n) and J.data.dtype is F64
                and J.indices.dtype is I32 and J.indptr.dtype is I32
                and P.indices.dtype is I32 and P.indptr.dtype is I32):
            data = np.empty(P.indices.shape[0])
            if csc_copy_on_pattern(J.indptr, J.indices, J.data, P.indptr, P.indices, data):
                return trusted_csc(data, P.indices.copy(), P.indptr.copy(), (n, n),
                                   canonical=True)  # (P is canonical)
        return self._fix_pattern(canonical_csc(J, n))

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
        keys_p, keys_s = pattern_keys(P), pattern_keys(S)
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

    # ------------------------------------------------------------------ primitives
    # The only places where the user's functions are called; each call is counted here.
    def _call_F(self, x):
        """(f, J or None) from one call of the user's F (J when ``jac is True``)."""
        self.counters.nfev += 1
        out = self._user_F(np.array(x, dtype=float, copy=True))
        if self._user_jac is True:
            if not (isinstance(out, tuple) and len(out) == 2):
                raise ShapeError("with jac=True, F(x) must return the pair (f, J)")
            f, J = out
        else:
            f, J = out, None
        if not (float_vector(f) and f.shape[0] == self.n):
            f = self._as_values(f)
        if J is not None:
            J = self._user_J_on_pattern(J)
        return f, J

    def _as_values(self, f):
        """F's returned value as a float vector of length n (the common case, already
        one, is tested by the caller in a tenth of a microsecond)."""
        f = np.asarray(f)
        if f.dtype.kind == "c":
            raise EvaluationError("F(x) returned complex values; F must be real")
        f = f.astype(float, copy=False)
        if f.shape != (self.n,):
            if f.size == self.n:
                f = f.reshape(self.n)
            else:
                raise ShapeError(f"F(x) returned shape {f.shape}, expected ({self.n},)")
        return f

    def _call_J(self, x):
        """J from one call of the user's jac callable."""
        self.counters.njev += 1
        J = self._user_jac(np.array(x, dtype=float, copy=True))
        return self._user_J_on_pattern(J)

    def _fd_jacobian(self, x, f):
        """Forward differences on the pattern, one F call per colour of columns."""
        self.counters.njev += 1
        P = self._pattern
        if self._colors is None:
            self._colors = color_columns(P.indptr, P.indices, self.n)
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
            fp = self._call_F(xp)[0]
            sel = cols[col_of_entry]
            data[sel] = (fp - f)[P.indices[sel]] / h[col_of_entry[sel]]
        return sp.csc_matrix((data, P.indices.copy(), P.indptr.copy()), shape=(self.n, self.n))

    # ------------------------------------------------------------------ raising calls
    def F(self, x, _k=None) -> np.ndarray:
        """F(x); raises what the user's F raises.  (``_k``: the memo key of x, when the
        caller has made it.)"""
        x = np.asarray(x, dtype=float)
        # one key for the look-up and, on a miss, the store (NaN-tested only then)
        k = _k if _k is not None else Memo.probe(x)
        memo = self._mf
        f = memo.get(x, k)
        if f is None:
            f, J = self._call_F(x)
            if _k is None and k[2]:  # (a point with a NaN is not stored)
                k = None
            memo.put(x, f, k)
            if J is not None:
                self._mj.put(x, (J, False), k)  # counted when used
        return f.copy()  # callers may write into their F values; the memo stays intact

    def J(self, x, f=None, _k=None) -> sp.csc_matrix:
        """J(x) on the fixed pattern.  ``f`` = F(x) when the caller has it (differences
        reuse it).  (``_k``: the memo key of x, when the caller has made it.)"""
        x = np.asarray(x, dtype=float)
        k = _k if _k is not None else Memo.probe(x)
        hit = self._mj.get(x, k)
        if hit is not None:
            J, counted = hit
            if J.nnz != self._pattern.nnz:  # kept from before an undeclared pattern grew
                J = self._fix_pattern(J)
            if not counted:
                self.counters.njev += 1
                self._mj.put(x, (J, True), k)  # (k matched a stored key: no NaN)
            return J
        if _k is None and k[2]:  # (a point with a NaN is not stored)
            k = None
        if self._user_jac is True:  # one call gives both; F's memo takes the new f too
            f, J = self._call_F(x)
            self._mf.put(x, f, k)
            self.counters.njev += 1
        elif self._user_jac is None:
            if f is None:
                f = self.F(x, k)
            J = self._fd_jacobian(x, np.asarray(f, dtype=float))
        else:
            J = self._call_J(x)
        self._mj.put(x, (J, True), k)
        return J

    def FJ(self, x):
        """(F(x), J(x))."""
        f = self.F(x)
        return f, self.J(x, f)

    def F_uncounted(self, x) -> np.ndarray:
        """F(x) straight from the user's function, outside the counters and the memo: the
        independent residual check of a returned point, not work of the solver."""
        saved = self.counters.nfev
        try:
            return self._call_F(x)[0]
        finally:
            self.counters.nfev = saved

    # ------------------------------------------------------------------ guarded calls
    def _reject(self, why: str):
        self.counters.domain_errors += 1
        self.last_error = why
        return None

    def guarded(self, call, finite, what):
        """call(), or None when it raised or its value is not ``finite`` (the point is
        rejected and counted as a domain error; the solver's errors and Ctrl-C pass)."""
        try:
            v = call()
        except (CompassError, KeyboardInterrupt):
            raise
        except Exception as exc:  # the user's function failed here: reject the point
            return self._reject(repr(exc))
        if not finite(v):
            return self._reject(f"{what} returned NaN/Inf")
        return v

    # f, f_once and jac are guarded() of F, of _call_F and of J written out: they evaluate
    # every point of a solve, and the general helper's indirection cost two Python calls
    # per evaluation (benchmarks/small.md, round 13).
    def f(self, x, _k=None):
        """F(x), or None when F raised or returned NaN/Inf there (counted)."""
        try:
            v = self.F(x, _k)
        except (CompassError, KeyboardInterrupt):
            raise
        except Exception as exc:  # the user's function failed here: reject the point
            return self._reject(repr(exc))
        return v if all_finite(v) else self._reject("F returned NaN/Inf")

    def f_once(self, x):
        """:meth:`f` at a point the solver will not ask about again (the homotopy's
        corrector iterates): counted and guarded the same, without the memo's look-up and
        store (~3 us of a small problem's evaluation, the memo would never be hit)."""
        try:
            v = self._call_F(np.asarray(x, dtype=float))[0]
        except (CompassError, KeyboardInterrupt):
            raise
        except Exception as exc:
            return self._reject(repr(exc))
        return v if all_finite(v) else self._reject("F returned NaN/Inf")

    def jac(self, x, f=None, _k=None):
        """J(x), or None when J raised or returned NaN/Inf there (counted)."""
        try:
            J = self.J(x, f, _k)
        except (CompassError, KeyboardInterrupt):
            raise
        except Exception as exc:
            return self._reject(repr(exc))
        return J if all_finite(J.data) else self._reject("J returned NaN/Inf")

    def fj(self, x):
        """(f, J), or (None, None) when either is rejected (the memo key of x is made
        once for both)."""
        x = np.asarray(x, dtype=float)
        k = Memo.key_of(x)
        f = self.f(x, k)
        if f is None:
            return None, None
        J = self.jac(x, f, k)
        if J is None:
            return None, None
        return f, J

    # ------------------------------------------------------------------ start point
    def pin(self, x):
        """Keep F(x) and J(x), evaluated last, in the memo until :meth:`forget`: the start
        point's values are asked for by several passes."""
        x = np.asarray(x, dtype=float)
        k = Memo.key_of(x)
        self._mf.pin(x, k)
        self._mj.pin(x, k)

    def start_values(self):
        """F at the pinned (start) point, or None: the acceptance test's reference for the
        rows whose F and J later vanish (:mod:`compass_sparse.nms.acceptance`, test 3)."""
        return self._mf.pvalue

    def check_at(self, x):
        """(F(x), J(x)) at the start point, raising :class:`EvaluationError` that names the
        row (and column) of the first non-finite value or the user's exception."""
        try:
            f, J = self.FJ(x)
        except CompassError:  # our own diagnostics (shapes, pattern, ...) pass through
            raise
        except Exception as exc:  # the user's code failed at the start point
            raise EvaluationError(f"F or J raised at the start point: {exc!r}") from exc
        if not all_finite(f):
            bad = np.flatnonzero(~np.isfinite(f))
            i = bad[0]
            raise EvaluationError(
                f"F is {f[i]} in row {self.row_label(i)} at the start point "
                f"({bad.size} non-finite rows)")
        if not all_finite(J.data):
            k = int(np.flatnonzero(~np.isfinite(J.data))[0])
            j = int(np.searchsorted(J.indptr, k, side="right") - 1)
            i = int(J.indices[k])
            raise EvaluationError(
                f"J is {J.data[k]} at (row {self.row_label(i)}, column {self.var_label(j)}) "
                "at the start point")
        self.pin(x)
        return f, J

    # ------------------------------------------------------------------ lifetime
    def forget(self):
        """Drop the memo (the user's functions may read data that changes between solves)."""
        self._mf.clear()
        self._mj.clear()

    def fresh(self) -> "Evaluator":
        """An evaluator of the same functions and pattern with new counters and no memo."""
        other = copy.copy(self)
        other.counters = EvalCounters()
        other.last_error = ""
        other._mf = Memo()
        other._mj = Memo()
        return other

    def restrict(self, fill, rows, cols, take, pattern, *, constant_jac=None, ub=None,
                 row_label=_default_row_label, var_label=_default_var_label) -> "Evaluator":
        """The evaluator of ``F_R(y) = F(fill(y))[rows]`` on the variables ``cols``, whose
        Jacobian entries are the parent's entries ``take`` (in the canonical order of
        ``pattern``).  Its F and J come from this evaluator (memo and counters shared)."""
        return _RestrictedEvaluator(self, fill, rows, cols, take, pattern,
                                    constant_jac=constant_jac, ub=ub, row_label=row_label,
                                    var_label=var_label)


class _RestrictedEvaluator(Evaluator):
    """See :meth:`Evaluator.restrict`."""

    def __init__(self, parent: Evaluator, fill, rows, cols, take, pattern, *, constant_jac,
                 ub, row_label, var_label):
        m = int(np.size(cols))
        super().__init__(None, parent.jac_mode, m, pattern=pattern, constant_jac=constant_jac,
                         fd_step=parent.fd_step, ub=ub, row_label=row_label,
                         var_label=var_label, counters=parent.counters)
        self.parent = parent
        self._fill = fill
        self._rows = np.asarray(rows)
        self._cols = np.asarray(cols)
        self._take = np.asarray(take)
        self._parent_nnz = parent._pattern.nnz if parent._pattern is not None else -1
        self.pattern_declared = parent.pattern_declared  # as certain as the parent's
        P = self._pattern
        self._indices, self._indptr = P.indices, P.indptr

    def _restrict_J(self, J):
        if J.nnz != self._parent_nnz:  # the parent's undeclared pattern grew: by index
            return self._fix_pattern(canonical_csc(J[self._rows][:, self._cols], self.n))
        return sp.csc_matrix((J.data[self._take], self._indices.copy(), self._indptr.copy()),
                             shape=(self.n, self.n))

    # F and a given J go through the parent's memo and counters; differences are taken on
    # the restriction itself (fewer colours) through the parent's counted primitive.
    def _call_F(self, y):
        return self.parent._call_F(self._fill(y))[0][self._rows], None

    def F(self, y, _k=None) -> np.ndarray:  # (no memo of its own: _k is not used)
        return self.parent.F(self._fill(y))[self._rows]

    def J(self, y, f=None, _k=None) -> sp.csc_matrix:
        if self.jac_mode is None:
            return super().J(y, f, _k)
        return self._restrict_J(self.parent.J(self._fill(y)))

    def pin(self, y):
        self.parent.pin(self._fill(y))
        super().pin(y)

    def forget(self):
        self.parent.forget()
        super().forget()

    def fresh(self) -> "Evaluator":
        other = super().fresh()
        other.parent = self.parent.fresh()
        other.counters = other.parent.counters
        return other


class ScaledEvaluator(Evaluator):
    """G(y) = R F(C y) and R J(C y) C through the parent evaluator's counted calls (the
    scaling pass's problem: ``s`` is its :class:`compass_sparse.scaling.Scaling`, z = C y
    with C = ``s.col`` and R = ``s.row``)."""

    def __init__(self, parent: Evaluator, s):
        P = parent.pattern_ref
        share = P is not None
        super().__init__(None, parent.jac_mode, parent.n,
                         pattern=None if share else parent.pattern,
                         fd_step=parent.fd_step, ub=parent.ub / s.col,
                         row_label=parent.row_label, var_label=parent.var_label,
                         counters=parent.counters)
        if share:
            # R J C has J's pattern: the parent's pattern object itself (never changed in
            # place: a pattern that grows is a new object) and its store of objects derived
            # from the pattern alone (its pattern_cache), so that a loop of scaled solves of one
            # model builds them once, not in every solve (the Newton linearizer's index
            # arrays: 0.15 ms of a 5 ms solve at n = 102, measured).  What the store holds
            # is built from the pattern alone (nms: the linearizer) or, on the user's
            # problem only, from its declared-constant entries too (solve: the count of
            # linear rows), which the scaling keeps constant: true of R J C as well.  (This
            # evaluator has no constant mask of its own: nothing built from one may be
            # asked through it.)
            self._pattern = P
            self._cache = parent._cache
        self.parent = parent
        self.scaling = s
        self.pattern_declared = parent.pattern_declared

    def _call_F(self, y):  # finite differences on G go through the parent's primitive
        return self.scaling.row * self.parent._call_F(self.scaling.col * y)[0], None

    def F(self, y, _k=None) -> np.ndarray:  # (no memo of its own: _k is not used)
        return self.scaling.row * self.parent.F(self.scaling.col * y)

    def J(self, y, f=None, _k=None) -> sp.csc_matrix:
        if self.jac_mode is None:
            return super().J(y, f, _k)
        J = self.parent.J(self.scaling.col * y)
        if self._pattern is not None and self._pattern is self.parent.pattern_ref:
            # the parent's J is on the parent's pattern, which is this one (shared, see
            # __init__), and R J C keeps J's index arrays: nothing to check
            return self.scaling.scale_jacobian(J)
        return self._fix_pattern(self.scaling.scale_jacobian(J))

    def pin(self, y):
        self.parent.pin(self.scaling.col * y)
        super().pin(y)

    def forget(self):
        self.parent.forget()
        super().forget()
