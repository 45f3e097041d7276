"""CGE benchmark: calibrated static and dynamic (Ramsey) CGE models as sparse MCPs.

Models come from ``compass_sparse.generators.cge``:

* static: ``static_cge(**size_for(n))`` - multi-region, multi-household CGE in calibrated
  share form (Armington trade on a sparse trade graph, CES / Cobb-Douglas nests, output
  taxes), numeraire = income of the largest household (MPSGE convention);
* dynamic: ``ramsey_cge(**ramsey_size_for(n))`` - the multi-sector Lau-Pahlke-Rutherford
  Ramsey model with the terminal constraint on investment growth.

Parts (``--parts``):

1. ``main``: for each n, benchmark replication (``major_iteration_limit=0``, and a default
   solve from the benchmark, which must take 0 iterations) and counterfactuals (static:
   25% tariff on imports of region 1, abolition of output taxes; dynamic: the LPR 10%
   capital subsidy ``capital_tax=-0.1`` and a 25% capital tax).  Recorded: solve time (median
   over repeats when fast), our natural residual, major iterations, pivots, factorizations,
   F/J evaluations, passes that ran, the time of ONE scipy ``splu`` (COLAMD,
   diag_pivot_thresh 0.1) of the Jacobian at the solution restricted to the non-fixed
   variables, the ratio solve time / splu time ("factorization equivalents"), nnz(L+U), and
   the peak-RSS increase of the first solve (``resource.getrusage`` in a fresh process).
2. ``tol``: time against error for one static model (n ~ 1e4; 3e3 with --quick),
   convergence_tolerance 1e-4 ... 1e-10.
3. ``stress``: badly scaled units (z = D y, rows S F), zero-activity degeneracy (prohibitive
   output tax, productivity -> 0), missing numeraire (homogeneous, singular model).
4. ``path``: the one-sector LPR Ramsey model written in GAMSPy and solved by PATH, against
   ours on the same capital-tax counterfactual.  Where GAMS cannot run (or with ``--path
   recorded``) PATH's rows are the recorded ones of ``benchmarks/reference/cge.csv``: the
   run's first lines say which source is used, and recorded rows carry ``path_source =
   "recorded <date> <rev>"`` (their ``max_rel_diff`` is left empty: PATH's point was not
   kept; ``K5_change`` and ``K_last_change`` are the recorded ones of PATH's point).

Success everywhere = OUR recomputation of ||z - clip(z - F(z), lb, ub)||_inf <= 1e-6 on the
original problem.  Every case runs in a freshly forked process (numba compiled before the
fork) with the solver's ``time_limit`` plus a hard timeout; CSV rows are written as soon as
a case finishes, so partial results survive.

    python benchmarks/bench_cge.py --quick      # < 2 minutes
    python benchmarks/bench_cge.py              # full: n = 1e3 ... 1e5
"""
from __future__ import annotations

import argparse
import math
import os
import pickle
import resource
import select
import signal
import sys
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402
    RECORDED_NOTE,
    RESULTS,
    CsvLog,
    add_path_argument,
    choose_path_source,
    machine_info,
    print_machine,
    recorded_mark,
)

SUCCESS_TOL = 1e-6


# =========================================================================== utilities
def nat_res(z, f, lb, ub) -> float:
    z = np.asarray(z, float)
    f = np.asarray(f, float)
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(f))):
        return math.inf
    return float(np.max(np.abs(z - np.clip(z - f, lb, ub)))) if z.size else 0.0


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_forked(fn, timeout: float, **kwargs) -> dict:
    """Run fn(**kwargs) in a forked child; return its dict, or a failure dict."""
    r, w = os.pipe()
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # child
        os.close(r)
        try:
            out = ("ok", fn(**kwargs))
        except BaseException:
            out = ("error", traceback.format_exc())
        try:
            data = pickle.dumps(out)
        except Exception:
            data = pickle.dumps(("error", traceback.format_exc()))
        with os.fdopen(w, "wb") as fh:
            fh.write(data)
        os._exit(0)
    os.close(w)
    chunks = []
    deadline = t0 + timeout
    timed_out = False
    with os.fdopen(r, "rb") as fh:
        fd = fh.fileno()
        while True:
            left = deadline - time.perf_counter()
            if left <= 0:
                timed_out = True
                break
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            buf = os.read(fd, 1 << 20)
            if not buf:
                break
            chunks.append(buf)
    if timed_out:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        os.waitpid(pid, 0)
        return {"error": f"hard timeout after {timeout:.0f} s", "status": "hard-timeout"}
    _, st = os.waitpid(pid, 0)
    if not chunks:
        return {"error": f"child died (wait status {st}; out of memory?)", "status": "died"}
    tag, payload = pickle.loads(b"".join(chunks))
    if tag != "ok":
        last = payload.strip().splitlines()[-1] if payload.strip() else "error"
        return {"error": last[:300], "status": "exception", "traceback": payload}
    return payload


def warm_up():
    """Compile the numba kernels (sparse and dense bases) before anything is timed."""
    from compass_sparse import solve_mcp
    from compass_sparse.generators.cge import ramsey_cge, static_cge

    m = static_cge(regions=3, sectors=8, factors=2, households=1, seed=1)
    solve_mcp(m.with_shock(output_tax=0.0).problem, options={"time_limit": 60})
    m = static_cge(regions=4, sectors=30, factors=2, households=2, seed=1)  # n > 300: sparse
    solve_mcp(m.with_shock(tariff=(0, 0.25)).problem, options={"time_limit": 60})
    r = ramsey_cge(periods=12, sectors=4)
    solve_mcp(r.with_shock(capital_tax=-0.1).problem, options={"time_limit": 60})
    import scipy.sparse as sp

    from compass_sparse.basis.ordering import compute_ordering
    compute_ordering(sp.csc_matrix(sp.eye(50) + sp.eye(50, k=1)), "amd")  # ordering kernel


def make_model(family: str, n: int, seed: int = 0):
    from compass_sparse.generators.cge import ramsey_cge, ramsey_size_for, size_for, static_cge

    if family == "static":
        kw = size_for(n)
        return static_cge(**kw, seed=seed), kw
    kw = ramsey_size_for(n)
    return ramsey_cge(**kw, seed=seed), kw


SHOCKS = {
    "tariff25": dict(tariff=(0, 0.25)),
    "notax": dict(output_tax=0.0),
    "ksub10": dict(capital_tax=-0.1),
    "ktax25": dict(capital_tax=0.25),
}


def result_fields(res, f, lb, ub) -> dict:
    passes = res.passes or {}
    return dict(
        status=res.status.name, reported_success=bool(res.success),
        natural=nat_res(res.x, f, lb, ub), fb_norm=float(res.residual.fb_norm),
        major=int(res.nit), minor=int(res.minor_iterations),
        crash=int(res.crash_iterations), factorizations=int(res.factorizations),
        restarts=int(res.restarts), nfev=int(res.nfev), njev=int(res.njev),
        passes="+".join(k for k, v in passes.items() if v.ran),
        pass_times=";".join(f"{k}={v.time:.3g}" for k, v in passes.items() if v.ran),
    )


def splu_stats(J, lb, ub, reps: int) -> dict:
    """Time of ONE scipy splu of J restricted to the non-fixed variables (median over reps
    when fast) and nnz(L+U)."""
    from scipy.sparse.linalg import splu

    free = np.flatnonzero(lb < ub)
    Jr = J.tocsr()[free][:, free].tocsc()
    times, lu_nnz, err = [], -1, ""
    for k in range(max(1, reps)):
        t = time.perf_counter()
        try:
            lu = splu(Jr, permc_spec="COLAMD", diag_pivot_thresh=0.1)
        except Exception as e:  # singular: still a data point
            err = f"splu: {e}"
            times.append(time.perf_counter() - t)
            break
        times.append(time.perf_counter() - t)
        lu_nnz = int(lu.L.nnz + lu.U.nnz)
        del lu
        if times[-1] > 2.0:
            break
    return dict(splu_time=float(np.median(times)), lu_nnz=lu_nnz, jac_nnz=int(J.nnz),
                n_free=int(free.size), splu_error=err)


# =========================================================================== part 1
MAIN_FIELDS = ["family", "n_target", "n", "nnz", "dims", "case", "success", "status",
               "reported_success", "natural", "fb_norm", "time", "time_min", "repeats",
               "major", "minor", "crash", "factorizations", "restarts", "nfev", "njev",
               "passes", "pass_times", "splu_time", "fact_equiv", "lu_nnz", "jac_nnz",
               "n_free", "rss_delta_mb", "rss_peak_mb", "ray_norm", "walras", "max_change",
               "gen_time", "error"]


def task_main(family, n_target, case, time_limit, repeats, splu_max_n=10**9):
    from compass_sparse import solve_mcp
    from compass_sparse.generators.cge import homogeneity_check, walras_check

    t = time.perf_counter()
    m, kw = make_model(family, n_target)
    gen_time = time.perf_counter() - t
    row = dict(family=family, n_target=n_target, n=m.n, nnz=m.nnz,
               dims=" ".join(f"{k}={v}" for k, v in kw.items()), case=case, gen_time=gen_time)
    opts = {"time_limit": float(time_limit)}
    if case == "bench-mil0":
        ms = m
        opts["major_iteration_limit"] = 0
    elif case == "bench-solve":
        ms = m
    else:
        ms = m.with_shock(**SHOCKS[case])
    prob = ms.problem
    lb, ub = prob.lb, prob.ub
    times, first = [], None
    base = rss_mb()
    for k in range(max(1, repeats)):
        t = time.perf_counter()
        res = solve_mcp(prob, options=opts)
        times.append(time.perf_counter() - t)
        if first is None:
            first = res
            row["rss_peak_mb"] = rss_mb()
            row["rss_delta_mb"] = row["rss_peak_mb"] - base
        if times[-1] > 3.0 or k == repeats - 1:
            break
    res = first
    f = ms.F(res.x)
    row.update(result_fields(res, f, lb, ub))
    row["success"] = bool(row["natural"] <= SUCCESS_TOL)
    row["time"] = float(np.median(times))
    row["time_min"] = float(np.min(times))
    row["repeats"] = len(times)
    row["max_change"] = float(np.max(np.abs(res.x - m.benchmark) / np.maximum(1.0, np.abs(m.benchmark))))
    row["ray_norm"] = homogeneity_check(ms, res.x)["ray_norm"]
    wv = walras_check(ms, res.x)["value"]
    row["walras"] = float("nan") if wv is None else float(wv)
    if case != "bench-mil0" and np.all(np.isfinite(res.x)) and m.n > splu_max_n:
        row["error"] = f"splu skipped (n > {splu_max_n})"
    elif case != "bench-mil0" and np.all(np.isfinite(res.x)):
        st = splu_stats(ms.J(res.x), lb, ub, reps=3)
        row.update(st)
        if st["splu_error"]:
            row["error"] = st["splu_error"]
        row["fact_equiv"] = row["time"] / st["splu_time"] if st["splu_time"] > 0 else float("nan")
    return row


def part_main(args, info):
    log = CsvLog(RESULTS / f"cge_main{args.suffix}.csv", MAIN_FIELDS, append=args.append)
    rows = []
    for n in args.sizes:
        for family, cases in (("static", ("bench-mil0", "bench-solve", "tariff25", "notax")),
                              ("dynamic", ("bench-mil0", "bench-solve", "ksub10", "ktax25"))):
            if family not in args.families:
                continue
            for case in cases:
                if args.cases and case not in args.cases:
                    continue
                reps = 1 if case == "bench-mil0" else args.repeats
                hard = args.time_limit * (reps + 1) + 120 + n / 500
                row = run_forked(task_main, hard, family=family, n_target=int(n), case=case,
                                 time_limit=args.time_limit, repeats=reps,
                                 splu_max_n=args.splu_max_n)
                row.setdefault("family", family)
                row.setdefault("n_target", int(n))
                row.setdefault("case", case)
                row.setdefault("success", False)
                log.write(row)
                rows.append(row)
                print(f"  {family:7s} n={row.get('n', n):>7} {case:11s} "
                      f"ok={row['success']!s:5s} {row.get('status', '')} "
                      f"res={row.get('natural', float('nan')):.1e} t={row.get('time', float('nan')):.3g}s "
                      f"maj={row.get('major', '')} fact={row.get('factorizations', '')} "
                      f"FE={row.get('fact_equiv', float('nan')):.3g} "
                      f"LU={row.get('lu_nnz', '')} rss+={row.get('rss_delta_mb', float('nan')):.0f}MB "
                      f"{row.get('error', '')}", flush=True)
    log.close()
    return rows


# =========================================================================== part lu
LU_FIELDS = ["family", "n_target", "n", "case", "lu", "rep", "success", "status", "natural", "time",
             "major", "crash", "factorizations", "splu_start", "fact_equiv", "ordering",
             "orderings_computed", "time_ordering", "time_factor", "est_nnz_lu", "est_gb",
             "max_nnz_lu", "jac_nnz", "rss_delta_mb", "load", "reuses", "reuse_steps",
             "reuse_fallbacks", "error"]

LU_CONFIGS = {"old": "superlu:colamd", "new": "", "noreuse": ""}
"""Linear algebra compared by part ``lu``: ``old`` = SuperLU with COLAMD and partial
pivoting everywhere (what the solver did before the fill-reducing orderings), ``new`` = the
automatic choice (``COMPASS_SPARSE_LU`` unset), ``noreuse`` = the automatic choice with
``factor_reuse=False`` (every basis factored afresh)."""


def task_splu_start(family, n_target, case):
    """One SuperLU (COLAMD, diag_pivot_thresh 0.1) of the free Jacobian block at the
    shocked start: the unit of 'factorization equivalents' (median of up to 3)."""
    m, _ = make_model(family, n_target)
    ms = m.with_shock(**SHOCKS[case])
    st = splu_stats(ms.J(m.benchmark), ms.lb, ms.ub, reps=3)
    return dict(splu_start=st["splu_time"], jac_nnz=st["jac_nnz"], error=st["splu_error"])


def task_lu(family, n_target, case, lu, time_limit):
    if LU_CONFIGS[lu]:
        os.environ["COMPASS_SPARSE_LU"] = LU_CONFIGS[lu]
    else:
        os.environ.pop("COMPASS_SPARSE_LU", None)
    from compass_sparse import solve_mcp

    m, _ = make_model(family, n_target)
    ms = m.with_shock(**SHOCKS[case])
    prob = ms.problem
    base = rss_mb()
    load = os.getloadavg()[0]
    t = time.perf_counter()
    res = solve_mcp(prob, options={"time_limit": float(time_limit),
                                   "factor_reuse": lu != "noreuse"})
    wall = time.perf_counter() - t
    row = dict(n=m.n, time=wall, rss_delta_mb=rss_mb() - base, load=load)
    row.update(result_fields(res, ms.F(res.x), prob.lb, prob.ub))
    row["success"] = bool(row["natural"] <= SUCCESS_TOL)
    lu_rep = getattr(res, "lu", {}) or {}
    for k in ("ordering", "orderings_computed", "time_ordering", "time_factor", "est_nnz_lu",
              "max_nnz_lu", "reuses", "reuse_steps", "reuse_fallbacks"):
        row[k] = lu_rep.get(k, "")
    eb = lu_rep.get("est_bytes", -1)
    row["est_gb"] = eb / 2**30 if eb and eb > 0 else ""
    return row


def part_lu(args, info):
    """Old and new linear algebra side by side, in one run, on the CGE counterfactuals."""
    log = CsvLog(RESULTS / f"cge_lu{args.suffix}.csv", LU_FIELDS, append=args.append)
    rows = []
    for n in args.sizes:
        for family, cases in (("static", ("tariff25", "notax")),
                              ("dynamic", ("ksub10", "ktax25"))):
            if family not in args.families:
                continue
            for case, rep in ((c, k) for c in cases for k in range(args.lu_repeats)):
                if args.cases and case not in args.cases:
                    continue
                # (with --lu-repeats the reference and the configurations alternate, so
                # that a change of the machine's load hits all of them alike)
                ref = {}
                if n <= args.splu_max_n:
                    ref = run_forked(task_splu_start, 700, family=family, n_target=int(n),
                                     case=case)
                for lu in args.lu:
                    row = run_forked(task_lu, args.time_limit + 60 + n / 500, family=family,
                                     n_target=int(n), case=case, lu=lu,
                                     time_limit=args.time_limit)
                    row.update(family=family, n_target=int(n), case=case, lu=lu, rep=rep)
                    row.setdefault("success", False)
                    if ref.get("splu_start"):
                        row["splu_start"] = ref["splu_start"]
                        row["jac_nnz"] = ref.get("jac_nnz", "")
                        if "time" in row:
                            row["fact_equiv"] = row["time"] / ref["splu_start"]
                    log.write(row)
                    rows.append(row)
                    print(f"  {family:7s} n={row.get('n', n):>7} {case:8s} {lu:4s} "
                          f"ok={row['success']!s:5s} {row.get('status', '')} "
                          f"t={row.get('time', float('nan')):.3g}s maj={row.get('major', '')} "
                          f"fact={row.get('factorizations', '')} "
                          f"FE={row.get('fact_equiv', float('nan')):.3g} "
                          f"ord={row.get('ordering', '')} LU={row.get('max_nnz_lu', '')} "
                          f"rss+={row.get('rss_delta_mb', float('nan')):.0f}MB "
                          f"load={row.get('load', float('nan')):.1f} {row.get('error', '')}",
                          flush=True)
    log.close()
    return rows


# =========================================================================== part 2
TOL_FIELDS = ["n", "tolerance", "success", "status", "natural", "fb_norm", "time", "major",
              "minor", "factorizations", "nfev", "njev", "passes", "error"]


def task_tol(n_target, tol, time_limit):
    from compass_sparse import solve_mcp

    m, _ = make_model("static", n_target)
    ms = m.with_shock(**SHOCKS["tariff25"])
    prob = ms.problem
    t = time.perf_counter()
    res = solve_mcp(prob, options={"time_limit": float(time_limit),
                                   "convergence_tolerance": float(tol)})
    wall = time.perf_counter() - t
    row = dict(n=m.n, tolerance=tol, time=wall)
    row.update(result_fields(res, ms.F(res.x), prob.lb, prob.ub))
    row["success"] = bool(row["natural"] <= SUCCESS_TOL)
    return row


def part_tol(args, info):
    log = CsvLog(RESULTS / f"cge_tolerance{args.suffix}.csv", TOL_FIELDS)
    rows = []
    for tol in (1e-4, 1e-6, 1e-8, 1e-10):
        row = run_forked(task_tol, args.time_limit + 120, n_target=args.tol_n, tol=tol,
                         time_limit=args.time_limit)
        row.setdefault("tolerance", tol)
        row.setdefault("success", False)
        log.write(row)
        rows.append(row)
        print(f"  tol={tol:.0e} ok={row['success']} {row.get('status', '')} "
              f"res={row.get('natural', float('nan')):.1e} fb={row.get('fb_norm', float('nan')):.1e} "
              f"t={row.get('time', float('nan')):.3g}s maj={row.get('major', '')} "
              f"{row.get('error', '')}", flush=True)
    log.close()
    return rows


# =========================================================================== part 3
STRESS_FIELDS = ["test", "variant", "n", "success", "status", "reported_success", "natural",
                 "natural_scaled", "err_vs_ref", "time", "major", "minor", "factorizations",
                 "restarts", "passes", "detail", "error"]


def _scaled_problem(prob, d, s):
    """The same MCP in new units: z = d * y, rows s * F(y).  G(z) = s F(z / d),
    J_G = diag(s) J diag(1/d) (scaled entry by entry, so explicit zeros of the fixed
    pattern are kept); bounds d*lb, d*ub; start d*x0."""
    import scipy.sparse as sp

    from compass_sparse import MCP

    dinv = 1.0 / d

    def scale(A):
        A = sp.csc_matrix(A, copy=True)
        cols = np.repeat(np.arange(A.shape[1]), np.diff(A.indptr))
        A.data = A.data * s[A.indices] * dinv[cols]
        return A

    def G(z):
        return s * prob.F_uncounted(z * dinv)

    def JG(z):
        return scale(prob.J(z * dinv))

    C = getattr(prob, "_constant_spec", None)
    return MCP(G, JG, prob.lb * d, prob.ub * d, prob.x0 * d,
               constant_jac=None if C is None else scale(C))


def task_scaling(n_target, kind, k, time_limit, seed=7):
    from compass_sparse import solve_mcp

    m, _ = make_model("static", n_target)
    ms = m.with_shock(**SHOCKS["tariff25"])
    prob = ms.problem
    ref = solve_mcp(prob, options={"time_limit": float(time_limit),
                                   "convergence_tolerance": 1e-10})
    rng = np.random.default_rng(seed + k)
    n = prob.n
    d = 10.0 ** rng.uniform(-k, k, n) if kind in ("D", "DS") else np.ones(n)
    s = 10.0 ** rng.uniform(-k, k, n) if kind in ("S", "DS") else np.ones(n)
    sp_ = _scaled_problem(prob, d, s)
    t = time.perf_counter()
    res = solve_mcp(sp_, options={"time_limit": float(time_limit)})
    wall = time.perf_counter() - t
    y = res.x / d
    f = ms.F(y)
    nat = nat_res(y, f, prob.lb, prob.ub)
    rel = np.abs(y - ref.x) / np.maximum(1.0, np.abs(ref.x))
    row = dict(test="scaling", variant=f"{kind} 1e-{k}..1e{k}", n=n, time=wall,
               status=res.status.name, reported_success=bool(res.success), natural=nat,
               natural_scaled=nat_res(res.x, sp_.F_uncounted(res.x), sp_.lb, sp_.ub),
               err_vs_ref=float(np.max(rel)), major=res.nit, minor=res.minor_iterations,
               factorizations=res.factorizations, restarts=res.restarts,
               passes="+".join(kk for kk, v in (res.passes or {}).items() if v.ran),
               detail=f"reference natural {nat_res(ref.x, ms.F(ref.x), prob.lb, prob.ub):.1e}")
    row["success"] = bool(nat <= SUCCESS_TOL)
    return row


def task_degenerate(n_target, variant, time_limit, homotopy=False):
    from compass_sparse import solve_mcp

    m, _ = make_model("static", n_target)
    R, N = m.block_shapes["Y"]
    j = 0  # sector s1 of region r1
    if variant.startswith("outtax"):
        rate = float(variant.split("=")[1])
        t = np.zeros((R, N))
        t[0, j] = rate
        shock = dict(output_tax=t)
    else:
        phi = float(variant.split("=")[1])
        p = np.ones((R, N))
        p[0, j] = phi
        shock = dict(productivity=p)
    t0 = time.perf_counter()
    steps = ""
    if homotopy and variant.startswith("outtax"):  # warm-started continuation in the rate
        z = m.benchmark
        for r_ in (0.5, 0.9, 0.97, 0.99, 0.999, 0.9999, 0.999999):
            if r_ >= rate:
                break
            tt = np.zeros((R, N))
            tt[0, j] = r_
            mi = m.with_shock(start=z, output_tax=tt)
            ri = solve_mcp(mi.problem, options={"time_limit": float(time_limit)})
            steps += f"{r_:g}:{ri.status.name}/{ri.nit} "
            z = ri.x
        ms = m.with_shock(start=z, **shock)
    else:
        ms = m.with_shock(**shock)
    prob = ms.problem
    res = solve_mcp(prob, options={"time_limit": float(time_limit)})
    wall = time.perf_counter() - t0
    if steps:
        variant = f"{variant} homotopy"
    f = ms.F(res.x)
    nat = nat_res(res.x, f, prob.lb, prob.ub)
    Y = ms.block(res.x, "Y")[0, j]
    P = ms.block(res.x, "P")[0, j]
    yl = ms.block(res.x, "Y")
    row = dict(test="degenerate", variant=variant, n=prob.n, time=wall, status=res.status.name,
               reported_success=bool(res.success), natural=nat, major=res.nit,
               minor=res.minor_iterations, factorizations=res.factorizations,
               restarts=res.restarts,
               passes="+".join(kk for kk, v in (res.passes or {}).items() if v.ran),
               detail=(f"Y[r1,s1]={Y:.3g} P[r1,s1]={P:.3g} F_Y[r1,s1]="
                       f"{f[ms.blocks['Y']][j]:.2e}; sectors with Y<1e-8: "
                       f"{int(np.sum(yl < 1e-8))}; domain_errors={res.domain_errors}"
                       + (f"; steps {steps}" if steps else "")))
    row["success"] = bool(nat <= SUCCESS_TOL)
    return row


def task_numeraire(family, n_target, variant, time_limit):
    from compass_sparse import solve_mcp
    from compass_sparse.generators.cge import homogeneity_check

    m, _ = make_model(family, n_target)
    shock = SHOCKS["tariff25" if family == "static" else "ksub10"]
    ref_m = m.with_shock(**shock)
    ref = solve_mcp(ref_m.problem, options={"time_limit": float(time_limit),
                                            "convergence_tolerance": 1e-10})
    if variant == "none-benchmark":
        ms = m.with_numeraire(None)
    elif variant == "none-shock":
        ms = m.with_numeraire(None).with_shock(**shock)
    elif variant == "scale1.1-shock":  # oracle: numeraire value x 1.1 -> prices x 1.1
        ms = m.with_numeraire(scale=1.1).with_shock(**shock)
    else:
        raise ValueError(variant)
    prob = ms.problem
    t0 = time.perf_counter()
    res = solve_mcp(prob, options={"time_limit": float(time_limit)})
    wall = time.perf_counter() - t0
    f = ms.F(res.x)
    nat = nat_res(res.x, f, prob.lb, prob.ub)
    hc = homogeneity_check(ms, res.x)
    # is res.x on the equilibrium ray through the reference solution?
    ray = ms.ray
    x, xr = res.x, (ref.x if variant != "none-benchmark" else m.benchmark)
    lam = float(np.dot(x[ray], xr[ray]) / np.dot(xr[ray], xr[ray]))
    err_q = float(np.max(np.abs(x[~ray] - xr[~ray]) / np.maximum(1.0, np.abs(xr[~ray]))))
    err_p = float(np.max(np.abs(x[ray] - lam * xr[ray]) / np.maximum(1.0, np.abs(lam * xr[ray]))))
    row = dict(test="numeraire", variant=f"{family} {variant}", n=prob.n, time=wall,
               status=res.status.name, reported_success=bool(res.success), natural=nat,
               err_vs_ref=max(err_q, err_p), major=res.nit, minor=res.minor_iterations,
               factorizations=res.factorizations, restarts=res.restarts,
               passes="+".join(kk for kk, v in (res.passes or {}).items() if v.ran),
               detail=(f"fixed on ray: {hc['fixed_on_ray'] or 'none'}; ||J v||={hc['ray_norm']:.1e}; "
                       f"lambda={lam:.6g}; quantity err={err_q:.1e}; price err on ray={err_p:.1e}"))
    row["success"] = bool(nat <= SUCCESS_TOL)
    return row


def part_stress(args, info):
    log = CsvLog(RESULTS / f"cge_stress{args.suffix}.csv", STRESS_FIELDS)
    rows = []
    tl = args.stress_time_limit
    tasks = []
    for kind in ("D", "S", "DS"):
        for k in (2, 4, 6):
            tasks.append((task_scaling, dict(n_target=args.stress_n, kind=kind, k=k,
                                              time_limit=tl)))
    tasks.append((task_scaling, dict(n_target=args.stress_n, kind="DS", k=0, time_limit=tl)))
    degen = (("outtax=0.9", "outtax=0.99", "productivity=1e-3") if args.quick else
             ("outtax=0.5", "outtax=0.9", "outtax=0.99", "outtax=0.999999",
              "productivity=1e-3", "productivity=1e-6", "productivity=0"))
    for v in degen:
        tasks.append((task_degenerate, dict(n_target=args.stress_n, variant=v, time_limit=tl)))
    for v in ("outtax=0.99",) if args.quick else ("outtax=0.99", "outtax=0.999999"):
        tasks.append((task_degenerate, dict(n_target=args.stress_n, variant=v, time_limit=tl,
                                            homotopy=True)))
    for fam in ("static", "dynamic"):
        for v in ("none-benchmark", "none-shock", "scale1.1-shock"):
            tasks.append((task_numeraire, dict(family=fam, n_target=args.stress_n, variant=v,
                                               time_limit=tl)))
    if args.stress_tests:
        tasks = [(fn, kw) for fn, kw in tasks if fn.__name__.replace("task_", "") in
                 args.stress_tests]
    for fn, kw in tasks:
        row = run_forked(fn, 8 * tl + 120, **kw)
        row.setdefault("test", fn.__name__.replace("task_", ""))
        row.setdefault("variant", str(kw))
        row.setdefault("success", False)
        log.write(row)
        rows.append(row)
        print(f"  {row['test']:10s} {row['variant']:24s} ok={row['success']!s:5s} "
              f"{row.get('status', '')} res={row.get('natural', float('nan')):.1e} "
              f"err={row.get('err_vs_ref', float('nan')):.1e} t={row.get('time', float('nan')):.3g}s "
              f"maj={row.get('major', '')} {row.get('detail', '')} {row.get('error', '')}",
              flush=True)
    log.close()
    return rows


# =========================================================================== part 4
PATH_FIELDS = ["T", "n", "tax", "solver", "success", "status", "natural", "time", "wall",
               "major", "minor", "crash", "nfev", "njev", "max_rel_diff", "K5_change",
               "K_last_change", "error", "path_source"]


def ramsey_gamspy(T, tax, x0_model, tol=1e-6):
    """The one-sector LPR Ramsey model (problem-families sec. 2.6, as in the generator with
    sectors=1) in GAMSPy, solved by PATH from the given start point."""
    import io
    import logging
    import re

    import gamspy as gp
    import pandas as pd

    gamma, rbar, delta, Y0, C0, I0 = 0.02, 0.04, 0.08, 10.0, 7.5, 2.5
    K0 = I0 / (gamma + delta)
    RK0 = K0 * (rbar + delta)
    L0 = Y0 - RK0
    thK = RK0 / Y0
    rd = rbar + delta
    tt = np.arange(T)
    qref = (1 + gamma) ** tt
    pref = (1 + rbar) ** (-tt.astype(float))
    theta = pref * qref / np.sum(pref * qref)
    HA0 = float(np.sum(pref * C0 * qref))

    m = gp.Container()
    labels = [f"t{k}" for k in tt]
    t = gp.Set(m, "t", records=labels)
    first = gp.Set(m, "first", domain=t, records=[labels[0]])
    last = gp.Set(m, "last", domain=t, records=[labels[-1]])
    prev = gp.Set(m, "prev", domain=t, records=[labels[-2]])
    qr = gp.Parameter(m, "qref", domain=t, records=np.c_[labels, qref].tolist())
    th = gp.Parameter(m, "theta", domain=t, records=np.c_[labels, theta].tolist())
    tauK = gp.Parameter(m, "tauK", records=float(tax))
    isfirst = gp.Parameter(m, "isfirst", domain=t, records=[[labels[0], 1.0]])
    islast = gp.Parameter(m, "islast", domain=t, records=[[labels[-1], 1.0]])

    pos = {}
    for name in ("Y", "I", "K", "C", "P", "RK", "PL", "PK", "PU"):
        pos[name] = gp.Variable(m, name, domain=t, type="positive")
    Y, I, K, C, P, RK, PL, PK, PU = (pos[k] for k in ("Y", "I", "K", "C", "P", "RK", "PL",
                                                       "PK", "PU"))
    PKT = gp.Variable(m, "PKT", type="positive")
    TK = gp.Variable(m, "TK", type="free")
    HA = gp.Variable(m, "HA", type="free")

    def cost(tt_):
        return PL[tt_] ** (1 - thK) * (RK[tt_] * (1 + tauK) / rd) ** thK

    prf_Y = gp.Equation(m, "prf_Y", domain=t)
    prf_Y[t] = Y0 * cost(t) - Y0 * P[t] >= gp.Number(0)
    prf_I = gp.Equation(m, "prf_I", domain=t)
    prf_I[t] = P[t] - PK[t.lead(1)] - islast[t] * PKT >= gp.Number(0)
    prf_K = gp.Equation(m, "prf_K", domain=t)
    prf_K[t] = PK[t] - RK[t] - (1 - delta) * (PK[t.lead(1)] + islast[t] * PKT) >= gp.Number(0)
    prf_C = gp.Equation(m, "prf_C", domain=t)
    prf_C[t] = P[t] - PU[t] >= gp.Number(0)
    mkt_P = gp.Equation(m, "mkt_P", domain=t)
    mkt_P[t] = Y0 * Y[t] - I[t] - C[t] >= gp.Number(0)
    mkt_RK = gp.Equation(m, "mkt_RK", domain=t)
    mkt_RK[t] = K[t] - Y[t] * K0 * cost(t) / (RK[t] * (1 + tauK) / rd) >= gp.Number(0)
    mkt_PL = gp.Equation(m, "mkt_PL", domain=t)
    mkt_PL[t] = L0 * qr[t] - Y[t] * L0 * cost(t) / PL[t] >= gp.Number(0)
    mkt_PK = gp.Equation(m, "mkt_PK", domain=t)
    mkt_PK[t] = K0 * isfirst[t] + (1 - delta) * K[t.lag(1)] + I[t.lag(1)] - K[t] >= gp.Number(0)
    mkt_PKT = gp.Equation(m, "mkt_PKT")
    mkt_PKT[...] = gp.Sum(last, (1 - delta) * K[last] + I[last]) - TK >= gp.Number(0)
    mkt_PU = gp.Equation(m, "mkt_PU", domain=t)
    mkt_PU[t] = C[t] - th[t] * HA / PU[t] >= gp.Number(0)
    inc_HA = gp.Equation(m, "inc_HA")
    inc_HA[...] = HA - (L0 * gp.Sum(t, PL[t] * qr[t]) + gp.Sum(first, PK[first]) * K0
                        - PKT * TK
                        + tauK * gp.Sum(t, RK[t] * Y[t] * K0 * cost(t)
                                        / (RK[t] * (1 + tauK) / rd))) == gp.Number(0)
    term = gp.Equation(m, "term")
    term[...] = (gp.Sum(last, I[last]) / gp.Sum(prev, I[prev])
                 - gp.Sum(last, Y[last]) / gp.Sum(prev, Y[prev])) == gp.Number(0)
    HA.fx[...] = HA0

    # start point: the generator's benchmark (same variable layout: blocks of length T)
    names = ("Y", "I", "K", "C", "TK", "P", "RK", "PL", "PK", "PU", "PKT", "HA")
    sizes = {k: (1 if k in ("TK", "PKT", "HA") else T) for k in names}
    off, vals = 0, {}
    for k in names:
        vals[k] = x0_model[off:off + sizes[k]]
        off += sizes[k]
    for k in ("Y", "I", "K", "C", "P", "RK", "PL", "PK", "PU"):
        start = gp.Parameter(m, f"start_{k}", domain=t,
                             records=pd.DataFrame({"t": labels, "value": vals[k]}))
        pos[k].l[t] = start[t]
    PKT.l[...] = float(vals["PKT"][0])
    TK.l[...] = float(vals["TK"][0])
    HA.fx[...] = HA0

    model = gp.Model(m, "ramsey", problem="MCP", matches={
        prf_Y: Y, prf_I: I, prf_K: K, prf_C: C, mkt_P: P, mkt_RK: RK, mkt_PL: PL, mkt_PK: PK,
        mkt_PKT: PKT, mkt_PU: PU, inc_HA: HA, term: TK})
    buf = io.StringIO()
    lg = logging.getLogger("MODEL")
    old = lg.level
    lg.setLevel(logging.ERROR)
    t0 = time.perf_counter()
    try:
        model.solve(solver="PATH", solver_options={"convergence_tolerance": tol}, output=buf)
    finally:
        lg.setLevel(old)
    wall = time.perf_counter() - t0
    log = buf.getvalue()

    def grab(label, typ=float):
        mt = re.findall(rf"^\s*{re.escape(label)}[ .]*?\.\s+([-+0-9.eE]+)\s*$", log, flags=re.M)
        return typ(float(mt[-1])) if mt else None

    x = []
    for k in names:
        sym = {"TK": TK, "PKT": PKT, "HA": HA}.get(k, pos.get(k))
        rec = sym.records
        if k in ("TK", "PKT", "HA"):
            x.append(np.array([float(rec["level"].iloc[0])]))
        else:
            v = np.zeros(T)
            idx = rec["t"].astype(str).str[1:].astype(int).to_numpy()
            v[idx] = rec["level"].to_numpy(float)
            x.append(v)
    ex = re.findall(r"\*\* EXIT - (.*?)\.?\s*$", log, flags=re.M)
    return dict(x=np.concatenate(x), wall=wall, time=grab("Total Time"),
                major=grab("Major Iterations", int), minor=grab("Minor Iterations", int),
                crash=grab("Crash Iterations", int), nfev=grab("Function Evaluations", int),
                njev=grab("Gradient Evaluations", int),
                status=ex[-1].strip() if ex else str(model.solve_status), log=log)


def _live_path_row(T, tax, m, ms, prob, res, repeats):
    """PATH's row from ``repeats`` live runs of the GAMSPy model (median time)."""
    try:
        pr = None
        pt = []
        for _ in range(max(1, repeats)):
            pr = ramsey_gamspy(T, tax, m.benchmark)
            pt.append(pr["time"] if pr["time"] is not None else pr["wall"])
        xp = pr["x"]
        nat_p = nat_res(xp, ms.F(xp), prob.lb, prob.ub)
        diff = float(np.max(np.abs(xp - res.x) / np.maximum(1.0, np.abs(res.x))))
        return dict(T=T, n=prob.n, tax=tax, solver="PATH", time=float(np.median(pt)),
                    wall=pr["wall"], status=pr["status"], natural=nat_p, major=pr["major"],
                    minor=pr["minor"], crash=pr["crash"], nfev=pr["nfev"], njev=pr["njev"],
                    max_rel_diff=diff, _x=xp, path_source="live")
    except Exception:
        return dict(T=T, n=prob.n, tax=tax, solver="PATH", status="exception",
                    natural=math.inf, error=traceback.format_exc().strip().splitlines()[-1],
                    path_source="live")


def _recorded_path_row(T, tax, prob, recorded):
    """PATH's recorded row of the case in this part's fields; a row with an error when the
    reference's model has another size (it would be another problem)."""
    if int(recorded["n"]) != prob.n:
        return dict(T=T, n=prob.n, tax=tax, solver="PATH", status="not recorded",
                    natural=math.inf, path_source=recorded["path_source"],
                    error=f"the reference's model has n = {recorded['n']}, this one {prob.n}")
    rec = dict(T=T, n=prob.n, tax=tax, solver="PATH", max_rel_diff="",
               path_source=recorded["path_source"])
    rec.update({k: recorded[k] for k in ("time", "wall", "status", "natural", "major", "minor",
                                          "crash", "nfev", "njev", "K5_change",
                                          "K_last_change")})
    return rec


def task_path(T, tax, time_limit, repeats, recorded=None):
    """Ours and PATH's rows of one case.  ``recorded``: PATH's recorded row
    (benchmarks/reference/cge.csv) instead of a live PATH run; False: the reference does
    not have the case (PATH's row is left out)."""
    from compass_sparse import solve_mcp
    from compass_sparse.generators.cge import ramsey_cge

    m = ramsey_cge(periods=T, sectors=1)
    ms = m.with_shock(capital_tax=tax)
    prob = ms.problem
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        res = solve_mcp(prob, options={"time_limit": float(time_limit)})
        times.append(time.perf_counter() - t0)
    ours = dict(T=T, n=prob.n, tax=tax, solver="compass_sparse", _x=res.x,
                time=float(np.median(times)),
                wall=float(np.median(times)), status=res.status.name,
                natural=nat_res(res.x, ms.F(res.x), prob.lb, prob.ub), major=res.nit,
                minor=res.minor_iterations, crash=res.crash_iterations, nfev=res.nfev,
                njev=res.njev)
    rows = [ours]
    if recorded is None:
        rows.append(_live_path_row(T, tax, m, ms, prob, res, repeats))
    elif recorded is not False:
        rows.append(_recorded_path_row(T, tax, prob, recorded))
    K0 = m.block(m.benchmark, "K").ravel()
    for r in rows:
        r["success"] = bool(r.get("natural", math.inf) <= SUCCESS_TOL)
        if r.get("path_source", "").startswith("recorded"):
            continue  # the capital changes of PATH's point as recorded (no point kept)
        K = ms.block(r.pop("_x", np.full(prob.n, np.nan)), "K").ravel()
        r["K5_change"] = float(K[5] / K0[5] - 1) if T > 5 else float("nan")
        r["K_last_change"] = float(K[-1] / K0[-1] - 1)
    return {"rows": rows}


def part_path(args, info):
    source = args.path_source
    log = CsvLog(RESULTS / f"cge_path{args.suffix}.csv", PATH_FIELDS)
    rows = []
    for T in args.path_T:
        for tax in (-0.1, 0.25):
            recorded = None
            if source.recorded:
                recorded = source.lookup(T=T, tax=tax) or False
                if recorded is False:
                    print(f"  T={T} tax={tax:+.2f} PATH – (not in the reference)", flush=True)
            out = run_forked(task_path, 600, T=int(T), tax=tax, time_limit=args.time_limit,
                             repeats=3, recorded=recorded)
            rs = out.get("rows") or [dict(T=T, tax=tax, solver="both", success=False,
                                          error=out.get("error", ""))]
            for r in rs:
                log.write(r)
                rows.append(r)
                print(f"  T={T} n={r.get('n', '')} tax={tax:+.2f} {r['solver']:14s} "
                      f"ok={r['success']!s:5s} {r.get('status', '')} "
                      f"res={r.get('natural', float('nan')):.1e} t={r.get('time', float('nan'))}s "
                      f"maj={r.get('major', '')} minor={r.get('minor', '')} "
                      f"diff={r.get('max_rel_diff', '')} dK5={r.get('K5_change', '')} "
                      f"{r.get('error', '')}{recorded_mark(r)}", flush=True)
    log.close()
    return rows


# =========================================================================== report
def report(suffix: str):
    """Markdown tables from the CSV files of a run (printed)."""
    from _common import fmt_e, fmt_time, md_table, read_csv

    def g(r, k, f=str):
        v = r.get(k, "")
        if v == "" or v is None:
            return "–"
        try:
            return f(v)
        except Exception:
            return str(v)

    p = RESULTS / f"cge_main{suffix}.csv"
    if p.exists():
        rows = read_csv(p)
        print("\n### Benchmark replication\n")
        print(md_table(["model", "n", "nnz(J)", "case", "status", "natural res.", "major",
                        "time"],
                       [[r["family"], g(r, "n"), g(r, "nnz"), r["case"], g(r, "status"),
                         g(r, "natural", fmt_e), g(r, "major"), g(r, "time", fmt_time)]
                        for r in rows if str(r["case"]).startswith("bench")]))
        print("\n### Counterfactuals\n")
        print(md_table(["model", "n", "nnz(J)", "shock", "ok", "status", "natural res.",
                        "time (median)", "reps", "major", "crash", "pivots", "fact.", "F/J evals",
                        "passes", "splu", "fact. equiv.", "nnz(L+U)", "peak RSS +MB",
                        "max change"],
                       [[r["family"], g(r, "n"), g(r, "nnz"), r["case"], g(r, "success"),
                         g(r, "status"), g(r, "natural", fmt_e), g(r, "time", fmt_time),
                         g(r, "repeats"), g(r, "major"), g(r, "crash"), g(r, "minor"),
                         g(r, "factorizations"), f"{g(r, 'nfev')}/{g(r, 'njev')}",
                         g(r, "passes"), g(r, "splu_time", fmt_time),
                         g(r, "fact_equiv", lambda v: f"{v:.1f}"), g(r, "lu_nnz", fmt_e),
                         g(r, "rss_delta_mb", lambda v: f"{v:.0f}"),
                         g(r, "max_change", lambda v: f"{v:.2f}")]
                        for r in rows if not str(r["case"]).startswith("bench")]))
        errs = [r for r in rows if r.get("error") not in ("", None)]
        for r in errs:
            print(f"\n- {r['family']} n={r.get('n', r['n_target'])} {r['case']}: {r['error']}")
    p = RESULTS / f"cge_tolerance{suffix}.csv"
    if p.exists():
        rows = read_csv(p)
        print("\n### Time against error\n")
        print(md_table(["n", "convergence_tolerance", "status", "||Phi_FB||", "natural res.",
                        "ok (<= 1e-6)", "major", "fact.", "time"],
                       [[g(r, "n"), g(r, "tolerance", fmt_e), g(r, "status"),
                         g(r, "fb_norm", fmt_e), g(r, "natural", fmt_e), g(r, "success"),
                         g(r, "major"), g(r, "factorizations"), g(r, "time", fmt_time)]
                        for r in rows]))
    p = RESULTS / f"cge_stress{suffix}.csv"
    if p.exists():
        rows = read_csv(p)
        print("\n### Stress\n")
        print(md_table(["test", "variant", "n", "ok", "status", "natural res. (orig.)",
                        "err vs ref.", "major", "pivots", "fact.", "restarts", "time", "detail"],
                       [[r["test"], r["variant"], g(r, "n"), g(r, "success"), g(r, "status"),
                         g(r, "natural", fmt_e), g(r, "err_vs_ref", fmt_e), g(r, "major"),
                         g(r, "minor"), g(r, "factorizations"), g(r, "restarts"),
                         g(r, "time", fmt_time), g(r, "detail") + " " + g(r, "error")]
                        for r in rows]))
    p = RESULTS / f"cge_path{suffix}.csv"
    if p.exists():
        rows = read_csv(p)
        rec = any(str(r.get("path_source", "")).startswith("recorded") for r in rows)
        print("\n### Side by side with PATH (one-sector LPR Ramsey)\n")
        print(md_table(["T", "n", "capital tax", "solver", "ok", "status", "natural res.",
                        "time", "major", "minor", "crash", "F/J evals", "max rel. diff",
                        "dK(t=5)", "dK(T-1)"],
                       [[g(r, "T"), g(r, "n"), g(r, "tax"), r["solver"] + recorded_mark(r),
                         g(r, "success"),
                         g(r, "status"), g(r, "natural", fmt_e), g(r, "time", fmt_time),
                         g(r, "major"), g(r, "minor"), g(r, "crash"),
                         f"{g(r, 'nfev')}/{g(r, 'njev')}", g(r, "max_rel_diff", fmt_e),
                         g(r, "K5_change", lambda v: f"{100 * v:+.2f}%"),
                         g(r, "K_last_change", lambda v: f"{100 * v:+.2f}%")]
                        for r in rows]))
        if rec:
            print("\n" + RECORDED_NOTE)


# =========================================================================== main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (< 2 minutes)")
    ap.add_argument("--sizes", type=float, nargs="+", default=None)
    ap.add_argument("--parts", nargs="+", default=["main", "tol", "stress", "path"],
                    choices=["main", "tol", "stress", "path", "lu"])
    ap.add_argument("--lu", nargs="+", default=list(LU_CONFIGS), choices=list(LU_CONFIGS),
                    help="linear algebra compared by part lu")
    ap.add_argument("--time-limit", type=float, default=None, help="per-solve seconds")
    ap.add_argument("--lu-repeats", type=int, default=1,
                    help="part lu: repeats of (reference, configurations), alternating")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--suffix", default=None, help="CSV name suffix (default '' / '_quick')")
    ap.add_argument("--families", nargs="+", default=["static", "dynamic"])
    ap.add_argument("--cases", nargs="+", default=None, help="subset of the part-1 cases")
    ap.add_argument("--splu-max-n", type=int, default=10**9,
                    help="skip the reference splu above this n (it took > 10 min for the "
                         "dynamic model at n = 1e5)")
    ap.add_argument("--append", action="store_true", help="append to the part-1 CSV")
    ap.add_argument("--stress-tests", nargs="+", default=None,
                    choices=["scaling", "degenerate", "numeraire"], help="subset of part 3")
    add_path_argument(ap)
    ap.add_argument("--report", action="store_true",
                    help="only print markdown tables from the CSV files of a run")
    args = ap.parse_args(argv)
    if args.report:
        report(args.suffix if args.suffix is not None else ("_quick" if args.quick else ""))
        return
    if args.sizes is None:
        args.sizes = [1e3, 3e3] if args.quick else [1e3, 3e3, 1e4, 3e4, 1e5]
    args.sizes = [int(s) for s in args.sizes]
    if args.time_limit is None:
        args.time_limit = 60.0 if args.quick else 300.0
    args.stress_time_limit = min(args.time_limit, 10.0 if args.quick else 30.0)
    if args.suffix is None:
        args.suffix = "_quick" if args.quick else ""
    args.tol_n = 3000 if args.quick else 10000
    args.stress_n = 1000
    args.path_T = [40] if args.quick else [40, 110]
    info = machine_info()
    print_machine(info)
    if "path" in args.parts:
        args.path_source = choose_path_source("cge", args.path_mode)
        print(args.path_source.line(), flush=True)
    t0 = time.perf_counter()
    warm_up()
    print(f"# warm-up {time.perf_counter() - t0:.1f} s", flush=True)
    out = {}
    for part in args.parts:
        print(f"## part {part}", flush=True)
        tp = time.perf_counter()
        out[part] = globals()[f"part_{part}"](args, info)
        print(f"## part {part} done in {time.perf_counter() - tp:.1f} s", flush=True)
    print(f"# total {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main()
