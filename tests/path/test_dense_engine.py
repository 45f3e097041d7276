"""The small-problem engine (compass_sparse.path.dense_engine): its repair against the
thesis' rule, the time limit between pivot chunks, and its paths from degenerate starts
(t's bound, ties, the pivot budget below zero, the singular inward guess).  Its paths
against the Python pivot loop: tests/routes/test_path_routes.py.

The ordinary path tests (tests/path/test_pivotal.py) run with this engine as a third
manager; its LU and Forrest-Tomlin kernels are checked against numpy in
tests/path/test_dense_lu.py.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import Options
from compass_sparse.basis.dense import DenseBasis
from compass_sparse.path import _dense_lu as K
from compass_sparse.path import dense_engine as dense_path
from compass_sparse.path._kernels import VAR_A, VAR_S, VAR_T, VAR_W, VAR_Z
from compass_sparse.path.dense_engine import DensePathEngine
from compass_sparse.path.outcome import LinearCode
from compass_sparse.path.pivotal import PivotalPath


def _basis(sk, si, M, r):
    n = sk.size
    B = np.zeros((n, n))
    for k in range(n):
        if sk[k] == VAR_Z:
            B[:, k] = M[:, si[k]]
        elif sk[k] == VAR_T:
            B[:, k] = r
        else:
            B[si[k], k] = -1.0 if sk[k] in (VAR_W, VAR_S) else 1.0
    return B


def test_factor_repairs_dependent_columns_with_artificials_on_their_rows():
    """Two equal M columns basic together: the second is dependent; its artificial takes
    the slot on the column's home row, and the repaired basis is regular."""
    n = 6
    rng = np.random.default_rng(4)
    M = rng.standard_normal((n, n))
    M[:, 4] = M[:, 1]
    sk = np.full(n, VAR_Z, np.int64)
    si = np.arange(n, dtype=np.int64)
    L, U = np.zeros((n, n), order="F"), np.zeros((n, n), order="F")
    prow, qslot = np.zeros(n, np.int64), np.zeros(n, np.int64)
    rs, rr = np.zeros(n, np.int64), np.zeros(n, np.int64)
    nrep = K.factor(np.asfortranarray(M), np.zeros(n), sk, si, np.ones(n, np.int64), L, U,
                    prow, qslot, 1e-9, rs, rr, True, np.zeros((4, n), np.int64), np.zeros(n))
    assert nrep == 1 and rs[0] == 4 and rr[0] == 4
    sk[4] = VAR_A
    B = _basis(sk, si, M, np.zeros(n))
    B[4, 4] = 1.0
    assert np.linalg.matrix_rank(B) == n


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


def test_engine_path_stops_at_the_time_limit_between_pivot_chunks(monkeypatch):
    """The deadline is checked between compiled chunks of pivots: with a chunk of one
    pivot and a deadline in the past the path stops after one pivot."""
    import time

    monkeypatch.setattr(dense_path, "PIVOT_CHUNK", 1)
    g = gen.p_matrix_lcp(50, "grid", 1, "ncp")
    M, q, lb, ub = g.lcp
    res = PivotalPath(M, q, lb, ub, DensePathEngine(M), Options(),
                      deadline=time.perf_counter() - 1.0).run(np.zeros(q.size))
    assert res.code is LinearCode.MINOR_LIMIT
    assert res.message == "time limit during the path"
    assert res.pivots == 1


def _fam2_n10_seed1_linearization():
    """The first linearization of thesis family 2, n = 10, seed 1 at its start z0 (every
    component at a bound; at four of them F pushes inwards, so the start vertex is
    degenerate): M = J(z0), q = F(z0) - M z0, and the normal-map start x (x = z0 - F(z0)
    where F pushes outwards, x = z0 where it pushes inwards)."""
    g = gen.thesis_family(10, family=2, seed=1)
    info = g.info
    lb, ub = np.asarray(info["lb"], float), np.asarray(info["ub"], float)
    z0 = np.clip(np.asarray(info["x0"], float), lb, ub)
    D, A, b = info["D"], np.asarray(info["A"].todense() if hasattr(info["A"], "todense")
                                    else info["A"], float), info["b"]
    f = D * z0 * z0 + A @ z0 + b
    M = A + np.diag(2.0 * D * z0)
    q = f - M @ z0
    x = np.where(((z0 <= lb) & (f > 0)) | ((z0 >= ub) & (f < 0)), z0 - f, z0)
    return M, q, lb, ub, x


def test_first_path_from_a_degenerate_start_vertex_does_not_stop_with_t_at_zero():
    """At this start the first pivots make zero steps and t must go below 0 (PATH's path
    goes to t = -0.97) before it rises to 1.  With t bounded below by 0 the path ended
    after two pivots ("t decreased to 0"): on the second, t (at 2.5e-16) tied with z_1 (at
    its upper bound) and t had the tie priority of t reaching 1.  Both implementations now
    take PATH's 7 pivots and end in a solution of the linear MCP."""
    import scipy.sparse as sps

    M, q, lb, ub, x = _fam2_n10_seed1_linearization()
    Ms = sps.csc_matrix(M)
    py, cc = _both((Ms, q, lb, ub), x=x)
    _assert_same_path(py, cc, Ms, q)
    assert cc.code is LinearCode.SOLVED and cc.pivots == 7
    for res in (py, cc):
        z, w, v = res.z, res.w, res.v
        assert np.all(z >= lb) and np.all(z <= ub) and np.all(w >= 0) and np.all(v >= 0)
        # M z + q = w - v with w_i (z_i - l_i) = 0 and v_i (u_i - z_i) = 0
        scale = 1.0 + np.abs(M @ z).max() + np.abs(q).max()
        assert np.max(np.abs(M @ z + q - w + v)) <= 1e-9 * scale
        assert np.max(np.abs(w * (z - lb))) <= 1e-9 * scale
        assert np.max(np.abs(v * (ub - z))) <= 1e-9 * scale
        f = M @ z + q
        assert np.max(np.abs(z - np.clip(z - f, lb, ub))) <= 1e-9 * scale


def test_artificial_zero_tolerance_decides_the_side_of_an_artificial_at_zero():
    """An artificial within ARTIFICIAL_ZERO of 0 is at 0 from above whatever the sign of
    its rounding: moving down it blocks at once; beyond the tolerance it is on the
    negative side and moving down takes it away from 0, so another slot blocks."""
    from compass_sparse.path._kernels import ARTIFICIAL_ZERO, project_slots, ratio_test

    sk = np.array([VAR_A, VAR_W], np.int64)
    si = np.array([0, 1], np.int64)
    lb, ub = np.zeros(2), np.full(2, np.inf)
    rate = np.array([-1.0, -1.0])
    for val, blocks in ((-0.5 * ARTIFICIAL_ZERO, True), (-0.99 * ARTIFICIAL_ZERO, True),
                        (-2.0 * ARTIFICIAL_ZERO, False), (1e-17, True)):
        xb = np.array([val, 0.5])
        slot, theta, up = ratio_test(sk, si, xb, rate, lb, ub, 1e-9, 0.0, -np.inf)
        assert (slot == 0) is blocks, (val, slot, theta)
        assert theta == (max(val, 0.0) if blocks else 0.5)
        xb2 = xb.copy()
        project_slots(sk, si, xb2, lb, ub, -np.inf)
        assert xb2[0] == (max(val, 0.0) if blocks else val)


def test_t_at_its_bound_wins_a_tie_and_is_free_below_on_a_path_from_the_current_point():
    """t reaching 1 or falling to its lower bound 0 wins a tie (the path ends either way);
    with no lower bound (a path from the current point before it has been above t = 0) t
    never blocks going down and another slot leaves."""
    from compass_sparse.path._kernels import ratio_test

    sk = np.array([VAR_T, VAR_W], np.int64)
    si = np.array([0, 1], np.int64)
    lb, ub = np.zeros(2), np.full(2, np.inf)
    slot, theta, up = ratio_test(sk, si, np.zeros(2), np.array([-0.01, -2.0]), lb, ub,
                                 1e-9, 0.0, 0.0)
    assert slot == 0 and theta == 0.0 and up == 0
    slot, theta, up = ratio_test(sk, si, np.array([1.0, 0.0]), np.array([0.01, -2.0]), lb,
                                 ub, 1e-9, 0.0, 0.0)
    assert slot == 0 and up == 1
    slot, theta, up = ratio_test(sk, si, np.array([0.0, 0.5]), np.array([-1.0, -1.0]),
                                 lb, ub, 1e-9, 0.0, -np.inf)
    assert slot == 1 and theta == 0.5


def _degenerate_start_lcp():
    """A 3-variable LCP whose start x = (0, 0, 1) is a degenerate vertex (z_0 = w_0 = 0,
    z_1 = w_1 = 0): t enters with a zero step, on the second pivot t alone blocks at 0, and
    the path goes on through t = -2 to t = 1 and the solution z = (0, 3, 0), w = (0, 0, 9)."""
    M = np.array([[1.0, 1.0, -2.0], [1.0, 1.0, 3.0], [1.0, 3.0, 3.0]])
    q = np.array([-3.0, -3.0, 0.0])
    lb, ub = np.zeros(3), np.full(3, np.inf)
    return (M, q, lb, ub), np.array([0.0, 0.0, 1.0])


def test_path_blocked_by_t_at_zero_at_a_degenerate_start_vertex_goes_below_zero_to_t_one():
    """With t >= 0 as a bound this path ended on its second pivot ("t decreased to 0")."""
    lcp, x = _degenerate_start_lcp()
    M, q, lb, ub = lcp
    py, cc = _both(lcp, x=x)
    _assert_same_path(py, cc, M, q)
    assert cc.code is LinearCode.SOLVED and cc.pivots == 4
    for res in (py, cc):
        assert np.allclose(res.z, [0.0, 3.0, 0.0], atol=1e-12)
        assert np.allclose(M @ res.z + q, [0.0, 0.0, 9.0], atol=1e-12)


def test_lemke_ray_start_keeps_t_at_or_above_zero():
    """The ray start never lifts t's bound (its t = 0 is the start at infinity): the same
    path in both implementations, and no point of it below t = 0."""
    lcp, x = _degenerate_start_lcp()
    M, q, lb, ub = lcp
    seen = []
    for mgr in (DenseBasis, DensePathEngine):
        path = PivotalPath(M, q, lb, ub, mgr(M), Options())
        res = path.run(x, ray_start=True)
        assert path.st.t_lower == 0.0 and path.st.below_from == -1
        assert all(t >= 0.0 for t, _ in path.st.breakpoints)
        seen.append(res)
    _assert_same_path(*seen, M, q)


@pytest.mark.parametrize("budget,code,pivots", [(1, LinearCode.RAY, 2), (2, LinearCode.RAY, 3),
                                                 (3, LinearCode.SOLVED, 4)])
def test_pivot_budget_below_zero_ends_paths_that_do_not_get_above_zero(monkeypatch, budget,
                                                                       code, pivots):
    """t's bound is lifted on the path's second pivot (pivot count 1) and t gets above 0
    on its fourth: a budget of 1 or 2 pivots ends the path first ("t not above 0", the
    start point returned at t = 0), 3 lets it reach t = 1; both implementations alike."""
    from compass_sparse.path import _kernels as PK

    monkeypatch.setattr(PK, "BELOW_ZERO_PIVOTS", budget)
    lcp, x = _degenerate_start_lcp()
    M, q, lb, ub = lcp
    py, cc = _both(lcp, x=x)
    _assert_same_path(py, cc, M, q)
    assert cc.code is code and cc.pivots == pivots
    if code is LinearCode.RAY:
        assert cc.message == f"t not above 0 after {pivots} pivots" and not cc.unbounded
        assert cc.t == 0.0 and np.array_equal(cc.z, np.clip(x, lb, ub))


@pytest.mark.parametrize("eps,t_progress,code", [
    (1e-10, None, LinearCode.SOLVED), (1e-8, None, LinearCode.RAY),
    (1e-8, 1e-7, LinearCode.SOLVED), (1e-10, 1e-12, LinearCode.RAY)])
def test_t_below_t_progress_is_not_progress_above_zero(monkeypatch, eps, t_progress, code):
    """From x = (0, -eps, 1) the first pivot puts t at eps/3, and t blocks at 0 on the
    third.  At most T_PROGRESS (1e-9) that is not progress: the bound is lifted and the path
    reaches t = 1; above it the path has been above 0 and ends there, as with the
    tolerance moved across eps/3 either way; both implementations alike."""
    from compass_sparse.path import _kernels as PK

    if t_progress is not None:
        monkeypatch.setattr(PK, "T_PROGRESS", t_progress)
    (M, q, lb, ub), _ = _degenerate_start_lcp()
    py, cc = _both((M, q, lb, ub), x=np.array([0.0, -eps, 1.0]))
    _assert_same_path(py, cc, M, q)
    assert cc.code is code, cc.message
    if code is LinearCode.RAY:
        assert cc.message == "t decreased to 0" and cc.pivots <= 3
        assert abs(cc.t - eps / 3.0) <= 1e-3 * eps  # the path's best point
    else:
        assert np.allclose(cc.z, [0.0, 3.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_singular_inward_guess_falls_back_to_the_slack_basis_in_the_engine(seed):
    """A start where the inward guess makes z_i basic on a zero column of M: the guessed
    basis is singular (an artificial repairs it), so the path starts again on the basis
    without the guess.  The engine does this inside its one start call; it gives the
    Python loop's path (same code, pivots, point and basis)."""
    import scipy.sparse as sps

    rng = np.random.default_rng(seed)
    n = 6
    M = rng.standard_normal((n, n)) + n * np.eye(n)
    j = int(rng.integers(n))
    M[:, j] = 0.0  # z_j's column: dependent whenever z_j is basic
    M[j, j] = 0.0
    q = rng.standard_normal(n)
    q[j] = -1.0  # F_j < 0 at z = 0: the residual pushes z_j inwards
    lb, ub = np.zeros(n), np.full(n, np.inf)
    x = np.zeros(n)  # z = 0 at the lower bounds with no slack value: the guess applies
    Ms = sps.csc_matrix(M)
    r = Ms @ x + q
    assert r[j] < 0.0
    py, cc = _both((Ms, q, lb, ub), x=x, r=r)
    _assert_same_path(py, cc, Ms, q)


def test_dense_engine_refills_its_matrix_in_place_from_each_linearization():
    """The engine's dense copy of M is allocated once per order and refilled by every
    set_matrix: CSC (duplicates summed, unsorted indices), other sparse formats and dense
    input give M exactly; a new order gets a new array."""
    from compass_sparse.path.dense_engine import DensePathEngine

    rng = np.random.default_rng(4)
    A = sp.random(6, 6, density=0.5, format="csc", random_state=4)
    eng = DensePathEngine(A)
    buf = eng.M
    np.testing.assert_array_equal(eng.M, A.toarray())
    dup = sp.csc_matrix((np.array([1.0, 2.0, 3.0]), np.array([4, 1, 4]),
                         np.array([0, 3, 3, 3, 3, 3, 3])), shape=(6, 6))
    eng.set_matrix(dup)
    assert eng.M is buf and eng.M.flags.f_contiguous
    np.testing.assert_array_equal(eng.M, dup.toarray())
    D = rng.standard_normal((6, 6))
    for M in (sp.csr_matrix(D), D):
        eng.set_matrix(M)
        assert eng.M is buf
        np.testing.assert_array_equal(eng.M, D)
    eng.set_matrix(sp.identity(3, format="csc"))
    assert eng.M.shape == (3, 3) and eng.n == 3
    np.testing.assert_array_equal(eng.M, np.eye(3))

