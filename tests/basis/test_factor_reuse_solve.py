"""Option factor_reuse end to end: the pivotal path and solve_mcp on reused factors give
the answers of fresh factorizations, and a path whose reused basis is singular starts
again on fresh factors."""

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import Options, Status, solve_mcp
from compass_sparse.basis import BasisManager, BasisOptions
from compass_sparse.path.outcome import LinearCode
from compass_sparse.path.pivotal import PivotalPath


def _interior_lcp(n, seed):
    """A linear MCP with wide bounds whose solution is interior: the path from the
    interior start ends with 0 pivots, every z basic (the Newton steps of the CGE models)."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.02, random_state=seed, format="csc")
    M = sp.csc_matrix(A + sp.diags(np.abs(A).sum(axis=1).A.ravel() + 2.0))
    z_star = rng.uniform(-1.0, 1.0, n)
    q = -(M @ z_star)
    lb, ub = np.full(n, -10.0), np.full(n, 10.0)
    return M, q, lb, ub, z_star


def _path(M, q, lb, ub, bm, x, warm=None):
    return PivotalPath(M, q, lb, ub, bm, Options()).run(x, warm=warm)


def test_path_on_reused_factors_agrees_with_fresh():
    M, q, lb, ub, z_star = _interior_lcp(400, 0)
    bm = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0))
    x0 = np.zeros(M.shape[0])
    r1 = _path(M, q, lb, ub, bm, x0)
    assert r1.code is LinearCode.SOLVED and r1.pivots == 0
    M2 = M.copy()
    M2.data = M2.data * (1.0 + 1e-3 * np.cos(np.arange(M2.nnz)))   # the next "Jacobian"
    q2 = -(M2 @ z_star)
    bm.set_matrix(M2)
    r2 = _path(M2, q2, lb, ub, bm, x0, warm=r1.basis)
    assert bm.stats.reuses == 1 and bm.stats.factorizations == 1
    fresh = _path(M2, q2, lb, ub, BasisManager(M2), x0, warm=r1.basis)
    assert r2.code is fresh.code is LinearCode.SOLVED
    assert np.abs(r2.z - fresh.z).max() <= 1e-10 * (1 + np.abs(fresh.z).max())
    assert np.abs(r2.z - z_star).max() <= 1e-9


def test_path_whose_reused_basis_is_singular_restarts_on_fresh_factors():
    M, q, lb, ub, _ = _interior_lcp(400, 1)
    bm = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0))
    x0 = np.zeros(M.shape[0])
    r1 = _path(M, q, lb, ub, bm, x0)
    M2 = M.copy()
    M2.data[M2.indptr[7]:M2.indptr[8]] = 0.0        # column 7 vanishes: B singular
    bm.set_matrix(M2)
    r2 = _path(M2, q, lb, ub, bm, x0, warm=r1.basis)
    fresh = _path(M2, q, lb, ub, BasisManager(M2), x0, warm=r1.basis)
    # the fallback's factorization found the singularity, the path's restart repaired it
    assert bm.stats.reuse_fallbacks == 1 and bm.stats.rank_repairs == 2
    assert bm.stats.factorizations == 3 and r2.factorizations == 2
    assert r2.code is fresh.code
    assert np.allclose(r2.z, fresh.z, rtol=0, atol=1e-9)


@pytest.mark.parametrize("shock", [dict(output_tax=0.0), dict(tariff=(0, 0.25))])
def test_solve_with_factor_reuse_agrees_with_fresh_factorizations(shock):
    from compass_sparse.generators.cge import static_cge

    m = static_cge(regions=6, sectors=30, factors=2, households=2, seed=1).with_shock(**shock)
    p = m.problem
    a = solve_mcp(p, options={"factor_reuse": True})
    b = solve_mcp(p, options={"factor_reuse": False})
    assert a.status is b.status is Status.SOLVED
    assert a.lu["reuses"] >= 1 and b.lu["reuses"] == 0
    assert a.factorizations < b.factorizations
    assert np.abs(a.x - b.x).max() <= 1e-8 * (1 + np.abs(b.x).max())
    z = a.x
    f = m.F(z)
    assert np.abs(z - np.clip(z - f, p.lb, p.ub)).max() <= 1e-6


def test_factor_reuse_does_not_stall_the_ramsey_model_above_the_acceptance_test(monkeypatch):
    """With a reuse backward-error tolerance of 1e-12 the Newton iterates of the one-sector
    Ramsey model (n = 2703, 25% capital tax) stalled at a residual of 4e-9 that the
    acceptance test rejects; the solve failed after 50 restarts and the homotopy (89 s)
    where fresh factors take 3 major iterations.  The reuse is forced here below its
    minimum fill so that every Newton step after the first runs on reused factors."""
    import compass_sparse.basis.types as types
    from compass_sparse.generators.cge import ramsey_cge

    init = types.BasisOptions.__init__

    def forced(self, *a, **k):
        k.setdefault("reuse_min_nnz", 0)
        init(self, *a, **k)

    monkeypatch.setattr(types.BasisOptions, "__init__", forced)
    m = ramsey_cge(periods=300, sectors=1).with_shock(capital_tax=0.25)
    p = m.problem
    # (factor reuse is the basis manager's: its route, not the sparse engine's)
    r = solve_mcp(p, options={"factor_reuse": True, "restart_limit": 0, "homotopy": "off",
                              "major_iteration_limit": 8, "path_basis": "sparse"})
    assert r.status is Status.SOLVED and r.nit <= 4
    assert r.lu["reuses"] >= 1
    z = r.x
    assert np.abs(z - np.clip(z - m.F(z), p.lb, p.ub)).max() <= 1e-6


def test_small_factors_are_not_reused():
    # below reuse_min_nnz entries in L + U a fresh factorization is the cheaper solve
    from compass_sparse.generators.cge import ramsey_cge

    p = ramsey_cge(periods=110, sectors=1).with_shock(capital_tax=0.25).problem
    r = solve_mcp(p, options={"factor_reuse": True})
    assert r.status is Status.SOLVED and r.lu["max_nnz_lu"] < 50000
    assert r.lu["reuses"] == 0
