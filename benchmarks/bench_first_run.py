"""The first run after installing: the demos with an empty kernel cache, the warm-up that
set-up runs, and the demos after it, each a fresh process (its whole wall and CPU time:
what a new user waits for).

    python3 benchmarks/bench_first_run.py [--cache DIR] [--skip-cold]

Steps, in one run and in this order, with the numba cache in a fresh folder (``--cache``,
default a temporary one; ``NUMBA_CACHE_DIR`` points there so that the package's own cache is
not touched):

1. ``compass-sparse demo --problem thesis`` with an empty cache (it compiles what it needs);
2. the same again (its kernels now cached; the other routes still are not);
3. the cache emptied, then ``compass-sparse warmup`` (its per-workload lines are kept);
4. ``compass-sparse demo --problem thesis`` and ``compass-sparse demo`` after the warm-up.

The table goes to stdout; the raw lines to ``results/first_run.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _run(args, env):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "compass_sparse.cli", *args], env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if p.returncode != 0:
        sys.exit(f"{' '.join(args)} failed (exit {p.returncode}):\n{p.stderr}")
    return {"command": "compass-sparse " + " ".join(args), "wall": wall, "cpu": cpu,
            "stdout": p.stdout, "stderr": p.stderr}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", help="the numba cache folder (emptied first)")
    ap.add_argument("--skip-cold", action="store_true", help="skip steps 1-2")
    a = ap.parse_args(argv)
    cache = Path(a.cache or tempfile.mkdtemp(prefix="compass_first_run_"))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    rows = []

    def step(label, args):
        r = _run(args, env)
        r["step"] = label
        rows.append(r)
        print(f"{label:34s} {r['wall']:8.1f} s wall {r['cpu']:8.1f} s CPU", flush=True)
        return r

    print(f"# load average at start: {os.getloadavg()[0]:.1f} (2-core machine)", flush=True)
    if not a.skip_cold:
        shutil.rmtree(cache, ignore_errors=True)
        step("demo --problem thesis, cold", ["demo", "--problem", "thesis"])
        step("demo --problem thesis, again", ["demo", "--problem", "thesis"])
    shutil.rmtree(cache, ignore_errors=True)
    w = step("warmup", ["warmup"])
    print("".join("    " + s + "\n" for s in w["stdout"].splitlines()[1:]), end="")
    step("demo --problem thesis, after warmup", ["demo", "--problem", "thesis"])
    d = step("demo (n = 1e5), after warmup", ["demo"])
    solve = [s for s in d["stdout"].splitlines() if s.startswith("time")]
    print(f"    the demo's own solve: {solve[0] if solve else '?'}")
    print(f"# load average at end: {os.getloadavg()[0]:.1f}")
    out = HERE / "results" / "first_run.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
