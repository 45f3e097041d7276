"""Compiled candidate scans of the preprocessor's passes.

Each pass first selects its candidate rows or columns with a mask expression over the
workspace's vectors (counts, activity, touched marks, bounds); on a small model that finds
nothing -- the common case: a CGE model whose only reduction is its fixed numeraire --
those expressions were most of the preprocessor's time (seven to ten array operations per
pass, ~0.6-1.3 ms per solve of a Ramsey or static model at n = 91-363, measured with the
solve around them).  Here each selection is one compiled pass that gives the same indices
as the expression it replaces (boolean tests and the same floating-point products, so the
same sets), and a pass with no candidate returns after it.
"""
from __future__ import annotations

import numpy as np

from .._jit import njit


@njit(cache=True)
def fixed_columns(col_active, lb, ub, touched_col):
    """flatnonzero(col_active & (lb == ub) & ~touched_col)."""
    n = lb.shape[0]
    out = np.empty(n, dtype=np.intp)
    k = 0
    for j in range(n):
        if col_active[j] and lb[j] == ub[j] and not touched_col[j]:
            out[k] = j
            k += 1
    return out[:k]


@njit(cache=True)
def linear_rows_with(linear, row_nnz, touched_row, lo, hi):
    """flatnonzero(linear & (lo <= row_nnz) & (row_nnz <= hi) & ~touched_row)."""
    n = row_nnz.shape[0]
    out = np.empty(n, dtype=np.intp)
    k = 0
    for i in range(n):
        if linear[i] and lo <= row_nnz[i] <= hi and not touched_row[i]:
            out[k] = i
            k += 1
    return out[:k]


@njit(cache=True)
def linear_columns_with(col_active, col_nnz, col_nl, touched_col, lb, ub, count,
                        finite_box):
    """flatnonzero(col_active & (col_nnz == count) & (col_nl == 0) & ~touched_col), and
    with ``finite_box`` only the columns whose bounds are both finite."""
    n = col_nnz.shape[0]
    out = np.empty(n, dtype=np.intp)
    k = 0
    for j in range(n):
        if (col_active[j] and col_nnz[j] == count and col_nl[j] == 0
                and not touched_col[j]
                and (not finite_box or (np.isfinite(lb[j]) and np.isfinite(ub[j])))):
            out[k] = j
            k += 1
    return out[:k]


@njit(cache=True)
def forcing_candidates(linear, row_nnz, touched_row, partner_var, lb, ub, fmin, fmax,
                       scale, ftol, up):
    """The rows of the forcing-rows pass: linear, with an entry, untouched, and
    |fmax| <= t with an upper bound +inf on the partner (``up[i]`` set) or |fmin| <= t
    with a lower bound -inf (t = ftol * scale_i); ``up`` is written at every row."""
    n = row_nnz.shape[0]
    out = np.empty(n, dtype=np.intp)
    k = 0
    for i in range(n):
        up[i] = False
        if not (linear[i] and row_nnz[i] >= 1 and not touched_row[i]):
            continue
        t = ftol * scale[i]
        p = partner_var[i]
        u = ub[p] == np.inf and np.isfinite(fmax[i]) and abs(fmax[i]) <= t
        d = lb[p] == -np.inf and np.isfinite(fmin[i]) and abs(fmin[i]) <= t
        up[i] = u
        if u or d:
            out[k] = i
            k += 1
    return out[:k]


@njit(cache=True)
def range_candidates(linear, touched_row, fmin, fmax, scale, ftol, low):
    """The rows of the range-fixing pass: linear, untouched, with fmin > t (``low[i]``
    set) or fmax < -t (t = ftol * scale_i); ``low`` is written at every row."""
    n = fmin.shape[0]
    out = np.empty(n, dtype=np.intp)
    k = 0
    for i in range(n):
        low[i] = False
        if not linear[i] or touched_row[i]:
            continue
        t = ftol * scale[i]
        pos = fmin[i] > t
        low[i] = pos
        if pos or fmax[i] < -t:
            out[k] = i
            k += 1
    return out[:k]


@njit(cache=True)
def touch(cols, rows, col_ptr, er, row_ptr, row_order, ec, touched_col, touched_row):
    """Mark the columns ``cols`` and rows ``rows`` touched, with every row that has an
    entry in one of the columns and every column that has an entry in one of the rows."""
    for j in cols:
        touched_col[j] = True
        for k in range(col_ptr[j], col_ptr[j + 1]):
            touched_row[er[k]] = True
    for i in rows:
        touched_row[i] = True
        for k in range(row_ptr[i], row_ptr[i + 1]):
            touched_col[ec[row_order[k]]] = True


@njit(cache=True)
def refresh_masks(live, const, ev, zero_tolerance, nz, nl):
    """nz = live & const & (|ev| > zero_tolerance); nl = live & ~const."""
    for k in range(ev.shape[0]):
        nz[k] = live[k] and const[k] and abs(ev[k]) > zero_tolerance
        nl[k] = live[k] and not const[k]


@njit(cache=True)
def duplicate_row_keys(row_order, nz, er, ec, ev, cand, w1, w2, h1, h2):
    """The hash keys of the duplicate-rows pass over the nonzero constant entries of the
    candidate rows, in row-major order: h1_i = sum of w1 over row i's columns and
    h2_i = sum of w2_j (a_ij / a_i,first) -- summed in the order, and with the products,
    of ``np.bincount(r, weights=...)`` over those entries."""
    prev = -1
    lead = 0.0
    for q in range(row_order.shape[0]):
        k = row_order[q]
        i = er[k]
        if not (nz[k] and cand[i]):
            continue
        if i != prev:
            lead = ev[k]
            prev = i
        j = ec[k]
        h1[i] += w1[j]
        h2[i] += w2[j] * (ev[k] / lead)
