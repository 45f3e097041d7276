"""The kernel route: interpreted kernels (the cold start of a process, or
COMPASS_SPARSE_JIT=interpret) solve the small problems as the compiled ones do."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import known_problems as kp

from compass_sparse import solve_mcp
from compass_sparse.generators import thesis_family

ROOT = Path(__file__).resolve().parents[2]


def _cold_env(**extra):
    """The environment of a fresh process with the default cold start (the test session
    itself compiles from the first call: conftest.py)."""
    env = {k: v for k, v in os.environ.items() if k != "COMPASS_SPARSE_JIT"}
    env.update(extra)
    return env


def _run_fresh(code, **env):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=_cold_env(**env), cwd=ROOT)
    return out.stdout.strip().splitlines()[-1]


def test_interpreted_kernels_solve_the_small_problems_as_the_compiled_ones():
    """With every small solve interpreted (COMPASS_SPARSE_JIT=interpret), a fresh process
    solves the known problems and thesis instances at n = 10 with interpreted kernels
    only; statuses, major iterations, pivots, F and J evaluations are the compiled
    kernels' (this process), and both points pass the tolerance."""
    code = textwrap.dedent("""
        import sys, json
        sys.path.insert(0, "tests")
        import known_problems as kp
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        out, routes = {}, set()
        def row(r):
            routes.add(r.routes["kernels"])
            return [r.status.name, r.nit, r.minor_iterations, r.nfev, r.njev,
                    r.residual.natural]
        for name, make in kp.ALL_SOLVABLE.items():
            q = make()
            out[name] = row(solve_mcp(q.F, q.J, q.lb, q.ub, q.x0))
        for fam in (1, 2):
            for seed in (1, 2, 3):
                out[f"f{fam}s{seed}"] = row(solve_mcp(thesis_family(10, fam, seed).problem))
        print(json.dumps([out, "numba" in sys.modules, sorted(routes)]))
        """)
    interpreted, numba_loaded, routes = json.loads(_run_fresh(code, COMPASS_SPARSE_JIT="interpret"))
    assert not numba_loaded and routes == ["interpreted"]
    compiled = {}
    for name, make in kp.ALL_SOLVABLE.items():
        q = make()
        compiled[name] = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0)
    for fam in (1, 2):
        for seed in (1, 2, 3):
            compiled[f"f{fam}s{seed}"] = solve_mcp(thesis_family(10, fam, seed).problem)
    assert set(compiled) == set(interpreted) and len(compiled) > 10
    for key, r in compiled.items():
        assert r.routes["kernels"] == "compiled"
        status, nit, minor, nfev, njev, natural = interpreted[key]
        assert (status, nit, minor, nfev, njev) == (
            r.status.name, r.nit, r.minor_iterations, r.nfev, r.njev), key
        if r.success:
            assert natural <= 1e-6 and r.residual.natural <= 1e-6, key
