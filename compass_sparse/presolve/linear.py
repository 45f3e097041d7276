"""Which Jacobian entries the preprocessor may treat as linear.

Only entries *declared* constant (``MCP(constant_jac=...)``) are ever used.  A row whose
remaining entries are all declared constant is affine in the remaining variables; a row
without any pattern entry is constant (the pattern is part of the problem's contract).

``verify_linear`` adds a conservative check, never a source of linearity: J is evaluated at
two more points of the box; a declared-constant entry whose value differs (bitwise) from its
value at the start point is no longer trusted, and a row whose entries are all declared
constant but whose F change disagrees with J times the step (relative 1e-8) loses its
linear status.  Both produce a warning naming the entry or row.  Agreement at three
points does not prove linearity, which is why detection is never used to *add* linear
entries.
"""
from __future__ import annotations

import numpy as np

__all__ = ["declared_constant_mask"]


def _sample_points(problem, rng, k=2):
    x0, lb, ub = problem.x0, problem.lb, problem.ub
    pts = []
    for _ in range(k):
        step = rng.uniform(-1.0, 1.0, size=x0.size) * np.maximum(1.0, np.abs(x0))
        x = x0 + step
        both = np.isfinite(lb) & np.isfinite(ub)
        x[both] = lb[both] + rng.random(np.count_nonzero(both)) * (ub[both] - lb[both])
        pts.append(np.clip(x, lb, ub))
    return pts


def declared_constant_mask(problem, J0, f0, options, warnings):
    """Mask over the pattern entries (CSC order) that presolve may treat as constant."""
    nnz = J0.indptr[-1]
    mask = problem.constant_mask
    mask = np.zeros(nnz, dtype=bool) if mask is None else np.asarray(mask, dtype=bool).copy()
    if not options.verify_linear or not mask.any():
        return mask
    rng = np.random.default_rng(options.seed)
    n = problem.n
    er = J0.indices
    ec = np.repeat(np.arange(n), np.diff(J0.indptr))
    try:
        for x in _sample_points(problem, rng):
            f = problem.F(x)
            J = problem.J(x)
            moved = mask & (J.data != J0.data)
            if moved.any():
                k = int(np.flatnonzero(moved)[0])
                warnings.append(
                    f"{int(moved.sum())} Jacobian entries declared constant change value, "
                    f"e.g. (row {problem.row_label(int(er[k]))}, column "
                    f"{problem.var_label(int(ec[k]))}): {J0.data[k]:.6g} vs {J.data[k]:.6g}; "
                    "presolve treats them as nonlinear")
                mask &= ~moved
            all_const = np.bincount(er[~mask], minlength=n) == 0
            dx = x - problem.x0
            pred = J0 @ dx
            df = f - f0
            scale = 1.0 + np.abs(f) + np.abs(f0) + np.abs(J0) @ np.abs(dx)
            off = all_const & ~(np.abs(df - pred) <= 1e-8 * scale)
            if off.any():
                i = int(np.flatnonzero(off)[0])
                warnings.append(
                    f"{int(off.sum())} rows with only declared-constant Jacobian entries are "
                    f"not affine, e.g. row {problem.row_label(i)} (F changed by {df[i]:.6g}, "
                    f"J predicts {pred[i]:.6g}); is an entry missing from the pattern? "
                    "Presolve treats these rows as nonlinear")
                mask &= ~off[er]
    except Exception as exc:  # evaluation failed inside the box: keep the declaration
        warnings.append(f"could not verify the declared linear entries ({exc!r})")
    return mask
