"""Two revisions of the solver timed on the same problems, alternating process by process.

On a shared machine the time of the same code moves by 30-50% between minutes, more than
most changes to a small solve's fixed cost; timing the two revisions in alternating fresh
processes, several times, and comparing the medians separates the change from the drift.

    git worktree add /tmp/old <revision>
    python3 benchmarks/alternate_revisions.py /tmp/old . kojshin cournot2 ramsey40 --rounds 4
    python3 benchmarks/alternate_revisions.py /tmp/old . cournot2 kojshin --one-shot

Each round runs one process per revision (old first); each process solves every problem
``--solves`` times per repeat after a warm-up (numba kernels loaded), ``--repeats`` times,
and reports the median CPU time per solve, F and J included.  By default each solve gets a
copy of one built problem (``MCP.with_start``: the Jacobian pattern is known); with
``--one-shot`` each solve is ``solve_mcp(F, J, lb, ub, x0)`` from the user's functions, as
a script calls it once: the problem's construction, its bounds' checks, the start check and
the first Jacobian's pattern are timed too (known problems only).  Problems: the names of
``bench_fixed_cost.py`` (known problems), ``ramseyT`` (one-sector Ramsey CGE model with
T periods, 25% capital tax), ``staticN`` (static CGE model of about N variables) or
``famF_nN_sS`` (the thesis' family F at n = N, seed S, as bench_small.py names them).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHILD = r"""
import json, statistics, sys, time
root, names, solves, repeats = sys.argv[1], sys.argv[2].split(","), int(sys.argv[3]), int(sys.argv[4])
one_shot = sys.argv[5] == "1"
sys.path[:0] = [root, root + "/tests", root + "/benchmarks"]
from compass_sparse import solve_mcp
try:  # timings of compiled kernels (revisions with a cold start: compass_sparse._jit)
    from compass_sparse._jit import end_cold_start
    end_cold_start()
except ImportError:
    pass

def problem(name):
    if name.startswith("ramsey"):
        from compass_sparse.generators.cge import ramsey_cge
        p = ramsey_cge(periods=int(name[6:]), sectors=1).with_shock(capital_tax=0.25).problem
        return p, p.x0
    if name.startswith("static"):
        from compass_sparse.generators.cge import size_for, static_cge
        m = static_cge(**size_for(int(name[6:])))
        m = m.with_shock(output_tax=0.25) if m.info["regions"] == 1 else m.with_shock(tariff=0.25)
        return m.problem, m.problem.x0
    if name.startswith("fam"):  # famF_nN_sS: thesis family F at n = N, seed S
        from compass_sparse.generators import thesis_family
        fam, n, seed = name[3:].split("_")
        p = thesis_family(int(n[1:]), int(fam), int(seed[1:])).problem
        return p, p.x0
    from bench_fixed_cost import _problem
    return _problem(name)

def user_problem(name):
    import known_problems as kp
    makers = dict(kp.ALL_SOLVABLE)
    makers.update(double_root=kp.degenerate_root, billups=kp.billups, sqrt_ncp=kp.sqrt_ncp,
                  log_ncp=lambda: kp.log_ncp(raise_errors=False))
    return makers[name]()

out = {}
for name in names:
    if one_shot:
        k = user_problem(name)
        run = lambda k=k: solve_mcp(k.F, k.J, k.lb, k.ub, k.x0)
        for _ in range(max(10, solves // 10)):
            r = run()
        times = []
        for _ in range(repeats):
            t = time.process_time()
            for _ in range(solves):
                run()
            times.append((time.process_time() - t) / solves)
        out[name] = dict(time=statistics.median(times), nit=r.nit, status=r.status.name)
        continue
    prob, x0 = problem(name)
    for _ in range(max(10, solves // 10)):
        r = solve_mcp(prob.with_start(x0))
    times = []
    for _ in range(repeats):
        copies = [prob.with_start(x0) for _ in range(solves)]
        t = time.process_time()
        for q in copies:
            solve_mcp(q)
        times.append((time.process_time() - t) / solves)
    out[name] = dict(time=statistics.median(times), nit=r.nit, status=r.status.name)
print(json.dumps(out))
"""


def run(root, names, solves, repeats, one_shot=False):
    out = subprocess.run([sys.executable, "-c", CHILD, os.path.abspath(root), ",".join(names),
                          str(solves), str(repeats), "1" if one_shot else "0"],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("problems", nargs="+")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--solves", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--one-shot", action="store_true",
                    help="every solve from the user's functions (see the module docstring)")
    a = ap.parse_args(argv)
    got = {"old": [], "new": []}
    for k in range(a.rounds):
        for side in ("old", "new"):
            got[side].append(run(getattr(a, side), a.problems, a.solves, a.repeats,
                                 a.one_shot))
            print(f"round {k + 1} {side}: " + ", ".join(
                f"{n} {v['time'] * 1e3:.3f} ms" for n, v in got[side][-1].items()), flush=True)
    print("\n| problem | old (median over rounds) | new | new / old | majors old / new |")
    print("|---|---|---|---|---|")
    for n in a.problems:
        o = statistics.median(r[n]["time"] for r in got["old"])
        w = statistics.median(r[n]["time"] for r in got["new"])
        print(f"| {n} | {o * 1e3:.3f} ms | {w * 1e3:.3f} ms | {w / o:.2f} | "
              f"{got['old'][0][n]['nit']} / {got['new'][0][n]['nit']} |")


if __name__ == "__main__":
    main()
