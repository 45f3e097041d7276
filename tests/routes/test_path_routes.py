"""The compiled dense engine (compass_sparse.path.dense_engine) against the Python pivot
loop on the dense reference basis (compass_sparse.path.pivotal with basis.dense): the same
algorithm, so the same codes, pivots and points, on random, degenerate, rank-deficient
and infeasible linear MCPs, at the limits, and through solve_lcp and solve_mcp."""

from __future__ import annotations

import numpy as np
import pytest

import compass_sparse.generators as gen
from compass_sparse import MCP, Options, solve_lcp, solve_mcp
from compass_sparse.basis.dense import DenseBasis
from compass_sparse.path.dense_engine import DensePathEngine
from compass_sparse.path.outcome import LinearCode
from compass_sparse.path.pivotal import PivotalPath


def _both(lcp, x=None, options=None, **kw):
    M, q, lb, ub = lcp
    x = np.clip(np.zeros(q.size), lb, ub) if x is None else x
    opt = options or Options()
    out = []
    for mgr in (DenseBasis, DensePathEngine):
        res = PivotalPath(M, q, lb, ub, mgr(M), opt).run(x, **kw)
        out.append(res)
    return out


def _assert_same_path(py, cc, M, q):
    assert cc.code is py.code, (py.code, cc.code, py.message, cc.message)
    assert cc.message == py.message
    assert cc.pivots == py.pivots
    assert cc.artificials == py.artificials
    assert abs(cc.t - py.t) <= 1e-9
    scale = 1.0 + np.abs(py.z).max(initial=0.0)
    assert np.max(np.abs(cc.z - py.z), initial=0.0) <= 1e-8 * scale
    assert np.array_equal(cc.basis.basic, py.basis.basic)
    assert cc.unbounded == py.unbounded
    if py.unbounded:  # the same ray: base point and direction of z
        assert np.allclose(cc.ray_base, py.ray_base, rtol=1e-8, atol=1e-8)
        assert np.allclose(cc.ray, py.ray, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("structure", ["grid", "banded"])
@pytest.mark.parametrize("bounds", ["ncp", "box", "mixed"])
@pytest.mark.parametrize("n,seed", [(12, 0), (45, 1), (100, 2)])
def test_same_path_as_python_loop_on_p_matrix_lcps(structure, bounds, n, seed):
    g = gen.p_matrix_lcp(n, structure, seed, bounds)
    py, cc = _both(g.lcp)
    _assert_same_path(py, cc, *g.lcp[:2])
    assert cc.code is LinearCode.SOLVED
    assert np.max(np.abs(cc.z - g.solution)) <= 1e-8


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("ray_start", [False, True])
def test_same_path_on_degenerate_and_rank_deficient_lcps(seed, ray_start):
    for g in (gen.obstacle_problem(8, seed, degenerate_fraction=0.5),
              gen.monotone_lcp(30, seed, rank=10),
              gen.duplicated_columns_lcp(40, seed, bounds="mixed")):
        py, cc = _both(g.lcp, ray_start=ray_start)
        _assert_same_path(py, cc, *g.lcp[:2])


@pytest.mark.parametrize("seed", [0, 1])
def test_same_status_on_infeasible_lcp(seed):
    g = gen.infeasible_lcp(20, seed)
    py, cc = _both(g.lcp, ray_start=True)
    _assert_same_path(py, cc, *g.lcp[:2])
    assert cc.code is LinearCode.RAY


def test_same_limits_cycle_and_minor():
    g = gen.p_matrix_lcp(60, "grid", 5, "mixed")
    for opt in (Options(lemke_cycle_limit=1), Options(minor_iteration_limit=3)):
        py, cc = _both(g.lcp, options=opt)
        _assert_same_path(py, cc, *g.lcp[:2])


def test_solves_agree_with_and_without_the_engine(monkeypatch):
    """solve_lcp and solve_mcp give the same statuses and points with the compiled engine
    and with the Python loop on the dense reference basis (option path_basis)."""
    cases = [gen.p_matrix_lcp(40, "banded", 3, "mixed"), gen.obstacle_problem(7, 2),
             gen.duplicated_columns_lcp(30, 1, bounds="box")]
    points = {}
    for basis in ("auto", "dense"):
        opt = {"path_basis": basis}
        points[basis] = []
        for g in cases:
            M, q, lb, ub = g.lcp
            r = solve_lcp(M, q, lb, ub, options=opt)
            assert r.routes["path"] == ("dense engine" if basis == "auto" else "dense basis")
            assert r.success, r.message
            points[basis].append(r.x)
            Md = M.toarray()

            def F(z, Md=Md, q=q):
                return Md @ z + q + 0.1 * z**3 * (z > 0)

            def J(z, Md=Md):
                return Md + np.diag(0.3 * z**2 * (z > 0))

            rm = solve_mcp(MCP(F, J, lb, ub, np.clip(np.zeros(q.size), lb, ub)), options=opt)
            assert rm.success, rm.message
            points[basis].append(rm.x)
    for a, b in zip(points["dense"], points["auto"]):
        assert np.max(np.abs(a - b)) <= 1e-6 * (1 + np.abs(b).max())


@pytest.mark.parametrize("kw", [{"growth_limit": 1.0}, {"stability_tolerance": 0.0},
                                {"growth_limit": 1e300, "stability_tolerance": 1.0}])
def test_same_path_whatever_the_update_safeguards_decline(kw):
    """The Forrest-Tomlin safeguards only choose between an update and a refactorization:
    declining (almost) every update, or none, leaves the path pivot for pivot that of the
    Python loop."""
    for g in (gen.p_matrix_lcp(60, "banded", 4, "mixed"),
              gen.duplicated_columns_lcp(40, 2, bounds="mixed")):
        M, q, lb, ub = g.lcp
        x = np.clip(np.zeros(q.size), lb, ub)
        py = PivotalPath(M, q, lb, ub, DenseBasis(M), Options()).run(x)
        eng = DensePathEngine(M, **kw)
        cc = PivotalPath(M, q, lb, ub, eng, Options()).run(x)
        _assert_same_path(py, cc, M, q)
        if kw.get("growth_limit") == 1.0 and py.pivots > 20:
            assert eng.stats.refactor_by_stability > 0
