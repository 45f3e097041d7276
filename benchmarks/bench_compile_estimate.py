"""The one-time notice's estimate against the compiling it announces: one solve per size
class of :func:`compass_sparse.routes.compile_estimate`, each in a fresh process with an
empty numba cache (its own folder), its whole CPU and wall time and the estimate the
notice printed.  What a user waits for on a first solve without the warm-up.

    python benchmarks/bench_compile_estimate.py        # -> results/compile_estimate.json

Cases: the thesis demo (n = 50: the compiled crash, major iterations, dense engine and
homotopy), the traffic equilibrium with 8 destinations (n = 912: the compiled major
iterations and the sparse engine), the structured demo (n = 1e5: the sparse engine,
Python major iterations).  The solve itself takes well under a second in each (after
compiling); ``tests/test_routes.py`` checks the estimates against this file's records.
"""
from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _revision import git_revision

HERE = Path(__file__).resolve().parent

_CLI = [sys.executable, "-c", "import sys; from compass_sparse.cli import main; "
        "sys.exit(main(sys.argv[1:]))"]

CASES = (
    ("thesis demo", 50, _CLI + ["demo", "--problem", "thesis"]),
    ("traffic, 8 destinations", 912,
     [sys.executable, "-c", "from compass_sparse.generators import traffic_equilibrium; "
      "from compass_sparse import solve_mcp; "
      "print(solve_mcp(traffic_equilibrium(8).problem).status)"]),
    ("structured demo", 100_000, _CLI + ["demo"]),
)


def _run(cmd):
    cache = tempfile.mkdtemp(prefix="compass_compile_")
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=HERE.parent)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed (exit {p.returncode}):\n{p.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    m = re.search(r"about (\d+) s", p.stderr)
    return wall, cpu, int(m.group(1)) if m else None


def main():
    rows = []
    print(f"# revision {git_revision()}; load average at start {os.getloadavg()[0]:.1f}")
    for label, n, cmd in CASES:
        wall, cpu, estimate = _run(cmd)
        rows.append({"case": label, "n": n, "wall": wall, "cpu": cpu, "notice": estimate,
                     "revision": git_revision()})
        print(f"{label:26s} n = {n:6d}: {wall:6.1f} s wall {cpu:6.1f} s CPU; the notice "
              f"said about {estimate} s", flush=True)
    out = HERE / "results" / "compile_estimate.json"
    out.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
