"""The smoothed projection and normal map of the homotopy (compass_sparse.homotopy.smoothing):
its limit and error bound, its derivatives, its compiled kernel's bits, extreme
smoothing, and the smoothing scale."""

import numpy as np
import pytest

import compass_sparse.homotopy.tracker as hom
from compass_sparse import Options
from compass_sparse.homotopy import SmoothedNormalMap


# ------------------------------------------------------------------ the smoothed projection
@pytest.mark.parametrize("mu", [1e-1, 1e-4, 1e-8])
def test_smoothed_projection_tends_to_the_projection_with_error_at_most_mu(mu):
    lb = np.array([-1.0, -1.0, -np.inf, -np.inf, 0.0])
    ub = np.array([2.0, np.inf, 3.0, np.inf, 0.0])
    sm = SmoothedNormalMap(lb, ub)
    rng = np.random.default_rng(0)
    for x in list(rng.uniform(-5, 5, (50, 5))) + [np.array([-1e12, 1e12, 1e12, -1e12, 1.0])]:
        p, dx, dmu = sm.project(x, mu)
        # |s_mu(r) - max(r, 0)| <= mu, and both bounds contribute at most mu each
        assert np.all(np.abs(p - np.clip(x, lb, ub)) <= 2 * mu + 1e-12 * np.abs(x))
        assert np.all((dx >= 0) & (dx <= 1))
        assert np.all(np.isfinite(dmu))


def test_smoothed_projection_derivatives_match_finite_differences():
    lb = np.array([-1.0, -1.0, -np.inf, -np.inf])
    ub = np.array([2.0, np.inf, 3.0, np.inf])
    sm = SmoothedNormalMap(lb, ub)
    x = np.array([-0.9, 0.3, 2.95, 7.0])
    mu, h = 0.05, 1e-7
    p, dx, dmu = sm.project(x, mu)
    fd_x = (sm.project(x + h, mu)[0] - sm.project(x - h, mu)[0]) / (2 * h)
    fd_mu = (sm.project(x, mu + h)[0] - sm.project(x, mu - h)[0]) / (2 * h)
    assert dx == pytest.approx(fd_x, rel=1e-6, abs=1e-8)
    assert dmu == pytest.approx(fd_mu, rel=1e-6, abs=1e-8)


@pytest.mark.parametrize("mu", [1.0, 1e-3, 1e-8, 0.0, 1e-200, 1e200])
def test_compiled_smoothed_projection_gives_the_array_formulas_bits(mu):
    lb = np.array([-1.0, -1.0, -np.inf, -np.inf, 0.0, 2.0])
    ub = np.array([2.0, np.inf, 3.0, np.inf, 0.0, 2.0])
    sm = SmoothedNormalMap(lb, ub)
    rng = np.random.default_rng(1)
    xs = list(rng.uniform(-5, 5, (100, 6))) + [np.array([-1e12, 1e12, 1e12, -1e12, 1.0, 2.0]),
                                                np.array([-1.0, -1.0, 3.0, 0.0, 0.0, 2.0])]
    for x in xs:
        for got, ref in zip(sm.project(x, mu), sm.project_arrays(x, mu)):
            assert np.array_equal(got, ref)


@pytest.mark.parametrize("mu", [1e-300, 1e300])
def test_extreme_homotopy_smoothing_does_not_turn_the_smoothed_projection_into_nan(mu):
    # mu^2 underflowed to 0 below 1e-154 (0/0 where x sits on a bound) and overflowed above
    # 1e154: the path then ended on NaN with numpy warnings.  Both ends of the option's
    # range now give the same projection as a moderate mu would in the limit.
    import warnings

    lb, ub = np.array([0.0, -1.0, -np.inf]), np.array([np.inf, 1.0, 2.0])
    x = np.array([0.0, 1.0, -3.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        p, dx, dmu = SmoothedNormalMap(lb, ub).project(x, mu)
    assert np.all(np.isfinite(p)) and np.all(np.isfinite(dx)) and np.all(np.isfinite(dmu))
    assert np.all((lb <= p) & (p <= ub))
    if mu < 1:  # the smoothing vanishes: the projection itself
        np.testing.assert_allclose(p, np.clip(x, lb, ub), atol=1e-12)


def test_tracker_smoothing_scale_is_numpys_median_of_the_finite_widths():
    """mu0 = homotopy_smoothing * max(median of the finite box widths, 1e-8), the median
    taken without np.median's dispatch: np.median's value for odd and even counts, 1 when
    no width is finite."""
    rng = np.random.default_rng(2)
    opt = Options()
    for n in (1, 2, 3, 7, 10, 31):
        for _ in range(10):
            lb = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4)
            ub = lb + rng.random(n) * 10.0 ** rng.integers(-3, 4)
            lb[rng.random(n) < 0.3] = -np.inf
            tr = hom.Tracker(None, lb, ub, opt, deadline=None, on_point=None, tol=1e-6,
                              log=None)
            w = (ub - lb)[np.isfinite(ub - lb)]
            want = opt.homotopy_smoothing * max(float(np.median(w)) if w.size else 1.0,
                                                1e-8)
            assert tr.mu0 == want
