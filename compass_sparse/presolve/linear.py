"""Which Jacobian entries and rows the preprocessor may treat as linear.

Only entries *declared* constant (``MCP(constant_jac=...)``) are ever used.  A row whose
remaining entries are all declared constant is affine in the remaining variables.

A row without any pattern entry is constant only when the problem says so: its pattern is
declared (``jac_sparsity=``, a contract that J never holds an entry outside it).  A
pattern recorded from J at the start point proves nothing -- a J assembled from arrays
drops the zeros of that point (F = x^3 - 2 has J = 0 at x = 0) -- so such a row is
nonlinear to presolve: no reduction and no infeasibility verdict rests on it.

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

__all__ = ["declared_constant_mask", "empty_row_status", "sample_evaluations"]


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


def sample_evaluations(problem, options):
    """(x, F(x), J(x)) at the points used for verification (empty when off or when an
    evaluation fails inside the box; an undeclared pattern may grow on the way)."""
    if not options.verify_linear:
        return []
    rng = np.random.default_rng(options.seed)
    out = []
    try:
        for x in _sample_points(problem, rng):
            out.append((x, problem.F(x), problem.J(x)))
    except Exception as exc:  # evaluation failed inside the box
        return exc
    return out


def empty_row_status(problem, J0):
    """(certain, nonlinear): masks over the rows without a pattern entry -- constant by
    declaration, or not known to be constant (see the module docstring)."""
    empty = np.bincount(J0.indices, minlength=problem.n) == 0
    if problem.pattern_declared:
        return empty, np.zeros(problem.n, dtype=bool)
    return np.zeros(problem.n, dtype=bool), empty


def declared_constant_mask(problem, J0, f0, options, warnings, samples=None):
    """Mask over the pattern entries (CSC order) that presolve may treat as constant."""
    nnz = J0.indptr[-1]
    mask = problem.constant_mask
    mask = np.zeros(nnz, dtype=bool) if mask is None else np.asarray(mask, dtype=bool).copy()
    if not options.verify_linear or not mask.any():
        return mask
    if samples is None:
        samples = sample_evaluations(problem, options)
    if isinstance(samples, list) and not samples:
        return mask  # no sample point: nothing to check (the driver's first call)
    if not isinstance(samples, list):
        # evaluation failed inside the box: keep the declaration
        warnings.append(f"could not verify the declared linear entries ({samples!r})")
        return mask
    n = problem.n
    er = J0.indices
    ec = np.repeat(np.arange(n), np.diff(J0.indptr))
    for x, f, J in samples:
        J = problem.evaluator.on_pattern(J)
        moved = mask & (J.data != J0.data)
        if moved.any():
            k = int(np.flatnonzero(moved)[0])
            warnings.append(
                f"{int(moved.sum())} Jacobian entries declared constant change value, "
                f"e.g. (row {problem.row_label(int(er[k]))}, column "
                f"{problem.var_label(int(ec[k]))}): {J0.data[k]:.6g} vs {J.data[k]:.6g}; "
                "presolve treats them as nonlinear")
            mask &= ~moved
        # rows without entries are judged by empty_row_status
        all_const = (np.bincount(er[~mask], minlength=n) == 0) & (np.bincount(er, minlength=n) > 0)
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
    return mask
