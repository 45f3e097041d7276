"""The box and vector toolkit (compass_sparse.box): the projection."""

from __future__ import annotations

import numpy as np


def test_project_gives_np_clip_bits_signed_zeros_and_infinite_bounds_included():
    """The start point's projection (box.project: np.minimum of np.maximum, which MCP
    uses instead of np.clip) gives np.clip's values bit for bit on validated bounds,
    signed zeros and infinite bounds included (20000 random boxes)."""
    from compass_sparse.box import project

    rng = np.random.default_rng(17)
    vals = np.array([0.0, -0.0, 1.0, -1.0, 2.5, -3e300, 5e-324, np.inf, -np.inf])
    for _ in range(20000):
        n = int(rng.integers(1, 7))
        x = rng.choice(vals[:7], n)
        a, b = rng.choice(vals, n), rng.choice(vals, n)
        lb, ub = np.minimum(a, b), np.maximum(a, b)
        assert project(x, lb, ub).tobytes() == np.clip(x, lb, ub).tobytes()
