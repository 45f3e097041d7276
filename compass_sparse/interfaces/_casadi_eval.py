"""F and its exact sparse Jacobian, compiled once from row templates.

A modelling language states F row by row, and the rows of one indexed component share
their structure: ``profit[m, f]`` is the same expression tree for every market and firm,
only the variables, parameters and numbers at its leaves differ.  A row is therefore given
as a *signature* (the tree with its leaves lifted out) and its *leaves*, in the order a
depth-first walk meets them:

    leaf kinds   'x' (an MCP variable: its column), 'p' (data that may change between
                 solves: its index in p), 'c' (a number)
    nodes        ('sum', kids), ('prod', kids), ('div', kids), ('pow', kids), ('neg', kids),
                 ('abs', kids), ('max', kids), ('min', kids), ('if', kids), ('le', kids),
                 ('lt', kids), ('eq', kids), ('u', name, kid) for exp, log, sqrt, ...

Rows are grouped by signature.  For each group one template t(leaves) is built in CasADi's
SX graph with its gradient with respect to its 'x' leaves (algorithmic differentiation on
the small template graph, with common subexpressions eliminated), and the template is
mapped over the group's rows, which lays out, in CasADi's C++ core, the expression graph of

    F_r(x, p) = t(leaves of row r)                          (one per row)
    J_rc(x, p) = sum over the 'x' leaves k of row r at column c of  dt/dleaf_k,

so J is exact, its pattern (the (row, column) pairs the leaves name) is structural and never
changes, and an entry is declared constant when no contributing partial derivative depends
on an 'x' leaf.  Two CasADi functions F(x, p) and J(x, p) (the nonzeros in CSC order) are
then evaluated by CasADi's virtual machine through preallocated buffers: one call copies x
in and writes F or J's nonzeros into numpy arrays with no per-entry Python work.  Changing
p only rewrites the p buffer; nothing is recompiled.

Building the graph through Python operator calls costs ~50 microseconds per node (CasADi's
overload dispatch), which made n = 1e4 models take 25 s to compile; templates make that
cost proportional to the number of distinct row structures instead of the number of nodes.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["CompiledFJ", "casadi_available"]

UNARY = ("exp", "log", "log10", "sqrt", "sin", "cos", "tan", "asin", "acos", "atan", "sinh",
         "cosh", "tanh", "asinh", "acosh", "atanh", "ceil", "floor")


def casadi_available() -> bool:
    try:
        # (CasADi: an optional extra, with Pyomo)
        import casadi  # noqa: F401
    except Exception:
        return False
    return True


def _build(ca, sig, syms):
    """The SX expression of a signature, consuming leaf symbols from the iterator syms."""
    if sig in ("x", "p", "c"):
        return next(syms)
    op = sig[0]
    if op == "u":
        return getattr(ca, sig[1])(_build(ca, sig[2], syms))
    a = [_build(ca, s, syms) for s in sig[1]]
    if op == "sum":
        out = a[0]
        for t in a[1:]:
            out = out + t
        return out
    if op == "prod":
        return a[0] * a[1]
    if op == "div":
        return a[0] / a[1]
    if op == "pow":
        return a[0] ** a[1]
    if op == "neg":
        return -a[0]
    if op == "abs":
        return ca.fabs(a[0])
    if op in ("max", "min"):
        f = ca.fmax if op == "max" else ca.fmin
        out = a[0]
        for t in a[1:]:
            out = f(out, t)
        return out
    if op == "if":
        return ca.if_else(a[0], a[1], a[2])
    if op == "le":
        return a[0] <= a[1]
    if op == "lt":
        return a[0] < a[1]
    if op == "eq":
        return a[0] == a[1]
    raise ValueError(f"unknown template node {op!r}")


class CompiledFJ:
    """F and J of n rows given as (signature, leaves), compiled once.

    ``rows[i] = (sig, leaves)`` with leaves a list of (kind, value): ('x', column),
    ('p', index into p) or ('c', number).  Attributes: ``n``, ``pattern`` (CSC, data = 1),
    ``constant`` (CSC whose stored entries do not depend on x), ``p`` (parameter values).
    """

    def __init__(self, rows, n: int, n_params: int, *, cse: bool = False):
        # (CasADi: an optional extra, with Pyomo)
        import casadi as ca

        self.n = n = int(n)
        X = ca.SX.sym("x", n)
        P = ca.SX.sym("p", max(int(n_params), 0))
        groups: dict = {}
        for i, (sig, leaves) in enumerate(rows):
            groups.setdefault(sig, []).append(i)
        f_parts, f_rows = [], []
        j_parts, j_rows, j_cols, j_const = [], [], [], []
        for sig, members in groups.items():
            kinds = [k for k, _ in rows[members[0]][1]]
            syms = [ca.SX.sym(f"l{k}") for k in range(len(kinds))]
            expr = _build(ca, sig, iter(syms))
            xk = [k for k, kind in enumerate(kinds) if kind == "x"]
            N = len(members)
            vals = np.array([[v for _, v in rows[i][1]] for i in members], dtype=float
                            ).reshape(N, len(kinds))
            args = []
            for k, kind in enumerate(kinds):
                col = vals[:, k]
                if kind == "x":
                    args.append(X[col.astype(np.int64).tolist()].T)
                elif kind == "p":
                    args.append(P[col.astype(np.int64).tolist()].T)
                else:
                    args.append(ca.DM(col).T)
            tf = ca.Function("t", syms, [expr])
            f_parts.append(tf.map(N)(*args).T)
            f_rows.append(np.asarray(members))
            if not xk:
                continue
            xs = ca.vertcat(*[syms[k] for k in xk])
            grad = ca.densify(ca.jacobian(expr, xs))  # 1 x len(xk)
            const = [not ca.depends_on(grad[0, t], xs) for t in range(len(xk))]
            tj = ca.Function("dt", syms, [grad], {"cse": True})
            j_parts.append(tj.map(N)(*args).T)  # (N * len(xk)) x 1, row-major by member
            j_rows.append(np.repeat(np.asarray(members), len(xk)))
            j_cols.append(vals[:, xk].astype(np.int64).ravel())
            j_const.append(np.tile(np.asarray(const, dtype=bool), N))
        f_all = ca.vertcat(*f_parts) if f_parts else ca.SX(0, 1)
        order = np.concatenate(f_rows) if f_rows else np.zeros(0, np.int64)
        inv = np.empty(n, dtype=np.int64)
        inv[order] = np.arange(n)
        f = f_all[inv.tolist()]
        # J: raw partials -> CSC nonzeros (duplicates summed) by a constant 0/1 matrix
        if j_parts:
            raw = ca.vertcat(*j_parts)
            r, c = np.concatenate(j_rows), np.concatenate(j_cols)
            rc = np.concatenate(j_const)
        else:
            raw = ca.SX(0, 1)
            r = c = np.zeros(0, np.int64)
            rc = np.zeros(0, bool)
        key = c * n + r  # column-major: CSC order
        uniq, slot = np.unique(key, return_inverse=True)
        nnz = uniq.size
        self._indices = (uniq % n).astype(np.int32)
        self._indptr = np.searchsorted(uniq // n, np.arange(n + 1)).astype(np.int32)
        A = sp.csc_matrix((np.ones(key.size), (slot, np.arange(key.size))),
                          shape=(nnz, key.size))
        Asx = ca.DM(ca.Sparsity(nnz, key.size, A.indptr.tolist(), A.indices.tolist()),
                    A.data)
        jnz = ca.mtimes(Asx, raw) if key.size else ca.SX(0, 1)
        self.pattern = sp.csc_matrix((np.ones(nnz), self._indices, self._indptr),
                                     shape=(n, n))
        nonconst = np.bincount(slot, weights=(~rc).astype(float), minlength=nnz) > 0
        cols = np.repeat(np.arange(n), np.diff(self._indptr))
        self.constant = sp.csc_matrix(
            (np.ones(int((~nonconst).sum())), (self._indices[~nonconst], cols[~nonconst])),
            shape=(n, n))
        self.groups = len(groups)
        # Common-subexpression elimination across rows finds the terms rows share (a
        # market's price in each of its firms' rows): measured at n = 1e4 it halves the
        # instructions of F and J but costs seconds of build time, so it is optional.
        opts = {"cse": True} if cse else {}
        self.cse = bool(cse)
        self._Ff = ca.Function("F", [X, P], [f], opts)
        self._Jf = ca.Function("J", [X, P], [jnz], opts)
        self._x = np.zeros(n)
        self.p = np.zeros(P.numel())
        self._f = np.zeros(n)
        self._jv = np.zeros(nnz)
        self._Fcall = self._bind(self._Ff, self._f)
        self._Jcall = self._bind(self._Jf, self._jv)

    def _bind(self, fun, out):
        buf, run = fun.buffer()
        buf.set_arg(0, memoryview(self._x))
        buf.set_arg(1, memoryview(self.p))
        buf.set_res(0, memoryview(out))
        return buf, run  # the buffer must live as long as its runner

    def set_parameters(self, values) -> None:
        """Replace the parameter values p (in place: the compiled functions read this buffer)."""
        v = np.asarray(values, dtype=float)
        if v.shape != self.p.shape:
            raise ValueError(f"expected {self.p.size} parameter values, got {v.size}")
        self.p[:] = v

    def F(self, x) -> np.ndarray:
        self._x[:] = x
        self._Fcall[1]()
        return self._f.copy()

    def J(self, x) -> sp.csc_matrix:
        self._x[:] = x
        self._Jcall[1]()
        return sp.csc_matrix((self._jv.copy(), self._indices, self._indptr),
                             shape=(self.n, self.n))
