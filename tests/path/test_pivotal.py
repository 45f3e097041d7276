"""The pivotal path (compass_sparse.path.PivotalPath) on linear MCPs, directly and via solve_lcp.

Every check is recomputed here from the problem data, independently of the solver's
bookkeeping: the natural residual ||z - clip(z - (M z + q), l, u)||_inf, the validity of the
returned triple (z, w, v), the path equation M z + q - w + v = (1 - t) r, and agreement
with manufactured or brute-force solutions.  Both basis managers (the sparse
Forrest–Tomlin one and the dense reference) run the same paths.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import compass_sparse.generators as gen
from compass_sparse import Options, Status, solve_lcp
from compass_sparse.basis.dense import DenseBasis
from compass_sparse.basis import BasisManager
from compass_sparse.path.dense_engine import DensePathEngine
from compass_sparse.path.outcome import LinearCode, WarmBasis
from compass_sparse.path.pivotal import PivotalPath
from compass_sparse.path.warm import components, default_basis
from minor_log import pivot_ts

MANAGERS = {"sparse": BasisManager, "dense": DenseBasis, "compiled": DensePathEngine}
HYP = settings(derandomize=True, max_examples=30, deadline=None,
               suppress_health_check=[HealthCheck.too_slow])


# ----------------------------------------------------------------------------- helpers
def nat_res(M, q, lb, ub, z):
    """Natural residual of the LCP at z, computed from scratch."""
    z = np.asarray(z, dtype=float)
    f = M @ z + q
    return float(np.max(np.abs(z - np.clip(z - f, lb, ub)))) if z.size else 0.0


def start_of(lb, ub):
    return np.clip(np.zeros(lb.size), lb, ub)


def corner_of(lb, ub):
    """Every z at a finite bound (lower first), free ones at 0."""
    return np.where(np.isfinite(lb), lb, np.where(np.isfinite(ub), ub, 0.0))


def run_path(lcp, manager="sparse", x=None, *, options=None, minor_limit=None, **kw):
    M, q, lb, ub = lcp
    bm = MANAGERS[manager](M)
    path = PivotalPath(M, q, lb, ub, bm, options or Options(), minor_limit=minor_limit)
    return path.run(start_of(lb, ub) if x is None else x, **kw)


def assert_valid_triple(res, lb, ub, tol=1e-9):
    """l <= z <= u, w, v >= 0, w_i > 0 only at z_i = l_i, v_i > 0 only at z_i = u_i."""
    z, w, v = res.z, res.w, res.v
    scale = 1.0 + np.max(np.abs(np.where(np.isfinite(lb), lb, 0.0)), initial=0.0) + \
        np.max(np.abs(np.where(np.isfinite(ub), ub, 0.0)), initial=0.0)
    t = tol * scale
    assert np.all(np.isfinite(z)), "z has non-finite entries"
    assert np.all(z >= lb - t), f"z below lb by {np.max(lb - z)}"
    assert np.all(z <= ub + t), f"z above ub by {np.max(z - ub)}"
    assert np.all(w >= -t) and np.all(v >= -t), "negative slack"
    wpos = w > t
    vpos = v > t
    assert np.all(z[wpos] - lb[wpos] <= t), "w_i > 0 with z_i off its lower bound"
    assert np.all(ub[vpos] - z[vpos] <= t), "v_i > 0 with z_i off its upper bound"
    assert 0.0 <= res.t <= 1.0 + 1e-12


def assert_on_path(res, lcp, x0, tol=1e-8):
    """The returned point satisfies M z + q - w + v = (1 - t) r with r the residual of the
    start triple (the defining equation of the path, for a non-Lemke start)."""
    M, q, lb, ub = lcp
    z0, w0, v0 = components(np.asarray(x0, float), lb, ub)
    r = M @ z0 + q - w0 + v0
    lhs = M @ res.z + q - res.w + res.v
    err = np.max(np.abs(lhs - (1.0 - res.t) * r))
    assert err <= tol * (1.0 + np.max(np.abs(r)) + np.max(np.abs(M @ res.z))), err


# ----------------------------------------------------------------------------- unique solutions
P_CASES = [
    ("grid", "ncp", 100, 0), ("grid", "box", 225, 1), ("grid", "mixed", 150, 2),
    ("banded", "ncp", 120, 3), ("banded", "box", 300, 4), ("banded", "mixed", 200, 5),
    ("grid", "box", 500, 6), ("banded", "mixed", 500, 7),
]


@pytest.mark.parametrize("structure,bounds,n,seed", P_CASES)
def test_p_matrix_unique_solution_both_managers(structure, bounds, n, seed):
    g = gen.p_matrix_lcp(n, structure, seed, bounds)
    M, q, lb, ub = g.lcp
    zs = {}
    for name in MANAGERS:
        res = run_path(g.lcp, name)
        assert res.code is LinearCode.SOLVED, (name, res.code, res.message)
        assert res.t == 1.0
        assert nat_res(M, q, lb, ub, res.z) <= 1e-10
        # P-matrix: the solution is unique, so it is the manufactured one
        assert np.max(np.abs(res.z - g.solution)) <= 1e-9
        assert_valid_triple(res, lb, ub)
        assert res.pivots > 0
        zs[name] = res.z
    assert np.max(np.abs(zs["sparse"] - zs["dense"])) <= 1e-9


@pytest.mark.parametrize("name", list(MANAGERS))
def test_obstacle_problem_path(name):
    g = gen.obstacle_problem(14, seed=3)
    M, q, lb, ub = g.lcp
    res = run_path(g.lcp, name, x=g.problem.x0)
    assert res.code is LinearCode.SOLVED
    # the obstacle matrix carries 1/h^2 = 225: scale the tolerance with ||M||
    assert nat_res(M, q, lb, ub, res.z) <= 1e-10 * abs(M).max()
    assert np.max(np.abs(res.z - g.solution)) <= 1e-9


@pytest.mark.parametrize("kw", [dict(), dict(bounds="box"),
                                dict(rank=10, bounds="mixed", degenerate_fraction=0.2),
                                dict(skew=3.0)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_monotone_feasible_solved(kw, seed):
    g = gen.monotone_lcp(80, seed, **kw)
    M, q, lb, ub = g.lcp
    # PSD check of the generator's claim (independent): x' M x >= 0 on random x
    X = np.random.default_rng(seed).standard_normal((80, 20))
    assert np.all(np.einsum("ij,ij->j", X, M @ X) >= -1e-9)
    res = run_path(g.lcp, "sparse")
    if res.code is not LinearCode.SOLVED:  # the Lemke start is the documented fallback
        res = run_path(g.lcp, "sparse", ray_start=True)
    assert res.code is LinearCode.SOLVED, res.message
    assert nat_res(M, q, lb, ub, res.z) <= 1e-10
    assert_valid_triple(res, lb, ub)
    r = solve_lcp(M, q, lb, ub, options={"crash_method": "none"})
    assert r.success and nat_res(M, q, lb, ub, r.x) <= 1e-6


# ----------------------------------------------------------------------------- infeasible
@pytest.mark.parametrize("n,seed", [(2, 0), (5, 1), (30, 2), (120, 3)])
@pytest.mark.parametrize("name", list(MANAGERS))
def test_infeasible_ray_from_lemke_start(n, seed, name):
    g = gen.infeasible_lcp(n, seed)
    M, q, lb, ub = g.lcp
    # the generator's Farkas certificate, checked independently: y >= 0, M'y = 0, y'q < 0
    y = g.info["certificate"]
    assert np.all(y >= 0) and np.max(np.abs(M.T @ y)) <= 1e-12 and y @ q < 0
    res = run_path(g.lcp, name, x=np.zeros(n), ray_start=True)
    assert res.code is LinearCode.RAY, (res.code, res.message)
    assert res.ray_start
    assert_valid_triple(res, lb, ub)


@pytest.mark.parametrize("n,seed", [(3, 0), (20, 1), (60, 2)])
@pytest.mark.parametrize("crash", ["pnewton", "none"])
def test_infeasible_solve_lcp_reports_infeasible(n, seed, crash):
    g = gen.infeasible_lcp(n, seed)
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub, options={"crash_method": crash})
    assert r.status is Status.INFEASIBLE
    assert not r.success
    assert nat_res(M, q, lb, ub, r.x) > 1e-6  # no solution exists, so never a small residual
    assert np.all(r.x >= lb) and np.all(r.x <= ub)


# ----------------------------------------------------------------------------- degenerate
@pytest.mark.parametrize("structure,bounds,frac,seed", [
    ("grid", "ncp", 0.3, 0), ("grid", "box", 0.5, 1), ("banded", "mixed", 0.3, 2),
    ("banded", "box", 1.0, 3), ("grid", "mixed", 0.8, 4),
])
@pytest.mark.parametrize("name", list(MANAGERS))
def test_degenerate_p_matrix(structure, bounds, frac, seed, name):
    g = gen.p_matrix_lcp(150, structure, seed, bounds, frac)
    M, q, lb, ub = g.lcp
    assert g.info["degenerate"].sum() > 0
    res = run_path(g.lcp, name)
    assert res.code is LinearCode.SOLVED, res.message
    assert nat_res(M, q, lb, ub, res.z) <= 1e-10
    assert np.max(np.abs(res.z - g.solution)) <= 1e-9


@pytest.mark.parametrize("seed", [0, 1])
def test_degenerate_obstacle(seed):
    g = gen.obstacle_problem(12, seed, degenerate_fraction=0.5)
    M, q, lb, ub = g.lcp
    res = run_path(g.lcp, "sparse", x=g.problem.x0)
    assert res.code is LinearCode.SOLVED
    assert nat_res(M, q, lb, ub, res.z) <= 1e-10 * abs(M).max()
    assert np.max(np.abs(res.z - g.solution)) <= 1e-9


@pytest.mark.parametrize("bounds", ["box", "ncp", "mixed"])
@pytest.mark.parametrize("n,seed", [(10, 0), (40, 1), (80, 2), (60, 3)])
@pytest.mark.parametrize("crash", ["pnewton", "none"])
def test_duplicated_columns_solve_lcp(bounds, n, seed, crash):
    """Rank-deficient M (duplicated columns), feasible by construction: solve_lcp solves it,
    with or without the crash, and never reports INFEASIBLE."""
    g = gen.duplicated_columns_lcp(n, seed, bounds=bounds)
    M, q, lb, ub = g.lcp
    assert np.linalg.matrix_rank(M.toarray()) < n  # really rank deficient
    assert nat_res(M, q, lb, ub, g.solution) == 0.0  # the manufactured solution is exact
    r = solve_lcp(M, q, lb, ub, options={"crash_method": crash})
    assert r.status is not Status.INFEASIBLE, r.message
    assert r.success, r.message
    assert nat_res(M, q, lb, ub, r.x) <= 1e-6


@pytest.mark.parametrize("bounds", ["box", "ncp", "mixed"])
@pytest.mark.parametrize("n,seed", [(10, 0), (40, 1), (60, 3)])
def test_duplicated_columns_path_validity(bounds, n, seed):
    """The path alone, from two starts: whatever its code, the triple stays valid and on the
    path; when it claims a solution, it is one."""
    g = gen.duplicated_columns_lcp(n, seed, bounds=bounds)
    M, q, lb, ub = g.lcp
    for x0 in (start_of(lb, ub), corner_of(lb, ub)):
        for name in MANAGERS:
            res = run_path(g.lcp, name, x=x0)
            assert_valid_triple(res, lb, ub)
            if res.artificials == 0:
                assert_on_path(res, g.lcp, x0)
            if res.code is LinearCode.SOLVED:
                assert nat_res(M, q, lb, ub, res.z) <= 1e-9


def test_duplicated_columns_path_from_corner_ncp():
    """NCP bounds: the start basis is all slacks (regular), the path solves."""
    for seed in (1, 2, 3, 5):
        g = gen.duplicated_columns_lcp(60, seed, bounds="ncp")
        M, q, lb, ub = g.lcp
        res = run_path(g.lcp, "sparse")
        assert res.code is LinearCode.SOLVED, (seed, res.message)
        assert nat_res(M, q, lb, ub, res.z) <= 1e-10


# ----------------------------------------------------------------------------- warm start
@pytest.mark.parametrize("bounds,seed", [("ncp", 0), ("box", 1), ("mixed", 2)])
@pytest.mark.parametrize("name", list(MANAGERS))
def test_warm_start_from_solution(bounds, seed, name):
    g = gen.p_matrix_lcp(225, "grid", seed, bounds)
    M, q, lb, ub = g.lcp
    bm = MANAGERS[name](M)
    res = PivotalPath(M, q, lb, ub, bm, Options()).run(start_of(lb, ub))
    assert res.code is LinearCode.SOLVED and res.pivots > 10
    assert isinstance(res.basis, WarmBasis)
    # From the exact manufactured solution (normal-map point x* = z* - w* + v*): r = 0.
    xs = g.solution - g.info["w_star"] + g.info["v_star"]
    again = PivotalPath(M, q, lb, ub, bm, Options()).run(xs, warm=res.basis)
    assert again.code is LinearCode.SOLVED
    assert again.pivots == 0
    assert nat_res(M, q, lb, ub, again.z) == 0.0
    # From the path's own solution (r ~ 1e-15, not exactly 0): no basis change at all; t
    # goes to 1 in one step (counted as one pivot by PivotalPath).
    again = PivotalPath(M, q, lb, ub, bm, Options()).run(res.x, warm=res.basis)
    assert again.code is LinearCode.SOLVED
    assert again.updates == 0
    assert again.pivots <= 1
    assert nat_res(M, q, lb, ub, again.z) <= 1e-10
    # From a nearby point: few pivots.
    rng = np.random.default_rng(seed)
    xp = res.x + 1e-3 * rng.standard_normal(res.x.size)
    near = PivotalPath(M, q, lb, ub, bm, Options()).run(xp, warm=res.basis)
    assert near.code is LinearCode.SOLVED
    assert near.pivots <= 10
    assert nat_res(M, q, lb, ub, near.z) <= 1e-10
    assert np.max(np.abs(near.z - g.solution)) <= 1e-9


def test_warm_start_after_data_change():
    """A warm basis from one q solves a slightly changed q in few pivots."""
    g = gen.p_matrix_lcp(400, "grid", 9, "box")
    M, q, lb, ub = g.lcp
    bm = BasisManager(M)
    res = PivotalPath(M, q, lb, ub, bm, Options()).run(start_of(lb, ub))
    assert res.code is LinearCode.SOLVED
    q2 = q.copy()
    q2[:3] += 1e-4
    res2 = PivotalPath(M, q2, lb, ub, bm, Options()).run(res.x, warm=res.basis)
    assert res2.code is LinearCode.SOLVED
    assert res2.pivots <= 10
    assert nat_res(M, q2, lb, ub, res2.z) <= 1e-10


# ----------------------------------------------------------------------------- brute force
def _brute_close(z, sols, tol=1e-7):
    return any(np.max(np.abs(z - s)) <= tol for s in sols)


@HYP
@given(n=st.integers(1, 8), seed=st.integers(0, 10**6),
       structure=st.sampled_from(["grid", "banded"]),
       bounds=st.sampled_from(["ncp", "box", "mixed"]),
       deg=st.sampled_from([0.0, 0.5]))
def test_brute_force_p_matrix(n, seed, structure, bounds, deg):
    g = gen.p_matrix_lcp(n, structure, seed, bounds, deg)
    M, q, lb, ub = g.lcp
    sols = gen.brute_force_lcp(M, q, lb, ub)
    assert len(sols) == 1  # P-matrix: exactly one solution
    assert np.max(np.abs(sols[0] - g.solution)) <= 1e-8
    for name in MANAGERS:
        res = run_path(g.lcp, name)
        assert res.code is LinearCode.SOLVED, res.message
        assert np.max(np.abs(res.z - sols[0])) <= 1e-8
        assert nat_res(M, q, lb, ub, res.z) <= 1e-10
    r = solve_lcp(M, q, lb, ub)
    assert r.success
    assert np.max(np.abs(r.x - sols[0])) <= 1e-6


@HYP
@given(n=st.integers(1, 6), seed=st.integers(0, 10**6))
def test_brute_force_random_box_lcp(n, seed):
    """Random dense (not P) M on a bounded box: solutions exist (compact box).  Whatever the
    path ends with, its triple is valid and on the path; a claimed solution is one of the
    enumerated ones (or at least has a tiny residual)."""
    rng = np.random.default_rng(seed)
    A = rng.uniform(-1.0, 1.0, (n, n))
    q = rng.uniform(-1.0, 1.0, n)
    lb = rng.uniform(-1.0, 0.0, n)
    ub = lb + rng.uniform(0.5, 2.0, n)
    M = sp.csc_matrix(A)
    sols = gen.brute_force_lcp(A, q, lb, ub)
    assert sols, "a box LCP always has a solution"
    for name in MANAGERS:
        x0 = start_of(lb, ub)
        res = run_path((M, q, lb, ub), name, x=x0)
        assert_valid_triple(res, lb, ub)
        if res.artificials == 0:
            assert_on_path(res, (M, q, lb, ub), x0)
        if res.code is LinearCode.SOLVED:
            assert nat_res(M, q, lb, ub, res.z) <= 1e-9 or _brute_close(res.z, sols)


@HYP
@given(n=st.integers(1, 7), seed=st.integers(0, 10**6))
def test_brute_force_monotone_ncp(n, seed):
    g = gen.monotone_lcp(n, seed)
    M, q, lb, ub = g.lcp
    sols = gen.brute_force_lcp(M, q, lb, ub)
    res = run_path(g.lcp, "dense")
    if res.code is not LinearCode.SOLVED:
        res = run_path(g.lcp, "dense", ray_start=True)
    assert res.code is LinearCode.SOLVED, res.message
    r = nat_res(M, q, lb, ub, res.z)
    # monotone: the solution set is convex and may be a continuum the enumeration samples
    assert r <= 1e-9 or _brute_close(res.z, sols)
    assert r <= 1e-9


# ----------------------------------------------------------------------------- cycling
@pytest.mark.parametrize("name", list(MANAGERS))
@pytest.mark.parametrize("n,seed", [(100, 2), (40, 15), (50, 0)])
def test_cycle_limit_returns_best_t_point(name, n, seed):
    g = gen.p_matrix_lcp(n, "grid", seed, "box")
    M, q, lb, ub = g.lcp
    x0 = start_of(lb, ub)
    # From the all-slack basis (the sign-guessed start basis needs no re-entries here).
    slack = WarmBasis(default_basis(components(x0, lb, ub)[0], lb, ub))
    log = []
    path = PivotalPath(M, q, lb, ub, MANAGERS[name](M), Options(lemke_cycle_limit=1),
                       log=log.append)
    res = path.run(x0, warm=slack)
    assert res.code is LinearCode.CYCLE, res.code
    assert 0.0 < res.t < 1.0
    assert_valid_triple(res, lb, ub)
    assert_on_path(res, g.lcp, x0)
    # the best-t point is returned: on the path (above) at the largest t of its pivots
    ts = pivot_ts(log)
    assert ts and abs(res.t - max(ts)) <= 1e-6 * max(ts)  # (the log prints t to 7 digits)
    # the same problem needs re-entries, and solves with the default limit
    full = run_path(g.lcp, name, x=x0, warm=slack)
    assert full.code is LinearCode.SOLVED
    assert np.max(np.abs(full.z - g.solution)) <= 1e-9


# ----------------------------------------------------------------------------- validity & limits
VALIDITY_CASES = [
    ("pmat", lambda s: gen.p_matrix_lcp(80, "grid", s, "box")),
    ("pmat_mixed_deg", lambda s: gen.p_matrix_lcp(60, "banded", s, "mixed", 0.3)),
    ("mono", lambda s: gen.monotone_lcp(50, s, rank=5)),
    ("dup", lambda s: gen.duplicated_columns_lcp(40, s)),
    ("infeasible", lambda s: gen.infeasible_lcp(20, s)),
]


@pytest.mark.parametrize("label,make", VALIDITY_CASES)
@pytest.mark.parametrize("opts", [dict(), dict(lemke_cycle_limit=1), dict(lemke_cycle_limit=2),
                                  dict(minor_iteration_limit=3),
                                  dict(minor_iteration_limit=17)])
def test_triple_always_valid(label, make, opts):
    for seed in range(3):
        g = make(seed)
        M, q, lb, ub = g.lcp
        x0 = start_of(lb, ub)
        for name in MANAGERS:
            for ray in (False, True):
                res = run_path(g.lcp, name, x=x0, options=Options(**opts), ray_start=ray)
                assert isinstance(res.code, LinearCode)
                assert_valid_triple(res, lb, ub)
                if not ray and res.artificials == 0:
                    assert_on_path(res, g.lcp, x0)
                if res.code is LinearCode.SOLVED:
                    assert nat_res(M, q, lb, ub, res.z) <= 1e-9
                assert res.basis is not None and res.basis.basic.shape == (M.shape[0],)


@pytest.mark.parametrize("name", list(MANAGERS))
def test_minor_iteration_limit(name):
    g = gen.p_matrix_lcp(100, "grid", 0, "box")
    M, q, lb, ub = g.lcp
    full = run_path(g.lcp, name)
    assert full.code is LinearCode.SOLVED and full.pivots > 10
    for limit_kw in (dict(minor_limit=5), dict(options=Options(minor_iteration_limit=5))):
        res = run_path(g.lcp, name, **limit_kw)
        assert res.code is LinearCode.MINOR_LIMIT
        assert res.pivots == 5
        assert res.t < 1.0
        assert_valid_triple(res, lb, ub)
        assert_on_path(res, g.lcp, start_of(lb, ub))


def test_components_and_trivial_start():
    """components(): z = clip(x), w = (z - x)+, v = (x - z)+ ; x = z - w + v."""
    lb = np.array([0.0, -1.0, -np.inf, 2.0])
    ub = np.array([np.inf, 1.0, 0.5, 2.0])
    x = np.array([-3.0, 5.0, 0.7, 1.0])
    z, w, v = components(x, lb, ub)
    np.testing.assert_array_equal(z, [0.0, 1.0, 0.5, 2.0])
    np.testing.assert_array_equal(w, [3.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(v, [0.0, 4.0, 0.2, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(z - w + v, x, rtol=0, atol=1e-15)
    # a start that already solves the linear problem: no pivots
    M = sp.identity(4, format="csc")
    q = -np.array([0.0, 0.0, 0.0, 0.0])
    lb2, ub2 = np.full(4, -1.0), np.full(4, 1.0)
    res = run_path((M, q, lb2, ub2), "sparse", x=np.zeros(4))
    assert res.code is LinearCode.SOLVED and res.pivots == 0
    assert nat_res(M, q, lb2, ub2, res.z) == 0.0


def test_fixed_variables():
    """l = u rows: the free slack is basic; the rest is solved."""
    g = gen.p_matrix_lcp(60, "banded", 11, "box")
    M, q, lb, ub = g.lcp
    lb, ub = lb.copy(), ub.copy()
    fix = np.arange(0, 60, 7)
    lb[fix] = ub[fix] = g.solution[fix]
    for name in MANAGERS:
        res = run_path((M, q, lb, ub), name)
        assert res.code is LinearCode.SOLVED
        assert nat_res(M, q, lb, ub, res.z) <= 1e-10
        np.testing.assert_allclose(res.z, g.solution, atol=1e-9)


def _random_slot_table(seed, n=40):
    """A slot table with every kind, repeated indices across and within kinds, NaN and
    signed-zero values, bounds of every kind (fixed ones included)."""
    from compass_sparse.path._kernels import VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z
    from compass_sparse.path.pivotal import PathState

    rng = np.random.default_rng(seed)
    lb = np.where(rng.random(n) < 0.3, -np.inf, rng.standard_normal(n))
    ub = np.where(rng.random(n) < 0.3, np.inf, np.nan_to_num(lb, neginf=-1.0)
                  + rng.random(n) * (rng.random(n) < 0.8))
    st = PathState(art_sign=np.ones(n, dtype=np.int64))
    st.sk = rng.choice([VAR_Z, VAR_W, VAR_V, VAR_S, VAR_A, VAR_T], n).astype(np.int64)
    st.si = rng.integers(0, n, n).astype(np.int64)  # repeated indices on purpose
    st.xb = rng.standard_normal(n) * 10.0
    st.xb[rng.random(n) < 0.1] = -0.0
    st.xb[rng.random(n) < 0.05] = np.nan
    st.zval = rng.standard_normal(n) * 10.0
    return lb, ub, st


@pytest.mark.parametrize("seed", range(5))
def test_compiled_slot_readout_matches_array_formulas(seed):
    """The compiled read-out of a slot table (the point (z, w, v) and the basis handed to
    the next path) equals the array formulas bit for bit, NaN and -0.0 included, with
    repeated indices assigned in the array version's order."""
    from compass_sparse.path._kernels import VAR_S, VAR_V, VAR_W, VAR_Z
    from compass_sparse.path._slot_kernels import slot_basis
    from compass_sparse.path.pivotal import PivotalPath
    from compass_sparse.path.warm import default_basis

    lb, ub, st = _random_slot_table(seed)
    n = lb.size
    p = PivotalPath.__new__(PivotalPath)
    p.n, p.st = n, st
    p.lb, p.ub = lb, ub
    got = p.current_point()
    p.lb, p.ub = lb.tolist(), ub.tolist()  # not float vectors: the array formulas
    with np.errstate(invalid="ignore"):
        ref = p.current_point()
    for a, b in zip(got, ref):
        assert np.array_equal(a, b, equal_nan=True)
        assert np.array_equal(np.signbit(a), np.signbit(b))
    z = np.nan_to_num(got[0])
    basic = np.full(n, VAR_Z, dtype=np.int8)
    slot_basis(z, lb, ub, st.sk, st.si, basic)
    expect = default_basis(z, lb, ub)
    for kind in (VAR_Z, VAR_W, VAR_V, VAR_S):
        expect[st.si[st.sk == kind]] = kind
    assert np.array_equal(basic, expect)


@pytest.mark.parametrize("seed", range(3))
def test_compiled_slot_table_matches_array_formulas(seed):
    from compass_sparse.path._kernels import VAR_S, VAR_V, VAR_W, VAR_Z
    from compass_sparse.path.pivotal import PathState, PivotalPath

    rng = np.random.default_rng(seed)
    n = 30
    basic = rng.choice([VAR_Z, VAR_W, VAR_V, VAR_S], n).astype(np.int8)
    z, w, v = (rng.standard_normal(n) for _ in range(3))
    w[::4] = -0.0
    p = PivotalPath.__new__(PivotalPath)
    p.n, p.st = n, PathState(art_sign=np.ones(n, dtype=np.int64))
    p._reset_slots(basic, z, w, v)
    got = (p.st.sk, p.st.si, p.st.xb)
    p._reset_slots(basic, z.tolist(), w, v)  # not a float vector: the array formulas
    for a, b in zip(got, (p.st.sk, p.st.si, p.st.xb)):
        assert a.dtype == b.dtype
        assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("seed", range(4))
def test_compiled_default_basis_matches_array_formulas(seed):
    """The start basis of a path (cold and warm-started) from the compiled pass equals the
    array formulas, at points inside, on and beyond bounds, fixed and infinite ones."""
    from compass_sparse.path._kernels import VAR_S, VAR_V, VAR_W, VAR_Z
    from compass_sparse.path.outcome import WarmBasis
    from compass_sparse.path.warm import default_basis

    lb, ub, st = _random_slot_table(seed)
    rng = np.random.default_rng(seed)
    z = np.clip(st.zval, lb, ub)
    at = rng.random(lb.size) < 0.4
    z[at] = np.where(np.isfinite(lb), lb, np.where(np.isfinite(ub), ub, z))[at]
    z[0] = np.nan
    prev = WarmBasis(rng.choice([VAR_Z, VAR_W, VAR_V, VAR_S], lb.size).astype(np.int8))
    for warm in (None, prev):
        got = default_basis(z, lb, ub, warm)
        with np.errstate(invalid="ignore"):
            # long doubles hold every double exactly: the array formulas, same comparisons
            ref = default_basis(z, lb.astype(np.longdouble), ub.astype(np.longdouble), warm)
        assert got.dtype == ref.dtype == np.int8
        assert np.array_equal(got, ref)


def test_path_starts_again_when_a_solve_repairs_the_basis(monkeypatch):
    """Regression: a residual check inside a solve that repaired a singular basis changed
    the manager's slot table behind the path's back.  The manager now raises
    SolveRepairedBasis; the path starts again on fresh factors and still solves, and a
    path whose solves keep repairing ends SINGULAR instead of raising."""
    from compass_sparse.basis import SolveRepairedBasis
    from compass_sparse.path.pivotal import PATH_ATTEMPTS

    g = gen.p_matrix_lcp(400, "grid", 9, "box")
    M, q, lb, ub = g.lcp
    real = BasisManager.ftran_column
    calls = {"n": 0}

    def once(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise SolveRepairedBasis("injected")
        return real(self, *a, **k)

    monkeypatch.setattr(BasisManager, "ftran_column", once)
    res = PivotalPath(M, q, lb, ub, BasisManager(M), Options()).run(start_of(lb, ub))
    assert calls["n"] > 3
    assert res.code is LinearCode.SOLVED
    assert nat_res(M, q, lb, ub, res.z) <= 1e-10
    assert np.max(np.abs(res.z - g.solution)) <= 1e-9

    def always(self, *a, **k):
        calls["n"] += 1
        raise SolveRepairedBasis("injected")

    calls["n"] = 0
    monkeypatch.setattr(BasisManager, "ftran_column", always)
    res = PivotalPath(M, q, lb, ub, BasisManager(M), Options()).run(start_of(lb, ub))
    assert res.code is LinearCode.SINGULAR
    assert calls["n"] == PATH_ATTEMPTS


def test_compiled_lemke_start_gives_the_array_versions_bits():
    """PivotalPath._lemke_start in one compiled pass: the same z, w, v, r and basis, bit
    for bit and dtype for dtype, as the array version, over random boxes with free,
    lower-, upper-bounded, boxed and fixed variables, f of every size around 1 and a NaN
    in q."""
    from compass_sparse.path.dense_engine import DensePathEngine

    rng = np.random.default_rng(0)
    for trial in range(200):
        n = int(rng.integers(1, 12))
        M = (sp.random(n, n, density=0.5, random_state=int(rng.integers(1 << 30)),
                       format="csc") + sp.identity(n)).tocsc()
        q = rng.normal(size=n) * rng.choice([0.1, 1.0, 10.0], size=n)
        if trial % 7 == 0:
            q[0] = np.nan
        kind = rng.integers(0, 5, size=n)  # free, upper only, boxed, fixed, lower only
        base = rng.normal(size=n)
        lb = np.select([kind == 0, kind == 1], [-np.inf, -np.inf], base)
        ub = np.select([kind == 0, kind == 2, kind == 3, kind == 4],
                       [np.inf, base + rng.uniform(0.0, 3.0, n), base, np.inf], base)
        p = PivotalPath(M, q, lb, ub, DensePathEngine(M), Options())
        for got, ref in zip(p._lemke_start(), p._lemke_start_arrays()):
            assert got.dtype == ref.dtype
            assert np.array_equal(got, ref, equal_nan=True)
