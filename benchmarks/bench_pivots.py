"""Pivot-heavy solves: pivots, factorizations and time per pivot, with PATH's recorded figures.

Problems (all from ``compass_sparse.generators``; only the public API is used):

* ``traffic8``, ``traffic24``: the Sioux Falls traffic equilibrium (the GAMS model library's
  ``traffic``), ``traffic_equilibrium(8)`` n = 912 and ``traffic_equilibrium(24)`` n = 2452;
* ``thesis{1,2}_n{600,1000}``: the thesis' random families (dense Jacobian), seed 0;
* ``cge_*``: the static CGE ``static_cge(**size_for(2000))`` (n = 2024) under shocks
  (from its benchmark equilibrium, as a counterfactual is solved): a 50% output tax on
  every sector, region 1's productivity halved, and cut to a fifth (sectors shut down),
  the first factor's endowment cut to a tenth in every region; ``cge_*_engine``: the same
  with ``path_basis="sparse engine"`` (the automatic route keeps them on the manager);
* ``grid4900``: ``p_matrix_lcp(4900, "grid")`` and ``obstacle60``: ``obstacle_problem(60)``
  (n = 3600), both with the crash off (one pivotal path does the work).

Per problem: status, recomputed natural residual, pivots (minor iterations), factorizations,
major iterations, restarts, crash iterations, F and J evaluations, CPU and wall time of the
solve (medians over ``--repeats`` timed solves, after one untimed solve that compiles and
loads the numba kernels), the time spent in the user's F and J (estimated: F and J timed
at the solution times the evaluation counts; "net" = solve CPU less that),
microseconds per pivot (net CPU / pivots), the largest factors' entries (``max_nnz_lu``,
the largest nnz(L + U) of the solve's factorizations) and the entries the sparse engine's
pivots read (``pivot_lu_entries``: the factors' entries held at each of its pivots,
summed; printed in millions): counts, free of this machine's timing noise, that a
pivot's time on the sparse engine follows.
Counts must be the same in every repeat (the solver is deterministic); a difference is
reported.  A problem whose untimed solve ends at its time limit gets one timed solve.  PATH's figures come from ``benchmarks/reference/pivots.csv`` (PATH cannot run
here: GAMS' demo licence expired).

    python benchmarks/bench_pivots.py --quick     # traffic8, cge_outtax, grid, obstacle
    python benchmarks/bench_pivots.py             # every problem, 3 timed repeats
    python benchmarks/bench_pivots.py --baseline /path/to/old/tree --suffix engine

With ``--baseline`` every problem is solved in two child processes in turn, one importing
the package from the baseline tree and one from this tree (before and after in the same
minutes of a shared machine; the ratio is what to read), and the CSV has one row per tree
(column ``tree``: "baseline" or "this").

The command, the git revision and the machine are printed and written to the CSV's
companion ``.json``; the CSV is ``benchmarks/results/pivots[_SUFFIX].csv``.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

# compiled kernels from the first call: timings of compiled code, runs repeat bit for bit
os.environ.setdefault("COMPASS_SPARSE_JIT", "always")

import numpy as np  # noqa: E402

from compass_sparse import solve_mcp  # noqa: E402
from _revision import git_revision  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
REFERENCE = HERE / "reference" / "pivots.csv"
SUCCESS_TOL = 1e-6  # natural residual of a success, recomputed here


# ------------------------------------------------------------------------- the problems
def _traffic(k):
    from compass_sparse.generators import traffic_equilibrium
    return traffic_equilibrium(k).problem, {}


def _thesis(family, n):
    from compass_sparse.generators import thesis_family
    return thesis_family(n, family, seed=0).problem, {}


def _cge(shock):
    from compass_sparse.generators.cge import size_for, static_cge
    m = static_cge(**size_for(2000), seed=0)
    R, N = m.block_shapes["Y"]
    _, F = m.block_shapes["W"]
    if shock == "outtax":  # a 50% output tax on every sector of every region
        kw = dict(output_tax=0.5)
    elif shock == "productivity":  # region 1's sectors at half their productivity
        p = np.ones((R, N))
        p[0] = 0.5
        kw = dict(productivity=p)
    elif shock == "productivity_deep":  # ... at a fifth: sectors shut down
        p = np.ones((R, N))
        p[0] = 0.2
        kw = dict(productivity=p)
    else:  # endowment: the first factor's endowment at a tenth in every region
        e = np.ones((R, F))
        e[:, 0] = 0.1
        kw = dict(endowment=e)
    return m.with_shock(**kw).problem, {}


def _on_engine(case):
    problem, opts = case
    from compass_sparse import OptionError, Options, routes
    try:
        Options(path_basis="sparse engine")
    except OptionError:  # a baseline tree from before the option: the same route by
        routes.SPARSE_ENGINE_MAX_DENSITY = math.inf  # lifting its density limit
        return problem, opts
    return problem, dict(opts, path_basis="sparse engine")


def _grid():
    from compass_sparse.generators import p_matrix_lcp
    return p_matrix_lcp(4900, "grid", seed=0).problem, {"crash_method": "none"}


def _obstacle():
    from compass_sparse.generators import obstacle_problem
    return obstacle_problem(60, seed=0).problem, {"crash_method": "none"}


CASES = {
    "traffic8": lambda: _traffic(8),
    "traffic24": lambda: _traffic(24),
    "thesis1_n600": lambda: _thesis(1, 600),
    "thesis2_n600": lambda: _thesis(2, 600),
    "thesis1_n1000": lambda: _thesis(1, 1000),
    "thesis2_n1000": lambda: _thesis(2, 1000),
    "cge_outtax": lambda: _cge("outtax"),
    "cge_productivity": lambda: _cge("productivity"),
    "cge_productivity_deep": lambda: _cge("productivity_deep"),
    "cge_endowment": lambda: _cge("endowment"),
    # the CGE shocks on the compiled sparse engine (option path_basis), which 'auto' does
    # not choose for their Jacobians (9.6 entries a column)
    "cge_outtax_engine": lambda: _on_engine(_cge("outtax")),
    "cge_productivity_engine": lambda: _on_engine(_cge("productivity")),
    "cge_endowment_engine": lambda: _on_engine(_cge("endowment")),
    "grid4900": _grid,
    "obstacle60": _obstacle,
}
QUICK = ["traffic8", "cge_outtax", "grid4900", "obstacle60"]
# Per-problem time limits (s) where the default (--time-limit) would let a failing solve
# dominate the run: the thesis families at n = 1000 and the deep productivity shock end at
# their limit on some revisions (a row with status TIME_LIMIT then says so).
TIME_LIMITS = {"thesis1_n1000": 60.0, "thesis2_n1000": 60.0, "cge_productivity_deep": 60.0}


def natural_residual(problem, z):
    f = np.asarray(problem.F_uncounted(z), float)
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(f))):
        return math.inf
    return float(np.max(np.abs(z - np.clip(z - f, problem.lb, problem.ub))))


def _call_cpu(fn, z, reps=21):
    """Median CPU time of fn(z) (repeated until 20 ms have passed, at least ``reps``)."""
    times = []
    t_end = time.perf_counter() + 0.02
    while len(times) < reps or time.perf_counter() < t_end:
        t = time.process_time()
        fn(z)
        times.append(time.process_time() - t)
        if len(times) >= 2000:
            break
    return statistics.median(times)


def user_cpu(problem, z, nfev, njev):
    """The user's share of a solve: F and J timed at the solution point (the MCP's F and
    J, with the evaluation layer's checks), times the solve's evaluation counts.  An
    estimate that leaves the solve itself untouched (a wrapper around the user's functions
    would change what it times)."""
    return nfev * _call_cpu(problem.F_uncounted, z) + njev * _call_cpu(problem.J, z)


# ------------------------------------------------------------------------- one problem
def run_case(name, repeats, time_limit):
    problem, opts = CASES[name]()
    options = dict(opts, time_limit=float(min(time_limit, TIME_LIMITS.get(name, math.inf))))
    first = solve_mcp(problem, options=options)  # untimed: compiles kernels, loads caches
    if first.status.name == "TIME_LIMIT":
        repeats = 1  # (a failure at the time limit: one timed solve says as much)
    rows = []
    for _ in range(repeats):
        p = problem.with_start(problem.x0)  # a fresh evaluator (no memo from the last solve)
        c0, w0 = time.process_time(), time.perf_counter()
        res = solve_mcp(p, options=options)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        lu = getattr(res, "lu", None) or {}  # (a baseline tree may report fewer figures)
        rows.append(dict(
            status=res.status.name, natural=natural_residual(problem, res.x),
            pivots=int(res.minor_iterations), factorizations=int(res.factorizations),
            majors=int(res.nit), restarts=int(res.restarts),
            crash=int(res.crash_iterations), nfev=int(res.nfev), njev=int(res.njev),
            domain_errors=int(getattr(res, "domain_errors", 0)),
            max_nnz_lu=int(lu.get("max_nnz_lu", 0)),
            pivot_lu_entries=int(lu.get("pivot_lu_entries", 0)),
            cpu=cpu, wall=wall))
        x = res.x
    counts = ("status", "pivots", "factorizations", "majors", "restarts", "crash", "nfev",
              "njev", "max_nnz_lu", "pivot_lu_entries")
    same = all(all(r[k] == rows[0][k] for k in counts) for r in rows)
    out = dict(rows[0])
    out.update({k: statistics.median(r[k] for r in rows) for k in ("cpu", "wall")})
    out["user_cpu"] = user_cpu(problem, x, out["nfev"], out["njev"])
    net = out["cpu"] - out["user_cpu"]
    out.update(problem=name, n=int(problem.n), repeats=repeats, counts_repeat=same,
               success=bool(out["natural"] <= SUCCESS_TOL), net_cpu=net,
               us_per_pivot=(1e6 * net / out["pivots"]) if out["pivots"] else math.nan,
               pivots_per_var=out["pivots"] / problem.n)
    return out


# ------------------------------------------------------------------------- reference, report
def load_reference():
    ref = {}
    if REFERENCE.exists():
        with open(REFERENCE) as fh:
            for row in csv.DictReader(r for r in fh if not r.startswith("#")):
                ref[row["problem"]] = row
    return ref


FIELDS = ["tree", "problem", "n", "status", "success", "natural", "pivots", "factorizations", "majors",
          "restarts", "crash", "nfev", "njev", "domain_errors", "cpu", "wall", "user_cpu",
          "net_cpu", "us_per_pivot", "pivots_per_var", "max_nnz_lu", "pivot_lu_entries",
          "repeats", "counts_repeat",
          "path_pivots", "path_time", "path_source"]


def run_child(name, tree, repeats, time_limit):
    """run_case in a child process importing compass_sparse from ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", name,
                          "--repeats", str(repeats), "--time-limit", str(time_limit)],
                         env=env, cwd=str(tree), capture_output=True, text=True)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"{name} in {tree}: {out.stderr[-2000:]}")
    return json.loads(lines[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="four problems, one timed repeat")
    ap.add_argument("--problems", nargs="+", choices=sorted(CASES), help="these problems only")
    ap.add_argument("--repeats", type=int, default=None, help="timed solves (default 3; 1 quick)")
    ap.add_argument("--time-limit", type=float, default=300.0, help="per solve (s)")
    ap.add_argument("--suffix", default="", help="CSV name: pivots[_SUFFIX].csv")
    ap.add_argument("--revision", default=None,
                    help="the revision to record when the tree is an export without git")
    ap.add_argument("--baseline", default=None,
                    help="a tree (export) of another revision: each problem is solved by "
                         "both, in child processes, in turn")
    ap.add_argument("--baseline-revision", default="", help="the baseline tree's revision")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:  # one problem, its row as JSON (run_child)
        print(json.dumps(run_case(args.child, args.repeats or 3, args.time_limit)))
        return
    names = args.problems or (QUICK if args.quick else list(CASES))
    repeats = args.repeats or (1 if args.quick else 3)
    command = "python " + " ".join([sys.argv[0]] + (argv if argv is not None else sys.argv[1:]))
    info = dict(command=command, revision=args.revision or git_revision(),
                baseline=args.baseline_revision, date=time.strftime("%Y-%m-%d %H:%M"),
                machine=f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}",
                numpy=np.__version__)
    print(f"# {info['command']}\n# revision {info['revision']}  {info['date']}  {info['machine']}",
          flush=True)
    RESULTS.mkdir(exist_ok=True)
    stem = "pivots" + (f"_{args.suffix}" if args.suffix else "")
    path = RESULTS / f"{stem}.csv"
    ref = load_reference()
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS, extrasaction="ignore")
        w.writeheader()
        hdr = (f"{'problem':18s} {'n':>5s} {'status':10s} {'pivots':>7s} {'PATH':>5s} "
               f"{'fact':>5s} {'maj':>4s} {'rst':>3s} {'crash':>5s} {'cpu s':>7s} "
               f"{'wall s':>7s} {'net s':>7s} {'us/piv':>7s} {'max L+U':>8s} {'read M':>7s}")
        print(hdr + ("   (* baseline)" if args.baseline else ""), flush=True)
        trees = ([("baseline", Path(args.baseline)), ("this", HERE.parent)]
                 if args.baseline else [("this", None)])
        for name, (tree, root) in ((nm, t) for nm in names for t in trees):
            r = (run_child(name, root, repeats, args.time_limit) if root is not None
                 else run_case(name, repeats, args.time_limit))
            r["tree"] = tree
            pr = ref.get(name, {})
            r.update(path_pivots=pr.get("pivots", ""), path_time=pr.get("time_s", ""),
                     path_source=pr.get("source", ""))
            w.writerow(r)
            fh.flush()
            print(f"{name[:13] + ('*' if tree == 'baseline' else ''):18s} {r['n']:5d} {r['status']:10s} {r['pivots']:7d} "
                  f"{r['path_pivots'] or '-':>5s} {r['factorizations']:5d} {r['majors']:4d} "
                  f"{r['restarts']:3d} {r['crash']:5d} {r['cpu']:7.3f} {r['wall']:7.3f} "
                  f"{r['net_cpu']:7.3f} {r['us_per_pivot']:7.0f} {r.get('max_nnz_lu', 0):8d} "
                  f"{r.get('pivot_lu_entries', 0) / 1e6:7.1f}"
                  + ("" if r["counts_repeat"] else "  (counts differ between repeats)")
                  + ("" if r["success"] else f"  natural residual {r['natural']:.1e}"),
                  flush=True)
    with open(path.with_suffix(".json"), "w") as fh:
        json.dump(info, fh, indent=1)
    print(f"# written {path.relative_to(HERE.parent)}")


if __name__ == "__main__":
    main()
