"""Shared generators for the basis-manager tests (imported by the test modules)."""

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from compass_sparse.basis import KIND_DENSE, KIND_M, KIND_UNIT


def dominant_matrix(n, density, rng, margin=1.0):
    """Sparse M that is strictly diagonally dominant by rows AND columns: every principal
    submatrix, and every basis mixing its columns with unit columns, is column-dominant
    and hence well-conditioned."""
    nnz = max(int(density * n * n), n)
    i = rng.integers(0, n, nnz)
    j = rng.integers(0, n, nnz)
    v = rng.uniform(-1.0, 1.0, nnz)
    A = sp.csc_matrix((v, (i, j)), shape=(n, n))
    A.setdiag(0.0)
    A.eliminate_zeros()
    rs = np.asarray(abs(A).sum(axis=1)).ravel()
    cs = np.asarray(abs(A).sum(axis=0)).ravel()
    d = (rs + cs + margin) * rng.choice([-1.0, 1.0], n)
    return sp.csc_matrix(A + sp.diags(d))


def dominant_dense_column(M, j0, rng):
    """A dense r whose entry j0 dominates the column, so r can replace the column of
    index j0 in any basis of the family."""
    n = M.shape[0]
    r = rng.uniform(-1.0, 1.0, n)
    r[j0] = 0.0
    r[j0] = (np.abs(r).sum() + 1.0) * 2.0
    return r


def dense_B(kinds, indices, signs, M, r):
    n = M.shape[0]
    Md = M.toarray()
    B = np.zeros((n, n))
    for s in range(n):
        k, i, g = kinds[s], indices[s], signs[s]
        if k == KIND_M:
            B[:, s] = g * Md[:, i]
        elif k == KIND_UNIT:
            B[i, s] = g
        else:
            B[:, s] = g * r
    return B


def rel_err(x, ref):
    return np.abs(x - ref).max() / max(np.abs(ref).max(), 1e-300)


def check_solves(bm, M, r, rng, tol):
    """ftran/btran/ftran_column against numpy on the explicitly assembled B."""
    B = dense_B(bm.kinds, bm.indices, bm.signs, M, r)
    n = B.shape[0]
    b = rng.standard_normal(n)
    lu = scipy.linalg.lu_factor(B)
    x = bm.ftran(b)
    assert rel_err(x, scipy.linalg.lu_solve(lu, b)) <= tol
    y = bm.btran(b)
    assert rel_err(y, scipy.linalg.lu_solve(lu, b, trans=1)) <= tol
    return B


def family_start(n, rng, r_index=None):
    """Random slot table of the family: index j is represented by M_j or +-e_j, slots
    permuted at random; optionally the dense column holds index r_index."""
    perm = rng.permutation(n)
    use_m = rng.random(n) < 0.5
    kinds = np.where(use_m, KIND_M, KIND_UNIT)
    signs = rng.choice([-1.0, 1.0], n)
    kinds = kinds[perm]
    indices = perm.copy()
    signs = signs[perm]
    if r_index is not None:
        s = int(np.flatnonzero(indices == r_index)[0])
        kinds[s] = KIND_DENSE
    return kinds, indices, signs


def family_move(bm, rng, n, r_index=None):
    """A replacement keeping the basis in the family: pick an index j, swap the
    representation of j (M_j <-> +-e_j <-> r if j == r_index). Returns (slot, column)."""
    j = int(rng.integers(n))
    s = bm.slot_of_m(j)
    if s < 0:
        s = bm.slot_of_unit(j)
    if s < 0:
        s = bm.slot_of_dense()
        j = r_index
    cur = int(bm.kinds[s])
    choices = [KIND_M, KIND_UNIT] + ([KIND_DENSE] if j == r_index else [])
    if len(choices) > 1 and rng.random() < 0.85:
        choices = [c for c in choices if c != cur]
    kind = int(rng.choice(choices))
    sign = float(rng.choice([-1.0, 1.0]))
    return s, (kind, j if kind != KIND_DENSE else 0, sign)


def column_vec(kind, index, sign, M, r):
    n = M.shape[0]
    if kind == KIND_M:
        return sign * M[:, [index]].toarray().ravel()
    if kind == KIND_UNIT:
        e = np.zeros(n)
        e[index] = sign
        return e
    return sign * r
