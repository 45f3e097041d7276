"""The homotopy's step control on the COMPASS thesis instances that reach it, in one process.

Variants set the tracker's step-control constants (compass_sparse.homotopy: KAPPA_NOMINAL,
DISTANCE_NOMINAL, STEP_GROWTH_MAX, CORRECTOR_TOLERANCE, CORRECTOR_ESTIMATE) and the option
homotopy_initial_step; the instances are
chosen with the package's defaults.
The instances are those of families 1 and 2 (n = 10, 20, 50 with seeds 0-29, n = 100,
200 with seeds 0-9) and billups whose default solve runs the homotopy; every variant
solves each of them once.  Reported per variant: instances solved (natural residual
<= 1e-6), path steps, F and J evaluations (deterministic), and time.

    python3 benchmarks/homotopy_steps.py
    python3 benchmarks/homotopy_steps.py --sizes 10 20 --variants "0.3 0.2 2 0.1, estimate (default)"

Results: benchmarks/results/homotopy_steps.md (the printed table).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE.parent / "tests")]

import known_problems as kp  # noqa: E402

import compass_sparse.homotopy as hom  # noqa: E402
from compass_sparse import MCP, solve_mcp  # noqa: E402
from compass_sparse.generators import thesis_family  # noqa: E402

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

BASE = dict(KAPPA_NOMINAL=hom.KAPPA_NOMINAL, DISTANCE_NOMINAL=hom.DISTANCE_NOMINAL,
            STEP_GROWTH_MAX=hom.STEP_GROWTH_MAX, CORRECTOR_TOLERANCE=hom.CORRECTOR_TOLERANCE,
            CORRECTOR_ESTIMATE=hom.CORRECTOR_ESTIMATE)


def _variant(kappa, dist, growth=2.0, init=0.01, ctol=1e-4, estimate=False):
    return ({"KAPPA_NOMINAL": kappa, "DISTANCE_NOMINAL": dist, "STEP_GROWTH_MAX": growth,
             "CORRECTOR_TOLERANCE": ctol, "CORRECTOR_ESTIMATE": estimate},
            {"homotopy_initial_step": init})


VARIANTS = {  # (kappa nominal, distance nominal, growth cap, initial step)
    "0.2 0.1 2 0.01 (before round 10)": _variant(0.2, 0.1),
    "0.2 0.1 3 0.01": _variant(0.2, 0.1, growth=3.0),
    "0.2 0.1 4 0.01": _variant(0.2, 0.1, growth=4.0),
    "0.3 0.1 2 0.01": _variant(0.3, 0.1),
    "0.4 0.1 2 0.01": _variant(0.4, 0.1),
    "0.2 0.2 2 0.01": _variant(0.2, 0.2),
    "0.3 0.2 2 0.01": _variant(0.3, 0.2),
    "0.2 0.1 2 0.1": _variant(0.2, 0.1, init=0.1),
    "0.2 0.1 3 0.1": _variant(0.2, 0.1, growth=3.0, init=0.1),
    "0.3 0.2 2 0.1 (round 10)": _variant(0.3, 0.2, init=0.1),
    "0.3 0.2 3 0.1": _variant(0.3, 0.2, growth=3.0, init=0.1),
    "0.4 0.2 3 0.1": _variant(0.4, 0.2, growth=3.0, init=0.1),
    "0.3 0.2 2 0.1, corrector 3e-4": _variant(0.3, 0.2, init=0.1, ctol=3e-4),
    "0.3 0.2 2 0.1, corrector 1e-3": _variant(0.3, 0.2, init=0.1, ctol=1e-3),
    "0.3 0.2 2 0.1, estimate (default)": _variant(0.3, 0.2, init=0.1, estimate=True),
    "0.3 0.2 2 0.1, estimate, corrector 3e-5": _variant(0.3, 0.2, init=0.1, ctol=3e-5,
                                                        estimate=True),
    "0.3 0.2 3 0.1, estimate": _variant(0.3, 0.2, growth=3.0, init=0.1, estimate=True),
    "0.3 0.2 2 0.3, estimate": _variant(0.3, 0.2, init=0.3, estimate=True),
    "0.3 0.2 3 0.3, estimate": _variant(0.3, 0.2, growth=3.0, init=0.3, estimate=True),
    "0.4 0.2 2 0.1, estimate": _variant(0.4, 0.2, init=0.1, estimate=True),
    "0.3 0.3 2 0.1, estimate": _variant(0.3, 0.3, init=0.1, estimate=True),
}


def _instances(sizes, seeds_small=30, seeds_large=10):
    """(label, maker) of the thesis instances (``seeds_small`` seeds up to n = 50,
    ``seeds_large`` above) and billups."""
    for fam in (1, 2):
        for n in sizes:
            for seed in range(seeds_small if n <= 50 else seeds_large):
                yield (f"fam{fam} n{n} s{seed}",
                       lambda fam=fam, n=n, seed=seed: thesis_family(n, fam, seed).problem)
    p = kp.billups()
    yield "billups", lambda: MCP(p.F, p.J, p.lb, p.ub, p.x0)


def _solve(make, constants, options):
    for k, v in {**BASE, **constants}.items():
        setattr(hom, k, v)
    prob = make()
    t = time.perf_counter()
    r = solve_mcp(prob, options={"time_limit": 60.0, **options})
    dt = time.perf_counter() - t
    f = prob.F_uncounted(r.x)
    nat = float(np.max(np.abs(r.x - np.clip(r.x - f, prob.lb, prob.ub))))
    h = r.passes.get("homotopy")
    return dict(ok=nat <= 1e-6, time=dt, nfev=r.nfev, njev=r.njev,
                steps=h.iterations if h is not None and h.ran else 0,
                ran=bool(h is not None and h.ran))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50, 100, 200])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    a = ap.parse_args(argv)
    chosen = [(label, make) for label, make in _instances(a.sizes)
              if _solve(make, {}, {})["ran"]]
    print(f"{len(chosen)} instances run the homotopy by default\n")
    print("| variant | solved | path steps | F evaluations | J evaluations | time |")
    print("|---|---|---|---|---|---|")
    for name in a.variants:
        consts, opts = VARIANTS[name]
        rows = [_solve(make, consts, opts) for _, make in chosen]
        print(f"| {name} | {sum(r['ok'] for r in rows)}/{len(rows)} | "
              f"{sum(r['steps'] for r in rows)} | {sum(r['nfev'] for r in rows)} | "
              f"{sum(r['njev'] for r in rows)} | {sum(r['time'] for r in rows):.2f} s |",
              flush=True)
        failed = [label for (label, _), r in zip(chosen, rows) if not r["ok"]]
        if failed:
            print(f"|  | not solved: {', '.join(failed)} | | | | |")
    for k, v in BASE.items():
        setattr(hom, k, v)


if __name__ == "__main__":
    main()
