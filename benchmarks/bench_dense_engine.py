"""The small-problem engine's dense factors: speed of its pivotal paths, accuracy of its
column updates, and the dimension up to which it beats the sparse basis manager.

Modes
-----
* ``--paths ROOT_BEFORE ROOT_AFTER``: the thesis families (1 and 2, ``--sizes``, ``--seeds``)
  solved by ``solve_mcp`` in one worker process per tree and round, the two trees
  alternately (``--rounds``), each problem ``--repeats`` times per worker.  Per solve: total
  CPU, CPU inside the engine's paths (``DensePathEngine.run_path``, wrapped), pivots,
  factorizations.  Medians over all repeats of all rounds.  A tree is a checkout of the
  package (e.g. ``git archive main | tar -x -C /tmp/main``); only public entry points are
  used, so any revision with ``compass_sparse.dense_path`` works.
* ``--accuracy``: random sequences of column replacements on dense bases; the backward
  error of ``B x = b`` after k updates with this tree's Forrest-Tomlin kernels (with the
  growth limit, and without it) against the product-form eta file the engine used before
  (the same formulas applied to ``scipy.linalg.lu_factor`` factors).
* ``--crossover``: this tree's engine against the sparse basis manager on the problems the
  threshold ``DENSE_ENGINE_MAX_N`` was set on: a banded P-matrix LCP (crash off) and the
  Ramsey CGE model with a 25% capital tax (NMS), and on the thesis families (dense
  Jacobians), alternating engine/manager per repeat.

    python3 benchmarks/bench_dense_engine.py --paths /tmp/main . --rounds 2 --repeats 3
    python3 benchmarks/bench_dense_engine.py --accuracy
    python3 benchmarks/bench_dense_engine.py --crossover --repeats 5

CPU times (``time.process_time``) are reported: the machine is shared.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

HERE = Path(__file__).resolve().parent


# --------------------------------------------------------------------------- paths
def _worker_paths(a):
    from compass_sparse import Options, dense_path, solve_mcp
    from compass_sparse.generators import thesis_family

    acc = {"paths_cpu": 0.0, "pivots": 0, "nfac": 0, "declined": 0}
    orig = dense_path.DensePathEngine.run_path

    def run_path(self, path, *args, **kw):
        f0, s0 = self.stats.factorizations, self.stats.refactor_by_stability
        c0 = time.process_time()
        try:
            return orig(self, path, *args, **kw)
        finally:
            acc["paths_cpu"] += time.process_time() - c0
            acc["pivots"] += int(path.st.pivots)
            acc["nfac"] += self.stats.factorizations - f0
            # updates declined by the stability or growth test (Forrest-Tomlin only)
            acc["declined"] += self.stats.refactor_by_stability - s0

    dense_path.DensePathEngine.run_path = run_path
    solve_mcp(thesis_family(10, 1, 1).problem)  # compile or load the kernels
    for n in a.sizes:
        for fam in a.families:
            for seed in a.seeds:
                g = thesis_family(n, fam, seed)
                for _ in range(a.repeats):
                    for k in acc:
                        acc[k] = 0
                    c0 = time.process_time()
                    r = solve_mcp(g.problem, Options(time_limit=a.time_limit))
                    cpu = time.process_time() - c0
                    print(json.dumps({"problem": f"fam{fam}_n{n}_s{seed}", "n": n,
                                      "success": bool(r.success), "cpu": cpu, **acc}),
                          flush=True)


def _run_worker(root, mode, a):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", mode, "--root", root,
           "--sizes", *map(str, a.sizes), "--families", *map(str, a.families),
           "--seeds", *map(str, a.seeds), "--repeats", str(a.repeats),
           "--time-limit", str(a.time_limit)]
    env = dict(os.environ, PYTHONPATH=root)
    out = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, check=True)
    return [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]


def _git_rev(root):
    try:
        return subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
    except (subprocess.CalledProcessError, FileNotFoundError):
        return "(exported tree)"


def paths(a):
    roots = [str(Path(r).resolve()) for r in a.paths]
    rows = {r: [] for r in roots}
    for rnd in range(a.rounds):
        for r in roots:
            t0 = time.time()
            rows[r] += _run_worker(r, "paths", a)
            print(f"round {rnd + 1}: {r} done in {time.time() - t0:.0f} s", file=sys.stderr)
    before, after = roots
    print(f"before: {before} {_git_rev(before)}; after: {after} {_git_rev(after)}\n")
    hdr = ("| problem | n | ok before / after | pivots before / after | path CPU before | "
           "path CPU after | pivots/s before | pivots/s after | factorizations before / after "
           "| total CPU before | total CPU after |")
    print(hdr)
    print("|" + "---|" * 11)
    names = list(dict.fromkeys(x["problem"] for x in rows[before]))
    totals = {r: [0.0, 0.0, 0, 0] for r in roots}
    for name in names:
        cells = {}
        for r in roots:
            xs = [x for x in rows[r] if x["problem"] == name]
            med = {k: statistics.median(x[k] for x in xs)
                   for k in ("cpu", "paths_cpu", "pivots", "nfac", "declined")}
            med["ok"] = sum(x["success"] for x in xs) / len(xs)
            cells[r] = med
            totals[r][0] += med["cpu"]
            totals[r][1] += med["paths_cpu"]
            totals[r][2] += med["pivots"]
            totals[r][3] += med["declined"]
        b, f = cells[before], cells[after]

        def rate(c):
            return c["pivots"] / c["paths_cpu"] if c["paths_cpu"] > 0 else float("nan")

        print(f"| {name} | {xs[0]['n']} | {b['ok']:.0%} / {f['ok']:.0%} | "
              f"{b['pivots']:.0f} / {f['pivots']:.0f} | {b['paths_cpu'] * 1e3:.1f} ms | "
              f"{f['paths_cpu'] * 1e3:.1f} ms | {rate(b):.0f} | {rate(f):.0f} | "
              f"{b['nfac']:.0f} / {f['nfac']:.0f} | {b['cpu'] * 1e3:.0f} ms | "
              f"{f['cpu'] * 1e3:.0f} ms |")
    tb, tf = totals[before], totals[after]
    print(f"\nsums of medians: path CPU {tb[1]:.2f} s -> {tf[1]:.2f} s "
          f"(x{tb[1] / tf[1]:.2f}); pivots/s {tb[2] / tb[1]:.0f} -> {tf[2] / tf[1]:.0f}; "
          f"total CPU {tb[0]:.2f} s -> {tf[0]:.2f} s; updates declined by the stability "
          f"and growth tests (after): {tf[3]:.0f} of {tf[2]:.0f} pivots")
    if a.out:
        with open(a.out, "w") as fh:
            for r in roots:
                fh.writelines(json.dumps({"tree": "before" if r == before else "after", **x})
                             + "\n" for x in rows[r])


# --------------------------------------------------------------------------- accuracy
def accuracy(a):
    import scipy.linalg as sl

    sys.path.insert(0, str(HERE.parent / "tests"))
    import test_dense_lu_update as T

    K = T.K
    buckets = [(1, 10), (11, 25), (26, 50)]
    print("| n | leaving pivots | method | backward error, k = 1-10 (median / max) "
          "| k = 11-25 | k = 26-50 | refactorizations |")
    print("|---|---|---|---|---|---|---|")
    for n in a.acc_sizes:
        for thr in (0.5, 1e-3):
            res = {}
            for method, growth in (("Forrest-Tomlin, growth limit 100", 100.0),
                                   ("Forrest-Tomlin, no growth limit", 1e300),
                                   ("product form (before)", None)):
                rng = np.random.default_rng(n)
                M, r = rng.standard_normal((n, n)), rng.standard_normal(n)
                f = T.Factors(M, r, *T._random_table(n, rng), limit=50,
                              growth=growth if growth else 1e300)
                lu, etas = sl.lu_factor(f.basis()), []
                errs = {b: [] for b in buckets}
                nref = 0
                for _ in range(a.acc_steps):
                    kind, idx = T._entering(f, rng)
                    d = f.d_of(kind, idx)
                    ok = np.flatnonzero(np.abs(d) > thr * np.abs(d).max())
                    s = int(rng.choice(ok))
                    if growth is None:  # the eta file: B' = B E, E = I + (d - e_s) e_s^T
                        dp = _pf_solve(lu, etas, T._column(kind, idx, f.M, f.r))
                        f.sk[s], f.si[s] = kind, idx
                        if len(etas) >= 50 or abs(dp[s]) <= 1e-11 * max(1, abs(dp).max()):
                            lu, etas = sl.lu_factor(f.basis()), []
                            nref += 1
                        else:
                            etas.append((s, dp))
                        k = len(etas)
                        solve = lambda b, lu=lu, etas=etas: _pf_solve(lu, etas, b)
                    else:
                        upd = f.replace(s, kind, idx)
                        nref += upd != K.UPD_OK
                        k = f.k
                        solve = f.ftran
                    if k == 0:
                        continue
                    B = f.basis()
                    b = rng.standard_normal(n)
                    x = solve(b)
                    err = np.abs(B @ x - b).max() / (np.abs(B).sum(1).max() * np.abs(x).max()
                                                     + np.abs(b).max())
                    for lo, hi in buckets:
                        if lo <= k <= hi:
                            errs[(lo, hi)].append(err)
                res[method] = (errs, nref)
                cells = " | ".join(
                    f"{np.median(errs[b]):.1e} / {np.max(errs[b]):.1e}" if errs[b] else "-"
                    for b in buckets)
                print(f"| {n} | |d_s| > {thr:g} max|d| | {method} | {cells} | {nref} |")


def _pf_solve(lu, etas, b):
    import scipy.linalg as sl

    x = sl.lu_solve(lu, b)
    for s, d in etas:
        xs = x[s] / d[s]
        x -= d * xs
        x[s] = xs
    return x


# --------------------------------------------------------------------------- crossover
def crossover(a):
    from compass_sparse import Options, dense_path, solve, solve_lcp, solve_mcp
    from compass_sparse.generators import p_matrix_lcp, thesis_family
    from compass_sparse.generators.cge import ramsey_cge

    cases = []
    for n in a.lcp_sizes:
        g = p_matrix_lcp(n, "banded", 1, "ncp")
        M, q, lb, ub = g.lcp
        cases.append(("banded P-matrix LCP, crash off", n,
                      lambda M=M, q=q, lb=lb, ub=ub: solve_lcp(
                          M, q, lb, ub, options=Options(crash_method="none"))))
    for T in a.ramsey_T:
        prob = ramsey_cge(periods=T, sectors=1).with_shock(capital_tax=0.25).problem
        cases.append(("Ramsey CGE, 25% capital tax, NMS", prob.n,
                      lambda prob=prob: solve_mcp(prob)))
    for n in a.thesis_n:
        for fam in (1, 2):
            prob = thesis_family(n, fam, 1).problem
            cases.append((f"thesis family {fam}, seed 1", n,
                          lambda prob=prob: solve_mcp(prob)))
    saved = dense_path.DENSE_ENGINE_MAX_N, solve.DENSE_BASIS_MAX_N
    print(f"threshold in the code: DENSE_ENGINE_MAX_N = {saved[0]}\n")
    print("| problem | n | engine CPU (median) | sparse manager CPU (median) | engine / manager |")
    print("|---|---|---|---|---|")
    try:
        for name, n, run in cases:
            t = {"engine": [], "manager": []}
            for rep in range(a.repeats + 1):
                for side in ("engine", "manager"):
                    if side == "engine":
                        dense_path.DENSE_ENGINE_MAX_N, solve.DENSE_BASIS_MAX_N = 10**9, 0
                    else:
                        dense_path.DENSE_ENGINE_MAX_N, solve.DENSE_BASIS_MAX_N = 0, 0
                    c0 = time.process_time()
                    r = run()
                    cpu = time.process_time() - c0
                    assert r.success, (name, n, side, r.message)
                    if rep:  # the first round warms caches and compiles
                        t[side].append(cpu)
            e, m = statistics.median(t["engine"]), statistics.median(t["manager"])
            print(f"| {name} | {n} | {e * 1e3:.1f} ms | {m * 1e3:.1f} ms | {e / m:.2f} |",
                  flush=True)
    finally:
        dense_path.DENSE_ENGINE_MAX_N, solve.DENSE_BASIS_MAX_N = saved


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--paths", nargs=2, metavar=("ROOT_BEFORE", "ROOT_AFTER"))
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--crossover", action="store_true")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--root", help=argparse.SUPPRESS)
    ap.add_argument("--sizes", nargs="+", type=int, default=[50, 100, 200, 300, 500])
    ap.add_argument("--families", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--out", help="JSON lines of every solve (--paths)")
    ap.add_argument("--acc-sizes", nargs="+", type=int, default=[50, 200])
    ap.add_argument("--acc-steps", type=int, default=600)
    ap.add_argument("--lcp-sizes", nargs="+", type=int, default=[150, 300, 500, 800])
    ap.add_argument("--ramsey-T", nargs="+", type=int, default=[40, 56, 84, 110])
    ap.add_argument("--thesis-n", nargs="*", type=int, default=[300, 500],
                    help="thesis families 1 and 2 (dense Jacobians) in --crossover")
    a = ap.parse_args()
    if a.worker:
        sys.path.insert(0, a.root)
        return _worker_paths(a)
    sys.path.insert(0, str(HERE.parent))
    if a.paths:
        paths(a)
    if a.accuracy:
        accuracy(a)
    if a.crossover:
        crossover(a)


if __name__ == "__main__":
    main()
