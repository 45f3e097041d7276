"""Build, evaluation and solve times of compass_sparse.mge models from 1e3 to 1e6 variables.

The model is the synthetic multi-region economy of ``compass_sparse.mge.multiregion``
(``--sectors`` and ``--households`` per region, default 10 and 2; the number of regions
sets the size).  For each
size:

* build: declaring the model, compiling it (flat arrays, nests, names), the start point
  and the ``compass_sparse.MCP`` (with its sparsity pattern) -- median of ``--repeats``;
* benchmark: max |F| at the reference point (replication check);
* F, J: one evaluation at the reference point, median of ``--evals`` calls;
* solve: removal of every tariff from the benchmark, through ``compass_sparse.solve_mcp``
  (public API, convergence tolerance 1e-8), with F and J wrapped by timers so that the
  share of the solve spent in them is measured; the solver's kernels are compiled before
  any timing by a solve of the smallest model.

Usage (from the repository root):

    python3 benchmarks/bench_mge.py --regions 10 100 1000 10000 --repeats 3

writes ``benchmarks/results/mge.csv`` and prints the table of ``benchmarks/mge.md``.
"""
from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import compass_sparse as cs
from compass_sparse.mge.multiregion import multiregion_model

SHAPE = {"S": 10, "H": 2}
"""Sectors and households per region (set from the command line)."""


def _build(R):
    t0 = time.perf_counter()
    m, h, _ = multiregion_model(R, SHAPE["S"], SHAPE["H"])
    problem, st, eq = m.mcp()
    return time.perf_counter() - t0, m, h, problem, st, eq


def _timed_problem(m, clock):
    """The MCP at the model's current data with F and J timed: (MCP, its equations)."""
    problem, _, eq = m.mcp()

    def F(z):
        t = time.perf_counter()
        f = eq.evaluate(z, deriv=False)[0]
        clock["F"] += time.perf_counter() - t
        clock["nF"] += 1
        return f

    def J(z):
        t = time.perf_counter()
        Jz = eq.jacobian(z)[1]
        clock["J"] += time.perf_counter() - t
        clock["nJ"] += 1
        return Jz

    mcp = cs.MCP(F, J, problem.lb, problem.ub, problem.x0, jac_sparsity=eq.sparsity(problem.x0),
                 var_names=problem.var_names, eqn_names=problem.eqn_names)
    return mcp, eq


def run(R, repeats, evals):
    builds = []
    for _ in range(repeats):
        tb, m, h, problem, _, eq = _build(R)
        builds.append(tb)
    x = problem.x0
    bench = float(np.max(np.abs(eq.evaluate(x, deriv=False)[0])))
    tf, tj = [], []
    for _ in range(evals):
        t = time.perf_counter()
        eq.evaluate(x, deriv=False)
        tf.append(time.perf_counter() - t)
        t = time.perf_counter()
        _, Jx = eq.jacobian(x)
        tj.append(time.perf_counter() - t)
    h["tm"].set(0.0)
    clock = {"F": 0.0, "J": 0.0, "nF": 0, "nJ": 0}
    mcp, eq = _timed_problem(m, clock)
    t = time.perf_counter()
    res = cs.solve_mcp(mcp, options={"convergence_tolerance": 1e-8})
    wall = time.perf_counter() - t
    f = eq.evaluate(res.x, deriv=False)[0]
    natural = float(np.max(np.abs(res.x - np.clip(res.x - f, mcp.lb, mcp.ub))))
    return {"regions": R, "n": eq.n, "nnz": Jx.nnz, "build_s": statistics.median(builds),
                "benchmark_max_F": bench, "F_s": statistics.median(tf), "J_s": statistics.median(tj),
                "solve_s": wall, "status": res.status.name, "iterations": res.nit,
                "natural_residual": natural, "F_calls": clock["nF"], "J_calls": clock["nJ"],
                "FJ_share": (clock["F"] + clock["J"]) / wall if wall > 0 else float("nan"),
                "lu_nnz": res.lu.get("max_nnz_lu")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--regions", type=int, nargs="+", default=[10, 100, 1000, 10000])
    ap.add_argument("--sectors", type=int, default=10)
    ap.add_argument("--households", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--evals", type=int, default=5)
    ap.add_argument("--out", default=str(HERE / "results" / "mge.csv"))
    a = ap.parse_args(argv)
    SHAPE.update(S=a.sectors, H=a.households)
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True, cwd=HERE, check=False).stdout.strip()
    print(f"revision {rev}; {platform.platform()}; {os.cpu_count()} cores; "
          f"load {os.getloadavg()[0]:.1f}; numpy {np.__version__}")
    run(2, 1, 1)   # compile the solver's kernels before any timing
    rows = []
    for R in a.regions:
        row = run(R, a.repeats, a.evals)
        row["revision"] = rev
        rows.append(row)
        print(row, flush=True)
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        with open(a.out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    print("\n| regions | variables | nnz(J) | build [s] | max abs F at benchmark | F [s] "
          "| J [s] | solve [s] | status | iterations | natural residual | F / J calls "
          "| share in F, J | nnz(LU) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['regions']} | {r['n']:,} | {r['nnz']:,} | {r['build_s']:.3f} | "
              f"{r['benchmark_max_F']:.1e} | {r['F_s']:.4f} | {r['J_s']:.4f} | "
              f"{r['solve_s']:.2f} | {r['status']} | {r['iterations']} | "
              f"{r['natural_residual']:.1e} | {r['F_calls']} / {r['J_calls']} | "
              f"{100 * r['FJ_share']:.1f}% | {r['lu_nnz']:,} |")


if __name__ == "__main__":
    main()
