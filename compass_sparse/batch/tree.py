"""The scenario tree: every scenario's parent is a near neighbour in parameter space
(parameters scaled to [0, 1] by their range) -- a comb for a Cartesian grid (branches along
its longest axis hanging from a spine along the others), the minimum spanning tree of the
nearest-neighbour graph otherwise -- and its cut into paths of at most ``chunk_size``
scenarios, one task each."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import (breadth_first_order, connected_components,
                                  minimum_spanning_tree)
from scipy.spatial import cKDTree

__all__ = ["paths", "scenario_tree"]


# ---------------------------------------------------------------------------- the tree
def _param_matrix(scenarios):
    """(N, d) float matrix of the scalar parameters scaled to [0, 1], or None when some
    parameter is not a number."""
    names = sorted({k for s in scenarios for k in s})
    try:
        P = np.array([[float(s.get(k, np.nan)) for k in names] for s in scenarios], float)
    except (TypeError, ValueError):
        return None
    if P.size == 0 or not np.all(np.isfinite(P)):
        return None
    lo, hi = P.min(axis=0), P.max(axis=0)
    keep = hi > lo
    return (P[:, keep] - lo[keep]) / (hi[keep] - lo[keep])


def scenario_tree(scenarios) -> np.ndarray:
    """parent[i] of every scenario in the warm-start tree (-1 at the root); see the module
    docstring.  Non-numeric parameters: a chain in the given order."""
    N = len(scenarios)
    parent = np.full(N, -1, dtype=np.int64)
    if N <= 1:
        return parent
    P = _param_matrix(scenarios)
    if P is None:
        parent[1:] = np.arange(N - 1)
        return parent
    if P.shape[1] == 0:  # all scenarios equal: a star around the first
        parent[1:] = 0
        return parent
    uniq = [np.unique(P[:, a]) for a in range(P.shape[1])]
    coords = np.column_stack([np.searchsorted(u, P[:, a]) for a, u in enumerate(uniq)])
    lengths = np.array([u.size for u in uniq])
    if (np.prod(lengths.astype(float)) == N
            and len({tuple(c) for c in coords.tolist()}) == N):
        return _comb_tree(coords, lengths)
    return _mst_tree(P)


def _comb_tree(coords, lengths):
    """Branches along the longest axis, hanging from a spine along the next, and so on."""
    order = np.argsort(-lengths, kind="stable")
    index = {tuple(c): i for i, c in enumerate(coords.tolist())}
    parent = np.full(len(coords), -1, dtype=np.int64)
    for i, c in enumerate(coords.tolist()):
        for a in order:
            if c[a] > 0:
                p = list(c)
                p[a] -= 1
                parent[i] = index[tuple(p)]
                break
    return parent


def _mst_tree(P):
    """Minimum spanning tree of the k-nearest-neighbour graph (components joined in
    order), rooted at scenario 0."""
    N = P.shape[0]
    k = min(N - 1, 10)
    dist, nb = cKDTree(P).query(P, k=k + 1)
    rows = np.repeat(np.arange(N), k)
    # +1e-12: csgraph drops zero weights, and equal scenarios are neighbours too.
    W = sp.csr_matrix((dist[:, 1:].ravel() + 1e-12, (rows, nb[:, 1:].ravel())), shape=(N, N))
    W = W.maximum(W.T)
    ncomp, lab = connected_components(W, directed=False)
    if ncomp > 1:
        firsts = [int(np.flatnonzero(lab == c)[0]) for c in range(ncomp)]
        extra = sp.csr_matrix((np.ones(ncomp - 1), (firsts[:-1], firsts[1:])), shape=(N, N))
        W = W + extra + extra.T
    T = minimum_spanning_tree(W)
    T = T + T.T
    _, pred = breadth_first_order(T, 0, directed=False, return_predecessors=True)
    parent = np.asarray(pred, dtype=np.int64)
    parent[parent < 0] = -1
    return parent


def paths(parent, todo, chunk_size):
    """Cut the tree restricted to ``todo`` into paths of at most chunk_size nodes, each
    following its largest subtree; returns [(nodes, subtree size of the head)]."""
    todo_set = {int(i) for i in todo}
    children = {i: [] for i in todo_set}
    for i in sorted(todo_set):
        p = int(parent[i])
        if p in todo_set:
            children[p].append(i)
    heads = [i for i in sorted(todo_set) if int(parent[i]) not in todo_set]
    size = {}
    stack = list(heads)
    order = []
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(children[i])
    for i in reversed(order):
        size[i] = 1 + sum(size[c] for c in children[i])
    out = []
    queue = list(heads)
    while queue:
        h = queue.pop()
        path, cur = [h], h
        while children[cur]:
            kids = sorted(children[cur], key=lambda c: (-size[c], c))
            queue.extend(kids[1:])
            if len(path) == chunk_size:
                queue.append(kids[0])
                break
            cur = kids[0]
            path.append(cur)
        out.append((path, size[h]))
    return out
