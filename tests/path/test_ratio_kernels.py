"""The ratio test and the projection of the basic values (compass_sparse.path._kernels):
the compiled engines' versions, which read each slot's bounds from arrays and pass over
slots by a multiplication, against the definition written out here (every slot's bounds
from its kind, every ratio by a division) -- the same slot, the same values, bit for
bit, on random slot tables with every kind, ties to the last bit and ratios one unit in
the last place either side of the minimum."""
from __future__ import annotations

import numpy as np
import pytest

from compass_sparse.path import _kernels as PK
from compass_sparse.path._kernels import VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z


def _bounds(kind, idx, val, lb, ub, t_lower):
    if kind == VAR_Z:
        return lb[idx], ub[idx]
    if kind == VAR_S:
        return -np.inf, np.inf
    if kind == VAR_T:
        return t_lower, 1.0
    if kind == VAR_A:
        return (0.0, np.inf) if val >= -PK.ARTIFICIAL_ZERO else (-np.inf, 0.0)
    return 0.0, np.inf


def _reference(sk, si, xb, rate, lb, ub, piv_tol, tol, t_lower):
    """Harris' two passes as the definition states them (ratio_test's docstring)."""
    rooms = []
    for k in range(sk.size):
        r = rate[k]
        if -piv_tol <= r <= piv_tol:
            rooms.append(None)
            continue
        lo, hi = _bounds(sk[k], si[k], xb[k], lb, ub, t_lower)
        rooms.append((max(hi - xb[k], 0.0), hi) if r > 0.0 else (max(xb[k] - lo, 0.0), lo))
    theta1 = np.inf
    for k, rb in enumerate(rooms):
        if rb is not None and np.isfinite(rb[1]):
            theta1 = min(theta1, (rb[0] + tol * max(1.0, abs(rb[1]))) / abs(rate[k]))
    if not np.isfinite(theta1):
        return -1, np.inf, 0
    best, best_pri, best_piv, out = -1, -1, -1.0, (-1, np.inf, 0)
    for k, rb in enumerate(rooms):
        if rb is None or not np.isfinite(rb[1]) or rb[0] / abs(rate[k]) > theta1:
            continue
        pri = 2 if sk[k] == VAR_T else (1 if sk[k] == VAR_A else 0)
        if pri > best_pri or (pri == best_pri and abs(rate[k]) > best_piv):
            best, best_pri, best_piv = k, pri, abs(rate[k])
            out = (k, rb[0] / abs(rate[k]), 1 if rate[k] > 0.0 else 0)
    return out


def _table(seed, n=300):
    rng = np.random.default_rng(seed)
    sk = rng.choice([VAR_Z, VAR_Z, VAR_W, VAR_V, VAR_S, VAR_A], n).astype(np.int64)
    sk[rng.integers(n)] = VAR_T
    si = rng.permutation(n).astype(np.int64)
    lb = np.where(rng.random(n) < 0.2, -np.inf, -rng.random(n))
    ub = np.where(rng.random(n) < 0.3, np.inf, rng.random(n) + 0.5)
    xb = rng.uniform(-1.0, 1.5, n)
    xb[rng.random(n) < 0.2] = 0.0  # degenerate slots at a bound
    art = np.flatnonzero(sk == VAR_A)
    xb[art[: art.size // 3]] = -PK.ARTIFICIAL_ZERO * np.array([0.5, 1.0, 2.0] * n)[: art.size // 3]
    rate = rng.standard_normal(n)
    rate[rng.random(n) < 0.2] = 0.0
    rate[rng.random(n) < 0.1] = 1e-12  # within the pivot tolerance
    return sk, si, xb, rate, lb, ub


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("t_lower", [0.0, -np.inf])
def test_ratio_tests_agree_with_the_definition_bit_for_bit(seed, t_lower):
    sk, si, xb, rate, lb, ub = _table(seed)
    rng = np.random.default_rng(seed + 100)
    if seed % 2:
        # ties: equal rates and equal rooms on several slots, and ratios one ulp apart
        k = rng.choice(sk.size, 6, replace=False)
        sk[k], rate[k], xb[k] = VAR_W, -1.0, 0.25
        xb[k[3]] = np.nextafter(0.25, 1.0)
        xb[k[4]] = np.nextafter(0.25, 0.0)
    lo, hi = np.empty(sk.size), np.empty(sk.size)
    PK.slot_bounds(sk, si, lb, ub, lo, hi)
    for piv_tol, tol in ((1e-11, 1e-9), (0.0, 0.0), (1e-11, 1e-12)):
        want = _reference(sk, si, xb, rate, lb, ub, piv_tol, tol, t_lower)
        got = PK.ratio_test(sk, si, xb, rate, lb, ub, piv_tol, tol, t_lower)
        fast = PK.ratio_test_bounds(sk, si, xb, rate, lb, ub, lo, hi, piv_tol, tol, t_lower,
                                    np.empty(sk.size, np.int64), np.empty(sk.size))
        assert tuple(got) == tuple(want) == tuple(fast), (piv_tol, tol, want, got, fast)


@pytest.mark.parametrize("seed", range(10))
def test_projection_from_the_bound_arrays_is_the_projection(seed):
    """Artificials on both sides of -ARTIFICIAL_ZERO and t with its lower bound lifted
    keep their moving bounds (NaN in the arrays)."""
    sk, si, xb, rate, lb, ub = _table(seed)
    lo, hi = np.empty(sk.size), np.empty(sk.size)
    PK.slot_bounds(sk, si, lb, ub, lo, hi)
    assert np.all(np.isnan(lo[(sk == VAR_A) | (sk == VAR_T)]))
    for t_lower in (0.0, -np.inf):
        x = xb * 3.0 - 1.0
        a, b = x.copy(), x.copy()
        PK.project_slots(sk, si, a, lb, ub, t_lower)
        PK.project_bounds(sk, si, b, lb, ub, lo, hi, t_lower)
        assert np.array_equal(a, b)
        want = [min(max(x[k], _bounds(sk[k], si[k], x[k], lb, ub, t_lower)[0]),
                    _bounds(sk[k], si[k], x[k], lb, ub, t_lower)[1]) for k in range(sk.size)]
        assert np.array_equal(a, want)


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("skip", [-1, 0, 17])
def test_step_with_projection_is_the_step_then_the_projection(seed, skip):
    """advance_values (the engines' one pass) leaves xb bit for bit as the step
    ``xb += theta rate`` followed by project_bounds, artificials near zero and t included,
    and slot ``skip`` as it was."""
    sk, si, xb, rate, lb, ub = _table(seed)
    lo, hi = np.empty(sk.size), np.empty(sk.size)
    PK.slot_bounds(sk, si, lb, ub, lo, hi)
    for theta in (0.0, 0.37, 2.5):
        for t_lower in (0.0, -np.inf):
            ref = xb.copy()
            ref += theta * rate
            PK.project_bounds(sk, si, ref, lb, ub, lo, hi, t_lower)
            if skip >= 0:
                ref[skip] = xb[skip]
            got = xb.copy()
            PK.advance_values(sk, si, got, rate, theta, lb, ub, lo, hi, t_lower, skip)
            assert np.array_equal(got.view(np.int64), ref.view(np.int64))
            one = got.copy()
            if skip >= 0:
                one[skip] = 10.0 * (1 + abs(one[skip]))  # out of every finite bound
                PK.project_slot(skip, sk, si, one, lb, ub, lo, hi, t_lower)
                full = got.copy()
                full[skip] = 10.0 * (1 + abs(full[skip]))
                PK.project_bounds(sk, si, full, lb, ub, lo, hi, t_lower)
                assert np.array_equal(one.view(np.int64), full.view(np.int64))
