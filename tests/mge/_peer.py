"""Reference values published with MPSGE.jl's test suite (computed with GAMS/MPSGE), and
the comparison that suite uses (Julia's ``isapprox``: relative tolerance sqrt(eps))."""
from __future__ import annotations

import csv
import math
from pathlib import Path

DATA = Path(__file__).resolve().parent / "data" / "mpsgejl_results"

RTOL = math.sqrt(2.0 ** -52)
"""Julia's default isapprox tolerance, ~1.49e-8 relative, used by every peer test."""


def sheet(name, keys=1):
    """{(row, column): value} of one sheet; ``keys=2`` joins two key columns with '.'."""
    with open(DATA / f"{name}.csv", newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0][keys:]
    out = {}
    for r in rows[1:]:
        key = ".".join(r[:keys]) if keys > 1 else r[0]
        key = key[:-2] if key.endswith(".L") else key
        for col, v in zip(head, r[keys:]):
            try:
                out[key, col] = float(v)
            except ValueError:  # blank, or GAMS' 'Undf' (a ratio undefined there)
                pass
    return out


def matches(sol, ref, column, getters, rtol=RTOL, atol=None):
    """Compare every row of ``getters`` (row -> callable(solution)) with the sheet's
    ``column``; return the list of mismatches (row, ours, theirs).  ``atol`` maps a row
    to the absolute tolerance the peer's test states for it (where the published GAMS
    value itself is less accurate than sqrt(eps))."""
    atol = atol or {}
    assert sol.success, sol.result.message
    bad = []
    for row, get in getters.items():
        theirs = ref[row, column]
        ours = get(sol)
        if not math.isclose(ours, theirs, rel_tol=rtol, abs_tol=atol.get(row, 1e-12)):
            bad.append((row, ours, theirs))
    return bad
