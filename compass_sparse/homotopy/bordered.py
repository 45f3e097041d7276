"""The tracker's linear algebra: the LU of the bordered matrix [[H_x, H_lam], [v^T, 0]],
dense (LAPACK's getrf, compiled solves) or sparse (SuperLU), and the end game's square
solves."""
from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp

from ..box import all_finite
from ..linalg._csc_kernels import csc_to_dense
from ._kernels import bordered_pivots_ok, lu_solve

__all__ = ["Bordered", "dense_copy", "dense_lu", "lapack_getrf", "solve_square"]


# ------------------------------------------------------------------ bordered linear algebra
class Bordered:
    """LU of [[A, c], [v^T, 0]] (A n x n sparse, c, v dense), dense or sparse."""

    def __init__(self, A, c, v, dense: bool):
        n = A.shape[0]
        self.dense = dense
        if dense:
            if c is None:
                B = A  # the whole bordered matrix already (Fortran order: factored in place)
            else:
                B = np.empty((n + 1, n + 1))
                B[:n, :n] = A
                B[:n, n] = c[:n]
                B[n, :] = v
                B[n, n] = v[n]
            lu, piv = self.lu = dense_lu(B)
            if not bordered_pivots_ok(lu):
                raise np.linalg.LinAlgError("singular bordered matrix")
        else:
            col = sp.csc_matrix(c[:n].reshape(-1, 1))
            row = sp.csr_matrix(v[:n].reshape(1, -1))
            B = sp.bmat([[A, col], [row, sp.csc_matrix([[v[n]]])]], format="csc")
            # (lazy: scipy.sparse.linalg adds ~0.15 s to the package's import)
            from scipy.sparse.linalg import splu

            self.lu = splu(B, permc_spec="COLAMD")

    def solve(self, b):
        if self.dense:
            x = np.array(b, dtype=float)
            finite = lu_solve(*self.lu, x)
        else:
            x = self.lu.solve(b)
            finite = all_finite(x)
        if not finite:
            raise np.linalg.LinAlgError("non-finite solution of the bordered system")
        return x


def solve_square(A, b, dense: bool):
    """A^-1 b (non-finite entries when A is singular: the caller tests the step)."""
    if dense:
        # getrf and the compiled triangular solves: scipy's lu_factor and lu_solve cost a
        # small problem's end game ~25 us per Newton iteration in their checks and dispatch
        M = A.toarray() if sp.issparse(A) else A
        x = np.array(b, dtype=float)
        lu_solve(*dense_lu(np.asarray(M, dtype=float)), x)
        return x
    # (lazy: scipy.sparse.linalg adds ~0.15 s to the package's import)
    from scipy.sparse.linalg import splu

    return splu(sp.csc_matrix(A), permc_spec="COLAMD").solve(b)


@functools.lru_cache(maxsize=1)
def lapack_getrf():
    """LAPACK's dgetrf, as scipy.linalg binds it (looked up when first needed)."""
    # (lazy: scipy.linalg adds ~0.12 s to the package's import)
    import scipy.linalg as sla

    return sla.lapack.get_lapack_funcs("getrf", (np.empty(1),))


def dense_lu(A):
    """(lu, piv) of A by LAPACK's getrf directly, in place when A is Fortran-ordered (what
    scipy.linalg.lu_factor calls, without its checks and dispatch: ~35 us a step at n = 1;
    the solves with these factors are compiled: lu_solve).  An exactly singular A gives
    factors with a zero pivot (the callers test the pivots or the solution)."""
    lu, piv, info = lapack_getrf()(A, overwrite_a=True)
    if info < 0:
        raise ValueError(f"illegal argument {-info} of getrf")
    return lu, piv


def dense_copy(J):
    """J (float CSC) as a new dense array, in one compiled pass (J.toarray() costs ~80 us
    at n = 1)."""
    out = np.empty(J.shape)
    csc_to_dense(J.indptr, J.indices, J.data, out)
    return out
