"""The homotopy's paths (compass_sparse.homotopy.paths): later paths from random points
around the center, the random generator made only when needed, the BLAS thread limit."""

import numpy as np
import pytest

import known_problems as kp

import compass_sparse.homotopy.paths as paths
import compass_sparse.homotopy.tracker as hom
from compass_sparse import MCP, Options, solve_mcp
from compass_sparse.generators import thesis_family
from compass_sparse.homotopy import track_paths


def test_later_homotopy_paths_start_at_random_points_around_the_center(monkeypatch):
    """track_paths: path 1 from z_start, paths 2 and 3 from random points of the box drawn
    around ``center`` (a one-step limit ends every path)."""
    g = thesis_family(10, 2, 1)
    p = g.problem
    starts, centers = [], []
    follow, draw = hom.Tracker.follow, paths.random_point

    def spy_follow(self, a, polish=None):
        starts.append(a.copy())
        return follow(self, a, polish=polish)

    def spy_draw(rng, z0, lb, ub):
        centers.append(np.array(z0, copy=True))
        return draw(rng, z0, lb, ub)

    monkeypatch.setattr(hom.Tracker, "follow", spy_follow)
    monkeypatch.setattr(paths, "random_point", spy_draw)
    z1 = np.clip(p.x0 + 0.5, p.lb, p.ub)
    out = track_paths(p.evaluator, p.lb, p.ub, z1, Options(homotopy_step_limit=1),
                      center=p.x0, rng=np.random.default_rng(0))
    assert out.paths == 3 and len(starts) == 3 and len(centers) == 2
    np.testing.assert_array_equal(starts[0], z1)
    for c in centers:
        np.testing.assert_array_equal(c, p.x0)
    assert not any(np.array_equal(s, z1) or np.array_equal(s, p.x0) for s in starts[1:])


def test_homotopy_random_generator_is_made_only_when_a_second_path_starts():
    """The generator of the later paths' start points is asked for when a second path
    starts, and only then: a pass that ends on its first path never makes it."""
    F, J, lb, ub, x0 = kp.diverging_free()
    made = []

    def rng():
        made.append(1)
        return np.random.default_rng(0)

    out = track_paths(MCP(F, J, lb, ub, x0).evaluator, lb, ub, x0,
                      Options(homotopy_path_limit=3), rng=rng)
    assert out.paths == 3 and len(made) == 1
    made.clear()
    out = track_paths(MCP(F, J, lb, ub, x0).evaluator, lb, ub, x0,
                      Options(homotopy_path_limit=1), rng=rng)
    assert out.paths == 1 and made == []


@pytest.mark.parametrize("n", [10, 20])
def test_homotopy_pass_limits_blas_threads_only_from_blas_limit_min_n(monkeypatch, n):
    """The homotopy pass sets BLAS to one thread around its dense factorizations from
    BLAS_LIMIT_MIN_N on; below it (OpenBLAS keeps such small kernels on one thread) the
    thread count is not touched."""
    import contextlib

    from compass_sparse.linalg.blas import BLAS_LIMIT_MIN_N

    entered = []

    def counting():
        entered.append(1)
        return contextlib.nullcontext()

    monkeypatch.setattr(paths, "single_threaded_blas", counting)
    r = solve_mcp(thesis_family(n, 2, 1).problem, options={"homotopy": "only"})
    assert r.passes["homotopy"].ran
    assert len(entered) == (1 if n >= BLAS_LIMIT_MIN_N else 0)
