"""CSC matrices from arrays the solver already knows to be valid, without scipy's checks.

scipy's ``csc_matrix((data, indices, indptr), shape)`` validates and re-types its index
arrays on every call (about 20 us); a small problem builds a dozen such matrices per solve
from arrays that are valid by construction (the full pattern of a dense Jacobian, the
fixed pattern of J + eps I, a copy of the stored pattern).  :func:`trusted_csc` sets the
same attributes directly.  It is used only where the caller guarantees a structurally
valid matrix: int32 index arrays, indptr non-decreasing from 0 to len(indices) = len(data),
row indices within the shape.  Nothing more is assumed: scipy still computes the sorted
and canonical flags from the arrays when asked.  A caller whose matrix is canonical by
construction (the evaluator's Jacobians: the full pattern of a dense J, values copied onto
the stored pattern) says so, ``canonical=True``, and :func:`without_duplicates` then
returns it without its scan (two scans of every evaluated J in a small solve).  When this
scipy keeps other attributes than the ones known here, or an index array is not int32,
the checked constructor is used instead (probed once, at first use).
"""
from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp

from ..exceptions import EvaluationError, ShapeError
from ._csc_kernels import csc_is_canonical, csc_matvec, free_block

_KNOWN = {"_shape", "maxprint", "indices", "indptr", "data"}
_STATE = []  # [usable: bool, maxprint] after the probe


def _probe():
    A = sp.csc_matrix((np.zeros(1), np.zeros(1, dtype=np.int32),
                       np.array([0, 1], dtype=np.int32)), shape=(1, 1))
    _STATE[:] = [set(vars(A)) == _KNOWN and A.indices.dtype == np.int32,
                 getattr(A, "maxprint", None)]


_CANONICAL = "_compass_canonical"  # the mark of a matrix canonical by construction


def trusted_csc(data, indices, indptr, shape, canonical: bool = False) -> sp.csc_matrix:
    """csc_matrix((data, indices, indptr), shape) for structurally valid int32 arrays;
    ``canonical``: the caller guarantees sorted, duplicate-free columns too (marked)."""
    if not _STATE:
        _probe()
    if not _STATE[0] or indices.dtype != np.int32 or indptr.dtype != np.int32:
        M = sp.csc_matrix((data, indices, indptr), shape=shape)
        if canonical:
            setattr(M, _CANONICAL, True)
        return M
    M = sp.csc_matrix.__new__(sp.csc_matrix)
    # the new object's attributes in one dict (the probe found exactly these): half the
    # cost of five attribute assignments, and every evaluated J is one such matrix
    M.__dict__ = {"_shape": (int(shape[0]), int(shape[1])), "maxprint": _STATE[1],
                  "indices": indices, "indptr": indptr, "data": data}
    if canonical:
        M.__dict__[_CANONICAL] = True
    return M


def is_csc(A) -> bool:
    """Whether A is a scipy CSC matrix (or array); the class is tested first, since
    scipy's issparse is an ABC check (~0.5 us) and the solver's matrices are csc_matrix."""
    return A.__class__ is sp.csc_matrix or (sp.issparse(A) and A.format == "csc")


def float_csc(J) -> sp.csc_matrix:
    """J as a CSC matrix of floats, as the compiled kernels read it: the evaluator's J
    itself, else a converted copy."""
    if is_csc(J) and J.data.dtype == np.float64:
        return J
    return sp.csc_matrix(J, dtype=np.float64)


def without_duplicates(A) -> sp.csc_matrix:
    """A as a CSC matrix in canonical form (sorted, no duplicate entries): A itself when
    it already is one, else a canonical copy.  The test is one compiled scan of the index
    arrays: scipy's ``has_canonical_format`` computes it again on every matrix that does
    not carry its flag (the solver's own matrices, built by :func:`trusted_csc`), ~10 us
    on a small matrix; a matrix marked canonical by :func:`trusted_csc` is not scanned."""
    if A.__dict__.get(_CANONICAL, False) if A.__class__ is sp.csc_matrix else False:
        return A
    if not is_csc(A):
        A = sp.csc_matrix(A)
    ip, ix = A.indptr, A.indices
    if ((ix.dtype == np.int32 or ix.dtype == np.int64) and ip.dtype == ix.dtype
            and csc_is_canonical(ip, ix, A.shape[0], ip[-1])):
        return A
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()
    return A



def csc_times(A, x):
    """A x: one compiled pass in scipy's order (the same bits) for a float64 CSC matrix and
    a float vector, without scipy's dispatch (~8 us per product on a small model); A @ x
    otherwise."""
    if (A.data.dtype == np.float64 and isinstance(x, np.ndarray) and x.dtype == np.float64
            and x.shape == (A.shape[1],)):
        out = np.empty(A.shape[0])
        csc_matvec(A.indptr, A.indices, A.data, x, out)
        return out
    return A @ x


def reduced_system(M, free, z, q):
    """(M_FF as CSC, -(q + M_FN z_N)_F) for the indices F where ``free`` is True (M: CSC,
    sorted indices give sorted indices), in one compiled pass without scipy's slicing."""
    if not (sp.issparse(M) and M.format == "csc"):
        M = sp.csc_matrix(M)
    z = np.asarray(z, dtype=float)
    q = np.asarray(q, dtype=float)
    # positions, arrays and the pass in one compiled call
    Kp, Ki, Kx, rhs, k = free_block(M.indptr, M.indices, M.data,
                                    np.asarray(free, dtype=np.bool_), z, q)
    nf = rhs.shape[0]
    return trusted_csc(Kx[:k], Ki[:k], Kp, (nf, nf)), rhs


I32 = np.dtype(np.int32)
"""The int32 dtype object of the index arrays (tested by identity, as box.F64)."""


@functools.lru_cache(maxsize=16)
def full_pattern(n: int):
    """(indptr, indices) of the full n x n CSC pattern (never handed out: copied)."""
    return (np.arange(0, n * n + 1, n, dtype=np.int32),
            np.tile(np.arange(n, dtype=np.int32), n))


def pattern_keys(A: sp.csc_matrix) -> np.ndarray:
    """Sorted keys col * n + row of the stored entries of a canonical CSC matrix."""
    n = A.shape[0]
    return np.repeat(np.arange(A.shape[1], dtype=np.int64), np.diff(A.indptr)) * n + A.indices


def dense_csc(A, n: int) -> sp.csc_matrix:
    """A real dense n x n array as a CSC matrix holding every entry (zeros included)."""
    if A.shape != (n, n):
        raise ShapeError(f"the Jacobian has shape {A.shape}, expected ({n}, {n})")
    # The full pattern, built once per n (a small problem with a dense Jacobian evaluates
    # it every major iteration); copies of the index arrays, since scipy may sort or
    # prune them in place.
    indptr, indices = full_pattern(n)
    return trusted_csc(A.T.flatten(), indices.copy(), indptr.copy(), (n, n), canonical=True)


def canonical_csc(J, n: int) -> sp.csc_matrix:
    """J as a canonical (sorted, duplicate-free) float CSC copy; a dense array keeps its
    full pattern (its zeros stay stored).  Any scipy.sparse form is accepted, matrix or
    array (dok, lil, coo, csr, bsr, dia, csc): they all have a ``dtype`` (a dok has no
    ``data`` array) and scipy converts each to CSC."""
    sparse = sp.issparse(J)
    if not sparse:
        J = np.asarray(J)
    if J.dtype.kind == "c":
        raise EvaluationError("the Jacobian has complex entries; J must be real")
    if sparse:
        if J.shape != (n, n):
            raise ShapeError(f"the Jacobian has shape {J.shape}, expected ({n}, {n})")
        if (J.format == "csc" and J.data.dtype == np.float64
                and J.indices.dtype == np.int32 and J.indptr.dtype == np.int32):
            nnz = J.indptr[-1]
            if csc_is_canonical(J.indptr, J.indices, n, nnz):
                # already canonical (the common case): copies of its arrays, without
                # scipy's constructor checks and sorting (~50 us per evaluation)
                return trusted_csc(J.data[:nnz].copy(), J.indices[:nnz].copy(),
                                   J.indptr.copy(), (n, n), canonical=True)
        C = sp.csc_matrix(J, dtype=float, copy=True)
    else:
        return dense_csc(J.astype(float, copy=False), n)
    if not C.has_canonical_format:
        C.sum_duplicates()  # sorts indices too
    C.sort_indices()
    return C
