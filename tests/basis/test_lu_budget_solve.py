"""A solve stops with TIME_LIMIT / MEMORY_LIMIT instead of starting a factorization its
symbolic estimate says cannot finish or fit; the Result reports the LU figures.

The budget of the basis manager's factorizations is tested on its route (path_basis
"sparse"; the automatic route gives this problem, 5 Jacobian entries per column, to the
sparse engine); the sparse engine, whose LU has no symbolic estimate, checks the storage
of its factors against the memory budget and reports its own figures."""

import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse.basis import backends
from compass_sparse.generators import structured_quadratic
from compass_sparse.status import Status

pytestmark = pytest.mark.usefixtures("lu_choice")


@pytest.fixture
def problem():
    # above the direct step's orders (2000): its factorizations and the crash's go
    # through the budgeted sparse LU (smaller sparse blocks are factored by KLU, without
    # an estimate, whatever their factorizations would cost)
    g = structured_quadratic(2100, seed=3)
    return g


def _natural(res, p):
    f = p.F(res.x)
    return float(np.abs(res.x - np.clip(res.x - f, p.lb, p.ub)).max())


MANAGER = {"path_basis": "sparse"}


def test_solve_reports_lu_estimates_and_peak_memory(problem, lu_choice):
    res = cs.solve_mcp(problem.problem, options=MANAGER)
    assert res.status is Status.SOLVED and _natural(res, problem.problem) <= 1e-6
    lu = res.lu
    assert lu["max_nnz_lu"] > 0 and lu["peak_rss_bytes"] > 0
    if lu["ordering"] in ("amd", "metis"):
        assert lu["est_nnz_lu"] >= 0 and lu["est_bytes"] > 0 and lu["est_flops"] > 0


def test_solve_stops_with_time_limit_before_a_factorization_that_cannot_finish(
        problem, monkeypatch, lu_choice):
    monkeypatch.setattr(backends, "FLOP_RATE", 1e-3)     # every factorization 'too slow'
    res = cs.solve_mcp(problem.problem, options={"time_limit": 3600, **MANAGER})
    if lu_choice in ("superlu:colamd", "umfpack"):
        # no symbolic estimate under these orderings: the check cannot fire
        assert res.status is Status.SOLVED
        return
    assert res.status is Status.TIME_LIMIT and "not started" in res.message
    assert res.x is not None and np.all(np.isfinite(res.x))
    assert res.time < 3600


def test_solve_stops_with_memory_limit_when_the_factors_would_not_fit(
        problem, monkeypatch, lu_choice):
    monkeypatch.setattr(backends.FactorBudget, "available_memory", staticmethod(lambda: 1e3))
    res = cs.solve_mcp(problem.problem, options=MANAGER)
    if lu_choice in ("superlu:colamd", "umfpack"):
        assert res.status is Status.SOLVED
        return
    assert res.status is Status.MEMORY_LIMIT and res.status.path_code() == 10
    assert "GiB" in res.message and np.all(np.isfinite(res.x))


def test_the_sparse_engine_reports_its_factors(problem, lu_choice):
    """The sparse engine's route left Result.lu empty (backend '', max_nnz_lu 0)."""
    if lu_choice != "auto":
        pytest.skip("a chosen LU keeps the paths on the basis manager")
    res = cs.solve_mcp(problem.problem)
    assert res.routes["path"] == "sparse engine"
    assert res.status is Status.SOLVED and _natural(res, problem.problem) <= 1e-6
    lu = res.lu
    assert (lu["backend"], lu["ordering"]) == ("sparse engine", "matching, minimum degree")
    assert lu["max_nnz_lu"] >= problem.problem.n and lu["peak_rss_bytes"] > 0


def test_the_sparse_engine_stops_with_memory_limit_when_its_factors_would_not_fit(
        problem, monkeypatch, lu_choice):
    """The sparse engine allocated its factors' storage (and doubled it) without a
    budget: a basis whose factors could not fit would have exhausted the memory."""
    if lu_choice != "auto":
        pytest.skip("a chosen LU keeps the paths on the basis manager")
    monkeypatch.setattr(backends.FactorBudget, "available_memory", staticmethod(lambda: 1e3))
    res = cs.solve_mcp(problem.problem)
    assert res.routes["path"] == "sparse engine"
    assert res.status is Status.MEMORY_LIMIT and "sparse engine" in res.message
    assert "GiB" in res.message and np.all(np.isfinite(res.x))


def test_a_chosen_lu_keeps_the_paths_on_the_basis_manager(problem, lu_choice):
    """lu_backend / lu_ordering (or COMPASS_SPARSE_LU) did nothing on the sparse engine's
    route: the engine has its own LU."""
    res = cs.solve_mcp(problem.problem, options={"lu_backend": "superlu", "lu_ordering": "amd"})
    assert res.routes["path"] == "sparse basis" and res.lu["ordering"] == "amd"
    assert res.status is Status.SOLVED and _natural(res, problem.problem) <= 1e-6
    if lu_choice == "auto":
        assert cs.solve_mcp(problem.problem).routes["path"] == "sparse engine"
    else:
        assert cs.solve_mcp(problem.problem).routes["path"] == "sparse basis"


def test_available_memory_is_read_at_most_every_max_age(monkeypatch):
    """The memory budget's reading of /proc/meminfo is reused for MEMINFO_MAX_AGE
    seconds, then read again."""
    import builtins

    backends._MEMINFO.clear()
    clock = [100.0]
    monkeypatch.setattr(backends.time, "monotonic", lambda: clock[0])
    opened = []
    real_open = builtins.open

    def spy(path, *a, **kw):
        opened.append(path)
        return real_open(path, *a, **kw)

    monkeypatch.setattr(builtins, "open", spy)
    first = backends.FactorBudget.available_memory()
    clock[0] += 0.5 * backends.MEMINFO_MAX_AGE
    assert backends.FactorBudget.available_memory() == first
    reads = opened.count("/proc/meminfo")
    assert reads == 1
    clock[0] += backends.MEMINFO_MAX_AGE
    backends.FactorBudget.available_memory()
    assert opened.count("/proc/meminfo") == reads + 1
