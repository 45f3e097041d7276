"""The COMPASS thesis' random nonlinear families (§4.3, Tables 4.1-4.4), compass_sparse vs PATH.

    F(z) = D z^2 + A z + b   (D diagonal, A dense),   l <= z <= u   (bounded box)

family 1 (Table 4.1): D, A, b ~ U[-1, 1], x0 ~ U[-1, 2], l ~ U[-1, 1], u ~ U[l, l + 1]
family 2 (Table 4.3): D ~ U[-2, 2], A ~ U[-5, 5], b ~ U[-7, 7], x0 ~ U[-10, 20],
                      l ~ U[-10, 10], u ~ U[l, l + 10]

Instance k of (family, n) is ``compass_sparse.generators.thesis_family(n, family, seed=k)``;
PATH gets the same raw data (``info``: D, A, b, lb, ub, x0) through
``solve_quadratic_mcp_with_path``.  Both solvers run on the SAME instances in the same run,
one after the other.  A solve counts as a success when OUR recomputation of the natural
residual ||z - clip(z - F(z), l, u)||_inf of the returned point is <= 1e-6 (F recomputed
from the raw data in float64).  A time-out counts as a failure.  Times: compass_sparse =
wall time of the ``solve_mcp`` call; PATH = its own "Total Time" (GAMS process overhead
excluded).

PATH's figures: a live run where GAMS can run; where it cannot (or with ``--path
recorded``) the recorded rows of ``benchmarks/reference/thesis.csv``.  The first lines of
the output say which; recorded rows carry ``path_source = "recorded <date> <rev>"`` in the
CSV and the tables say so; an instance the reference does not have is left out of PATH's
side (its cell counts only the instances both solvers have).

Table mode (default): the loop runs instance by instance over all (family, n) cells, so an
interrupted run leaves a balanced partial table; every solve is appended to the CSV at
once (``--resume`` skips the solves already in it).  ``--summarize CSV`` re-prints the
tables of an existing CSV.

Tolerance mode (``--tolerances``): time against achieved error for
convergence_tolerance in 1e-4 ... 1e-12 on a few instances, both solvers.

    python benchmarks/bench_thesis.py --quick
    python benchmarks/bench_thesis.py --instances 100 --time-limit 60     # full table
    python benchmarks/bench_thesis.py --tolerances
    python benchmarks/bench_thesis.py --quick --path recorded          # PATH's recorded rows
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402
    RECORDED_NOTE, RESULTS, SUCCESS_TOL, CsvLog, Worker, add_path_argument, any_recorded,
    choose_path_source, fmt_e, fmt_time, machine_info, md_table, median, ours_record,
    path_record, path_session, print_machine, read_csv, recorded_mark, run_task, warm_up,
    write_json)

FIELDS = ["family", "n", "seed", "tol", "solver", "success", "reported_success", "status",
          "natural", "fb_norm", "time", "wall", "major", "minor", "crash", "factorizations",
          "restarts", "repeats", "passes", "pass_times", "error", "path_source"]
SOLVERS = ("compass_sparse", "PATH")


# --------------------------------------------------------------------------- tasks (child)
def _instance(family, n, seed):
    from compass_sparse.generators import thesis_family

    return thesis_family(n, family, seed)


def _F(info, x):
    return info["D"] * x * x + info["A"] @ x + info["b"]


REPEAT_BELOW = 0.2
"""A solve faster than this (seconds) is repeated (``repeats`` times in all) and the
median time is reported: small times are noisy on a shared machine."""


def _repeat(once, repeats):
    recs = [once()]
    if recs[0]["time"] < REPEAT_BELOW:
        recs += [once() for _ in range(max(0, repeats - 1))]
    rec = recs[0]
    rec["time"] = median([r["time"] for r in recs])
    rec["wall"] = median([r["wall"] for r in recs])
    rec["repeats"] = len(recs)
    return rec


def task_ours(family, n, seed, time_limit, tol, repeats=1, homotopy=None):
    from compass_sparse import solve_mcp

    g = _instance(family, n, seed)
    info = g.info
    opts = {"time_limit": float(time_limit), "convergence_tolerance": float(tol)}
    if homotopy is not None:
        opts["homotopy"] = homotopy

    def once():
        t0 = time.perf_counter()
        res = solve_mcp(g.problem, options=opts)
        wall = time.perf_counter() - t0
        return ours_record(res, _F(info, res.x), info["lb"], info["ub"], wall)

    return _repeat(once, repeats)


def task_path(family, n, seed, time_limit, tol, repeats=1):
    from compass_sparse.interfaces.path_gamspy import solve_quadratic_mcp_with_path

    g = _instance(family, n, seed)
    info = g.info

    def once():
        run = solve_quadratic_mcp_with_path(
            info["D"], info["A"], info["b"], info["lb"], info["ub"], info["x0"],
            convergence_tolerance=float(tol), time_limit=float(time_limit),
            session=path_session(n, True))
        return path_record(run, info["lb"], info["ub"])

    rec = _repeat(once, repeats)
    rec["path_source"] = "live"
    return rec


TASKS = {"compass_sparse": task_ours, "PATH": task_path}


def recorded_path(reference, family, n, seed, tol):
    """PATH's recorded row of the instance (benchmarks/reference/thesis.csv) in this
    script's fields, or None when PATH was not recorded on it."""
    r = reference.get(family=family, n=n, seed=seed, tol=tol)
    if r is None:
        return None
    rec = {f: r.get(f, "") for f in FIELDS}
    rec.update(solver="PATH", factorizations=-1, passes="", pass_times="", error="",
               time_limit=r["time_limit"])
    return rec


def _solve(worker, source, s, hard, **kw):
    """One solve's row: ours or PATH's live (in the worker), or PATH's recorded row (None
    when the reference does not have the instance)."""
    if s == "PATH" and source.recorded:
        rec = recorded_path(source.reference, kw["family"], kw["n"], kw["seed"], kw["tol"])
        if rec is not None and float(rec["time"]) > kw["time_limit"]:
            rec["error"] = (f"recorded with a limit of {rec.get('time_limit', '?')} s: above "
                            f"this run's {kw['time_limit']:g} s")
        return rec
    rec = run_task(worker, TASKS[s], s, hard, **kw)
    if s == "PATH":
        rec.setdefault("path_source", "live")
    return rec


# --------------------------------------------------------------------------- summaries
def _cells(rows):
    cells = defaultdict(dict)  # (family, n, solver) -> {seed: row}
    for r in rows:
        cells[(int(r["family"]), int(r["n"]), r["solver"])][int(r["seed"])] = r
    return cells


def summarize(rows, out=print):
    """Print the anchor table (rows family/solver, columns n) and the detail table."""
    if not rows:
        out("(no rows)")
        return
    cells = _cells(rows)
    fams = sorted({k[0] for k in cells})
    ns = sorted({k[1] for k in cells})
    solvers = [s for s in SOLVERS if any(k[2] == s for k in cells)]
    rec = any_recorded(r for r in rows if r["solver"] == "PATH")
    label = {"compass_sparse": "compass_sparse", "PATH": "PATH (recorded)" if rec else "PATH"}

    out("\nSuccess rate (natural residual <= 1e-6) and median time of a success; "
        "K = instances that completed for BOTH solvers in that cell\n")
    header = ["family / solver"] + [f"n = {n}" for n in ns]
    table = []
    for fam in fams:
        for s in solvers:
            line = [f"{fam} / {label[s]}"]
            for n in ns:
                common = _common_seeds(cells, fam, n, solvers)
                if not common:
                    line.append("")
                    continue
                rr = [cells[(fam, n, s)][k] for k in common]
                ok = [r for r in rr if r["success"]]
                line.append(f"{100 * len(ok) / len(rr):.0f}% · {fmt_time(median([r['time'] for r in ok]))}"
                            f" (K={len(rr)})")
            table.append(line)
    out(md_table(header, table))

    out("\nDetails per cell (same instances for both solvers)\n")
    header = ["family", "n", "solver", "solved", "median t (success)", "median t (failure)",
              "timeouts", "median major", "median pivots", "median restarts",
              "only this solver solved",
              "median time ratio ours/" + ("recorded PATH" if rec else "PATH") + " (both solved)"]
    table = []
    for fam in fams:
        for n in ns:
            common = _common_seeds(cells, fam, n, solvers)
            if not common:
                continue
            for s in solvers:
                rr = [cells[(fam, n, s)][k] for k in common]
                ok = [r for r in rr if r["success"]]
                bad = [r for r in rr if not r["success"]]
                to = sum(1 for r in rr if "time" in str(r["status"]).lower())
                only = ""
                ratio = ""
                if len(solvers) == 2:
                    other = [x for x in solvers if x != s][0]
                    only = sum(1 for k in common if cells[(fam, n, s)][k]["success"]
                               and not cells[(fam, n, other)][k]["success"])
                    both = [k for k in common if cells[(fam, n, s)][k]["success"]
                            and cells[(fam, n, other)][k]["success"]]
                    if s == "compass_sparse" and both:
                        rat = [cells[(fam, n, s)][k]["time"] / max(cells[(fam, n, other)][k]["time"], 1e-6)
                               for k in both]
                        ratio = f"{median(rat):.3g} ({len(both)} inst.)"
                table.append([fam, n, label[s], f"{len(ok)}/{len(rr)}",
                              fmt_time(median([r["time"] for r in ok])),
                              fmt_time(median([r["time"] for r in bad])), to,
                              _med_int([r["major"] for r in rr]),
                              _med_int([r["minor"] for r in rr]),
                              _med_int([r["restarts"] for r in rr]), only, ratio])
    out(md_table(header, table))
    if rec:
        out("\n" + RECORDED_NOTE)


def _med_int(xs):
    xs = [x for x in xs if isinstance(x, (int, float)) and x >= 0]
    return f"{median(xs):g}" if xs else "–"


def _common_seeds(cells, fam, n, solvers):
    sets = [set(cells.get((fam, n, s), {})) for s in solvers]
    return sorted(set.intersection(*sets)) if sets else []


def summarize_tolerances(rows, out=print):
    if not rows:
        out("(no rows)")
        return
    by = defaultdict(list)
    for r in rows:
        by[(r["solver"], float(r["tol"]))].append(r)
    inst = sorted({(int(r["family"]), int(r["n"]), int(r["seed"])) for r in rows})
    out(f"\nTime against achieved error ({len(inst)} instances: "
        + ", ".join(f"family {f} n={n} seed {s}" for f, n, s in inst) + ")\n")
    header = ["solver", "convergence_tolerance", "reported solved", "natural <= tol",
              "median time", "total time", "median achieved FB norm", "median achieved natural",
              "max achieved natural"]
    table = []
    rec = any_recorded(r for r in rows if r["solver"] == "PATH")
    for s in SOLVERS:
        for tol in sorted({t for (ss, t) in by if ss == s}, reverse=True):
            rr = by[(s, tol)]
            fin = [r["natural"] for r in rr if math.isfinite(r["natural"])]
            name = s + (" (recorded)" if s == "PATH" and rec else "")
            table.append([name, f"{tol:.0e}",
                          f"{sum(bool(r['reported_success']) for r in rr)}/{len(rr)}",
                          f"{sum(r['natural'] <= tol for r in rr)}/{len(rr)}",
                          fmt_time(median([r["time"] for r in rr])),
                          fmt_time(sum(r["time"] for r in rr if math.isfinite(r["time"]))),
                          fmt_e(median([r["fb_norm"] for r in rr])),
                          fmt_e(median(fin)) if fin else "inf",
                          fmt_e(max(fin)) if fin else "inf"])
    out(md_table(header, table))
    if rec:
        out("\n" + RECORDED_NOTE)


# --------------------------------------------------------------------------- main
TOLERANCES = [1e-4, 1e-6, 1e-8, 1e-10, 1e-12]
"""``--tolerances``: the convergence tolerances of both solvers."""
TOLERANCE_INSTANCES = ([(1, 20, s) for s in range(3)] + [(1, 50, s) for s in range(3)]
                       + [(2, 20, s) for s in range(3)])
"""``--tolerances``: its (family, n, seed) instances (``--quick``: the next list)."""
TOLERANCE_INSTANCES_QUICK = [(1, 20, 0), (2, 10, 0)]


def _keys(source, plan):
    """The reference keys of the planned (family, n, seed, tol) solves (recorded mode)."""
    if not source.recorded:
        return None
    ref = source.reference
    return [ref.key(family=f, n=n, seed=s, tol=t) for f, n, s, t in plan]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smoke run (< 2 min)")
    ap.add_argument("--instances", "-K", type=int, default=None,
                    help="instances per (family, n) (full default 100)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None,
                    help="dimensions n (default 10 20 50 100 200)")
    ap.add_argument("--families", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--family2-max", type=int, default=200,
                    help="largest n for family 2 (the thesis stops at 100)")
    ap.add_argument("--time-limit", type=float, default=None,
                    help="per-solve time limit in seconds, both solvers (default 60)")
    ap.add_argument("--repeats", type=int, default=3,
                    help="solves faster than 0.2 s are repeated this often; median time")
    ap.add_argument("--seed0", type=int, default=0, help="instance k uses seed seed0 + k")
    ap.add_argument("--no-path", action="store_true", help="compass_sparse only")
    add_path_argument(ap)
    ap.add_argument("--out", type=Path, default=None, help="CSV output")
    ap.add_argument("--resume", action="store_true",
                    help="append to --out and skip solves already in it")
    ap.add_argument("--summarize", type=Path, default=None, metavar="CSV",
                    help="print the tables of an existing CSV and exit")
    ap.add_argument("--path-only", action="store_true",
                    help="PATH only (e.g. to add PATH's rows to a CSV with --resume)")
    ap.add_argument("--homotopy", choices=("auto", "off", "only"), default=None,
                    help="compass_sparse's homotopy option (default: the solver's default)")
    ap.add_argument("--tolerances", action="store_true",
                    help="time against achieved error for convergence_tolerance 1e-4..1e-12")
    a = ap.parse_args(argv)

    if a.summarize is not None:
        rows = read_csv(a.summarize)
        (summarize_tolerances if "tolerances" in a.summarize.name else summarize)(rows)
        return 0

    info = machine_info()
    print_machine(info)
    source = choose_path_source("thesis", a.path_mode, a.no_path)
    use_path = source.live
    solvers = [s for s in SOLVERS if s == "compass_sparse" or source.mode != "none"]
    if a.path_only:
        solvers = [s for s in solvers if s == "PATH"]
    tl = a.time_limit if a.time_limit is not None else (20.0 if a.quick else 60.0)
    hard = 2.0 * tl + 30.0
    worker = Worker(warm_up, dict(with_path=use_path))

    if a.tolerances:
        tols = TOLERANCES
        inst = TOLERANCE_INSTANCES_QUICK if a.quick else TOLERANCE_INSTANCES
        out = a.out or RESULTS / ("thesis_tolerances_quick.csv" if a.quick
                                  else "thesis_tolerances.csv")
        print(source.line(_keys(source, [(f, n, s, t) for f, n, s in inst for t in tols])),
              flush=True)
        log = CsvLog(out, FIELDS)
        rows = []
        for fam, n, seed in inst:
            for tol in tols:
                for s in solvers:
                    rec = _solve(worker, source, s, hard, family=fam, n=n, seed=seed,
                                 time_limit=tl, tol=tol, repeats=a.repeats)
                    if rec is None:
                        print(f"family {fam} n={n:4d} seed {seed:3d} tol {tol:.0e} {s:15s} "
                              f"– (not in the reference)", flush=True)
                        continue
                    rec.update(family=fam, n=n, seed=seed, tol=tol, solver=s)
                    log.write(rec)
                    rows.append(rec)
                    print(f"family {fam} n={n:4d} seed {seed:3d} tol {tol:.0e} {s:15s} "
                          f"natural {fmt_e(rec['natural'])} FB {fmt_e(rec['fb_norm'])} "
                          f"{fmt_time(rec['time'])} {rec['status']}{recorded_mark(rec)}",
                          flush=True)
        log.close()
        worker.close()
        write_json(out.with_suffix(".json"), dict(machine=info, time_limit=tl, tolerances=tols,
                                                  instances=inst,
                                                  path=source.line().lstrip("# ")))
        summarize_tolerances(rows)
        print(f"\n# rows in {out}", flush=True)
        return 0

    K = a.instances if a.instances is not None else (3 if a.quick else 100)
    sizes = a.sizes or ([10, 20, 50] if a.quick else [10, 20, 50, 100, 200])
    out = a.out or RESULTS / ("thesis_quick.csv" if a.quick else "thesis_table.csv")
    done = set()
    rows = []
    if a.resume and out.exists():
        rows = read_csv(out)
        done = {(int(r["family"]), int(r["n"]), int(r["seed"]), r["solver"]) for r in rows}
        print(f"# resuming: {len(done)} solves already in {out}", flush=True)
    plan = [(fam, n, a.seed0 + k, 1e-6) for k in range(K) for n in sizes
            for fam in a.families if not (fam == 2 and n > a.family2_max)]
    print(source.line(_keys(source, plan)), flush=True)
    log = CsvLog(out, FIELDS, append=a.resume)
    write_json(out.with_suffix(".json"), dict(machine=info, time_limit=tl, instances=K,
                                              sizes=sizes, families=a.families,
                                              family2_max=a.family2_max, seed0=a.seed0,
                                              homotopy=a.homotopy,
                                              success_tol=SUCCESS_TOL,
                                              path=source.line(_keys(source, plan))
                                              .lstrip("# ")))
    t_start = time.perf_counter()
    # instance-major order: every pass over k adds one instance to every cell
    for k in range(K):
        seed = a.seed0 + k
        for n in sizes:
            for fam in a.families:
                if fam == 2 and n > a.family2_max:
                    continue
                for s in solvers:
                    if (fam, n, seed, s) in done:
                        continue
                    extra = ({} if s != "compass_sparse" or a.homotopy is None
                             else dict(homotopy=a.homotopy))
                    rec = _solve(worker, source, s, hard, family=fam, n=n, seed=seed,
                                 time_limit=tl, tol=1e-6, repeats=a.repeats, **extra)
                    if rec is None:
                        print(f"[{time.perf_counter() - t_start:7.0f}s] family {fam} n={n:4d} "
                              f"seed {seed:3d} {s:15s} – (not in the reference)", flush=True)
                        continue
                    rec.update(family=fam, n=n, seed=seed, tol=1e-6, solver=s)
                    log.write(rec)
                    rows.append(rec)
                    print(f"[{time.perf_counter() - t_start:7.0f}s] family {fam} n={n:4d} "
                          f"seed {seed:3d} {s:15s} {'OK  ' if rec['success'] else 'FAIL'} "
                          f"natural {fmt_e(rec['natural'])} {fmt_time(rec['time']):>9s} "
                          f"major {rec['major']} pivots {rec['minor']} {rec['status']}"
                          + (f" [{rec['error']}]" if rec["error"] else "") + recorded_mark(rec),
                          flush=True)
    log.close()
    worker.close()
    summarize(rows)
    print(f"\n# rows in {out}; worker restarts after hard timeouts: {worker.restarts}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
