"""Maximum bipartite matching of a sparse pattern (a maximum transversal).

Rows and columns of an m x n pattern are the two vertex sets, entries the edges.  A
matching pairs columns with distinct rows through entries; a maximum one has as many pairs
as the structural rank.  The basis manager's rank repair, the fill-reducing orderings (a
zero-free diagonal first) and the preprocessor's structural check all need one.

Algorithm: depth-first search for augmenting paths from each unmatched column, one column
at a time, with a look-ahead (a column first takes any unmatched row among its own entries
before the search goes deeper) -- Duff's MC21 (ACM TOMS 7, 1981).  Two rules keep it
polynomial on every pattern:

* within one search a row is visited at most once (a stamp per search), so one search costs
  O(nnz);
* the rows visited by a search that FAILS are set aside for good: no later augmenting path
  can pass through them (if one did, its tail from such a row would complete an augmenting
  path from the failed column, against the failure; augmentations only extend the set of
  matched rows).  All failed searches together therefore cost O(nnz).

Hence O(n nnz) in the worst case and, on the Jacobians met here, close to O(nnz).
(``scipy.sparse.csgraph.maximum_bipartite_matching`` can take time exponential in the depth
of a layered pattern -- its depth-first phase never marks dead ends -- and did not return
in minutes on a 30 000-column reduced Jacobian of the period-layered dynamic CGE model.)
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._jit import njit

__all__ = ["column_matching", "matching"]

_I = np.int64


@njit(cache=True)
def augmenting_matching(m, n, indptr, indices):
    """(row matched to each column or -1, column matched to each row or -1)."""
    row_of = np.full(n, -1, np.int64)
    col_of = np.full(m, -1, np.int64)
    cheap = indptr[:n].copy()           # look-ahead pointer of each column
    stamp = np.full(m, -1, np.int64)    # the search that last visited each row
    dead = np.zeros(m, np.bool_)        # visited by a failed search: never useful again
    stack_col = np.empty(n + 1, np.int64)
    stack_ptr = np.empty(n + 1, np.int64)
    seen = np.empty(m, np.int64)        # rows visited by the current search
    for j0 in range(n):
        depth = 0
        stack_col[0] = j0
        stack_ptr[0] = indptr[j0]
        nseen = 0
        found = -1
        while depth >= 0:
            j = stack_col[depth]
            # look-ahead: an unmatched row of column j ends the search at once (a matched
            # row never becomes unmatched, so the pointer never moves back)
            while cheap[j] < indptr[j + 1]:
                i = indices[cheap[j]]
                cheap[j] += 1
                if col_of[i] < 0:
                    found = i
                    break
            if found >= 0:
                break
            advanced = False
            while stack_ptr[depth] < indptr[j + 1]:
                i = indices[stack_ptr[depth]]
                stack_ptr[depth] += 1
                if stamp[i] == j0 or dead[i]:
                    continue
                stamp[i] = j0
                seen[nseen] = i
                nseen += 1
                depth += 1
                stack_col[depth] = col_of[i]
                stack_ptr[depth] = indptr[col_of[i]]
                advanced = True
                break
            if not advanced:
                depth -= 1
        if found >= 0:
            # flip the path: the deepest column takes the free row, each column above it
            # the row through which the search left it
            i = found
            for d in range(depth, -1, -1):
                j = stack_col[d]
                prev = row_of[j]
                row_of[j] = i
                col_of[i] = j
                i = prev
        else:
            for k in range(nseen):
                dead[seen[k]] = True
    return row_of, col_of


def matching(A):
    """Maximum matching of the pattern of the m x n sparse matrix ``A`` (entries stored as
    explicit zeros count as entries: drop them first when the numerical pattern matters).

    Returns ``(row_of_col, col_of_row)``: the row matched to each column and the column
    matched to each row, -1 where unmatched; the matching's size is the structural rank.
    """
    A = A if (sp.issparse(A) and A.format == "csc") else sp.csc_matrix(A)
    m, n = A.shape
    if m == 0 or n == 0:
        return np.full(n, -1, _I), np.full(m, -1, _I)
    return augmenting_matching(m, n, A.indptr.astype(_I), A.indices.astype(_I))


def column_matching(A):
    """The row matched to each column of ``A`` by a maximum matching (-1: unmatched)."""
    return matching(A)[0]
