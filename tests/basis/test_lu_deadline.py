"""Orderings and factorizations under a deadline (compass_sparse.basis.ordering, "Time";
compass_sparse.basis.backends, "Budget"): no ordering is started past the deadline, METIS
is passed over where it cannot pay for itself or would not fit in the time left, AMD where
it would not fit, an ordering made for lack of time is not kept, and a factorization is
timed by its columns as well as its flops.  The costs are the modules' predictions (made
larger or smaller here by patching their constants); no test reads the wall clock."""

import time
from collections import OrderedDict

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.basis import backends
from compass_sparse.basis import ordering as ordmod
from compass_sparse.basis.krylov import preconditioned_gmres
from compass_sparse.exceptions import FactorBudgetError


def tridiagonal(n):
    """A diagonally dominant tridiagonal block (AMD orders it without fill)."""
    rng = np.random.default_rng(n)
    K = sp.diags([rng.uniform(-1, 1, n - 1), 3.0 + rng.uniform(0, 1, n),
                  rng.uniform(-1, 1, n - 1)], [-1, 0, 1], format="csc")
    K.sort_indices()
    return K


def grid3(m):
    """The 7-point Laplacian of an m x m x m grid: its LU fills, nested dissection pays."""
    T = sp.diags([-np.ones(m - 1), 6.0 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    return sp.csc_matrix(sp.kronsum(sp.kronsum(T, T), T))


@pytest.fixture(autouse=True)
def fresh_orderings(monkeypatch):
    """Each test orders its patterns afresh (the orderings are shared by the process)."""
    monkeypatch.setattr(ordmod, "_SHARED", OrderedDict())
    monkeypatch.setattr(ordmod, "_NEAR", [])


def spy(monkeypatch, module, name):
    calls = []
    real = getattr(module, name)

    def wrapper(*args, **kwargs):
        calls.append(args[0].shape)
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, wrapper)
    return calls


def test_an_ordering_is_not_started_past_the_deadline(monkeypatch):
    """Past the deadline a factorization is refused before its ordering is computed.  The
    old code computed the ordering first (METIS took 12.7 s on a block of order 7e5 in
    the crash of a 1 s solve) and only then refused the factorization."""
    computed = spy(monkeypatch, ordmod, "compute_ordering")
    K = tridiagonal(3000)
    b = backends.SuperLUBackend("auto", budget=backends.FactorBudget(
        deadline=time.perf_counter() - 1.0))
    with pytest.raises(FactorBudgetError) as e:
        b.solve(K, np.ones(3000))
    assert e.value.kind == "time" and computed == []


def test_metis_is_passed_over_on_a_banded_pattern_and_kept_where_it_pays(monkeypatch):
    """METIS is computed only where it can pay for itself: its predicted cost below that
    of the factorization under AMD.  The old code ran it on every block of order >= 2000:
    2.5 s on a tridiagonal block of order 7e5 that AMD orders without fill (its
    factorization 0.7 s).  On a 3-D grid, whose factorization fills, it is still computed
    and kept when its estimate is the cheaper."""
    metis = spy(monkeypatch, ordmod, "metis_order")
    cache = backends.SuperLUBackend("auto").orderings
    o = cache.get(tridiagonal(5000))
    assert o.method == "amd" and metis == [] and "cost more" in o.passed_over
    G = grid3(16)
    o = cache.get(G)
    S = ordmod.symmetrized(G)[0]
    amd_flops = ordmod.cholesky_estimate(S, ordmod.amd_order(S))[1]
    assert metis == [S.shape] and o.passed_over == ""
    assert o.method == "metis" and o.flops < amd_flops


def test_metis_is_passed_over_when_it_and_the_factorization_do_not_fit_the_time_left(
        monkeypatch):
    """With 30 s left and a factorization predicted at hours (a slow flop rate), METIS is
    not computed (AMD is taken), and that ordering, made for lack of time, is not kept:
    without a deadline the pattern is ordered afresh, and METIS chosen.  The old code
    computed METIS whatever the time left."""
    metis = spy(monkeypatch, ordmod, "metis_order")
    cache = backends.SuperLUBackend("auto").orderings
    G = grid3(16)
    monkeypatch.setattr(backends, "FLOP_RATE", 1e4)
    o = cache.get(G, deadline=time.perf_counter() + 30.0)
    assert o.method == "amd" and o.hurried and "left" in o.passed_over and metis == []
    monkeypatch.setattr(backends, "FLOP_RATE", 2e9)
    o = cache.get(G)
    assert cache.computed == 2 and cache.reused == 0
    assert o.method == "metis" and not o.hurried and len(metis) == 1


def test_amd_is_passed_over_for_colamd_when_it_does_not_fit(monkeypatch):
    """An automatic ordering whose AMD (predicted here at 1 s per entry) cannot finish in
    the 30 s left is COLAMD's, which SuperLU computes inside the factorization; an
    ordering the user chose (``amd``) is not replaced: it is not started.  The old code
    computed AMD whatever the time left."""
    monkeypatch.setattr(ordmod, "AMD_SECONDS_PER_ENTRY", 1.0, raising=False)
    amd = spy(monkeypatch, ordmod, "amd_order")
    K = tridiagonal(20000)
    deadline = time.perf_counter() + 30.0
    o = backends.SuperLUBackend("auto").orderings.get(K, deadline=deadline)
    assert o.method == "colamd" and o.hurried and amd == []
    with pytest.raises(FactorBudgetError, match="not started: amd"):
        backends.SuperLUBackend("amd").orderings.get(K, deadline=deadline)
    assert amd == []


def test_a_factorization_that_fills_little_is_timed_by_its_columns(monkeypatch):
    """A factorization's predicted time counts its columns, not only its flops, and COLAMD
    (which has no symbolic estimate) is timed by them too: with 1 ms per column a block of
    order 20000 needs 20 s and is not started with 5 s left.  The old code timed by flops
    alone, and COLAMD not at all: a tridiagonal block of order 7e5 (3.5e6 flops) was
    predicted at 2 ms and took 0.74 s."""
    monkeypatch.setattr(backends, "FACTOR_SECONDS_PER_COLUMN", 1e-3, raising=False)
    K = tridiagonal(20000)
    for ordering in ("colamd", "amd"):
        b = backends.SuperLUBackend(ordering, budget=backends.FactorBudget(
            deadline=time.perf_counter() + 5.0))
        with pytest.raises(FactorBudgetError, match="about 20 s"):
            b.solve(K, np.ones(20000))
    monkeypatch.setattr(backends, "FACTOR_SECONDS_PER_COLUMN", 1e-6)
    b = backends.SuperLUBackend("colamd", budget=backends.FactorBudget(
        deadline=time.perf_counter() + 5.0))
    x = b.solve(K, np.ones(20000))
    assert np.abs(K @ x - 1.0).max() <= 1e-12


def test_gmres_starts_no_step_after_the_deadline():
    """GMRES on held factors (the crash's inexact steps) stops at the deadline: past it no
    Krylov step is made.  The old code had no deadline: up to 40 steps, each a solve with
    factors of order 7e5 at n = 1e6."""
    rng = np.random.default_rng(3)
    n = 200
    B = sp.csc_matrix(sp.identity(n) * 4.0 + sp.random(n, n, density=0.05, random_state=rng))
    b = rng.standard_normal(n)
    _, steps, _ = preconditioned_gmres(lambda v: B @ v, lambda v: v / 4.0, b, 1e-12, 40,
                                       deadline=time.perf_counter() - 1.0)
    assert steps == 0
    x, steps, _ = preconditioned_gmres(lambda v: B @ v, lambda v: v / 4.0, b, 1e-12, 40,
                                       deadline=time.perf_counter() + 600.0)
    assert steps > 0 and np.linalg.norm(B @ x - b) <= 1e-10 * np.linalg.norm(b)
