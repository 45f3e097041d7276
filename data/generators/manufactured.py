"""Manufactured solutions: make a chosen point z* the solution of an MCP.

Given any smooth F, bounds [l, u] and a point z* in the box, split the indices into

* interior  I:  l_i < z*_i < u_i,   multiplier 0,
* at lower  L:  z*_i = l_i,         w*_i >= 0 (w*_i = 0: a *degenerate* index),
* at upper  U:  z*_i = u_i,         v*_i >= 0 (v*_i = 0: degenerate),

and define the shifted function

    F~(z) = (F(z) - F(z*)) + (w* - v*).

Then F~(z*) = w* - v* exactly (the first bracket is exactly zero at z* because F is
deterministic), so z* solves MCP(F~, [l, u]) with no rounding error at all.  Size,
sparsity (the Jacobian is J itself) and degeneracy are all under control.  A fixed
variable (l_i = u_i) is "at lower" and its multiplier may have either sign.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from compass_sparse.problem import MCP, as_bounds

__all__ = ["ManufacturedPoint", "manufactured_point", "manufacture", "quantize"]

INTERIOR, AT_LOWER, AT_UPPER = 0, 1, 2


def quantize(x, quantum):
    """Round to the nearest multiple of ``quantum`` (a power of two keeps this exact), so that
    sums and products of few such numbers are computed without rounding error."""
    if quantum is None:
        return np.asarray(x, dtype=float)
    return np.round(np.asarray(x, dtype=float) / quantum) * quantum


@dataclass
class ManufacturedPoint:
    """A point z* with complementary multipliers: F(z*) = w - v makes it a solution.

    kind[i] is 0 (interior), 1 (at lower bound) or 2 (at upper bound); ``degenerate`` marks
    active indices whose multiplier is zero (strict complementarity fails there)."""

    z: np.ndarray
    w: np.ndarray
    v: np.ndarray
    kind: np.ndarray
    degenerate: np.ndarray

    @property
    def target(self) -> np.ndarray:
        """The value F must take at z*: w - v."""
        return self.w - self.v


def _rng(seed):
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def manufactured_point(
    lb,
    ub,
    seed=0,
    *,
    mix=(0.5, 0.25, 0.25),
    degenerate_fraction: float = 0.0,
    multiplier_range=(0.5, 2.0),
    interior_scale: float = 1.0,
    quantum: float | None = None,
) -> ManufacturedPoint:
    """Draw z* in [lb, ub] with a mix of interior / at-lower / at-upper components.

    mix : fractions (interior, at_lower, at_upper), normalized.  An index asked to sit at
        an infinite bound sits at the other bound if that is finite, else inside.
    degenerate_fraction : fraction of the active indices that get a zero multiplier.
    multiplier_range : active multipliers are drawn uniformly from this range.
    interior_scale : spread of interior values from a one-sided bound (or from 0 when free).
    quantum : round z*, w*, v* to multiples of this (use a power of two, and bounds that
        are multiples of it, to keep linear manufactured data exact in floating point).

    Everything is drawn vectorized from ``numpy.random.default_rng(seed)`` (or the given
    Generator), so the result depends only on the seed and the bounds.
    """
    rng = _rng(seed)
    lb = np.asarray(lb, dtype=float)
    ub = np.asarray(ub, dtype=float)
    n = lb.size
    p = np.asarray(mix, dtype=float)
    if p.shape != (3,) or np.any(p < 0) or p.sum() <= 0:
        raise ValueError("mix must be three non-negative fractions (interior, lower, upper)")
    p = p / p.sum()
    finl, finu = np.isfinite(lb), np.isfinite(ub)
    u = rng.random(n)
    kind = np.where(u < p[0], INTERIOR, np.where(u < p[0] + p[1], AT_LOWER, AT_UPPER))
    kind = kind.astype(np.int8)
    bad_l = (kind == AT_LOWER) & ~finl
    kind[bad_l] = np.where(finu[bad_l], AT_UPPER, INTERIOR)
    bad_u = (kind == AT_UPPER) & ~finu
    kind[bad_u] = np.where(finl[bad_u], AT_LOWER, INTERIOR)
    fixed = finl & finu & (lb == ub)
    kind[fixed] = AT_LOWER

    # interior values, all drawn for every index (determinism independent of the kinds)
    t_box = rng.uniform(0.1, 0.9, n)
    t_one = rng.uniform(0.1, 1.0, n) * interior_scale
    t_free = rng.uniform(-1.0, 1.0, n) * interior_scale
    with np.errstate(invalid="ignore"):
        zi = np.where(
            finl & finu, lb + (ub - lb) * t_box,
            np.where(finl, lb + t_one, np.where(finu, ub - t_one, t_free)),
        )
    if quantum is not None:
        zq = quantize(zi, quantum)
        inside = (zq > lb) & (zq < ub)
        zi = np.where(inside, zq, zi)
    z = np.where(kind == AT_LOWER, lb, np.where(kind == AT_UPPER, ub, zi))

    mag = quantize(rng.uniform(multiplier_range[0], multiplier_range[1], n), quantum)
    sign_fixed = rng.random(n) < 0.5
    active = np.flatnonzero((kind != INTERIOR) & ~fixed)
    k = int(round(degenerate_fraction * active.size))
    deg_idx = rng.choice(active, size=k, replace=False) if k > 0 else np.array([], dtype=int)
    degenerate = np.zeros(n, dtype=bool)
    degenerate[deg_idx] = True
    mag = np.where(degenerate, 0.0, mag)
    w = np.where(kind == AT_LOWER, mag, 0.0)
    v = np.where(kind == AT_UPPER, mag, 0.0)
    # a fixed variable's multiplier may have either sign
    w = np.where(fixed & sign_fixed, 0.0, w)
    v = np.where(fixed & sign_fixed, mag, v)
    return ManufacturedPoint(z=z, w=w, v=v, kind=kind, degenerate=degenerate)


def _multipliers_for(z, lb, ub, rng, degenerate_fraction, multiplier_range):
    """Multipliers for a given z*: positive where z* sits at a bound, zero elsewhere."""
    n = z.size
    at_l = np.isfinite(lb) & (z == lb)
    at_u = np.isfinite(ub) & (z == ub) & ~at_l
    kind = np.where(at_l, AT_LOWER, np.where(at_u, AT_UPPER, INTERIOR)).astype(np.int8)
    mag = rng.uniform(multiplier_range[0], multiplier_range[1], n)
    active = np.flatnonzero(kind != INTERIOR)
    k = int(round(degenerate_fraction * active.size))
    degenerate = np.zeros(n, dtype=bool)
    if k > 0:
        degenerate[rng.choice(active, size=k, replace=False)] = True
    mag[degenerate] = 0.0
    w = np.where(at_l, mag, 0.0)
    v = np.where(at_u, mag, 0.0)
    return ManufacturedPoint(z=z, w=w, v=v, kind=kind, degenerate=degenerate)


class _Shifted:
    """F~(z) = (F(z) - F(z*)) + (w* - v*); picklable, keeps the pieces for inspection."""

    def __init__(self, F, f_star, target, pair: bool):
        self.F0 = F
        self.f_star = f_star
        self.target = target
        self.pair = pair

    def __call__(self, z):
        if self.pair:
            f, J = self.F0(z)
            return (np.asarray(f, dtype=float) - self.f_star) + self.target, J
        return (np.asarray(self.F0(z), dtype=float) - self.f_star) + self.target


def manufacture(
    F,
    jac,
    z_star,
    lb,
    ub,
    seed=0,
    *,
    active_fraction: float = 0.5,
    degenerate_fraction: float = 0.0,
    multiplier_range=(0.5, 2.0),
    w_star=None,
    v_star=None,
    x0=None,
    name: str = "manufactured",
    info: dict | None = None,
    **mcp_kwargs,
):
    """Build MCP(F~, [lb, ub]) with F~(z) = F(z) - F(z*) + w* - v*, so z* is a solution.

    F, jac : the base function and its Jacobian (as for :class:`MCP`; ``jac=True`` means F
        returns ``(f, J)``).  The Jacobian of F~ is the Jacobian of F.
    z_star : the solution, or None to draw one with :func:`manufactured_point` (a fraction
        ``active_fraction`` of the indices at bounds, split evenly between lower and upper).
    w_star, v_star : multipliers; by default drawn from ``multiplier_range`` on the indices
        where z* sits at a bound, with ``degenerate_fraction`` of them set to zero.
    Remaining keyword arguments go to :class:`MCP` (jac_sparsity, var_names, constant_jac,
    ...).  Returns a :class:`GeneratedProblem` whose info holds w*, v*, the kinds and F(z*).
    """
    from . import GeneratedProblem

    rng = _rng(seed)
    if z_star is not None:
        z_star = np.asarray(z_star, dtype=float).ravel()
        n = z_star.size
    else:
        n = None
        for b in (lb, ub, x0):
            if b is not None and np.ndim(b) > 0:
                n = np.size(b)
                break
        if n is None:
            raise ValueError("give z_star or array bounds so that the dimension is known")
    lo, hi = as_bounds(lb, ub, n)
    if z_star is None:
        a = float(active_fraction)
        pt = manufactured_point(
            lo, hi, rng, mix=(1.0 - a, a / 2, a / 2), degenerate_fraction=degenerate_fraction,
            multiplier_range=multiplier_range,
        )
    else:
        if np.any(z_star < lo) or np.any(z_star > hi) or not np.all(np.isfinite(z_star)):
            i = int(np.flatnonzero(~((z_star >= lo) & (z_star <= hi)))[0])
            raise ValueError(f"z_star[{i}] = {z_star[i]} is outside [{lo[i]}, {hi[i]}]")
        pt = _multipliers_for(z_star, lo, hi, rng, degenerate_fraction, multiplier_range)
    if w_star is not None or v_star is not None:
        w = np.zeros(n) if w_star is None else np.asarray(w_star, dtype=float).ravel()
        v = np.zeros(n) if v_star is None else np.asarray(v_star, dtype=float).ravel()
        if np.any(w < 0) or np.any(v < 0):
            raise ValueError("multipliers w*, v* must be non-negative")
        if np.any((w > 0) & (pt.z != lo)) or np.any((v > 0) & (pt.z != hi)):
            raise ValueError("w* may be positive only where z* = lb, v* only where z* = ub")
        pt = ManufacturedPoint(z=pt.z, w=w, v=v, kind=pt.kind,
                               degenerate=(pt.kind != INTERIOR) & (w == 0) & (v == 0))
    z = pt.z
    pair = jac is True
    out = F(z.copy())
    f_star = np.asarray(out[0] if pair else out, dtype=float).reshape(n).copy()
    Ft = _Shifted(F, f_star, pt.target.copy(), pair)
    problem = MCP(Ft, jac, lo, hi, x0, **mcp_kwargs)
    inf = dict(info or {})
    inf.update(w_star=pt.w, v_star=pt.v, kind=pt.kind, degenerate=pt.degenerate, F_star=f_star)
    return GeneratedProblem(name=name, problem=problem, solution=z.copy(), info=inf)
