"""Status, major iterations, pivots, restarts and residual of a fixed set of problems, one
line each, for comparing two revisions of the solver (a change meant to save time should
leave these alone).

    python3 benchmarks/compare_trajectories.py . [--bits] > new.txt
    python3 benchmarks/compare_trajectories.py /path/to/worktree/of/old > old.txt
    diff old.txt new.txt

With ``--bits`` each line also holds the F and J counts and the md5 of the returned x: a
change meant to leave every point alone must leave these identical too (run both sides
with COMPASS_SPARSE_JIT=always, so that no kernel is interpreted).

The argument is the repository root whose ``compass_sparse`` (and ``tests``) are imported.
Problems: every start of the known-problem runs of the test suite, billups, double_root,
sqrt_ncp, and the COMPASS thesis families 1 and 2 at n = 10, 20, 50, seeds 1-7.
"""
import hashlib
import os
import sys

root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else ".")
sys.path.insert(0, root)
sys.path.insert(0, os.path.join(root, "tests"))

import known_problems as kp  # noqa: E402
from compass_sparse import solve_mcp  # noqa: E402
from compass_sparse.generators import thesis_family  # noqa: E402
from test_solve_mcp import KNOWN_RUNS  # noqa: E402

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

EXTRA = {"billups": kp.billups, "double_root": kp.degenerate_root, "sqrt_ncp": kp.sqrt_ncp}


BITS = "--bits" in sys.argv[2:]


def line(label, r):
    text = (f"{label:14s} {r.status.name:14s} nit {r.nit:3d} piv {r.minor_iterations:4d} "
            f"rst {r.restarts:2d} nat {r.residual.natural:.1e}")
    if BITS:
        text += f" nfev {r.nfev:4d} njev {r.njev:4d} x {hashlib.md5(r.x.tobytes()).hexdigest()}"
    return text


def main():
    for name, x0 in KNOWN_RUNS + [(k, None) for k in EXTRA]:
        p = (kp.ALL_SOLVABLE.get(name) or EXTRA[name])(x0)
        print(line(name, solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)))
    for fam in (1, 2):
        for n in (10, 20, 50):
            for seed in range(1, 8):
                g = thesis_family(n, fam, seed)
                print(line(f"fam{fam} n{n} s{seed}", solve_mcp(g.problem,
                                                               options={"time_limit": 60})))


if __name__ == "__main__":
    main()
