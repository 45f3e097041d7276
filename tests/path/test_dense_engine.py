"""The small-problem engine (compass_sparse.path.dense_engine): its repair against the
thesis' rule, the time limit between pivot chunks, artificials at zero, t at its bound,
its matrix refilled in place.  Its paths against the Python pivot loop, from degenerate
starts too: tests/routes/test_path_routes.py.

The ordinary path tests (tests/path/test_pivotal.py) run with this engine as a third
manager; its LU and Forrest-Tomlin kernels are checked against numpy in
tests/path/test_dense_lu.py."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import Options
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


def test_engine_path_stops_at_the_time_limit_between_pivot_chunks(monkeypatch):
    """The deadline is checked between compiled chunks of pivots: with a chunk of one
    pivot and a deadline in the past the path stops after one pivot."""
    import time

    monkeypatch.setattr(DensePathEngine, "chunk", 1)
    g = gen.p_matrix_lcp(50, "grid", 1, "ncp")
    M, q, lb, ub = g.lcp
    res = PivotalPath(M, q, lb, ub, DensePathEngine(M), Options(),
                      deadline=time.perf_counter() - 1.0).run(np.zeros(q.size))
    assert res.code is LinearCode.MINOR_LIMIT
    assert res.message == "time limit during the path"
    assert res.pivots == 1


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
