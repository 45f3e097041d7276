"""Seeded test problems with known presolve structure (for the presolve tests only).

``build(seed, n, feats)`` returns (problem, info): F(z) = M z + q + cub * z^3 (cubic terms on
a set of diagonal entries, declared nonlinear; every other entry of M declared constant).
The base M is strictly diagonally dominant with a diagonally dominant symmetric part, so
the base problem is strongly monotone; each feature edits dedicated indices so that the
problem stays uniquely solvable in the variables that matter (monotone skew blocks are
used for the KKT-like features).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from compass_sparse.problem import MCP

ALL_FEATS = ("fixed", "singleton_diag", "singleton_off", "col_singleton", "free_col_singleton",
             "empty_row", "range", "forcing", "duplicate", "cubic", "empty_col")


def linear_mcp(M, q, lb, ub, x0=None, cubic=None, names=None, declare=True):
    """MCP for F = M z + q (+ cubic * z^3 on the diagonal), constant entries declared."""
    M = sp.csc_matrix(M)
    n = M.shape[0]
    cub = np.zeros(n) if cubic is None else np.asarray(cubic, dtype=float)
    pat = (abs(M) + sp.diags((cub != 0).astype(float))).tocsc()
    pat.data[:] = 1.0
    pat = sp.csc_matrix(pat)
    pat.sort_indices()
    Mp = (M + 0.0 * pat).tocsc()  # M on the full pattern (explicit zeros kept)
    Mp = sp.csc_matrix((np.asarray(M[pat.nonzero()]).ravel(), pat.nonzero()), shape=(n, n))
    Mp = _on_pattern(M, pat)
    const = pat.copy()
    if (cub != 0).any():
        const = const - sp.diags((cub != 0).astype(float)).multiply(const)
        const = sp.csc_matrix(const)
        const.eliminate_zeros()

    def F(z):
        return Mp @ z + q + cub * z ** 3

    def J(z):
        return _on_pattern(Mp + sp.diags(3 * cub * z ** 2), pat)

    return MCP(F, J, lb, ub, np.zeros(n) if x0 is None else x0,
               constant_jac=const if declare else None, var_names=names,
               jac_sparsity=pat if declare else None)


def _on_pattern(A, pat):
    """A's values on the fixed pattern ``pat`` (explicit zeros where A has none)."""
    A = sp.csc_matrix(A)
    r, c = pat.nonzero()
    vals = np.asarray(A[r, c]).ravel()
    out = sp.csc_matrix((vals + 1.0, (r, c)), shape=pat.shape)  # +1 keeps zeros stored
    out.sort_indices()
    out.data -= 1.0
    return out


def build(seed: int, n: int = 40, feats=ALL_FEATS):
    rng = np.random.default_rng(seed)
    off = sp.random(n, n, density=min(1.0, 3.0 / n), random_state=rng,
                    data_rvs=lambda k: rng.uniform(-1, 1, k)).tolil()
    off.setdiag(0)
    off = sp.csr_matrix(off)
    rs = np.asarray(abs(off).sum(axis=1)).ravel()
    cs = np.asarray(abs(off).sum(axis=0)).ravel()
    s = np.maximum(1.0, np.maximum(rs.max(initial=0), cs.max(initial=0)))
    M = (off / s * 1.5).tolil()
    M.setdiag(4.0 + rng.random(n))
    q = rng.normal(size=n) * 2
    kinds = rng.integers(0, 4, n)
    lb = np.where(kinds == 0, -np.inf, np.where(kinds == 3, -1.0, 0.0))
    ub = np.where(kinds == 0, np.inf, np.where(kinds == 2, 2.0, np.where(kinds == 3, 1.0, np.inf)))
    cub = np.zeros(n)
    order = list(rng.permutation(n))
    info = {f: [] for f in ALL_FEATS}

    def take(k):
        out = [int(order.pop()) for _ in range(k)] if len(order) >= k else None
        return out

    def clear_row(i, keep=()):
        for j in list(M.rows[i]):
            if j not in keep:
                M[i, j] = 0.0

    def clear_col(j, keep=()):
        for i in range(n):
            if i not in keep and M[i, j] != 0:
                M[i, j] = 0.0

    for f in feats:
        if f == "fixed":
            for _ in range(2):
                t = take(1)
                if t:
                    j = t[0]
                    lb[j] = ub[j] = rng.uniform(-1, 1)
                    info[f].append(j)
        elif f == "singleton_diag":
            t = take(1)
            if t:
                clear_row(t[0], keep=(t[0],))
                info[f].append(t[0])
        elif f == "singleton_off":
            t = take(2)
            if t:
                i, j = t
                clear_row(i), clear_col(i)
                clear_row(j, keep=(j,))
                M[j, i] = 5.0
                M[i, j] = -5.0
                lb[i], ub[i] = -np.inf, np.inf
                lb[j], ub[j] = 0.0, np.inf
                q[i] = 5.0 * 0.7  # z_j = 0.7
                info[f].append((i, j))
        elif f == "col_singleton":
            t = take(1)
            if t:
                clear_col(t[0], keep=(t[0],))
                info[f].append(t[0])
        elif f == "free_col_singleton":
            t = take(2)
            if t:
                i, k = t
                clear_col(k), clear_row(k), clear_col(i, keep=(i,))
                M[i, k] = 3.0
                M[k, i] = -3.0
                lb[[i, k]], ub[[i, k]] = -np.inf, np.inf
                info[f].append((i, k))
        elif f == "empty_row":
            t = take(1)
            if t:
                i = t[0]
                clear_row(i)
                q[i] = 1.0
                lb[i] = 0.0 if not np.isfinite(lb[i]) else lb[i]
                info[f].append(i)
        elif f == "range":
            t = take(1)
            if t:
                i = t[0]
                for j in list(M.rows[i]):
                    M[i, j] = abs(M[i, j]) if lb[j] == 0 and j != i else 0.0
                M[i, i] = 4.0
                lb[i], ub[i] = 0.0, np.inf
                q[i] = 0.5
                info[f].append(i)
        elif f == "forcing":
            t = take(3)
            if t:
                p, j1, j2 = t  # row p: -(z_j1 + 2 z_j2) >= 0 forced, z_j >= 0
                clear_row(p), clear_col(p)
                for j, a in ((j1, 1.0), (j2, 2.0)):
                    lb[j], ub[j] = 0.0, np.inf
                    M[p, j] = -a
                    M[j, p] = a
                lb[p], ub[p] = 0.0, np.inf
                q[p] = 0.0
                info[f].append((p, j1, j2))
        elif f == "duplicate":
            t = take(3)
            if t:
                y1, y2, x = t  # F_y1 = z_x - 1 >= 0, F_y2 = 2 z_x - 1 (weaker: delta = 1)
                clear_row(y1), clear_col(y1), clear_row(y2), clear_col(y2)
                lb[[y1, y2, x]], ub[[y1, y2, x]] = 0.0, np.inf
                M[y1, x], M[x, y1] = 1.0, -1.0
                M[y2, x], M[x, y2] = 2.0, -2.0
                q[y1], q[y2] = -1.0, -1.0
                info[f].append((y1, y2, x))
        elif f == "cubic":
            t = take(2)
            if t:
                for j in t:
                    cub[j] = 0.5
                    info[f].append(j)
        elif f == "empty_col":
            t = take(1)
            if t:
                j = t[0]
                clear_col(j)
                lb[j], ub[j] = -1.0, 1.0
                info[f].append(j)
    M = sp.csc_matrix(M)
    x0 = np.clip(rng.normal(size=n), lb, ub)
    return linear_mcp(M, q, lb, ub, x0=x0, cubic=cub), info
