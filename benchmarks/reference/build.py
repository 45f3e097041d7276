"""How the reference files of this directory were made from the recorded benchmark runs.

PATH 5.2's rows are copied, unchanged, from the result files of ``benchmarks/results/``
as they stand at revision ``SOURCE_REV`` (read with ``git show``, so that this script
still runs after those files leave the working tree), one reference file per suite with a
sidecar JSON that names each run: its date, the revision of the package, the command and
the source file.  Nothing is computed here except the choice of the run a row comes from
and a cross-check: where several runs measured the same solve, PATH's status, counters
and residuals must agree in all of them (they do: PATH is deterministic; only its times
differ from run to run).

    python3 benchmarks/reference/build.py            # rewrites the files of this directory
    python3 benchmarks/reference/build.py --check    # compares them with what it would write

The benchmarks read these files at run time (``benchmarks/_common.py``: path_reference);
they never need this script or ``benchmarks/results/``.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
SOURCE_REV = "01329722af9bd5dfc1ce190b59d07733fdbb6e73"
"""The revision whose ``benchmarks/results/`` holds every source file used here."""

PATH_VERSION = ("PATH 5.2.01 in GAMS 54.6.1, through gamspy 1.29.1 (gamspy_base 54.6.1), "
                "under GAMSPy's bundled demo licence (at most 1000 rows/columns for an "
                "MCP), which expired on 2026-11-26")
MACHINE = "2 cores (AMD EPYC), Linux, Python 3.11.7, numpy 2.4.6, scipy 1.17.1, numba 0.68.1"
SUCCESS_TOL = 1e-6

# columns every suite may carry, with their meaning (the JSON repeats those a file has)
COLUMNS = {
    "success": "our independent verdict: the natural residual of PATH's point, "
               "||z - clip(z - F(z), l, u)||_inf, recomputed in float64, is <= 1e-6",
    "reported_success": "PATH's own verdict (exit 'solution found' with normal GAMS "
                        "solve and model status)",
    "status": "PATH's exit message (e.g. 'solution found', 'other error')",
    "natural": "the natural residual of PATH's point (see success), no unit",
    "fb_norm": "PATH's own final residual (the 2-norm of the Fischer-Burmeister function "
               "it tests convergence_tolerance on)",
    "time": "PATH's own 'Total Time' from its log, seconds (GAMS process start, model "
            "generation and reading back the solution excluded); the median over the "
            "run's repeats",
    "time_min": "the least of the repeats' 'Total Time', seconds",
    "time_max": "the largest of the repeats' 'Total Time', seconds",
    "wall": "wall time of the GAMSPy model.solve call (GAMS process included), seconds",
    "repeats": "PATH runs of the solve whose times the median is taken over",
    "major": "PATH's major iterations",
    "minor": "PATH's minor iterations (pivots)",
    "crash": "PATH's crash iterations",
    "restarts": "PATH's restarts",
    "nfev": "PATH's function evaluations",
    "njev": "PATH's gradient (Jacobian) evaluations",
    "n": "the MCP's number of variables",
    "time_limit": "the time limit given to PATH in that run, seconds",
    "run": "the run the row comes from (a key of 'runs' in the JSON)",
}


# --------------------------------------------------------------------------- sources
def source_text(name: str, rev: str = SOURCE_REV) -> str:
    return subprocess.run(["git", "show", f"{rev}:benchmarks/results/{name}"], cwd=ROOT,
                          capture_output=True, text=True, check=True).stdout


def source_rows(name: str, rev: str = SOURCE_REV, solver: str | None = "PATH") -> list[dict]:
    rows = list(csv.DictReader(io.StringIO(source_text(name, rev))))
    return [r for r in rows if solver is None or r.get("solver") == solver]


def source_json(name: str, rev: str = SOURCE_REV) -> dict:
    return json.loads(source_text(name, rev))


def commit_of(name: str, rev: str = SOURCE_REV) -> str:
    """The commit that last wrote the source file (at or before ``rev``)."""
    return subprocess.run(["git", "log", "-1", "--format=%h %cd",
                           "--date=format-local:%Y-%m-%d %H:%M UTC", rev, "--",
                           f"benchmarks/results/{name}"], cwd=ROOT, capture_output=True,
                          text=True, check=True, env=dict(os.environ, TZ="UTC")).stdout.strip()


def run_from_json(name: str, **extra) -> dict:
    meta = source_json(name.rsplit(".", 1)[0] + ".json")
    mach = meta["machine"]
    out = dict(date=mach["date"][:10], started=mach["date"], revision=mach["git"],
               command=mach["command"], sources=[f"benchmarks/results/{name}",
                                                 f"benchmarks/results/{name[:-4]}.json"],
               source_commit=commit_of(name), gamspy=mach.get("gamspy", ""),
               machine=f"{mach['cores']} cores ({mach['cpu']}), Python {mach['python']}, "
                       f"numpy {mach['numpy']}, scipy {mach['scipy']}, numba {mach['numba']}",
               time_limit=meta.get("time_limit"))
    out.update(extra)
    return out


# --------------------------------------------------------------------------- helpers
def _cross_check(rows_by_run: dict[str, dict], fields: list[str]) -> dict:
    """Compare the non-time fields of every key measured by more than one run."""
    keys = {}
    for run, rows in rows_by_run.items():
        for k, r in rows.items():
            keys.setdefault(k, []).append((run, r))
    compared, differ, spread = 0, [], []
    for k, seen in keys.items():
        if len(seen) < 2:
            continue
        compared += 1
        first = seen[0][1]
        for run, r in seen[1:]:
            bad = [f for f in fields if r[f] != first[f]]
            if bad:
                differ.append(dict(key=list(k), runs=[seen[0][0], run], fields=bad))
        ts = [float(r["time"]) for _, r in seen]
        if min(ts) > 0:
            spread.append(max(ts) / min(ts))
    spread.sort()
    return dict(keys_measured_more_than_once=compared, fields_compared=fields,
                disagreements=differ,
                time_spread=dict(
                    what="largest / least recorded PATH time of the same solve over the "
                         "runs that measured it",
                    median=round(spread[len(spread) // 2], 2) if spread else None,
                    max=round(spread[-1], 2) if spread else None))


def _write(name: str, key: dict, columns: list[str], rows: list[dict], meta: dict,
           check: bool) -> bool:
    seen = set()
    for r in rows:
        k = tuple(r[c] for c in key)
        if k in seen:
            raise SystemExit(f"{name}: duplicate key {k}")
        seen.add(k)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(key) + columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c, "") for c in list(key) + columns})
    meta = dict(meta)
    meta["file"] = f"{name}.csv"
    meta["key"] = key
    extra = meta.get("extra_columns", {})
    meta["columns"] = {c: extra.get(c, COLUMNS.get(c, "")) for c in columns}
    assert all(meta["columns"].values()), meta["columns"]
    meta.pop("extra_columns", None)
    meta["rows"] = len(rows)
    text_json = json.dumps(meta, indent=1, ensure_ascii=False) + "\n"
    targets = {HERE / f"{name}.csv": buf.getvalue(), HERE / f"{name}.json": text_json}
    ok = True
    for path, text in targets.items():
        if check:
            if not path.exists() or path.read_text() != text:
                print(f"differs: {path.relative_to(ROOT)}")
                ok = False
        else:
            path.write_text(text)
            print(f"wrote {path.relative_to(ROOT)} ({len(rows)} rows)" if path.suffix == ".csv"
                  else f"wrote {path.relative_to(ROOT)}")
    return ok


def _base(suite: str, benchmark: str, selection: str, coverage: str) -> dict:
    return dict(suite=suite, benchmark=benchmark, solver=PATH_VERSION,
                success_tol=SUCCESS_TOL, selection=selection, coverage=coverage,
                built_by="benchmarks/reference/build.py", built_from_revision=SOURCE_REV[:7])


# --------------------------------------------------------------------------- suites
def build_small(check):
    src = "small_r16_review.csv"
    run = dict(date="2026-11-26", started="2026-11-26 (before 15:38 UTC, when the file was "
               "committed)", revision="2546e28",
               command="PYTHONPATH=. python3 benchmarks/bench_small.py --rounds 3 --repeats 3 "
                       "--path-repeats 1 --suffix _r16_review",
               sources=[f"benchmarks/results/{src}"], source_commit=commit_of(src),
               gamspy="1.29.1", machine=MACHINE, time_limit=60.0,
               notes="round 16's final review run (benchmarks/small.md, 'Side by side with "
                     "PATH 5.2 (round 16)', row r16_review); a slow phase of the shared "
                     "machine for our solver, PATH's times as in the other round-16 runs. "
                     "PATH's time is the median of its 'Total Time' over 3 runs (one per "
                     "round). This run did not record PATH's iteration counts. Its CSV "
                     "records no versions: those of the machine that day are in "
                     "benchmarks/results/thesis_round16.json (2026-11-26 15:04 UTC: "
                     "gamspy 1.29.1, the versions above).")
    rows = []
    for r in source_rows(src):
        rows.append(dict(group=r["group"], name=r["name"], n=int(r["n"]),
                         success=r["success"], status=r["status"], natural=r["natural"],
                         time=r["time"], repeats=r["repeats"], run="r16_review"))
    for r in rows:
        assert (r["success"] == "True") == (float(r["natural"]) <= SUCCESS_TOL), r
    meta = _base("small", "benchmarks/bench_small.py",
                 "the PATH rows of round 16's final review run, unchanged (one run: no "
                 "medians over runs)",
                 "every problem of bench_small.py's default case list (groups known, thesis, "
                 "cge with their default sizes, families and seeds)")
    meta["runs"] = {"r16_review": run}
    meta["absent"] = []
    return _write("small", {"group": "str", "name": "str", "n": "int"},
                  ["success", "status", "natural", "time", "repeats", "run"], rows, meta,
                  check)


THESIS_FIELDS = ["success", "reported_success", "status", "natural", "fb_norm", "major",
                 "minor", "crash", "restarts"]


def _thesis_rows(src):
    out = {}
    for r in source_rows(src):
        k = (int(r["family"]), int(r["n"]), int(r["seed"]), float(r["tol"]))
        out[k] = r
    return out


def build_thesis(check):
    # newest first: a key takes its row from the first run of this list that measured it
    runs = {
        "homotopy_30_path": run_from_json(
            "thesis_homotopy_30.csv",
            notes="PATH's side of the 30-instance table at n = 200 and 500 (benchmarks/"
                  "thesis.md, 'The full table, compass_sparse'; PATH run right after ours, "
                  "18:28-18:38 UTC, load average 4-7); this CSV's compass_sparse rows come "
                  "from an earlier command of the same file and are not used"),
        "final": run_from_json(
            "thesis_final.csv",
            notes="the side-by-side table of 30 instances per cell, n = 10 ... 200 "
                  "(benchmarks/thesis.md, 'Final table of this session', 2026-11-23 "
                  "00:00-00:16 UTC)"),
        "tolerances": run_from_json(
            "thesis_tolerances.csv",
            notes="the tolerance study (--tolerances): convergence_tolerance 1e-4 ... 1e-12 "
                  "on family 1 n = 20 and 50 and family 2 n = 20, seeds 0-2"),
        "tolerances_quick": run_from_json(
            "thesis_tolerances_quick.csv",
            notes="the quick tolerance study (--tolerances --quick): family 1 n = 20 and "
                  "family 2 n = 10, seed 0"),
    }
    sources = {"homotopy_30_path": "thesis_homotopy_30.csv", "final": "thesis_final.csv",
               "tolerances": "thesis_tolerances.csv",
               "tolerances_quick": "thesis_tolerances_quick.csv"}
    by_run = {rid: _thesis_rows(src) for rid, src in sources.items()}
    chosen = {}
    for rid, rows in by_run.items():  # newest first
        for k, r in rows.items():
            if k not in chosen:
                chosen[k] = (rid, r)
    others = {name: _thesis_rows(name) for name in (
        "thesis_table.csv", "thesis_combined.csv", "thesis_quick.csv", "thesis_homotopy.csv",
        "thesis_homotopy_final.csv")}
    cross = _cross_check({**by_run, **others}, THESIS_FIELDS)
    if cross["disagreements"]:
        raise SystemExit(f"thesis: runs disagree: {cross['disagreements'][:3]}")
    rows = []
    for k in sorted(chosen, key=lambda k: (k[3] != 1e-6, k[0], k[1], k[2], -k[3])):
        rid, r = chosen[k]
        rows.append(dict(family=k[0], n=k[1], seed=k[2], tol=r["tol"],
                         success=r["success"], reported_success=r["reported_success"],
                         status=r["status"], natural=r["natural"], fb_norm=r["fb_norm"],
                         time=r["time"], wall=r["wall"], major=r["major"], minor=r["minor"],
                         crash=r["crash"], restarts=r["restarts"], repeats=r["repeats"],
                         time_limit=runs[rid]["time_limit"], run=rid))
        assert (r["success"] == "True") == (float(r["natural"]) <= SUCCESS_TOL), k
    longest = max(float(r["time"]) for r in rows)
    meta = _base(
        "thesis", "benchmarks/bench_thesis.py",
        "each (family, n, seed, tol) from the newest run that measured it, in the order "
        "of 'runs' (newest first); one run per row, no medians over runs. PATH's times "
        "are the run's own (a median over 3 repeats when the solve took < 0.2 s); "
        "the other fields are identical in every run that measured the same solve "
        "(cross_check)",
        "tol 1e-6: families 1 and 2, n = 10, 20, 50, 100, 200, 500, seeds 0-29 (the 30-instance "
        "tables; --quick's instances are among them). The default table of bench_thesis.py "
        "(--instances 100) asks for seeds 0-99: PATH was recorded on seeds 0-29 only (the "
        "100-instance run of 2026-11-22, thesis_table.csv, was stopped after seeds 0-16, "
        "all of which the 30-instance tables hold). Other tolerances: the instances of "
        "--tolerances and --tolerances --quick")
    meta["runs"] = runs
    meta["cross_check"] = dict(cross, other_sources=[f"benchmarks/results/{n}" for n in others])
    meta["longest_time"] = longest
    meta["time_limit_note"] = (
        f"the longest recorded PATH time is {longest:.3g} s, below every run's time limit "
        "(20-60 s): the limits did not bind, so the rows stand for any limit above that")
    meta["absent"] = []
    return _write("thesis", {"family": "int", "n": "int", "seed": "int", "tol": "float"},
                  ["success", "reported_success", "status", "natural", "fb_norm", "time",
                   "wall", "major", "minor", "crash", "restarts", "repeats", "time_limit",
                   "run"], rows, meta, check)


def build_lcp(check):
    src = "lcp.csv"
    run = run_from_json(src, notes="benchmarks/lcp.md, 'Measured' (2026-11-22 23:09-23:21 "
                        "UTC; the thesis benchmark and other jobs shared the 2 cores, load "
                        "average 4-5); part B: PATH side by side at n = 100, 300, 1000")

    def rows_of(name):
        out = {}
        for r in source_rows(name):
            out[(r["kind"], r["bounds"], int(r["n"]), int(r["seed"]), r["config"])] = r
        return out

    main = rows_of(src)
    others = {n: rows_of(n) for n in ("lcp_quick.csv", "lcp_final_quick.csv",
                                       "lcp_guess_quick.csv")}
    fields = ["success", "reported_success", "status", "natural", "fb_norm", "major", "minor",
              "crash", "restarts"]
    cross = _cross_check({"lcp": main, **others}, fields)
    if cross["disagreements"]:
        raise SystemExit(f"lcp: runs disagree: {cross['disagreements'][:3]}")
    rows = []
    for k, r in main.items():
        assert (r["success"] == "True") == (float(r["natural"]) <= SUCCESS_TOL), k
        rows.append(dict(kind=k[0], bounds=k[1], n=k[2], seed=k[3], config=k[4],
                         **{c: r[c] for c in ("success", "reported_success", "status",
                                              "natural", "fb_norm", "time", "time_min",
                                              "time_max", "repeats", "wall", "major", "minor",
                                              "crash", "restarts")},
                         time_limit=run["time_limit"], run="lcp"))
    meta = _base("lcp", "benchmarks/bench_lcp.py",
                 "the PATH rows (part B) of the newest complete run, unchanged; the three "
                 "later --quick runs measured a subset (n = 100 and 1000) with identical "
                 "statuses, counters and residuals (cross_check) and are not used",
                 "part B of bench_lcp.py's default and --quick runs: grid and banded "
                 "(bounds ncp and mixed) and obstacle (lower), requested n = 100, 300, 1000 "
                 "(obstacle: n = 100, 289, 961), seed 0, configurations default and nocrash. "
                 "The key's n is the instance's true size (the benchmark's row n)")
    meta["runs"] = {"lcp": run}
    meta["cross_check"] = dict(cross, other_sources=[f"benchmarks/results/{n}" for n in others])
    meta["absent"] = []
    return _write("lcp", {"kind": "str", "bounds": "str", "n": "int", "seed": "int",
                          "config": "str"},
                  ["success", "reported_success", "status", "natural", "fb_norm", "time",
                   "time_min", "time_max", "repeats", "wall", "major", "minor", "crash",
                   "restarts", "time_limit", "run"], rows, meta, check)


def build_cge(check):
    src = "cge_path.csv"
    run = dict(date="2026-11-22", started="2026-11-22 23:57 UTC (benchmarks/cge.md, 'How it "
               "was measured': part 3 and the PATH comparison)", revision="c6c1c37",
               command="python benchmarks/bench_cge.py --time-limit 180 --parts path stress "
                       "--suffix _b (the output renamed to cge_path.csv)",
               sources=[f"benchmarks/results/{src}"], source_commit=commit_of(src),
               gamspy="1.29.1", machine=MACHINE, time_limit=180.0,
               notes="benchmarks/cge.md, '4. Side by side with PATH': the one-sector LPR "
                     "Ramsey model in GAMSPy (bench_cge.py: ramsey_gamspy), from the "
                     "pre-shock benchmark, convergence_tolerance 1e-6; time = median over "
                     "3 PATH runs, wall = the last run's model.solve call")

    def rows_of(name):
        return {(int(r["T"]), float(r["tax"])): r for r in source_rows(name)}

    main = rows_of(src)
    quick = rows_of("cge_path_quick.csv")
    fields = ["success", "status", "natural", "major", "minor", "crash", "nfev", "njev",
              "K5_change", "K_last_change"]
    cross = _cross_check({"cge_path": main, "cge_path_quick": quick}, fields)
    if cross["disagreements"]:
        raise SystemExit(f"cge: runs disagree: {cross['disagreements'][:3]}")
    rows = []
    for k, r in main.items():
        assert (r["success"] == "True") == (float(r["natural"]) <= SUCCESS_TOL), k
        rows.append(dict(T=k[0], tax=r["tax"], n=int(r["n"]),
                         **{c: r[c] for c in ("success", "status", "natural", "time", "wall",
                                              "major", "minor", "crash", "nfev", "njev",
                                              "max_rel_diff", "K5_change", "K_last_change")},
                         repeats=3, run="cge_path"))
    meta = _base("cge", "benchmarks/bench_cge.py (part path)",
                 "the PATH rows of the newest complete run of part path, unchanged; the later "
                 "--quick run (T = 40 only) agrees on every field but the times (cross_check) "
                 "and is not used",
                 "part path of bench_cge.py, default and --quick: T = 40 (n = 363) and T = 110 "
                 "(n = 993), capital tax -0.1 (the LPR subsidy) and 0.25")
    meta["extra_columns"] = {
        "max_rel_diff": "max |x_PATH - x_ours| / max(1, |x_ours|) against compass_sparse's "
                        "point of the same run (revision c6c1c37): a property of that run, "
                        "not comparable with a later revision's point",
        "K5_change": "from PATH's point: the capital stock in period 5 relative to the "
                     "benchmark, K(5)/K0(5) - 1",
        "K_last_change": "from PATH's point: the capital stock in the last period relative "
                         "to the benchmark",
    }
    meta["runs"] = {"cge_path": run}
    meta["cross_check"] = dict(cross, other_sources=["benchmarks/results/cge_path_quick.csv"])
    meta["absent"] = []
    return _write("cge", {"T": "int", "tax": "float"},
                  ["n", "success", "status", "natural", "time", "wall", "repeats", "major",
                   "minor", "crash", "nfev", "njev", "max_rel_diff", "K5_change",
                   "K_last_change", "run"], rows, meta, check)


def build_links(check):
    src = "links_gamspy.txt"
    text = source_text(src)
    head = re.search(r"revision (\w+), (\d{4}-\d\d-\d\d \d\d:\d\d UTC)", text)
    sizes = {"cournot": {100: 20, 1000: 199}, "spatial": {100: 29, 1000: 285}}  # GAMS_SIZES
    rows = []
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 9 or cells[0] not in sizes:
            continue
        model, n = cells[0], int(cells[1])
        target = 100 if n < 500 else 1000
        rows.append(dict(model=model, n_target=target, size_arg=sizes[model][target], n=n,
                         solve_wall=cells[7], max_level_diff=cells[8], repeats=3,
                         run="links_gamspy"))
    assert len(rows) == 4, rows
    run = dict(date=head.group(2)[:10], started=head.group(2), revision=head.group(1),
               command="python benchmarks/bench_links.py --parts gamspy --repeats 3",
               sources=[f"benchmarks/results/{src}"], source_commit=commit_of(src),
               gamspy="1.29.1", machine=MACHINE + " (shared with about eight other jobs)",
               time_limit=None,
               notes="benchmarks/links.md, '3. GAMSPy route': the part run alone in a fresh "
                     "process; the source is the printed table (times to 0.01 s)")
    meta = _base("links", "benchmarks/bench_links.py (part gamspy)",
                 "the PATH column of the one run of the GAMSPy part alone, as printed",
                 "part gamspy of bench_links.py: cournot (n = 100, 995) and spatial "
                 "(n = 101, 997), the models of compass_sparse.examples at GAMS_SIZES")
    meta["extra_columns"] = {
        "n_target": "the size the benchmark asks for (a key of GAMS_SIZES)",
        "size_arg": "the model's data argument at that size (markets or nodes)",
        "n": "the MCP's size in GAMS",
        "solve_wall": "wall time of model.solve(solver='path') on the GAMSPy model, GAMS "
                      "process, generation and read-back included, seconds; the median over "
                      "3 runs, as printed (0.01 s)",
        "max_level_diff": "the largest difference between PATH's levels and those of "
                          "compass_sparse's GAMSPy route in that run (revision 90c43c7)",
    }
    meta["runs"] = {"links_gamspy": run}
    meta["absent"] = []
    return _write("links", {"model": "str", "n_target": "int"},
                  ["size_arg", "n", "solve_wall", "max_level_diff", "repeats", "run"], rows,
                  meta, check)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true",
                    help="compare the files with what would be written; exit 1 on a difference")
    a = ap.parse_args(argv)
    ok = all([build_small(a.check), build_thesis(a.check), build_lcp(a.check),
              build_cge(a.check), build_links(a.check)])
    if a.check:
        print("up to date" if ok else "out of date")
        return 0 if ok else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
