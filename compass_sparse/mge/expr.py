"""Vectorized algebraic expressions with exact sparse first derivatives.

An expression ``e`` of length L is a vector function e(x) in R^L of the model's variables
x and parameters.  Evaluating it returns the values and the Jacobian de/dx as *triplets*
(rows, cols, vals): forward-mode differentiation in which every node of the expression
tree carries its own sparse Jacobian, combined by the usual rules

    d(a + b) = da + db,     d(a b) = b da + a db,     d(a / b) = da / b - a db / b^2,
    d(a^k) = k a^(k-1) da,  d(exp a) = exp(a) da,     d(log a) = da / a.

The triplets of a node depend only on the tree's structure, never on the values (an entry
whose value happens to be zero is kept), so the sparsity pattern of a model built from
expressions is fixed and can be computed once.  Every operation is a numpy operation on
whole vectors: the cost of an evaluation is proportional to the number of triplets, with
no per-element Python.

Expressions are used for auxiliary constraints, for tax rates and endowments that depend
on auxiliary variables, and (variable-free) for parameter-dependent data: quantities,
reference prices and elasticities.
"""
from __future__ import annotations

import numpy as np

__all__ = ["Expr", "as_expr", "esum", "exp", "log"]

_EMPTY = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))


class Context:
    """What an evaluation reads: the point x, the parameter values, and a memo so that a
    sub-expression shared by several parents is evaluated once per point."""

    def __init__(self, x, params, deriv=True):
        self.x = x
        self.params = params
        self.deriv = deriv
        self.memo = {}


def _scale(trips, factor):
    """Triplets multiplied row-wise by ``factor`` (a vector indexed by row, or a scalar)."""
    out = []
    for r, c, v in trips:
        f = factor[r] if np.ndim(factor) else factor
        out.append((r, c, v * f))
    return out


def _broadcast(val, trips, n):
    """A length-1 expression repeated n times (its triplets repeated on every row)."""
    if val.shape[0] == n:
        return val, trips
    rows = np.arange(n)
    out = []
    for r, c, v in trips:
        k = r.shape[0]
        out.append((np.repeat(rows, k), np.tile(c, n), np.tile(v, n)))
    return np.full(n, val[0]), out


class Expr:
    """A vector expression; build it with +, -, *, /, ** (constant exponent), ``exp``,
    ``log``, ``esum``, and indexing ``e[idx]`` (take elements)."""

    __array_priority__ = 100  # numpy arrays on the left defer to our operators

    size: int = 1

    # -- evaluation ---------------------------------------------------------------
    def evaluate(self, ctx):
        """(values (L,), triplets) at ctx, memoized per context."""
        key = id(self)
        hit = ctx.memo.get(key)
        if hit is None:
            hit = self._eval(ctx)
            ctx.memo[key] = hit
        return hit

    def _eval(self, ctx):  # pragma: no cover - abstract
        raise NotImplementedError

    def variables(self):
        """The set of variable columns the expression can depend on (structural)."""
        out = set()
        self._collect(out)
        return out

    def _collect(self, out):
        for child in getattr(self, "children", ()):
            child._collect(out)

    def has_variables(self):
        return bool(self.variables())

    def value(self, params, x=None):
        """Values only (no derivative), for variable-free data or at a point x."""
        ctx = Context(x, params, deriv=False)
        return self.evaluate(ctx)[0]

    # -- algebra --------------------------------------------------------------------
    def __add__(self, other):
        return _Binary("+", self, as_expr(other))

    def __radd__(self, other):
        return _Binary("+", as_expr(other), self)

    def __sub__(self, other):
        return _Binary("-", self, as_expr(other))

    def __rsub__(self, other):
        return _Binary("-", as_expr(other), self)

    def __mul__(self, other):
        return _Binary("*", self, as_expr(other))

    def __rmul__(self, other):
        return _Binary("*", as_expr(other), self)

    def __truediv__(self, other):
        return _Binary("/", self, as_expr(other))

    def __rtruediv__(self, other):
        return _Binary("/", as_expr(other), self)

    def __neg__(self):
        return _Binary("*", Const(-1.0), self)

    def __pos__(self):
        return self

    def __pow__(self, k):
        if isinstance(k, Expr):
            raise TypeError("an exponent must be a number (a ** b with b an expression is "
                            "exp(b * log(a)))")
        return _Unary("pow", self, float(k))

    def __getitem__(self, idx):
        return _Take(self, np.asarray(idx, dtype=np.int64).reshape(-1))

    def __len__(self):
        return self.size


class Const(Expr):
    """Constant values."""

    def __init__(self, values):
        self.values = np.atleast_1d(np.asarray(values, dtype=float)).reshape(-1)
        self.size = self.values.shape[0]

    def _eval(self, ctx):
        return self.values, []


class VarLeaf(Expr):
    """Variables x[cols]."""

    def __init__(self, cols):
        self.cols = np.asarray(cols, dtype=np.int64).reshape(-1)
        self.size = self.cols.shape[0]

    def _eval(self, ctx):
        if ctx.x is None:
            raise ValueError("this expression depends on variables and no point was given")
        val = ctx.x[self.cols]
        if not ctx.deriv:
            return val, []
        return val, [(np.arange(self.size), self.cols, np.ones(self.size))]

    def _collect(self, out):
        out.update(self.cols.tolist())


class ParamLeaf(Expr):
    """Parameter values params[key][positions] (current values, read at evaluation)."""

    def __init__(self, key, positions):
        self.key = key
        self.positions = np.asarray(positions, dtype=np.int64).reshape(-1)
        self.size = self.positions.shape[0]

    def _eval(self, ctx):
        return np.asarray(ctx.params[self.key], dtype=float).reshape(-1)[self.positions], []


class _Binary(Expr):
    def __init__(self, op, a, b):
        if a.size != b.size and 1 not in (a.size, b.size):
            raise ValueError(f"expressions of lengths {a.size} and {b.size} do not broadcast")
        self.op, self.children = op, (a, b)
        self.size = max(a.size, b.size)

    def _eval(self, ctx):
        a, b = self.children
        va, ta = a.evaluate(ctx)
        vb, tb = b.evaluate(ctx)
        n = self.size
        if ctx.deriv:
            va, ta = _broadcast(va, ta, n)
            vb, tb = _broadcast(vb, tb, n)
        else:
            va, vb = np.broadcast_to(va, n), np.broadcast_to(vb, n)
        op = self.op
        if op == "+":
            return va + vb, ta + tb
        if op == "-":
            return va - vb, ta + _scale(tb, -1.0)
        if op == "*":
            return va * vb, _scale(ta, vb) + _scale(tb, va)
        val = va / vb
        return val, _scale(ta, 1.0 / vb) + _scale(tb, -val / vb)


class _Unary(Expr):
    def __init__(self, op, a, k=None):
        self.op, self.children, self.k = op, (a,), k
        self.size = a.size

    def _eval(self, ctx):
        va, ta = self.children[0].evaluate(ctx)
        if self.op == "pow":
            val = va ** self.k
            d = self.k * va ** (self.k - 1.0) if self.k != 0 else np.zeros_like(va)
        elif self.op == "exp":
            val = np.exp(va)
            d = val
        else:
            val = np.log(va)
            d = 1.0 / va
        return val, (_scale(ta, d) if ctx.deriv else [])


class _Take(Expr):
    """Elements a[idx] (idx may repeat elements: a broadcast to a larger index set)."""

    def __init__(self, a, idx):
        if idx.size and (idx.min() < 0 or idx.max() >= a.size):
            raise IndexError(f"index out of range for an expression of length {a.size}")
        self.children, self.idx = (a,), idx
        self.size = idx.shape[0]

    def _eval(self, ctx):
        va, ta = self.children[0].evaluate(ctx)
        if not ctx.deriv:
            return va[self.idx], []
        out = []
        for r, c, v in ta:
            # Group the triplets by row, then for each output row copy its source row's.
            order = np.argsort(r, kind="stable")
            counts = np.bincount(r, minlength=va.shape[0])
            starts = np.concatenate(([0], np.cumsum(counts)))
            k = counts[self.idx]
            rows = np.repeat(np.arange(self.size), k)
            offs = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
            pick = order[np.repeat(starts[self.idx], k) + offs]
            out.append((rows, c[pick], v[pick]))
        return va[self.idx], out


class _GroupSum(Expr):
    """out[g] = sum of a[i] over the i with groups[i] == g (g < n)."""

    def __init__(self, a, groups, n):
        self.children = (a,)
        self.groups = np.broadcast_to(np.asarray(groups, dtype=np.int64), (a.size,))
        self.size = int(n)

    def _eval(self, ctx):
        va, ta = self.children[0].evaluate(ctx)
        val = np.bincount(self.groups, weights=va, minlength=self.size)
        return val, [(self.groups[r], c, v) for r, c, v in ta] if ctx.deriv else []


def as_expr(value) -> Expr:
    """An Expr from an Expr, a number or an array of numbers."""
    if isinstance(value, Expr):
        return value
    arr = np.asarray(value)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"cannot use a {type(value).__name__} in a model expression")
    return Const(arr)


def esum(a, groups=None, n=None) -> Expr:
    """Sum of the elements of ``a`` (a length-1 expression), or sums by group."""
    a = as_expr(a)
    if groups is None:
        return _GroupSum(a, 0, 1)
    return _GroupSum(a, groups, n if n is not None else int(np.max(groups)) + 1)


def exp(a) -> Expr:
    return _Unary("exp", as_expr(a))


def log(a) -> Expr:
    return _Unary("log", as_expr(a))


def concat(parts) -> Expr:
    """The concatenation of expressions (used to gather a model's tax rates)."""
    return _Concat([as_expr(p) for p in parts])


class _Concat(Expr):
    def __init__(self, parts):
        self.children = tuple(parts)
        self.offsets = np.cumsum([0] + [p.size for p in parts])
        self.size = int(self.offsets[-1])

    def _eval(self, ctx):
        vals, trips = [], []
        for off, p in zip(self.offsets, self.children):
            v, t = p.evaluate(ctx)
            vals.append(np.broadcast_to(v, p.size))
            trips.extend((r + off, c, w) for r, c, w in t)
        return (np.concatenate(vals) if vals else np.zeros(0)), trips


def triplets(trips):
    """The triplets of an evaluation as three concatenated arrays."""
    if not trips:
        return _EMPTY
    return (np.concatenate([t[0] for t in trips]).astype(np.int64),
            np.concatenate([t[1] for t in trips]).astype(np.int64),
            np.concatenate([t[2] for t in trips]).astype(float))
