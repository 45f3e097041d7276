"""Plots of the measured benchmarks (matplotlib), drawn from the per-solve CSV files in
``benchmarks/results/`` and written as PNG next to the benchmark documents.

    python benchmarks/plots.py                 # all four figures
    python benchmarks/plots.py --only profiles # one of: profiles success tolerances scaling

Figures (see benchmarks/plots.md):

* ``thesis_profiles.png``  Dolan–Moré performance profiles of compass_sparse against PATH 5.2
  (time; a failure costs infinity) on the thesis' families 1 and 2 and on the small sparse
  LCPs (n = 100 .. 1000) measured against PATH;
* ``thesis_success.png``   success rate against n on the thesis families, both solvers;
* ``thesis_tolerances.png`` solve time against the achieved natural residual, over the
  convergence tolerances 1e-4 .. 1e-12, both solvers;
* ``scaling_time.png``     solve time against n for the large structured MCPs/LCPs and the
  CGE models, each with the time of ONE sparse LU of its Jacobian (dashed).

Nothing is solved here: the figures show exactly the rows the benchmark scripts wrote.
"""
from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE.parent))

OURS, PATH = "compass_sparse", "PATH"
COLORS = {OURS: "tab:blue", PATH: "tab:orange"}


def _rows(name):
    with open(RESULTS / name, newline="") as fh:
        return list(csv.DictReader(fh))


def _true(s) -> bool:
    return str(s).strip() == "True"


def _float(s) -> float:
    try:
        return float(s)
    except (TypeError, ValueError):
        return float("nan")


def _paired_costs(rows, key):
    """(instances, 2) times of (ours, PATH), inf for failures; instances both solved."""
    by = defaultdict(dict)
    for r in rows:
        by[key(r)][r["solver"]] = _float(r["time"]) if _true(r["success"]) else np.inf
    keys = sorted(k for k, v in by.items() if OURS in v and PATH in v)
    return np.array([[by[k][OURS], by[k][PATH]] for k in keys]).reshape(-1, 2)


def profiles(plt, out):
    from compass_sparse.plot import performance_profile

    # One run, both solvers side by side on each instance: times compared under one load.
    thesis = _rows("thesis_final.csv")
    # Default options only (the study's no-crash configuration is not a user's setting).
    lcp = [r for r in _rows("lcp.csv") if r["part"] == "B" and r["config"] == "default"]
    panels = [
        ("thesis family 1, n = 10..200", [r for r in thesis if r["family"] == "1"]),
        ("thesis family 2, n = 10..200", [r for r in thesis if r["family"] == "2"]),
        ("sparse LCPs, n = 100..1000", lcp),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for ax, (title, rows) in zip(axes, panels):
        costs = _paired_costs(rows, lambda r: tuple(r.get(k, "") for k in (
            "family", "kind", "n", "seed", "config")))
        performance_profile(costs, ["compass_sparse", "PATH 5.2"], ax=ax,
                            title=f"{title} ({len(costs)} instances)",
                            xlabel="tau (time / best time)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def success(plt, out):
    # Our rows of the final code with PATH's rows of the side-by-side run (same seeds):
    # the table of thesis.md and the README.
    rows = _rows("thesis_combined.csv")
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), sharey=True)
    for ax, fam in zip(axes, ("1", "2")):
        for solver, label in ((OURS, "compass_sparse"), (PATH, "PATH 5.2")):
            cell = defaultdict(list)
            for r in rows:
                if r["family"] == fam and r["solver"] == solver:
                    cell[int(r["n"])].append(_true(r["success"]))
            ns = sorted(cell)
            ax.plot(ns, [100 * np.mean(cell[n]) for n in ns], marker="o", label=label,
                    color=COLORS[solver])
        ax.set_xscale("log")
        ax.set_xlabel("n")
        ax.set_title(f"thesis family {fam} (30 instances per n)")
        ax.set_ylim(0, 102)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("solved (%)")
    axes[0].legend(loc="lower left")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def tolerances(plt, out):
    # One line per (instance, solver): the same instance solved at tolerances 1e-4 .. 1e-12,
    # so each line shows what the extra digits cost.
    rows = [r for r in _rows("thesis_tolerances.csv") if _true(r["success"])]
    fig, ax = plt.subplots(figsize=(6, 4))
    lines = defaultdict(list)
    for r in rows:
        lines[(r["solver"], r["family"], r["n"], r["seed"])].append(
            (float(r["tol"]), max(_float(r["natural"]), 1e-17), _float(r["time"])))
    labelled = set()
    for (solver, *_), pts in sorted(lines.items()):
        pts.sort(reverse=True)  # loose to tight tolerance
        _, e, t = zip(*pts)
        label = None if solver in labelled else ("compass_sparse" if solver == OURS
                                                 else "PATH 5.2")
        labelled.add(solver)
        ax.plot(e, t, marker="o", markersize=3, linewidth=0.8, alpha=0.7,
                color=COLORS[solver], label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("achieved natural residual (recomputed)")
    ax.set_ylabel("solve time (s)")
    ax.set_title("thesis families, n = 20, 50; tolerance 1e-4 .. 1e-12", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def scaling(plt, out):
    structured = {}
    for name in ("scaling.csv", "scaling_final.csv", "scaling_1e6.csv"):  # later rows win
        for r in _rows(name):
            if _true(r["success"]):
                structured[(r["family"], int(r["n"]))] = (_float(r["time"]),
                                                          _float(r["splu_time"]))
    cge = defaultdict(dict)
    for r in _rows("cge_main.csv"):
        if r["case"] in ("notax", "ktax25") and _true(r["success"]) and r["n"]:
            cge[f"{r['family']} CGE ({r['case']})"][int(r["n"])] = (_float(r["time"]),
                                                                    _float(r["splu_time"]))
    fams = defaultdict(dict)
    for (fam, n), v in structured.items():
        fams[fam][n] = v
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, groups, title in ((axes[0], fams, "large structured MCPs and LCPs"),
                              (axes[1], cge, "CGE counterfactuals")):
        for k, (name, pts) in enumerate(sorted(groups.items())):
            ns = sorted(pts)
            color = f"C{k}"
            ax.plot(ns, [pts[n][0] for n in ns], marker="o", color=color, label=name)
            lu = [(n, pts[n][1]) for n in ns if np.isfinite(pts[n][1])]
            if lu:
                ax.plot(*zip(*lu), linestyle="--", color=color, alpha=0.7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("n")
        ax.set_title(title + " (dashed: one sparse LU of J)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    axes[0].set_ylabel("seconds")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


FIGURES = {"profiles": (profiles, "thesis_profiles.png"),
           "success": (success, "thesis_success.png"),
           "tolerances": (tolerances, "thesis_tolerances.png"),
           "scaling": (scaling, "scaling_time.png")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", choices=sorted(FIGURES), action="append",
                    help="draw only this figure (repeatable)")
    ap.add_argument("--outdir", default=str(HERE), help="where the PNGs go (default benchmarks/)")
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name in args.only or FIGURES:
        fn, png = FIGURES[name]
        out = Path(args.outdir) / png
        fn(plt, out)
        plt.close("all")
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
