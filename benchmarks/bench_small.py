"""Small and medium models (n = 1 ... 1000): compass_sparse against PATH 5.2, per solve.

Groups
------
* ``known``: the problems with known solutions of the test suite (``tests/known_problems.py``:
  kojshin, josephy, mathiesen, cournot2, nash5, boxvi, double_root, billups, log_ncp,
  sqrt_ncp).  For PATH each one is written once in GAMSPy (:func:`_gamspy_known`, the same
  formulas as the Python F).
* ``thesis``: the COMPASS thesis' random nonlinear families 1 and 2 at n = 10, 50, 100, 200
  (PATH gets the same data through ``solve_quadratic_mcp_with_path``, as bench_thesis.py).
* ``cge``: the one-sector Lau-Pahlke-Rutherford Ramsey model at n ~ 100, 360, 990 with a 25%
  capital tax (PATH: the GAMSPy model of bench_cge.py), and the static Armington CGE model
  at n ~ 90 (one region: a 25% output tax) and 760 (three regions: a 25% tariff) (PATH: the
  GAMSPy model of static_cge_gamspy.py, written from the generator's data).

Timing
------
Everything runs in this one warm process: numba kernels are compiled (or loaded from the
disk cache) by a warm-up before anything is timed.  Each problem is solved ``--repeats`` times
by each solver (PATH: ``--path-repeats``) in each of ``--rounds`` passes over all problems, and
the MEDIAN over all rounds is reported: with several rounds a problem's samples are spread
over the whole run, so that a slow minute of a shared machine weighs on every problem alike.
Within a round, compass_sparse's solves of all problems come first and PATH's runs of all
problems after them (``--order sweeps``); ``--order interleaved`` follows each problem's
solves with its PATH runs, so that each of our solves follows a wait on the GAMS process,
which slows this process' next solves (and the user's F and J in them) down by up to 2x
(see small.md, Round 11).
For compass_sparse, ``time`` is the wall time of ``solve_mcp`` MINUS the time spent inside
the user's F and J (measured by wrapping the callbacks); ``user`` is that F/J time.  For
PATH, ``time`` is PATH's own "Total Time" from its log (the GAMS process start and model
generation are not counted; PATH evaluates F and J through GAMS' compiled instructions,
included in its time).  Success = OUR natural residual
``||z - clip(z - F(z), l, u)||_inf <= 1e-6`` of the returned point, for both solvers.

PATH's figures
--------------
Where GAMS cannot run (e.g. its licence expired) PATH's rows are the recorded ones of
``benchmarks/reference/small.csv`` (``--path recorded`` asks for them where GAMS runs;
``--path live`` insists on a live run).  The first lines of the output say which source
is used; recorded rows carry ``path_source = "recorded <date> <rev>"`` in the CSV (live
ones ``live``) and are marked in the tables, whose ratios then compare with PATH's run
of that day; a problem the reference does not have gets "–".

    python3 benchmarks/bench_small.py                     # all groups, 5 repeats
    python3 benchmarks/bench_small.py --groups known --repeats 21
    python3 benchmarks/bench_small.py --rounds 3 --repeats 3 --path-repeats 1
    python3 benchmarks/bench_small.py --no-path           # compass_sparse only
    python3 benchmarks/bench_small.py --path recorded     # PATH's recorded figures
    python3 benchmarks/bench_small.py --import-time       # import and first solve only

Results: ``benchmarks/results/small<suffix>.csv`` (one row per problem and solver) and a
summary printed as markdown (copied into small.md).
"""
from __future__ import annotations

import argparse
import copy
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "tests"))
from _common import (
    RECORDED_NOTE,
    RESULTS,
    SUCCESS_TOL,
    CsvLog,
    add_path_argument,
    any_recorded,
    choose_path_source,
    fmt_time,
    machine_info,
    md_table,
    natural_residual,
    path_session,
    print_machine,
    recorded_mark,
    warm_up,
)

FIELDS = ["group", "name", "n", "solver", "success", "status", "natural", "time", "user",
          "wall", "cpu", "user_cpu", "major", "minor", "repeats", "error", "cpu_min",
          "path_source"]


# --------------------------------------------------------------------------- cases
class Case:
    """One problem: our MCP, an independent F for the residual, and a PATH runner."""

    def __init__(self, group, name, problem, F, lb, ub, path_run=None):
        self.group, self.name, self.problem = group, name, problem
        self.F, self.lb, self.ub = F, lb, ub
        self.path_run = path_run  # () -> (x, PATH total time, status) or None

    @property
    def n(self):
        return self.problem.n


def _known_cases():
    import known_problems as kp

    from compass_sparse import MCP

    makers = dict(kp.ALL_SOLVABLE)
    makers.update(double_root=kp.degenerate_root, billups=kp.billups,
                  log_ncp=lambda: kp.log_ncp(raise_errors=False), sqrt_ncp=kp.sqrt_ncp)
    cases = []
    for name, make in makers.items():
        p = make()
        prob = MCP(p.F, p.J, p.lb, p.ub, p.x0)
        cases.append(Case("known", name, prob, p.F, p.lb, p.ub,
                          lambda p=p, name=name: _gamspy_known(name, p)))
    return cases


def _gamspy_known(name, p):
    """The known problem ``name`` written in GAMSPy (scalar variables x0..x{n-1}) and solved
    by PATH from the same start point.  Returns (x, PATH total time, exit message)."""
    import io
    import logging

    import gamspy as gp

    from compass_sparse.interfaces.path_gamspy import parse_path_log

    m = gp.Container()
    n = p.n
    xs = [gp.Variable(m, f"x{k}") for k in range(n)]
    for k in range(n):
        if np.isfinite(p.lb[k]):
            xs[k].lo[...] = float(p.lb[k])
        if np.isfinite(p.ub[k]):
            xs[k].up[...] = float(p.ub[k])
        xs[k].l[...] = float(p.x0[k])
    x = xs
    if name in ("kojshin", "josephy"):
        x1, x2, x3, x4 = x
        c3 = (9, 9) if name == "kojshin" else (3, 1)
        F = [3 * x1**2 + 2 * x1 * x2 + 2 * x2**2 + x3 + 3 * x4 - 6,
             2 * x1**2 + x1 + x2**2 + 3 * x3 + 2 * x4 - 2,
             3 * x1**2 + x1 * x2 + 2 * x2**2 + 2 * x3 + c3[0] * x4 - c3[1],
             x1**2 + 3 * x2**2 + 2 * x3 + 3 * x4 - 3]
    elif name == "mathiesen":
        x1, x2, x3, x4 = x
        F = [-x2 + x3 + x4, x1 - (4.5 * x3 + 2.7 * x4) / (x2 + 1.0),
             5.0 - x1 - (0.5 * x3 + 0.3 * x4) / (x3 + 1.0), 3.0 - x1]
    elif name == "cournot2":
        c, a, b = (1.0, 2.0), 10.0, 1.0
        F = [c[i] - (a - b * (x[0] + x[1])) + b * x[i] for i in range(2)]
    elif name == "nash5":
        from known_problems import MSS_BETA, MSS_C, MSS_GAMMA, MSS_L

        g = MSS_GAMMA
        k = 5000.0 ** (1.0 / g)
        Q = x[0] + x[1] + x[2] + x[3] + x[4]
        p_ = k * gp.math.rpower(Q, -1.0 / g)
        c_, L_, b_ = (MSS_C.tolist(), MSS_L.tolist(), MSS_BETA.tolist())  # python floats
        F = [c_[i] + gp.math.rpower(L_[i] * x[i], 1.0 / b_[i]) - p_
             - x[i] * (-(1.0 / g) * p_ / Q) for i in range(5)]
    elif name == "boxvi":
        c = [8.0, -1.0, 27.0, 0.125, -8.0, 1.0]
        F = [gp.math.power(x[i], 3) - c[i] for i in range(6)]
    elif name == "double_root":
        F = [gp.math.sqr(x[0]) - 2.0 * x[0] + 1.0]
    elif name == "billups":
        F = [gp.math.sqr(x[0] - 1.0) - 1.01]
    elif name == "log_ncp":
        c = [-3.0, -2.0, 0.5, 1.0]
        F = [gp.math.log(x[i]) - c[i] for i in range(4)]
    elif name == "sqrt_ncp":
        F = [gp.math.sqrt(x[0] - 1.0) + x[0] - 3.0]
    else:
        raise KeyError(name)
    eqs = []
    for k in range(n):
        e = gp.Equation(m, f"e{k}", type="nonbinding")  # =N=: complementarity by matching
        e[...] = F[k]
        eqs.append(e)
    model = gp.Model(m, f"known_{name}", problem="MCP",
                     matches={eqs[k]: xs[k] for k in range(n)})
    buf = io.StringIO()
    lg = logging.getLogger("MODEL")
    old = lg.level
    lg.setLevel(logging.ERROR)
    try:
        model.solve(solver="PATH", solver_options={"convergence_tolerance": 1e-6}, output=buf)
    finally:
        lg.setLevel(old)
    info = parse_path_log(buf.getvalue())
    xv = np.array([float(v.records["level"].iloc[0]) if v.records is not None else 0.0
                   for v in xs])
    return xv, info.get("path_time"), str(info.get("exit_message") or model.solve_status)


def _thesis_cases(sizes, families, seeds):
    from compass_sparse.generators import thesis_family
    from compass_sparse.interfaces.path_gamspy import solve_quadratic_mcp_with_path

    cases = []
    for fam in families:
        for n in sizes:
            for seed in seeds:
                g = thesis_family(n, fam, seed)
                info = g.info

                def F(x, info=info):
                    return info["D"] * x * x + info["A"] @ x + info["b"]

                def run(info=info, n=n):
                    r = solve_quadratic_mcp_with_path(
                        info["D"], info["A"], info["b"], info["lb"], info["ub"], info["x0"],
                        convergence_tolerance=1e-6, time_limit=60.0,
                        session=path_session(n, True))
                    return r.x, (r.path_time if r.path_time is not None else r.wall_time), \
                        str(r.exit_message or r.solver_status)

                cases.append(Case("thesis", f"fam{fam}_n{n}_s{seed}", g.problem, F,
                                  info["lb"], info["ub"], run))
    return cases


def _cge_cases(ramsey_T, static_n):
    from compass_sparse.generators.cge import ramsey_cge, size_for, static_cge

    cases = []
    for T in ramsey_T:
        m = ramsey_cge(periods=T, sectors=1)
        ms = m.with_shock(capital_tax=0.25)
        prob = ms.problem

        def run(T=T, m=m):
            from bench_cge import ramsey_gamspy

            out = ramsey_gamspy(T, 0.25, m.benchmark)
            return out["x"], (out["time"] if out["time"] is not None else out["wall"]), \
                out["status"]

        cases.append(Case("cge", f"ramsey_T{T}_tax25", prob, ms.F, prob.lb, prob.ub, run))
    for n in static_n:
        m = static_cge(**size_for(n))
        # a tariff changes nothing in a closed economy (one region: no imports), where the
        # benchmark would already be the solution; there the shock is a 25% output tax
        closed = m.info["regions"] == 1
        ms = m.with_shock(output_tax=0.25) if closed else m.with_shock(tariff=0.25)
        prob = ms.problem

        def run(ms=ms):
            from static_cge_gamspy import solve_static_with_path

            out = solve_static_with_path(ms)
            return out["x"], (out["time"] if out["time"] is not None else out["wall"]), \
                out["status"]

        shock = "otax25" if closed else "tariff25"
        cases.append(Case("cge", f"static_n{prob.n}_{shock}", prob, ms.F, prob.lb, prob.ub,
                          run))
    return cases


# --------------------------------------------------------------------------- timing
class _Timed:
    """Wraps a user callback and accumulates the seconds spent inside it: ``clock`` is
    [wall seconds, CPU seconds, calls] (a two-entry clock gets no count)."""

    def __init__(self, fn, clock):
        self.fn, self.clock = fn, clock

    def __call__(self, x):
        # The wall window encloses the CPU window: the CPU clock's reads (~1 us each, a
        # system call) fall on the user's side of the wall time.  What the wrapper does
        # outside a window (its call, the other clock's reads, the sums) is charged to the
        # solver by the subtraction: measured per call by _instrument_cost and taken off.
        t0 = time.perf_counter()
        c0 = time.process_time()
        try:
            return self.fn(x)
        finally:
            c1 = time.process_time()
            t1 = time.perf_counter()
            clock = self.clock
            clock[0] += t1 - t0
            clock[1] += c1 - c0
            if len(clock) > 2:
                clock[2] += 1


CALIBRATION_CALLS = 20000
"""Calls of a timed no-op per batch of the instrument's calibration (five batches)."""
_COST: list = []  # [the instrument's costs (see _instrument_cost)], once measured


def _instrument_cost():
    """(wall, CPU) seconds that the instrument charges to the solver: per timed call of F
    or J, what it costs outside the windows it measures (the wrapper's call and sums, and
    on the CPU side half of each CPU clock read: ~1 us a call, and a solve of thesis
    family 2 at n = 10 makes ~95 calls); and per solve, what the solve's own bracket of
    clock reads measures around nothing.  The medians over five batches (timed no-op calls
    less the same loop of direct calls; empty brackets) are taken off the solver's time
    instead.  Measured once per process: ``(call_wall, call_cpu, solve_wall, solve_cpu)``."""
    if _COST:
        return _COST[0]

    def noop(x):
        return x

    clock = [0.0, 0.0, 0]
    timed = _Timed(noop, clock)
    k = CALIBRATION_CALLS
    walls, cpus, bracket_walls, bracket_cpus = [], [], [], []
    for _ in range(5):
        clock[:] = [0.0, 0.0, 0]
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(k):
            timed(None)
        w1, c1 = time.perf_counter() - t0, time.process_time() - c0
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(k):
            noop(None)
        w2, c2 = time.perf_counter() - t0, time.process_time() - c0
        walls.append((w1 - clock[0] - w2) / k)
        cpus.append((c1 - clock[1] - c2) / k)
        c0 = time.process_time()  # run_ours's bracket around an empty solve
        t0 = time.perf_counter()
        w3 = time.perf_counter() - t0
        bracket_walls.append(w3)
        bracket_cpus.append(time.process_time() - c0)
    _COST.append(tuple(max(statistics.median(v), 0.0)
                       for v in (walls, cpus, bracket_walls, bracket_cpus)))
    return _COST[0]


def _timed_problem(problem, clock):
    """A copy of the problem whose user callbacks are timed (the evaluation object's F
    and J; before that object existed, the MCP's own)."""
    p = copy.copy(problem)
    ev = getattr(problem, "evaluator", None)
    owner, f_attr, j_attr = (p, "_F", "_jac") if ev is None else (None, "_user_F", "_user_jac")
    if ev is not None:
        owner = p.evaluator = ev.fresh()
    setattr(owner, f_attr, _Timed(getattr(owner, f_attr), clock))
    if callable(getattr(owner, j_attr)):
        setattr(owner, j_attr, _Timed(getattr(owner, j_attr), clock))
    return p


def run_ours(case, repeats, time_limit, samples=None):
    """``repeats`` timed solves of the case; the row reports the medians over these and
    the solves already in ``samples`` (a dict kept by the caller across rounds)."""
    from compass_sparse import solve_mcp

    clock = [0.0, 0.0, 0]
    prob = _timed_problem(case.problem, clock)
    samples = {} if samples is None else samples
    times, users, walls, cpus, ucpus = (samples.setdefault(k, []) for k in
                                        ("time", "user", "wall", "cpu", "user_cpu"))
    call_wall, call_cpu, solve_wall, solve_cpu = _instrument_cost()
    res = None
    for _ in range(repeats):
        clock[:] = [0.0, 0.0, 0]
        p = prob.with_start(case.problem.x0)
        c0 = time.process_time()  # (outside the wall window: see _Timed)
        t0 = time.perf_counter()
        res = solve_mcp(p, options={"time_limit": time_limit})
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        walls.append(wall)
        users.append(clock[0])
        times.append(wall - clock[0] - clock[2] * call_wall - solve_wall)
        cpus.append(cpu - clock[1] - clock[2] * call_cpu - solve_cpu)
        ucpus.append(clock[1])
    nat = natural_residual(res.x, case.F(res.x), case.lb, case.ub)
    return dict(group=case.group, name=case.name, n=case.n, solver="compass_sparse",
                success=nat <= SUCCESS_TOL, status=res.status.name, natural=nat,
                time=statistics.median(times), user=statistics.median(users),
                wall=statistics.median(walls), cpu=statistics.median(cpus),
                user_cpu=statistics.median(ucpus), major=res.nit, minor=res.minor_iterations,
                repeats=len(times), error="", cpu_min=min(cpus))


def run_path(case, repeats, times=None):
    """``repeats`` PATH runs; the row reports the median over these and the run times
    already in ``times`` (a list kept by the caller across rounds)."""
    times = [] if times is None else times
    x, status = None, ""
    try:
        for _ in range(repeats):
            x, t, status = case.path_run()
            times.append(float(t))
    except Exception as exc:  # a failing PATH run is a data point, not a crash
        return dict(group=case.group, name=case.name, n=case.n, solver="PATH",
                    success=False, status="exception", natural=math.inf, time=math.nan,
                    user=math.nan, wall=math.nan, repeats=0,
                    error=str(exc).strip().splitlines()[0][:200])
    nat = natural_residual(x, case.F(x), case.lb, case.ub)
    return dict(group=case.group, name=case.name, n=case.n, solver="PATH",
                success=nat <= SUCCESS_TOL, status=status, natural=nat,
                time=statistics.median(times), user=math.nan, wall=math.nan,
                major="", minor="", repeats=len(times), error="", path_source="live")


def recorded_path(case, reference):
    """PATH's recorded row of the case (benchmarks/reference/small.csv) in this script's
    fields, or None when PATH was not recorded on it."""
    r = reference.get(group=case.group, name=case.name, n=case.n)
    if r is None:
        return None
    return dict(group=case.group, name=case.name, n=case.n, solver="PATH",
                success=bool(r["success"]), status=r["status"], natural=float(r["natural"]),
                time=float(r["time"]), user=math.nan, wall=math.nan, major="", minor="",
                repeats=r["repeats"], error="", path_source=r["path_source"])


# --------------------------------------------------------------------------- import time
def import_time(repeats=7):
    """Median wall times in fresh interpreters (warm caches: one discarded run first):
    (total, own, first, second) -- ``import compass_sparse`` in all and after numpy and
    scipy.sparse are loaded (what the package itself adds), then the first solve of a
    small problem (kojshin, n = 4: what a fresh batch worker or a one-shot script pays;
    its kernels interpreted, numba not loaded -- compass_sparse._jit, "Cold start") and a
    second solve of it."""
    code = ("import sys, time; sys.path.insert(0, 'tests'); t = time.perf_counter(); "
            "import numpy, scipy.sparse; t1 = time.perf_counter(); import compass_sparse; "
            "t2 = time.perf_counter(); import known_problems as kp; q = kp.kojima_shindo(); "
            "s = time.perf_counter(); compass_sparse.solve_mcp(q.F, q.J, q.lb, q.ub, q.x0); "
            "s1 = time.perf_counter(); compass_sparse.solve_mcp(q.F, q.J, q.lb, q.ub, q.x0); "
            "s2 = time.perf_counter(); print(t2 - t, t2 - t1, s1 - s, s2 - s1)")
    env = dict(os.environ)
    env["PYTHONPATH"] = str(HERE.parent)
    runs = []
    for k in range(repeats + 1):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True, env=env, cwd=HERE.parent)
        if k:
            runs.append([float(v) for v in r.stdout.strip().splitlines()[-1].split()])
    return tuple(statistics.median(col) for col in zip(*runs))


# --------------------------------------------------------------------------- summary
def _ours(o) -> float:
    """Our solver time of a row: CPU time when recorded (the machine is shared), else wall."""
    c = o.get("cpu", "")
    return float(c) if c not in ("", None) and not math.isnan(float(c)) else float(o["time"])


def summarize(rows, imp=None) -> str:
    by = {}
    for r in rows:
        by.setdefault((r["group"], r["name"]), {})[r["solver"]] = r
    out = []
    table = []
    rec = any_recorded(r for r in rows if r["solver"] == "PATH")
    mark = " (recorded)" if rec else ""
    for (g, name), d in by.items():
        o, p = d.get("compass_sparse"), d.get("PATH")
        ratio = (_ours(o) / p["time"] if o and p and p["success"] and o["success"]
                 and p["time"] > 0 else math.nan)
        table.append([g, name, o["n"] if o else p["n"],
                      ("yes" if o["success"] else "NO") if o else "–",
                      fmt_time(_ours(o)) if o else "–", fmt_time(o["time"]) if o else "–",
                      fmt_time(o["user"]) if o else "–", o["minor"] if o else "–",
                      ("yes" if p["success"] else "NO") if p else "–",
                      fmt_time(p["time"]) if p else "–",
                      f"{ratio:.2f}" if not math.isnan(ratio) else "–"])
    out.append(md_table(["group", "problem", "n", "ours ok", "ours CPU", "ours wall", "in F/J",
                         "pivots", f"PATH ok{mark}", f"PATH time{mark}",
                         "ratio vs recorded PATH" if rec else "ratio"], table))
    out.append("")
    gt = []
    for g in dict.fromkeys(r["group"] for r in rows):
        pairs = [(d["compass_sparse"], d["PATH"]) for (gg, _), d in by.items()
                 if gg == g and "compass_sparse" in d and "PATH" in d
                 and d["compass_sparse"]["success"] and d["PATH"]["success"]]
        ours_all = [d["compass_sparse"] for (gg, _), d in by.items()
                    if gg == g and "compass_sparse" in d]
        ok_o = sum(bool(r["success"]) for r in ours_all)
        ok_p = sum(bool(d["PATH"]["success"]) for (gg, _), d in by.items()
                   if gg == g and "PATH" in d)
        ratios = [_ours(o) / p["time"] for o, p in pairs if p["time"] > 0]
        gt.append([g, len(ours_all), ok_o, ok_p,
                   fmt_time(statistics.median([_ours(o) for o, _ in pairs])) if pairs else "–",
                   fmt_time(statistics.median([p["time"] for _, p in pairs])) if pairs else "–",
                   f"{statistics.median(ratios):.2f}" if ratios else "–",
                   f"{max(ratios):.2f}" if ratios else "–"])
    out.append(md_table(["group", "problems", "ours solved", f"PATH solved{mark}",
                         "median ours (both solved)", f"median PATH{mark}",
                         "median ratio" + (" vs recorded PATH" if rec else ""),
                         "worst ratio" + (" vs recorded PATH" if rec else "")], gt))
    if rec:
        out.append("")
        out.append(RECORDED_NOTE)
    small = [r for r in rows if r["solver"] == "compass_sparse" and int(r["n"]) <= 10]
    if small:
        out.append("")
        out.append(f"n <= 10 ({len(small)} problems): median solver time (CPU) "
                   f"{fmt_time(statistics.median([_ours(r) for r in small]))}, worst "
                   f"{fmt_time(max(_ours(r) for r in small))}")
        mins = [float(r["cpu_min"]) for r in small if r.get("cpu_min") not in ("", None)]
        if len(mins) == len(small):  # the least CPU of each problem's repeats: the
            # estimate least disturbed by other jobs on a shared machine
            out.append(f"n <= 10, each problem's fastest repeat (CPU): median "
                       f"{fmt_time(statistics.median(mins))}")
    if imp is not None:
        out.append(f"import compass_sparse (fresh interpreter, warm caches, median of 7): "
                   f"{imp[0]:.3f} s in all, {imp[1]:.3f} s after numpy and scipy.sparse; "
                   f"then the first solve (kojshin) {imp[2]:.3f} s, the second "
                   f"{imp[3] * 1e3:.2f} ms")
    return "\n".join(out)


def compare(before, after) -> str:
    """Per-group table of two runs (e.g. before and after a change): our median CPU time,
    successes, and PATH's median from the run that has it."""
    def index(rows):
        return {(r["group"], r["name"], r["solver"]): r for r in rows}

    b, a = index(before), index(after)
    out = []
    for g in dict.fromkeys(r["group"] for r in after):
        names = [k[1] for k in a if k[0] == g and k[2] == "compass_sparse"]
        ob = [b[(g, nm, "compass_sparse")] for nm in names if (g, nm, "compass_sparse") in b]
        oa = [a[(g, nm, "compass_sparse")] for nm in names]
        pa = [a.get((g, nm, "PATH")) or b.get((g, nm, "PATH")) for nm in names]
        both = [(x, p) for x, p in zip(oa, pa) if p and p["success"] and x["success"]]
        out.append([g, len(names), sum(bool(x["success"]) for x in ob),
                    sum(bool(x["success"]) for x in oa),
                    fmt_time(statistics.median([_ours(x) for x in ob])) if ob else "–",
                    fmt_time(statistics.median([_ours(x) for x in oa])),
                    fmt_time(statistics.median([p["time"] for p in pa if p and p["success"]]))
                    if any(p and p["success"] for p in pa) else "–",
                    f"{max(_ours(x) / p['time'] for x, p in both):.1f}" if both else "–"])
    return md_table(["group", "problems", "solved before", "solved after",
                     "median CPU before", "median CPU after", "median PATH (its solves)",
                     "worst ratio after / PATH"], out)


def parser():
    """The command line (its defaults are the default case list)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--groups", nargs="+", default=["known", "thesis", "cge"],
                    choices=["known", "thesis", "cge"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--path-repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=1,
                    help="passes over all problems; medians over all rounds' samples")
    ap.add_argument("--thesis-n", nargs="+", type=int, default=[10, 50, 100, 200])
    ap.add_argument("--families", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--ramsey-T", nargs="+", type=int, default=[11, 40, 110])
    ap.add_argument("--static-n", nargs="+", type=int, default=[90, 830])
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--no-path", action="store_true")
    add_path_argument(ap)
    ap.add_argument("--order", choices=["sweeps", "interleaved"], default="sweeps",
                    help="within a round: all our solves, then all PATH runs (sweeps), or "
                         "each problem's solves followed by its PATH runs (interleaved)")
    ap.add_argument("--import-time", action="store_true",
                    help="only measure the import and the first solve in fresh interpreters")
    ap.add_argument("--suffix", default="")
    ap.add_argument("--out", type=Path, default=None,
                    help="CSV of the rows (default benchmarks/results/small<suffix>.csv)")
    ap.add_argument("--no-import-time", action="store_true",
                    help="leave out the import time (fresh interpreters) after the solves")
    ap.add_argument("--summarize", metavar="CSV", help="print the tables of an existing CSV")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"),
                    help="per-group table of two CSVs")
    return ap


def cases_of(a):
    """The cases the parsed command line ``a`` asks for."""
    cases = []
    if "known" in a.groups:
        cases += _known_cases()
    if "thesis" in a.groups:
        cases += _thesis_cases(a.thesis_n, a.families, a.seeds)
    if "cge" in a.groups:
        cases += _cge_cases(a.ramsey_T, a.static_n)
    return cases


def main(argv=None):
    a = parser().parse_args(argv)
    if a.compare:
        from _common import read_csv

        print(compare(read_csv(Path(a.compare[0])), read_csv(Path(a.compare[1]))))
        return
    if a.summarize:
        from _common import read_csv

        print(summarize(read_csv(Path(a.summarize))))
        return
    if a.import_time:
        tot, own, first, second = import_time()
        print(f"import compass_sparse: {tot:.3f} s in all, {own:.3f} s after numpy and "
              f"scipy.sparse; first solve (kojshin) {first:.3f} s, second "
              f"{second * 1e3:.2f} ms (medians of 7 fresh interpreters)")
        return
    info = machine_info()
    print_machine(info)
    source = choose_path_source("small", a.path_mode, a.no_path)
    print(source.line(), flush=True)
    use_path = source.live
    warm_up(with_path=use_path)
    cw, cc, sw, sc = _instrument_cost()
    print(f"instrument (taken off the solver's time): per call of F or J {cw * 1e6:.2f} us "
          f"wall, {cc * 1e6:.2f} us CPU; per solve {sw * 1e6:.2f} us wall, "
          f"{sc * 1e6:.2f} us CPU")
    cases = cases_of(a)
    # Rounds: every round times every problem (``--repeats`` solves, ``--path-repeats``
    # PATH runs), so that each problem's samples are spread over the whole run and a slow
    # minute of the shared machine touches all problems alike instead of a few; the rows
    # of the last round report the medians over all rounds.
    # Sweeps (the default order): within a round, our solves of all problems come first,
    # then PATH's runs of all problems.  With --order interleaved each problem's solves
    # follow the previous problem's PATH run: this process then waits, idle, on the GAMS
    # process, and its next solves run on a cooled-down core (measured at f2aee1a: cournot2
    # 0.32 ms per solve with the sweeps, 0.69 ms interleaved; the user's F and J slow
    # down alike, 0.038 -> 0.070 ms; the first ~10 solves after a PATH run take 1.2-2.5x
    # the steady time).  PATH's time is its own timer inside the GAMS process either way.
    ours_samples = {c.name: {} for c in cases}
    path_samples = {c.name: [] for c in cases}
    rows = []
    out = a.out or RESULTS / f"small{a.suffix}.csv"
    log = CsvLog(out, FIELDS)  # rows of the last round

    def ours(c, rnd):
        if rnd == 0:
            run_ours(c, 1, a.time_limit)  # first solve of a new shape: not timed
        return run_ours(c, a.repeats, a.time_limit, ours_samples[c.name])

    def theirs(c):
        if use_path and c.path_run is not None:
            return run_path(c, a.path_repeats, path_samples[c.name])
        if source.recorded:
            return recorded_path(c, source.reference)
        return None

    for rnd in range(a.rounds):
        last = rnd == a.rounds - 1
        if a.order == "interleaved":
            pairs = [(ours(c, rnd), theirs(c)) for c in cases]
        else:
            mine = [ours(c, rnd) for c in cases]
            pairs = list(zip(mine, [theirs(c) for c in cases]))
        for c, (r, p) in zip(cases, pairs):
            line = f"{c.group:7s} {c.name:22s} n={c.n:5d} ours {fmt_time(r['time']):>9s} " \
                   f"(F/J {fmt_time(r['user'])}) {'ok' if r['success'] else 'FAIL'}"
            if p is not None:
                line += (f" | PATH {fmt_time(p['time']):>9s} {'ok' if p['success'] else 'FAIL'}"
                         + recorded_mark(p))
            elif source.recorded:
                line += " | PATH         – (not in the reference)"
            if last:
                for row in [r] + ([p] if p is not None else []):
                    log.write(row)
                    rows.append(row)
            print(f"[round {rnd + 1}/{a.rounds}] " + line, flush=True)
    log.close()
    imp = None if a.no_import_time else import_time()
    print()
    print(summarize(rows, imp))
    print(f"\n# rows in {out}", flush=True)


if __name__ == "__main__":
    main()
