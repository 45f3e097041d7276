"""The box [l, u] and the vectors of a solve: projection, norms, float-vector tests.

pi(x) = min(max(x, l), u) is the projection on the box (thesis §3.1: the normal map
F_B(x) = F(pi(x)) + x - pi(x) is built on it).  The norms here are the ones every pass
reads several times per iteration -- ||x||_inf and ||x - y||_inf in one compiled pass,
||v||_2 as the square root of v . v (what np.linalg.norm computes for a real vector, without
its dispatch) -- and the tests of whether a vector is the solver's own float64 vector,
which the compiled kernels take as they are.
"""
from __future__ import annotations

import math

import numpy as np

from ._merit_kernels import all_finite_kernel, max_abs_kernel

__all__ = ["F64", "all_finite", "broadcast_box", "dot_norm", "float_vector", "float_vectors",
           "max_abs", "max_abs_diff", "norm2", "project", "solver_vectors"]


F64 = np.dtype(np.float64)
"""The float64 dtype object (tested by identity: ``==`` converts np.float64 first)."""


def float_vector(x) -> bool:
    """x is a float64 vector, the compiled kernels' argument (every point of a solve).
    (Identity tests: a tenth of a microsecond where ``dtype ==`` and the flags cost a
    microsecond, asked several times at every evaluated point.)"""
    return x.__class__ is np.ndarray and x.ndim == 1 and x.dtype is F64


def solver_vectors(z, f, lb, ub) -> bool:
    """z, F, l, u are float64 vectors of one length: the solver's own vectors at every
    evaluated point, handed straight to the compiled kernels (a microsecond of tests
    instead of the conversions of the general case)."""
    return (float_vector(z) and float_vector(f) and float_vector(lb) and float_vector(ub)
            and z.shape == f.shape == lb.shape == ub.shape)


def broadcast_box(lb, ub, z):
    """Broadcast scalar (or array) bounds to the shape of z (no validation: that is
    :func:`compass_sparse.problem.as_bounds`, for user input)."""
    if (isinstance(lb, np.ndarray) and isinstance(ub, np.ndarray) and lb.shape == z.shape
            and ub.shape == z.shape and lb.dtype == float and ub.dtype == float):
        return lb, ub  # the solver's own bound arrays: nothing to broadcast
    return (np.broadcast_to(np.asarray(lb, dtype=float), z.shape),
            np.broadcast_to(np.asarray(ub, dtype=float), z.shape))


def project(x, lb, ub):
    """pi(x): the projection of x on the box [lb, ub]."""
    return np.minimum(np.maximum(x, lb), ub)


def max_abs(x) -> float:
    """||x||_inf of a vector (0 when empty; NaN when x holds a NaN), in one compiled pass
    for a float vector: np.max(np.abs(x)) costs ~5 us of dispatch on a short one, and the
    solver asks it several times per major iteration."""
    if float_vector(x):
        return float(max_abs_kernel(x, x, False))
    x = np.asarray(x, dtype=float)
    return float(np.max(np.abs(x))) if x.size else 0.0


def max_abs_diff(x, y) -> float:
    """||x - y||_inf of two vectors of one length (as :func:`max_abs`)."""
    if float_vector(x) and float_vector(y) and x.shape == y.shape:
        return float(max_abs_kernel(x, y, True))
    return max_abs(np.asarray(x, dtype=float) - np.asarray(y, dtype=float))


def dot_norm(v) -> float:
    """||v||_2 of a float vector as the square root of v . v, which is what np.linalg.norm
    computes for a real vector (the same bits), without its dispatch (~4 us; the crash and
    the homotopy's corrector ask several per step).  (:func:`norm2` scales against
    overflow instead.)"""
    return math.sqrt(float(v.dot(v)))


def norm2(v, inf_norm=None) -> float:
    """||v||_2 without underflow or overflow of the squares (``inf_norm``: ||v||_inf when
    known)."""
    if inf_norm is not None:
        m = float(inf_norm)
    else:
        m = float(np.abs(v).max()) if v.size else 0.0
    if m == 0.0 or not math.isfinite(m):
        return m
    s = v / m
    return m * math.sqrt(float(np.dot(s, s)))  # (the correctly rounded root, as np.sqrt)


def all_finite(x) -> bool:
    """Whether every entry of the array x is finite; a float vector (every point of a
    solve) in one compiled pass, a quarter of np.isfinite(x).all() on a short vector."""
    if float_vector(x):
        return bool(all_finite_kernel(x))
    return bool(np.isfinite(x).all())


def float_vectors(n, *arrays) -> bool:
    """All float64 vectors of length n (the compiled kernels' arguments)."""
    shape = (n,)
    for a in arrays:  # (a loop, not all(...): this runs several times per path)
        # (the dtype by identity, as float_vector: ``==`` converts np.float64 first)
        if not (isinstance(a, np.ndarray) and a.dtype is F64 and a.shape == shape):
            return False
    return True


def random_point(rng, z0, lb, ub):
    """A uniform point of the box; unbounded directions get a range that grows with the
    start point's magnitude, 10 (1 + |z0_i|) on each side."""
    spread = 10.0 * (1.0 + np.abs(z0))
    lo = np.where(np.isfinite(lb), lb, z0 - spread)
    hi = np.where(np.isfinite(ub), ub, z0 + spread)
    return rng.uniform(lo, hi)


def near_point(rng, z, lb, ub):
    """z moved by up to 10% of the box width (of 1 + |z_i| where unbounded), projected."""
    width = np.where(np.isfinite(ub - lb), ub - lb, 1.0 + np.abs(z))
    return project(z + 0.1 * width * rng.uniform(-1, 1, z.size), lb, ub)
