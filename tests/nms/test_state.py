"""The state of the major iterations (compass_sparse.nms.state)."""

from __future__ import annotations

import numpy as np


def test_point_norm_by_math_sqrt_equals_the_numpy_square_root():
    from compass_sparse.nms.state import Point

    rng = np.random.default_rng(0)
    psis = np.concatenate([rng.random(2000) * 10.0 ** rng.integers(-320, 308, 2000),
                           [0.0, 5e-324, 1e308, np.inf, np.nan]])
    e = np.zeros(1)
    for psi in psis:
        got = Point(e, e, e, float(psi)).fbn
        ref = float(np.sqrt(2.0 * float(psi)))  # (Python floats overflow to inf silently)
        assert got == ref or (np.isnan(got) and np.isnan(ref))
