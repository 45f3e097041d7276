"""Scenario batches of a static CGE model (n ~ 1000): warm starts along the grid against
cold starts, local pool against Dask, a killed and restarted batch, sensitivities.

Parts (``--parts``):

* ``grid``  -- a tariff x Armington-elasticity grid through the local pool, once per start
  mode: ``predicted`` (warm + first-order predictor, the default), ``warm`` (neighbour's
  point and basis), ``cold`` (the model's benchmark point, no basis).  Reports wall time,
  major iterations per scenario, failures and lost scenarios (rows missing from the file).
* ``dask``  -- the same 100-scenario batch through the local pool and a Dask LocalCluster
  (processes, 2 workers x 1 thread): statuses and max |x_local - x_dask|.
* ``kill``  -- a batch in a child process killed when about half its scenarios are written,
  then run again: every scenario must be in the results exactly once, and the rerun must
  solve only the missing ones.
* ``sens``  -- dx/dtariff at a solution against central differences of re-solves.

Each part appends a JSON record (with the git revision and the machine's load) to
``benchmarks/results/batch.json``.  Result files go to ``--out`` (default a temporary
directory; they are not part of the repository).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from compass_sparse.batch import grid, read_results, solve_batch
from compass_sparse.generators.cge import size_for, static_cge

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")


def revision() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                              capture_output=True, check=True).stdout.strip()
    except Exception:
        return "unknown"


def record(rec: dict):
    rec = {"revision": revision(), "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
           "loadavg": os.getloadavg(), "cores": os.cpu_count(), **rec}
    out = HERE / "results" / "batch.json"
    out.parent.mkdir(exist_ok=True)
    with open(out, "a") as fh:
        fh.write(json.dumps(rec) + "\n")
    print(json.dumps(rec, indent=1))


def model(n: int, seed: int = 0):
    return static_cge(**size_for(n), seed=seed)


def scenarios(tariffs: int, elasticities: int):
    return grid(sigma_armington=np.linspace(1.0, 4.0, elasticities),
                tariff=np.linspace(0.0, 0.5, tariffs))


def stats(b, out_dir) -> dict:
    nit = b.column("nit")
    on_file = read_results(out_dir).num_rows if out_dir else len(b.rows)
    starts = [r["start"] for r in b.rows]
    return {"scenarios": len(b.rows), "wall_s": round(b.wall_time, 2),
            "scenarios_per_s": round(len(b.rows) / b.wall_time, 3),
            "nit_mean": round(float(nit.mean()), 3), "nit_median": float(np.median(nit)),
            "nit_max": int(nit.max()), "failed": b.failed, "lost": len(b.rows) - on_file,
            "predicted_starts": starts.count("predicted"), "warm_starts": starts.count("warm"),
            "cold_starts": starts.count("cold"),
            "residual_median": float(np.median(b.column("residual"))),
            "residual_max": float(np.max(b.column("residual"))),
            "solve_time_sum_s": round(float(b.column("solve_time").sum()), 2),
            "scenario_time_sum_s": round(float(b.column("time").sum()), 2)}


def part_grid(args, out):
    m = model(args.n)
    sc = scenarios(args.tariffs, args.elasticities)
    for mode in args.modes:
        kw = {"predicted": {}, "warm": {"predictor": False},
              "cold": {"warm_start": False}}[mode]
        d = Path(out) / f"grid_{mode}"
        b = solve_batch(m, sc, workers=args.workers, output=d, progress=False, **kw)
        record({"part": "grid", "mode": mode, "n": m.n, "workers": args.workers,
                "grid": f"{args.elasticities} elasticities x {args.tariffs} tariffs",
                **stats(b, d)})


def part_dask(args, out):
    import distributed

    m = model(args.n)
    sc = scenarios(10, 10)
    local = solve_batch(m, sc, workers=2, output=Path(out) / "dask_local", progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        dask = solve_batch(m, sc, executor=client, output=Path(out) / "dask_dask",
                           progress=False)
    same = local.statuses == dask.statuses
    record({"part": "dask", "n": m.n, "scenarios": len(sc), "statuses_identical": same,
            "max_abs_x_difference": float(np.max(np.abs(local.x - dask.x))),
            "local_wall_s": round(local.wall_time, 2), "dask_wall_s": round(dask.wall_time, 2),
            "local_failed": local.failed, "dask_failed": dask.failed})


_CHILD = """
import sys, numpy as np, warnings
warnings.simplefilter("ignore")
sys.path.insert(0, {root!r})
from compass_sparse.batch import solve_batch
from compass_sparse.generators.cge import static_cge, size_for
sys.path.insert(0, {here!r})
from bench_batch import scenarios
m = static_cge(**size_for({n}), seed=0)
b = solve_batch(m, scenarios({t}, {e}), workers={w}, output={out!r}, progress=False,
                chunk_size=4)
print(b.solved_now, b.resumed)
"""


def part_kill(args, out):
    d = str(Path(out) / "kill")
    script = Path(out) / "kill_child.py"
    script.write_text(_CHILD.format(root=str(ROOT), here=str(HERE), n=args.n, t=10, e=10,
                                    w=args.workers, out=d))
    total = 100
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    t0 = time.time()
    written = 0
    while proc.poll() is None:
        try:
            written = read_results(d).num_rows if os.path.isdir(d) else 0
        except Exception:
            written = 0
        if written >= total // 2:
            break
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)  # the driver and its workers, as a crash would
    proc.wait()
    killed_after = time.time() - t0
    finished = read_results(d).num_rows
    rerun = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                           check=True)
    solved_now, resumed = map(int, rerun.stdout.split()[-2:])
    table = read_results(d)
    keys = table.column("key").to_pylist()
    record({"part": "kill", "n": args.n, "scenarios": total,
            "killed_after_s": round(killed_after, 1), "finished_before_kill": finished,
            "rerun_solved": solved_now, "rerun_resumed": resumed, "rows": len(keys),
            "distinct_scenarios": len(set(keys)),
            "all_solved": all(table.column("success").to_pylist()),
            "each_exactly_once": len(keys) == len(set(keys)) == total
            and solved_now + resumed == total and resumed == finished})


def part_sens(args, out):
    from compass_sparse import solve_mcp

    m = model(args.n)
    tight = {"convergence_tolerance": 1e-10}

    def prob(t):
        return m.with_shock(tariff=t).problem

    p0, h, H = 0.2, 1e-6, 1e-5
    r = solve_mcp(prob(p0), options=tight)
    G = (prob(p0 + h).F_uncounted(r.x) - prob(p0 - h).F_uncounted(r.x)) / (2 * h)
    t0 = time.perf_counter()
    S = r.sensitivity(prob(p0), G)
    ts = time.perf_counter() - t0
    rp = solve_mcp(prob(p0 + H).with_start(r.x), options=tight)
    rm = solve_mcp(prob(p0 - H).with_start(r.x), options=tight)
    fd = (rp.x - rm.x) / (2 * H)
    record({"part": "sens", "n": m.n, "solves_ok": bool(r.success and rp.success and rm.success),
            "degenerate": int(S.degenerate.size),
            "max_rel_error_vs_resolves": float(np.max(np.abs(fd - S.dx[:, 0]))
                                               / np.max(np.abs(fd))),
            "sensitivity_s": round(ts, 4)})


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", nargs="+", default=["grid", "dask", "kill", "sens"],
                    choices=["grid", "dask", "kill", "sens"])
    ap.add_argument("--modes", nargs="+", default=["predicted", "warm", "cold"],
                    choices=["predicted", "warm", "cold"])
    ap.add_argument("--n", type=int, default=1000, help="model size (size_for(n))")
    ap.add_argument("--tariffs", type=int, default=50)
    ap.add_argument("--elasticities", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None, help="directory for the Parquet results")
    args = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    out = args.out or tempfile.mkdtemp(prefix="bench_batch_")
    os.makedirs(out, exist_ok=True)
    for p in args.parts:
        globals()[f"part_{p}"](args, out)


if __name__ == "__main__":
    main()
