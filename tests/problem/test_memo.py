"""The evaluation memo (compass_sparse.problem.memo): its key made once per point, a copy
of the point, never made for a point with a NaN; the finite tests by one dot product."""

from __future__ import annotations

import numpy as np
import pytest

from compass_sparse import MCP
from compass_sparse.problem.memo import Memo


def _cournot():
    def F(q):
        return np.array([1.0, 2.0]) - (10.0 - q.sum()) + q

    return MCP(F, lambda q: np.array([[2.0, 1.0], [1.0, 2.0]]), 0.0, np.inf, np.zeros(2))


@pytest.mark.parametrize("x, none", [
    (np.array([1.0, np.nan]), True),
    (np.array([np.inf, -np.inf, 1.0]), False),
    (np.array([1e200, -1e300, 5e-324]), False),
    (np.array([-0.0, 0.0]), False),
])
def test_memo_key_is_none_exactly_for_points_with_a_nan(x, none):
    k = Memo.key_of(x)
    assert (k is None) == none
    if not none:  # equal points (-0.0 == 0.0) share the key
        assert k == Memo.key_of(np.where(x == 0, 0.0, x))


def test_memo_key_made_once_still_finds_the_pinned_start_point():
    prob = _cournot()
    ev = prob.evaluator.fresh()
    x0 = np.array([0.5, 0.25])
    f0, J0 = ev.fj(x0)
    ev.pin(x0)
    calls = ev.counters.nfev, ev.counters.njev
    ev.fj(np.array([1.0, 1.0]))  # a later point replaces the last one, not the pinned one
    f, J = ev.fj(x0.copy())
    assert (ev.counters.nfev, ev.counters.njev) == (calls[0] + 1, calls[1] + 1)
    np.testing.assert_array_equal(f, f0)
    np.testing.assert_array_equal(J.toarray(), J0.toarray())


def test_memo_key_is_a_copy_so_a_point_changed_in_place_is_evaluated_again():
    calls = []

    def F(x):
        calls.append(x.copy())
        return x - 1.0

    prob = MCP(F, lambda x: np.eye(2), -np.inf, np.inf, np.zeros(2))
    ev = prob.evaluator.fresh()
    calls.clear()  # (the problem's start check evaluated F once)
    x = np.array([3.0, 4.0])
    np.testing.assert_array_equal(ev.F(x), [2.0, 3.0])
    x[0] = 5.0  # the caller reuses its array
    np.testing.assert_array_equal(ev.F(x), [4.0, 3.0])
    np.testing.assert_array_equal(ev.F(np.array([5.0, 4.0])), [4.0, 3.0])  # memo hit
    assert len(calls) == 2
    assert ev.F(np.array([-0.0, 4.0])) is not None and len(calls) == 3
    np.testing.assert_array_equal(ev.F(np.array([0.0, 4.0])), [-1.0, 3.0])  # -0.0 == 0.0
    assert len(calls) == 3


def test_memo_never_stores_or_matches_a_point_with_a_nan():
    calls = []

    def F(x):
        calls.append(1)
        return np.nan_to_num(x) - 1.0

    prob = MCP(F, lambda x: np.eye(2), -np.inf, np.inf, np.zeros(2))
    ev = prob.evaluator.fresh()
    calls.clear()
    bad = np.array([np.nan, 1.0])
    ev.F(bad)
    ev.F(bad)  # NaN equals nothing: evaluated again
    ev.J(bad)
    ev.J(bad)
    assert len(calls) == 2 and ev.counters.njev == 2
    good = np.array([2.0, 1.0])
    ev.F(good)
    ev.F(good.copy())
    assert len(calls) == 3


@pytest.mark.parametrize("seed", range(4))
def test_nan_and_finite_tests_by_one_dot_product_equal_numpy(seed):
    """The memo key's NaN flag and all_finite (the memo's and the evaluator's checks at
    every point, in one compiled pass for float vectors) give numpy's answers across
    magnitudes, with NaN, +-inf, subnormals, empty vectors, and on the numpy path for
    2-D and strided arrays."""
    from compass_sparse.box import all_finite
    from compass_sparse.problem.memo import Memo

    def has_nan(x):
        return Memo.probe(x)[2]

    rng = np.random.default_rng(seed)
    for n in (0, 1, 4, 50):
        for special in (None, np.nan, np.inf, -np.inf, 1e200, -1e300, 5e-324):
            x = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 150, n)
            if special is not None and n:
                x[rng.integers(n)] = special
            assert has_nan(x) == bool(np.isnan(x).any())
            assert all_finite(x) == bool(np.isfinite(x).all())
            for X in (np.vstack([x, x]) if n else np.zeros((2, 0)), x[::2]):
                assert has_nan(X) == bool(np.isnan(X).any())
                assert all_finite(X) == bool(np.isfinite(X).all())
