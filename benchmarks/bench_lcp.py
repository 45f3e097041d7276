"""Pivotal-path benchmark on sparse LCPs, n = 1e3 ... 1e5, and side by side with PATH.

    lb <= z <= ub  _|_  F(z) = M z + q

Instances (``compass_sparse.generators``, all with a manufactured solution):

* ``grid``     p_matrix_lcp(n, "grid", seed, bounds)   SPD weighted 5-point Laplacian + 0.5 I
* ``banded``   p_matrix_lcp(n, "banded", seed, bounds) non-symmetric, diagonally dominant
* ``obstacle`` obstacle_problem(m, seed)               (1/h^2) 5-point Laplacian, n = m^2,
                                                       lower bound = obstacle

Two configurations for both solvers: ``default`` (projected-Newton crash first; on these
P-matrix LCPs the crash usually finds the active set and no pivot is needed) and
``nocrash`` (``crash_method = none``: one pivotal path from the start point does all the
work, which is what this benchmark is about).

Part A (scaling, compass_sparse only): n = 1e3, 1e4, 1e5: pivots (minor iterations),
factorizations, time (median over repeats), recomputed natural residual, and which passes
ran.  Part B (PATH side by side, n = 100 ... 1000, the free PATH licence's limit): the same
instances solved by both in the same run; time ratio = our wall time / PATH's own Total
Time (GAMS process overhead excluded), both medians over repeats.

Success = OUR recomputation ||z - clip(z - (M z + q), l, u)||_inf <= 1e-6, for both.
Every solve runs in a child process with a per-solve time limit (passed to both solvers)
and a hard timeout, so a hung solve is a failure row, not a crash of the benchmark.

    python benchmarks/bench_lcp.py --quick
    python benchmarks/bench_lcp.py                  # full: 1e3..1e5 and PATH at 100..1000
    python benchmarks/bench_lcp.py --quick --path recorded   # part B against PATH's record

PATH's figures in part B: a live run where GAMS can run; where it cannot (or with ``--path
recorded``) the recorded rows of ``benchmarks/reference/lcp.csv``, marked as such in the
output and in the CSV (``path_source``); an instance the reference does not have gets "–".
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402
    RECORDED_NOTE, RESULTS, CsvLog, Worker, add_path_argument, any_recorded,
    choose_path_source, fmt_e, fmt_time, machine_info, md_table, median, ours_record,
    path_record, path_session, print_machine, recorded_mark, run_task, warm_up, write_json)

FIELDS = ["part", "kind", "bounds", "n", "seed", "config", "solver", "success",
          "reported_success", "status", "natural", "fb_norm", "time", "time_min", "time_max",
          "repeats", "wall", "major", "minor", "crash", "factorizations", "restarts", "passes",
          "pass_times", "error", "path_source"]
CONFIGS = {"default": {}, "nocrash": {"crash_method": "none"}}


# --------------------------------------------------------------------------- tasks (child)
def _instance(kind, n, seed, bounds):
    from compass_sparse.generators import obstacle_problem, p_matrix_lcp

    if kind == "obstacle":
        m = max(2, int(math.isqrt(int(n))))  # n = m^2 <= the requested n
        return obstacle_problem(m, seed)
    return p_matrix_lcp(n, kind, seed, bounds=bounds)


def _repeat(once, repeats, budget):
    """Run ``once`` up to ``repeats`` times (fewer when the first run is slower than
    ``budget`` seconds); report the median time and the min/max."""
    recs = [once()]
    while len(recs) < repeats and recs[0]["time"] * (len(recs) + 1) <= budget:
        recs.append(once())
    ts = [r["time"] for r in recs]
    rec = dict(recs[0])
    rec.update(time=median(ts), time_min=min(ts), time_max=max(ts), repeats=len(recs),
               wall=median([r["wall"] for r in recs]))
    return rec


def task(kind, n, seed, bounds, config, solver, time_limit, repeats, budget):
    g = _instance(kind, n, seed, bounds)
    M, q, lb, ub = g.lcp
    x0 = g.problem.x0
    n_true = q.size
    if solver == "compass_sparse":
        from compass_sparse import solve_lcp

        opts = dict(CONFIGS[config], time_limit=float(time_limit))

        def once():
            t0 = time.perf_counter()
            res = solve_lcp(M, q, lb, ub, x0, options=opts)
            wall = time.perf_counter() - t0
            return ours_record(res, M @ res.x + q, lb, ub, wall)
    else:
        from compass_sparse.interfaces.path_gamspy import solve_lcp_with_path

        popts = dict(CONFIGS[config])

        def once():
            run = solve_lcp_with_path(M, q, lb, ub, x0, options=popts or None,
                                      time_limit=float(time_limit),
                                      session=path_session(n_true, False))
            return path_record(run, lb, ub)

    rec = _repeat(once, repeats, budget)
    rec["n"] = n_true
    if solver == "PATH":
        rec["path_source"] = "live"
    return rec


def recorded_path(reference, kind, bounds, n, seed, config):
    """PATH's recorded row (benchmarks/reference/lcp.csv; ``n`` the instance's true size)
    in this script's fields, or None when PATH was not recorded on it."""
    r = reference.get(kind=kind, bounds=bounds, n=n, seed=seed, config=config)
    if r is None:
        return None
    rec = {f: r.get(f, "") for f in FIELDS}
    rec.update(part="B", solver="PATH", factorizations=-1, passes="", pass_times="",
               error="")
    return rec


# --------------------------------------------------------------------------- tables
def table_a(rows):
    header = ["instance", "n", "config", "solved", "natural res.", "pivots",
              "factorizations", "crash its", "major", "time (median)", "repeats",
              "passes ran (time)", "status"]
    out = []
    for r in rows:
        out.append([f"{r['kind']} ({r['bounds']})" if r["kind"] != "obstacle" else "obstacle",
                     r["n"], r["config"], "yes" if r["success"] else "**no**",
                     fmt_e(r["natural"]), r["minor"], r["factorizations"], r["crash"],
                     r["major"], fmt_time(r["time"]), r.get("repeats", 1),
                     r["pass_times"].replace(";", ", ") or "–",
                     r["status"] + (f" [{r['error']}]" if r["error"] else "")])
    return md_table(header, out)


def table_b(pairs):
    rec = any_recorded(p for _, p in pairs)
    mark = " (recorded)" if rec else ""
    header = ["instance", "n", "config", "ours solved", f"PATH solved{mark}", "ours natural",
              "PATH natural", "ours pivots", "PATH crash/major/minor", "ours time",
              f"PATH time{mark}", "ratio ours/" + ("recorded PATH" if rec else "PATH"),
              "PATH status"]
    out = []
    for o, p in pairs:
        if p is None:  # not in the reference
            out.append([f"{o['kind']} ({o['bounds']})" if o["kind"] != "obstacle"
                        else "obstacle", o["n"], o["config"],
                        "yes" if o["success"] else "**no**", "–", fmt_e(o["natural"]), "–",
                        o["minor"], "–", fmt_time(o["time"]), "–", "–",
                        "not in the reference"])
            continue
        ratio = o["time"] / p["time"] if (o["success"] and p["success"]
                                          and p["time"] > 0) else math.nan
        out.append([f"{o['kind']} ({o['bounds']})" if o["kind"] != "obstacle" else "obstacle",
                    o["n"], o["config"], "yes" if o["success"] else "**no**",
                    "yes" if p["success"] else "**no**", fmt_e(o["natural"]),
                    fmt_e(p["natural"]), o["minor"],
                    f"{p['crash']}/{p['major']}/{p['minor']}", fmt_time(o["time"]),
                    fmt_time(p["time"]), f"{ratio:.3g}" if math.isfinite(ratio) else "–",
                    p["status"]])
    return md_table(header, out) + ("\n\n" + RECORDED_NOTE if rec else "")


# --------------------------------------------------------------------------- main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smoke run (< 2 min)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None,
                    help="part A sizes (default 1000 10000 100000; obstacle uses m = isqrt(n))")
    ap.add_argument("--path-sizes", type=int, nargs="+", default=None,
                    help="part B sizes, <= 1000 (default 100 300 1000)")
    ap.add_argument("--bounds", nargs="+", default=["ncp", "mixed"],
                    choices=["ncp", "box", "mixed"], help="bounds of the p_matrix_lcp instances")
    ap.add_argument("--seeds", type=int, default=1, help="seeds 0..S-1 per instance")
    ap.add_argument("--repeats", type=int, default=5, help="timing repeats (median)")
    ap.add_argument("--repeat-budget", type=float, default=20.0,
                    help="stop repeating a solve once the repeats would exceed this many s")
    ap.add_argument("--time-limit", type=float, default=60.0, help="per-solve limit, s")
    ap.add_argument("--nocrash-max-n", type=int, default=10000,
                    help="part A runs the nocrash configuration only up to this n "
                         "(a crash-free path needs O(n) pivots)")
    ap.add_argument("--no-path", action="store_true", help="skip part B")
    add_path_argument(ap)
    ap.add_argument("--out", type=Path, default=None, help="CSV output")
    a = ap.parse_args(argv)

    info = machine_info()
    print_machine(info)
    source = choose_path_source("lcp", a.path_mode, a.no_path)
    print(source.line(), flush=True)
    use_path = source.live
    sizes = a.sizes or ([1000] if a.quick else [1000, 10000, 100000])
    psizes = a.path_sizes or ([100, 1000] if a.quick else [100, 300, 1000])
    tl = min(a.time_limit, 10.0) if a.quick else a.time_limit
    repeats = 3 if a.quick else a.repeats
    budget = 5.0 if a.quick else a.repeat_budget
    # the hard timeout covers all repeats (a repeat only starts while within the budget)
    hard = 15.0 if a.quick else tl + budget + 30.0
    out = a.out or RESULTS / ("lcp_quick.csv" if a.quick else "lcp.csv")
    log = CsvLog(out, FIELDS)
    write_json(out.with_suffix(".json"), dict(machine=info, sizes=sizes, path_sizes=psizes,
                                              bounds=a.bounds, seeds=a.seeds, repeats=repeats,
                                              time_limit=tl, path=source.line().lstrip("# ")))
    worker = Worker(warm_up, dict(with_path=use_path))

    def instances(ns):
        for n in ns:
            for kind in ("grid", "banded", "obstacle"):
                for bounds in (a.bounds if kind != "obstacle" else ["lower"]):
                    for seed in range(a.seeds):
                        yield kind, n, seed, bounds

    def solve(part, kind, n, seed, bounds, config, solver):
        rec = run_task(worker, task, solver, hard, kind=kind, n=n, seed=seed, bounds=bounds,
                       config=config, solver=solver, time_limit=tl, repeats=repeats,
                       budget=budget)
        rec.setdefault("n", n)
        rec.update(part=part, kind=kind, bounds=bounds, seed=seed, config=config, solver=solver)
        log.write(rec)
        print(f"{part} {kind:8s} {bounds:5s} n={rec['n']:7d} seed {seed} {config:8s} "
              f"{solver:15s} {'OK  ' if rec['success'] else 'FAIL'} natural "
              f"{fmt_e(rec['natural'])} pivots {rec['minor']:6d} fact {rec['factorizations']:4d} "
              f"{fmt_time(rec['time']):>9s} {rec['status']}"
              + (f" [{rec['error']}]" if rec["error"] else ""), flush=True)
        return rec

    rows_a = []
    for kind, n, seed, bounds in instances(sizes):
        for config in CONFIGS:
            if config == "nocrash" and n > a.nocrash_max_n:
                continue
            rows_a.append(solve("A", kind, n, seed, bounds, config, "compass_sparse"))
    def recorded(kind, n, seed, bounds, config):
        rec = recorded_path(source.reference, kind, bounds, n, seed, config)
        if rec is None:
            print(f"B {kind:8s} {bounds:5s} n={n:7d} seed {seed} {config:8s} {'PATH':15s} "
                  f"– (not in the reference)", flush=True)
            return None
        rec.update(kind=kind, bounds=bounds, seed=seed, config=config)
        log.write(rec)
        print(f"B {kind:8s} {bounds:5s} n={rec['n']:7d} seed {seed} {config:8s} {'PATH':15s} "
              f"{'OK  ' if rec['success'] else 'FAIL'} natural {fmt_e(rec['natural'])} pivots "
              f"{rec['minor']:6d} {fmt_time(rec['time']):>9s} {rec['status']}"
              f"{recorded_mark(rec)}", flush=True)
        return rec

    pairs = []
    if source.mode != "none":
        for kind, n, seed, bounds in instances(psizes):
            for config in CONFIGS:
                o = solve("B", kind, n, seed, bounds, config, "compass_sparse")
                if use_path:
                    p = solve("B", kind, n, seed, bounds, config, "PATH")
                else:  # the reference is keyed by the instance's true size, as our row
                    p = recorded(kind, o["n"], seed, bounds, config)
                pairs.append((o, p))
    log.close()
    worker.close()

    print("\n## A. compass_sparse on large LCPs\n")
    print(table_a(rows_a))
    if pairs:
        rec = any_recorded(p for _, p in pairs)
        print("\n## B. Side by side with PATH " + (
            "(same instances; PATH's recorded rows)\n" if rec else "(same instances, same run)\n"))
        print(table_b(pairs))
        for config in CONFIGS:
            pp = [(o, p) for o, p in pairs if o["config"] == config and p is not None]
            rat = [o["time"] / p["time"] for o, p in pp
                   if o["success"] and p["success"] and p["time"] > 0]
            print(f"\n{config}: ours solved {sum(o['success'] for o, _ in pp)}/{len(pp)}, "
                  f"PATH{' (recorded)' if rec else ''} solved "
                  f"{sum(p['success'] for _, p in pp)}/{len(pp)}, median time "
                  f"ratio ours/{'recorded ' if rec else ''}PATH over both-solved "
                  f"{median(rat):.3g}" if rat else "")
    print(f"\n# rows in {out}; worker restarts after hard timeouts: {worker.restarts}",
          flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
