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


@njit(cache=True)
def recount(er, ec, ev, nz, nl, base, lb, ub, f, counts, vals):
    """The recount of :meth:`Workspace.refresh` in one pass over the entries, replacing
    seven bincounts and a dozen array operations (a small model's recount was their
    overhead: ~130 us at n = 102).  Entries are visited in storage order and summed into
    their row as ``np.bincount(rows, weights=w)`` sums them, and every term is formed as
    the array formulas formed it, so the results are the same bits:

    counts = (row_nnz, row_nl, col_nnz, col_nl): entries in ``nz`` (live, declared
    constant, above the zero tolerance) and in ``nl`` (live, not constant);
    vals = (c, fmin, fmax, scale): c = f - sum a_ij base_j, fmin/fmax = c + sum of
    min/max of a_ij z_j over [l_j, u_j], scale = 1 + |c| + sum of the finite |bounds|."""
    n = f.shape[0]
    acc = np.zeros(n)
    amin = np.zeros(n)
    amax = np.zeros(n)
    amag = np.zeros(n)
    for k in range(er.shape[0]):
        i = er[k]
        j = ec[k]
        if nl[k]:
            counts[1, i] += 1
            counts[3, j] += 1
        elif nz[k]:
            counts[0, i] += 1
            counts[2, j] += 1
            a = ev[k]
            acc[i] += a * base[j]
            if a > 0:
                tmin = a * lb[j]
                tmax = a * ub[j]
            else:
                tmin = a * ub[j]
                tmax = a * lb[j]
            amin[i] += tmin
            amax[i] += tmax
            m1 = abs(tmin) if np.isfinite(tmin) else 0.0
            m2 = abs(tmax) if np.isfinite(tmax) else 0.0
            amag[i] += m1 + m2
    for i in range(n):
        c = f[i] - acc[i]
        vals[0, i] = c
        vals[1, i] = c + amin[i]
        vals[2, i] = c + amax[i]
        vals[3, i] = 1.0 + abs(c) + amag[i]


@njit(cache=True)
def simple_reductions_screen(er, ec, ev, const, col_ptr, row_ptr, row_order, lb, ub, base,
                             f, zero_tolerance, feasibility_tolerance, pattern_declared, w1,
                             w2, max_rounds):
    """Whether the passes of :func:`~compass_sparse.presolve.core.presolve` would reduce
    nothing but what the solver does as well itself -- the fixed variables (l = u) and
    diagonal column singletons -- replayed round by round on the counts of the workspace
    (the same live entries, counts and activity bounds, by :func:`refresh_masks` and
    :func:`recount`) without building it.  ``base`` is the start point with the fixed
    values, ``f`` = F(base) (finite).  Returns (code, rounds, singletons): code 0 when
    that is all the passes would do, in ``rounds`` rounds, removing ``singletons``
    diagonal column singletons; else the number of the first pass that may do more (1
    empty rows, 2-3 singleton rows, 4 forcing rows, 5 range fixing, 6 empty columns, 8
    column singletons, 9 duplicate rows).

    Each pass's candidates are selected by its own scan (the kernels above); where the
    pass goes on to read values, the screen is conservative: a singleton row on its own
    variable or with a free variable, every forcing or range candidate and every pair of
    candidate rows with equal column hash (the duplicate-rows pass compares only such
    pairs, by the keys of :func:`duplicate_row_keys`, computed here too) count as "may
    act".  Column
    singletons are replayed exactly (their order, the marks their removals leave for the
    passes after them in the round), since they are removed.  A 0 is therefore exact.

    A compiled kernel whose length is the algorithm (every simple reduction's screen in
    one pass over the rows): exempt from the package's limit of 100 lines per function."""
    n = f.shape[0]
    nnz = er.shape[0]
    gone_col = np.empty(n, dtype=np.bool_)
    for j in range(n):
        gone_col[j] = lb[j] == ub[j]
    gone_row = gone_col.copy()  # the pairs are the identity until a free pair is re-made
    live = np.empty(nnz, dtype=np.bool_)
    nz = np.empty(nnz, dtype=np.bool_)
    nl = np.empty(nnz, dtype=np.bool_)
    linear = np.empty(n, dtype=np.bool_)
    touched_row = np.zeros(n, dtype=np.bool_)
    touched_col = np.zeros(n, dtype=np.bool_)
    partner = np.arange(n)  # (the pairs are the identity: see gone_row)
    side = np.empty(n, dtype=np.bool_)  # (the forcing and range scans' side flags)
    singletons = 0
    for rnd in range(max_rounds):
        # the refresh at the start of the round
        for k in range(nnz):
            live[k] = not gone_row[er[k]] and not gone_col[ec[k]]
        refresh_masks(live, const, ev, zero_tolerance, nz, nl)
        counts = np.zeros((4, n), dtype=np.intp)
        vals = np.empty((4, n))
        recount(er, ec, ev, nz, nl, base, lb, ub, f, counts, vals)
        row_nnz, row_nl, col_nnz, col_nl = counts[0], counts[1], counts[2], counts[3]
        fmin, fmax, scale = vals[1], vals[2], vals[3]
        touched_row[:] = False
        touched_col[:] = False
        for i in range(n):
            no_entry = row_ptr[i + 1] == row_ptr[i]
            linear[i] = (not gone_row[i] and row_nl[i] == 0
                         and not (no_entry and not pattern_declared))
        # the passes' own candidate scans (nothing is touched before column singletons)
        if linear_rows_with(linear, row_nnz, touched_row, 0, 0).size:
            return 1, rnd + 1, singletons
        for i in linear_rows_with(linear, row_nnz, touched_row, 1, 1):
            for q in range(row_ptr[i], row_ptr[i + 1]):
                k = row_order[q]
                if nz[k]:
                    if ec[k] == i:
                        return 2, rnd + 1, singletons
                    if lb[i] == -np.inf and ub[i] == np.inf:
                        return 3, rnd + 1, singletons
        col_active = ~gone_col
        if linear_columns_with(col_active, col_nnz, col_nl, touched_col, lb, ub, 0,
                               True).size:
            return 6, rnd + 1, singletons
        # column singletons, replayed in the pass's order with its marks
        changed = 0
        for j in linear_columns_with(col_active, col_nnz, col_nl, touched_col, lb, ub, 1,
                                     False):
            if touched_col[j]:
                continue
            i = -1
            b = 0.0
            for k in range(col_ptr[j], col_ptr[j + 1]):
                if nz[k]:
                    i = er[k]
                    b = ev[k]
            if touched_row[i]:
                continue
            if i == j:
                if not (b > 0 or (np.isfinite(lb[j]) and np.isfinite(ub[j]))):
                    continue
                gone_col[j] = True
                gone_row[i] = True
                cols = np.array([j])
                touch(cols, cols, col_ptr, er, row_ptr, row_order, ec, touched_col,
                      touched_row)
                singletons += 1
                changed += 1
                continue
            if (lb[j] == -np.inf and ub[j] == np.inf and lb[i] == -np.inf
                    and ub[i] == np.inf and not touched_col[i]):
                return 8, rnd + 1, singletons
        # forcing rows, then duplicate rows, on the rows left untouched
        if forcing_candidates(linear, row_nnz, touched_row, partner, lb, ub, fmin, fmax,
                              scale, feasibility_tolerance, side).size:
            return 4, rnd + 1, singletons
        rows = linear_rows_with(linear, row_nnz, touched_row, 1, n)
        if rows.size >= 2:
            cand = np.zeros(n, dtype=np.bool_)
            cand[rows] = True
            h1 = np.zeros(n)
            h2 = np.zeros(n)
            duplicate_row_keys(row_order, nz, er, ec, ev, cand, w1, w2, h1, h2)
            keys = np.sort(h1[rows])
            for m in range(1, keys.shape[0]):
                if keys[m] == keys[m - 1]:
                    return 9, rnd + 1, singletons
        if changed:
            continue
        # phase two (range fixing) runs only on a round that changed nothing
        if range_candidates(linear, touched_row, fmin, fmax, scale, feasibility_tolerance,
                            side).size:
            return 5, rnd + 1, singletons
        return 0, rnd + 1, singletons
    return 0, max_rounds, singletons
