"""Round 7's routes against the old ones, in ONE process (benchmarks/small.md, "Round 7").

The machine's speed drifts by 30-50% between minutes, more than these changes; two
processes timed one after the other see different minutes.  Here the old routes are
loaded beside the new ones and the two alternate batch by batch in the same process, so
that every drift falls on both:

* the crash's reduced solve: the old ``_solve_reduced`` (read from ``crash.py`` of the
  old revision's checkout: dense attempts one by one through LAPACK's Python wrappers,
  the structural test on a scipy copy, SuperLU for every sparse block) against the
  compiled dense attempts and KLU for small sparse blocks;
* the direct step's factorizations: SuperLU first and KLU after a first block of low fill
  (the old policy, emulated on the current class) against KLU first.

Everything else is the current code in both.  CPU time per solve, F and J included;
batches of ``solves`` solves, ``rounds`` batches per route, the order of the two routes
swapped every round.

    git worktree add /tmp/old b67fb73
    python3 benchmarks/ab_crash_lu_routes.py /tmp/old kojshin josephy ramsey40 --rounds 30
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import types
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent), str(HERE.parent / "tests")]


def _old_crash_module(root):
    """The old revision's crash.py as a module of the current package (its relative
    imports resolve to the current modules)."""
    path = Path(root) / "compass_sparse" / "crash.py"
    mod = types.ModuleType("compass_sparse._old_crash")
    mod.__package__, mod.__file__ = "compass_sparse", str(path)
    sys.modules[mod.__name__] = mod  # (dataclasses look their module up)
    exec(compile(path.read_text(), str(path), "exec"), mod.__dict__)
    return mod


def _cases(names):
    import bench_small as bs

    out = [(c.name, c.problem) for c in bs._known_cases() if c.name in names]
    for nm in names:
        if nm.startswith("ramsey"):
            out.append((nm, bs._cge_cases([int(nm[6:])], [])[0].problem))
        elif nm.startswith("static"):
            out.append((nm, bs._cge_cases([], [int(nm[6:])])[0].problem))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old_root", help="checkout of the old revision (its crash.py is read)")
    ap.add_argument("problems", nargs="+")
    ap.add_argument("--rounds", type=int, default=30)
    ap.add_argument("--solves", type=int, default=4)
    a = ap.parse_args()

    from compass_sparse import solve_mcp
    import compass_sparse.crash as crash
    import compass_sparse.direct_step as ds
    import compass_sparse.nms as nms

    old = _old_crash_module(a.old_root)

    class SuperLUFirst(ds.DirectFactors):
        """The old policy: SuperLU factors the first block; KLU the later ones when that
        LU held at most 4x the block's entries."""

        def __init__(self, klu=False, dense=False, rank_tolerance=1e-9):
            super().__init__(klu=False, dense=dense, rank_tolerance=rank_tolerance)
            self._probe = not dense and ds.klu_available()

        def solve(self, K, rhs):
            x = super().solve(K, rhs)
            if self._probe and self.method[0] == "superlu" and \
                    0 < self.lu_nnz <= 4.0 * max(K.nnz, 1):
                self.klu, self._probe = True, False
            return x

    routes = {"old": (old._solve_reduced, SuperLUFirst),
              "new": (crash._solve_reduced, nms.DirectFactors)}

    def use(name):
        crash._solve_reduced, nms.DirectFactors = routes[name]

    print("| problem | old routes | new routes | new / old | new faster |")
    print("|---|---|---|---|---|")
    for name, p in _cases(a.problems):
        for r in routes:  # warm-up: kernels loaded, first solves of the shape
            use(r)
            solve_mcp(p.with_start(p.x0))
        t = {"old": [], "new": []}
        for k in range(a.rounds):
            for r in (("old", "new") if k % 2 == 0 else ("new", "old")):
                use(r)
                batch = [p.with_start(p.x0) for _ in range(a.solves)]
                c0 = time.process_time()
                for q in batch:
                    solve_mcp(q)
                t[r].append((time.process_time() - c0) / a.solves)
        o, n = statistics.median(t["old"]), statistics.median(t["new"])
        wins = sum(y < x for x, y in zip(t["old"], t["new"]))
        print(f"| {name} | {o * 1e3:.3f} ms | {n * 1e3:.3f} ms | {n / o:.2f} | "
              f"{wins}/{a.rounds} |", flush=True)
    use("new")


if __name__ == "__main__":
    main()
