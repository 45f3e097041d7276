"""The compiled sparse engine (compass_sparse.path.sparse_engine) against the Python pivot
loop on the sparse basis manager (the reference route, engine='reference'): the same
algorithm, so the same entering and leaving variables pivot for pivot, the same codes and
counts, and points equal to rounding -- on random sparse LCPs, degenerate and
rank-deficient ones (repair), infeasible ones (rays), at the cycle and minor limits, with
every update declined, from degenerate start vertices (t below 0), and on the paths of
whole solves of real problems (traffic, CGE, obstacle, thesis families)."""

from __future__ import annotations


import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import Options, solve_mcp
from compass_sparse.basis import BasisManager
from compass_sparse.path.outcome import LinearCode
from compass_sparse.path.pivotal import PivotalPath
from compass_sparse.path.sparse_engine import SparsePathEngine
from minor_log import pivots_without_t

def _both(lcp, x=None, options=None, engine_kw=None, **kw):
    M, q, lb, ub = lcp
    M = sp.csc_matrix(M)
    x = np.clip(np.zeros(q.size), lb, ub) if x is None else x
    opt = options or Options()
    out = []
    for make in (BasisManager, lambda A: SparsePathEngine(A, **(engine_kw or {}))):
        log = []
        res = PivotalPath(M, q, lb, ub, make(M), opt, log=log.append).run(x, **kw)
        out.append((res, pivots_without_t(log)))
    return out


def _assert_same_path(both, M, q, lb=None, ub=None):
    """The same pivots, codes, counts and points (to rounding), and the same basis --
    but where the two points hold z_i at a bound to rounding (``lb``, ``ub`` given): a
    path whose t never rose above rounding returns the point of largest t, which
    rounding decides, and a z_i at lb + 1e-17 in one of them is basic there while the
    other's z_i <= lb makes w_i basic."""
    (py, lpy), (cc, lcc) = both
    assert lcc == lpy
    assert cc.code is py.code, (py.code, cc.code, py.message, cc.message)
    assert cc.message == py.message
    assert cc.pivots == py.pivots
    assert cc.artificials == py.artificials
    assert abs(cc.t - py.t) <= 1e-9
    scale = 1.0 + np.abs(py.z).max(initial=0.0)
    assert np.max(np.abs(cc.z - py.z), initial=0.0) <= 1e-8 * scale
    differ = np.flatnonzero(cc.basis.basic != py.basis.basic)
    if differ.size:
        assert lb is not None and max(abs(cc.t), abs(py.t)) <= 1e-12, differ
        for z in (cc.z, py.z):
            gap = np.minimum(np.abs(z[differ] - lb[differ]), np.abs(z[differ] - ub[differ]))
            assert np.all(gap <= 1e-12 * (1.0 + np.abs(z[differ]))), (differ, gap)
    assert cc.unbounded == py.unbounded
    if py.unbounded:
        assert np.allclose(cc.ray_base, py.ray_base, rtol=1e-8, atol=1e-8)
        assert np.allclose(cc.ray, py.ray, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("structure", ["grid", "banded"])
@pytest.mark.parametrize("bounds", ["ncp", "box", "mixed"])
@pytest.mark.parametrize("n,seed", [(60, 0), (300, 1), (900, 2)])
def test_same_path_as_python_loop_on_sparse_p_matrix_lcps(structure, bounds, n, seed):
    g = gen.p_matrix_lcp(n, structure, seed, bounds)
    both = _both(g.lcp)
    _assert_same_path(both, *g.lcp[:2])
    cc = both[1][0]
    assert cc.code is LinearCode.SOLVED and cc.pivots > 0
    assert np.max(np.abs(cc.z - g.solution)) <= 1e-8


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("ray_start", [False, True])
def test_same_path_on_degenerate_lcps_and_same_outcome_on_rank_deficient_ones(seed,
                                                                               ray_start):
    """Degenerate obstacle problems: pivot for pivot.  Rank-deficient LCPs (a rank-20 M,
    duplicated columns), whose start bases are singular: the repair keeps the same
    columns, but which rows the artificials take is the factorization's choice (the
    manager's dense QR, the engine's LU), so the paths may differ: from the current point
    both end alike; every point either calls a solution solves the LCP."""
    g = gen.obstacle_problem(12, seed, degenerate_fraction=0.5)
    _assert_same_path(_both(g.lcp, ray_start=ray_start), *g.lcp[:2])
    for g in (gen.monotone_lcp(60, seed, rank=20),
              gen.duplicated_columns_lcp(80, seed, bounds="mixed")):
        M, q, lb, ub = g.lcp
        (py, _), (cc, _) = _both(g.lcp, ray_start=ray_start)
        if not ray_start:
            assert cc.code is py.code, (py.message, cc.message)
        for res in (py, cc):
            if res.code is LinearCode.SOLVED:
                f = M @ res.z + q
                assert np.max(np.abs(res.z - np.clip(res.z - f, lb, ub))) <= 1e-8 * (
                    1.0 + np.abs(f).max())


@pytest.mark.parametrize("seed", [0, 1])
def test_same_ray_on_infeasible_lcp(seed):
    g = gen.infeasible_lcp(40, seed)
    both = _both(g.lcp, ray_start=True)
    _assert_same_path(both, *g.lcp[:2])
    assert both[1][0].code is LinearCode.RAY


def test_same_limits_cycle_and_minor():
    g = gen.p_matrix_lcp(200, "grid", 5, "mixed")
    for opt in (Options(lemke_cycle_limit=1), Options(minor_iteration_limit=3)):
        both = _both(g.lcp, options=opt)
        _assert_same_path(both, *g.lcp[:2])
    assert both[1][0].code is LinearCode.MINOR_LIMIT and both[1][0].pivots == 3


@pytest.mark.parametrize("kw", [{"growth_limit": 1.0}, {"stability_tolerance": 0.0},
                                {"fill_factor": 1.0}, {"pivot_tolerance": 0.5},
                                {"update_limit": 1}])
def test_same_path_whatever_the_update_safeguards_decline(kw):
    """Each safeguard only chooses between an update and a refactorization: declining
    (nearly) every update leaves the path pivot for pivot that of the Python loop; the
    declined updates are refactorizations."""
    g = gen.p_matrix_lcp(300, "banded", 4, "mixed")
    M, q, lb, ub = g.lcp
    both = _both(g.lcp, engine_kw=kw)
    _assert_same_path(both, M, q)
    (_, _), (default, _) = _both(g.lcp)
    cc = both[1][0]
    assert cc.pivots > 10 and default.updates > 10
    assert cc.factorizations > default.factorizations + default.updates // 4, kw
    assert cc.updates < default.updates


def _degenerate_start_lcp():
    """A 3-variable LCP whose start x = (0, 0, 1) is a degenerate vertex: t enters with a
    zero step, on the second pivot t alone blocks at 0, and the path goes on through
    t = -2 to t = 1 (tests/routes/test_path_routes.py holds the dense engine to it)."""
    M = np.array([[1.0, 1.0, -2.0], [1.0, 1.0, 3.0], [1.0, 3.0, 3.0]])
    q = np.array([-3.0, -3.0, 0.0])
    return (M, q, np.zeros(3), np.full(3, np.inf)), np.array([0.0, 0.0, 1.0])


def test_t_below_zero_from_a_degenerate_start_vertex():
    lcp, x = _degenerate_start_lcp()
    both = _both(lcp, x=x)
    _assert_same_path(both, *lcp[:2])
    cc = both[1][0]
    assert cc.code is LinearCode.SOLVED and cc.pivots == 4
    assert np.allclose(cc.z, [0.0, 3.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_singular_bases_are_repaired_as_the_manager_does(seed):
    """z_j's column is zero and so is row j of M off the diagonal: whenever z_j is basic
    the basis is singular and the only row its artificial can take is j; the inward guess
    makes it basic at the start (repair, then the slack basis), and a path that later
    brings z_j in refuses the update and repairs.  Same pivots as the Python loop."""
    rng = np.random.default_rng(seed)
    n = 40
    M = sp.random(n, n, density=0.1, random_state=seed).toarray() + 4.0 * np.eye(n)
    j = int(rng.integers(n))
    M[:, j] = 0.0
    M[j, :] = 0.0
    q = rng.standard_normal(n)
    q[j] = -1.0
    lb, ub = np.zeros(n), np.full(n, np.inf)
    Ms = sp.csc_matrix(M)
    x = np.zeros(n)
    both = _both((Ms, q, lb, ub), x=x, r=Ms @ x + q)
    _assert_same_path(both, Ms, q)


@pytest.mark.parametrize("n,family,seed", [(10, 2, 1), (50, 1, 3), (100, 2, 5)])
def test_same_path_on_thesis_family_linearizations(n, family, seed):
    """The first linearization of a thesis family at its start (dense M, given to both as
    a sparse matrix): the normal-map start x; family 2, n = 10, seed 1 starts at a
    degenerate vertex and goes below t = 0 (PATH's 7 pivots)."""
    g = gen.thesis_family(n, family=family, seed=seed)
    info = g.info
    lb, ub = np.asarray(info["lb"], float), np.asarray(info["ub"], float)
    z0 = np.clip(np.asarray(info["x0"], float), lb, ub)
    A = info["A"]
    A = np.asarray(A.todense() if hasattr(A, "todense") else A, float)
    f = info["D"] * z0 * z0 + A @ z0 + info["b"]
    M = A + np.diag(2.0 * info["D"] * z0)
    q = f - M @ z0
    x = np.where(((z0 <= lb) & (f > 0)) | ((z0 >= ub) & (f < 0)), z0 - f, z0)
    both = _both((sp.csc_matrix(M), q, lb, ub), x=x)
    _assert_same_path(both, M, q, lb, ub)
    if (n, family, seed) == (10, 2, 1):
        assert both[1][0].code is LinearCode.SOLVED and both[1][0].pivots == 7


def _minorpivots_without_t(problem, options):
    """The pivots of a whole solve (its minor log) and its Result."""
    import logging

    lines = []

    class _H(logging.Handler):
        def emit(self, record):
            msg = record.getMessage()
            # (the Python loop's route may solve a pivot-free path on reused factors
            # where the engine takes the direct step: the same point, another line)
            if msg.lstrip().startswith("minor") and "direct step" not in msg:
                lines.append(msg)

    lg = logging.getLogger("compass_sparse")
    h = _H(level=logging.DEBUG)
    old = lg.level
    lg.addHandler(h)
    lg.setLevel(logging.DEBUG)
    try:
        res = solve_mcp(problem, options=dict(options, verbosity=3))
    finally:
        lg.removeHandler(h)
        lg.setLevel(old)
    return pivots_without_t(lines), res


def _cge_outtax():
    from compass_sparse.generators.cge import size_for, static_cge

    return static_cge(**size_for(1000), seed=0).with_shock(output_tax=0.5).problem


@pytest.mark.parametrize("name,make,opts,same_from", [
    ("traffic n=912", lambda: gen.traffic_equilibrium(8).problem, {}, 50),
    ("CGE output tax", _cge_outtax, {}, None),
    ("obstacle m=30, no crash", lambda: gen.obstacle_problem(30, 0).problem,
     {"crash_method": "none"}, None),
    ("banded LCP n=700, no crash",
     lambda: gen.p_matrix_lcp(700, "banded", 3, "mixed").problem, {"crash_method": "none"},
     None),
])
def test_whole_solves_take_the_python_loopspivots_without_t(name, make, opts, same_from, monkeypatch):
    """solve_mcp on the sparse engine and on the Python loop (path_basis='sparse'): the
    same status, major iterations and pivots, the same pivots in the same order, points
    equal to rounding -- but on traffic, whose rates are often equal in exact arithmetic
    (a network: two slacks blocking with rates equal to 1e-16 relative): there the first
    50 pivots are the same, then rounding decides a tie differently in the two
    factorizations; the solve takes the same counts all the same, and both points solve
    the problem (its path flows are not unique: the points may differ)."""
    import compass_sparse.routes as routes

    # (the CGE model is denser than the route gives the engine: forced onto it here)
    monkeypatch.setattr(routes, "SPARSE_ENGINE_MAX_DENSITY", np.inf)
    problem = make()
    piv_e, re_ = _minorpivots_without_t(problem, opts)
    piv_p, rp = _minorpivots_without_t(problem.with_start(problem.x0), dict(opts, path_basis="sparse"))
    assert re_.routes["path"] == "sparse engine" and rp.routes["path"] == "sparse basis"
    if same_from is None:
        assert piv_e == piv_p
    else:
        assert piv_e[:same_from] == piv_p[:same_from]
    assert (re_.status, re_.nit, re_.minor_iterations) == (rp.status, rp.nit,
                                                           rp.minor_iterations)
    assert re_.success and rp.success
    if same_from is None:
        assert np.max(np.abs(re_.x - rp.x)) <= 1e-8 * (1.0 + np.abs(rp.x).max())
