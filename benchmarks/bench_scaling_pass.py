"""The scaling pass on badly scaled CGE models: scaling on against scaling off.

The static CGE model (n ~ 1000, 25% tariff shock) is rewritten in bad units exactly as in
``bench_cge.py`` part 3 (z = D y, rows multiplied by S, factors log-uniform in
[10^-k, 10^k]); each variant is solved with ``scaling=True`` and ``scaling=False``.
Success is judged on the recovered point y = z / D in the ORIGINAL model (natural residual
<= 1e-6) and against a reference solve of the unscaled model; the solver's own status
refers to the scaled model the user gave it.

    python3 benchmarks/bench_scaling_pass.py [--n 1000] [--k 4 6] [--time-limit 60]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cge import SHOCKS, _scaled_problem, make_model, nat_res  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--k", type=int, nargs="+", default=[4, 6])
    ap.add_argument("--kinds", nargs="+", default=["S", "DS"])
    ap.add_argument("--time-limit", type=float, default=60.0)
    args = ap.parse_args(argv)
    from compass_sparse import solve_mcp

    m, _ = make_model("static", args.n)
    ms = m.with_shock(**SHOCKS["tariff25"])
    prob = ms.problem
    ref = solve_mcp(prob, options={"convergence_tolerance": 1e-10,
                                   "time_limit": args.time_limit})
    print(f"n = {prob.n}; reference {ref.status.name}, natural "
          f"{nat_res(ref.x, ms.F(ref.x), prob.lb, prob.ub):.1e}")
    print("| variant | scaling | status | natural (orig.) | err vs ref. | major | time |")
    print("|---|---|---|---|---|---|---|")
    for kind in args.kinds:
        for k in args.k:
            rng = np.random.default_rng(7 + k)
            n = prob.n
            d = 10.0 ** rng.uniform(-k, k, n) if kind in ("D", "DS") else np.ones(n)
            s = 10.0 ** rng.uniform(-k, k, n) if kind in ("S", "DS") else np.ones(n)
            scaled = _scaled_problem(prob, d, s)
            for on in (True, False):
                t = time.perf_counter()
                r = solve_mcp(scaled, options={"scaling": on, "time_limit": args.time_limit})
                wall = time.perf_counter() - t
                y = r.x / d
                nat = nat_res(y, ms.F(y), prob.lb, prob.ub)
                err = float(np.max(np.abs(y - ref.x) / np.maximum(1.0, np.abs(ref.x))))
                print(f"| {kind} 1e-{k}..1e{k} | {'on' if on else 'off'} | {r.status.name} | "
                      f"{nat:.1e} | {err:.1e} | {r.nit} | {wall:.1f} s |", flush=True)


if __name__ == "__main__":
    main()
