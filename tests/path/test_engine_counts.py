"""The sparse engine's count of the factor entries its pivots read (``BasisStats.
pivot_lu_entries``, ``Result.lu["pivot_lu_entries"]``): for each pivot, the entries of
L + U (with the updates' columns and row etas) held when its FTRAN runs, summed."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import Options, solve_mcp
from compass_sparse.path import _path_kernels as K
from compass_sparse.path import engine as E
from compass_sparse.path import _sparse_lu as SL
from compass_sparse.path.pivotal import PivotalPath
from compass_sparse.path.sparse_engine import SparsePathEngine


def _held(S):
    h = S[0]
    return int(h[SL.H_NNZL] + h[SL.H_NNZU] + h[SL.H_NNZR])


def test_the_engine_counts_the_factor_entries_each_pivot_reads(monkeypatch):
    """With one pivot a chunk, each chunk adds the entries the factors held before it (as
    read between chunks), the first pivot's included in the path's start; the basis'
    stats hold the path's sum, and a solve's result reports it."""
    M, q, lb, ub = gen.p_matrix_lcp(400, "grid", 0).lcp
    M = sp.csc_matrix(M)
    x = np.clip(np.zeros(q.size), lb, ub)
    PivotalPath(M, q, lb, ub, SparsePathEngine(M), Options()).run(x)  # (loads the kernels)
    start, chunks = [], []
    run_pivots, start_path = K.run_pivots, K.start_path

    def counted_start(kind, prob, tab, state, D, S, *a):
        out = start_path(kind, prob, tab, state, D, S, *a)
        start.append((int(state[0][K.I_PIV]), int(state[0][K.I_LUSUM])))
        return out

    def counted_chunk(kind, prob, tab, state, D, S, *a):
        istate = state[0]
        held, sum0, piv0 = _held(S), int(istate[K.I_LUSUM]), int(istate[K.I_PIV])
        out = run_pivots(kind, prob, tab, state, D, S, *a)
        chunks.append((int(istate[K.I_PIV]) - piv0, int(istate[K.I_LUSUM]) - sum0, held))
        return out

    monkeypatch.setattr(E.K, "start_path", counted_start)
    monkeypatch.setattr(E.K, "run_pivots", counted_chunk)
    engine = SparsePathEngine(M)
    engine.chunk = 1
    res = PivotalPath(M, q, lb, ub, engine, Options()).run(x)
    assert res.pivots > 20 and len(start) == 1 and start[0][0] == 1
    for pivots, added, held in chunks:
        assert added in (0, held) and (pivots == 0 or added == held), (pivots, added, held)
    assert sum(p for p, _, _ in chunks) == res.pivots - 1
    total = start[0][1] + sum(a for _, a, _ in chunks)
    assert total > 0 and engine.stats.pivot_lu_entries == total

    result = solve_mcp(gen.traffic_equilibrium(4).problem,
                       options=dict(path_basis="sparse engine"))
    assert result.success and result.minor_iterations > 0
    assert result.lu["pivot_lu_entries"] > 0
