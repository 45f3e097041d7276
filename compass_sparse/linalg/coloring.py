"""Greedy colouring of Jacobian columns for sparse finite differences.

Two columns may share a colour (be perturbed together) when no row holds an entry of both:
their differences then land in disjoint rows (Curtis, Powell and Reid, 1974).  Greedy
colouring in natural order uses at most (max entries per row - 1) * (max entries per
column) + 1 colours; for stencil-like patterns it is close to the maximum row count.
"""
import numpy as np
import scipy.sparse as sp

from .._jit import njit


@njit(cache=True)
def _greedy(indptr, indices, rptr, rcols, n):
    colors = -np.ones(n, dtype=np.int64)
    mark = -np.ones(n + 1, dtype=np.int64)  # mark[c] == j: colour c is forbidden for column j
    for j in range(n):
        for p in range(indptr[j], indptr[j + 1]):
            i = indices[p]
            for q in range(rptr[i], rptr[i + 1]):
                k = rcols[q]
                c = colors[k]
                if c >= 0:
                    mark[c] = j
        c = 0
        while mark[c] == j:
            c += 1
        colors[j] = c
    return colors


def color_columns(indptr, indices, n):
    """Colour the columns of an n x n CSC pattern; returns an int array of colours."""
    P = sp.csc_matrix((np.ones(len(indices)), indices, indptr), shape=(n, n))
    R = P.tocsr()
    return _greedy(
        np.asarray(indptr, dtype=np.int64), np.asarray(indices, dtype=np.int64),
        R.indptr.astype(np.int64), R.indices.astype(np.int64), n,
    )
