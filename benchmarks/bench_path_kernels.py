"""The sparse engine's path kernels of one solve, replayed: each pivotal path of a solve of
the traffic model is captured at its start (the compiled engine's ``start_path`` call) and
run again on copies of its arguments, timed; then its first factorization alone, and the
factorization of the basis each path ends on (its order reused, and fresh).  Timings are
the minimum over ``--repeats`` replays (compiled kernels, after a solve that loads them).

    python benchmarks/bench_path_kernels.py --k 24          # traffic n = 2452
    python benchmarks/bench_path_kernels.py --k 8           # traffic n = 912

Per path: pivots, factorizations, the whole path (ms), its first factorization (ms), and
the factorization of its last basis reused / fresh (ms) with the entries of L + U and the
columns of the dense tail.  The totals give the path kernels of the solve and the loop's
time per pivot (the paths less their first factorizations).
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("COMPASS_SPARSE_JIT", "always")

import numpy as np  # noqa: E402

from compass_sparse import solve_mcp  # noqa: E402
from compass_sparse.generators import traffic_equilibrium  # noqa: E402
from compass_sparse.path import _path_kernels as K  # noqa: E402
from compass_sparse.path import _sparse_lu as SL  # noqa: E402
from compass_sparse.path import engine as E  # noqa: E402
from _revision import git_revision  # noqa: E402


def _copy(x):
    """A deep copy of the kernels' arguments that keeps each array's memory layout (a
    Fortran-ordered array copied to C order is another type to the compiled kernels: the
    first replay compiled start_path again, inside its timing)."""
    if isinstance(x, np.ndarray):
        return x.copy(order="K")
    if isinstance(x, tuple):
        return tuple(_copy(y) for y in x)
    return x


def capture(problem):
    """The arguments of every start_path call of one solve (copies)."""
    calls = []
    start = K.start_path

    def recording(*args):
        calls.append(_copy(args))
        return start(*args)

    E.K.start_path = recording
    try:
        solve_mcp(problem)
    finally:
        E.K.start_path = start
    return calls


def replay(args, chunk=None):
    """Run a captured path again (``chunk`` 0: its first factorization only); returns
    (seconds, the path's arguments after it)."""
    a = _copy(args)
    fk, prob, tab, state, D, S, tol, lim = a[:8]
    if chunk is not None:
        lim[K.L_CHUNK] = chunk
    t = time.perf_counter()
    factored, code, msg = K.start_path(*a)
    while code == K.RUNNING and chunk is None:
        code, msg = K.run_pivots(fk, prob, tab, state, D, S, tol, lim, a[-2], a[-1])
    return time.perf_counter() - t, a


def _factor_time(a, fresh, repeats):
    fk, prob, tab, state, D, S, tol = a[:7]
    h = S[0]
    best = np.inf
    for _ in range(repeats):
        if fresh:
            h[SL.H_FRESH] = 0
        t = time.perf_counter()
        K._factor(fk, prob, tab, D, S, tol[K.T_RANK], tol[K.T_THRESH], False)
        best = min(best, time.perf_counter() - t)
    return best, int(h[SL.H_LAST]), int(h[SL.H_TAIL])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--k", type=int, default=24, help="destinations of the traffic model")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    problem = traffic_equilibrium(args.k).problem
    solve_mcp(problem)  # loads the kernels
    calls = capture(problem)
    print(f"# traffic_equilibrium({args.k}), n = {problem.n}; revision {git_revision()}")
    print("pivots  fact   path ms  first ms  last basis: reused ms  fresh ms   L+U  tail")
    total = first = 0.0
    pivots = 0
    for call in calls:
        t_path = min(replay(call)[0] for _ in range(args.repeats))
        t_first = min(replay(call, 0)[0] for _ in range(args.repeats))
        _, end = replay(call)
        istate = end[3][0]
        t_fresh, _, _ = _factor_time(end, True, args.repeats)
        t_reuse, nnz, tail = _factor_time(end, False, args.repeats)
        p = int(istate[K.I_PIV])
        print(f"{p:6d} {int(istate[K.I_NFAC]):5d} {t_path * 1e3:9.2f} {t_first * 1e3:9.2f} "
              f"{t_reuse * 1e3:21.2f} {t_fresh * 1e3:9.2f} {nnz:6d} {tail:5d}")
        total += t_path
        first += t_first
        pivots += p
    print(f"# {len(calls)} paths, {pivots} pivots: path kernels {total * 1e3:.1f} ms, first "
          f"factorizations {first * 1e3:.1f} ms, the loop "
          f"{(total - first) / max(pivots, 1) * 1e6:.1f} us a pivot")


if __name__ == "__main__":
    main()
