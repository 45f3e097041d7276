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
        # GAMS' level suffix: "X.L" is X (a two-column key like "PF.L" is PF of L).
        key = ".".join(r[:keys]) if keys > 1 else r[0].removesuffix(".L")
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


def getters(values=None, inputs=None, outputs=None, finals=None):
    """Row -> callable(solution): variable values, compensated input demands and output
    supplies per unit of activity ((sector, commodity) pairs), final demands
    ((consumer, commodity) pairs)."""
    g = {}
    for row, ref in (values or {}).items():
        g[row] = lambda s, r=ref: s.value(r)
    for row, (a, b) in (inputs or {}).items():
        g[row] = lambda s, a=a, b=b: s.compensated_demand(a, b)
    for row, (a, b) in (outputs or {}).items():
        g[row] = lambda s, a=a, b=b: s.compensated_demand(a, b, output=True)
    for row, (a, b) in (finals or {}).items():
        g[row] = lambda s, a=a, b=b: s.final_demand(a, b)
    return g


def solve_and_match(m, ref, column, gets, atol=None):
    """Solve, check the returned point solves the model, match the peer's column."""
    sol = m.solve()
    assert sol.success, sol.result.message
    assert sol.residual() <= 1e-9
    bad = matches(sol, ref, column, gets, atol=atol)
    assert not bad, f"{column}: {bad}"
    return sol
