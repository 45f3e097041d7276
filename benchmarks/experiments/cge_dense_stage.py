"""Where a CGE pivot's time goes on the dense bases (an experiment; not part of the suite).

The endowment shock's long path on the compiled engine (``cge_endowment_engine`` of
bench_pivots.py) is captured at its start, replayed in chunks of 200 pivots (time a pivot,
the dense tail's columns, L, U and the row etas' entries, the block's stored zeros), then
stopped at pivot STOP and its parts timed on that state (minimum and median of repeats):
FTRAN of the entering column, U^{-T} e_p from several positions p (the update's solve), a
fresh factorization, and 20 pivots without one.

    python benchmarks/experiments/cge_dense_stage.py 2000
"""
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_path_kernels as B  # noqa: E402
import bench_pivots as bp  # noqa: E402
from compass_sparse import Options, solve_mcp  # noqa: E402

K, SL = B.K, B.SL
CHUNK = 200


def long_path():
    problem, o = bp.CASES["cge_endowment_engine"]()
    opts = Options(**o)
    solve_mcp(problem, options=opts)  # compiled kernels loaded
    calls = []
    start = K.start_path

    def rec(*a):
        calls.append(B._copy(a))
        return start(*a)

    B.E.K.start_path = rec
    try:
        solve_mcp(problem, options=opts)
    finally:
        B.E.K.start_path = start
    lens = [int(B.replay(c)[1][3][0][K.I_PIV]) for c in calls]
    print("pivots of the solve's paths:", lens)
    return calls[lens.index(max(lens))]


def chunks(call):
    a = B._copy(call)
    fk, prob, tab, state, D, S, tol, lim = a[:8]
    lim[K.L_CHUNK] = CHUNK
    code = K.start_path(*a)[1]
    last = time.perf_counter()
    while code == K.RUNNING:
        code = K.run_pivots(fk, prob, tab, state, D, S, tol, lim, a[-2], a[-1])[0]
        now = time.perf_counter()
        h, st = S[0], state[0]
        tail = int(h[SL.H_TAIL])
        print(f"pivot {st[K.I_PIV]:5d}  us a pivot {(now - last) / CHUNK * 1e6:7.1f}  tail {tail:4d}"
              f"  L {h[SL.H_NNZL]:7d}  U {h[SL.H_NNZU]:7d}  R {h[SL.H_NNZR]:6d}  block "
              f"{tail * (tail - 1):7d}  zeros {h[SL.H_ZL] + h[SL.H_ZU]:6d}  "
              f"factorizations {st[K.I_NFAC]}")
        last = now


def tm(f, reps=50):
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return f"{min(ts) * 1e6:.1f} / {np.median(ts) * 1e6:.1f} us"


def parts(call, stop):
    a = B._copy(call)
    fk, prob, tab, state, D, S, tol, lim = a[:8]
    lim[K.L_CHUNK] = stop
    K.start_path(*a)
    istate, h = state[0], S[0]
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    n = sk.shape[0]
    nupd = int(istate[K.I_NETA])
    tail = int(h[SL.H_TAIL])
    print(f"at pivot {istate[K.I_PIV]}: {nupd} updates, tail {tail}, L + U + R "
          f"{h[SL.H_NNZL] + h[SL.H_NNZU] + h[SL.H_NNZR]}")
    d = np.zeros(n)
    rate = np.zeros(n)
    ek, ei = int(istate[K.I_EK]), int(istate[K.I_EI])
    print("FTRAN of the entering column (min / median):",
          tm(lambda: SL.ftran_column(ek, ei, Mp, Mi, Mx, rI, rX, art_sign, S, nupd, d, rate,
                                     1.0)))
    y = S[21][1]
    N = n + nupd
    for p in (0, n - tail - 100, n - tail + 10, n - 50):
        def ut(p=p):
            y[:N] = 0.0
            y[p] = 1.0
            SL._utsolve(S, y, p, N)
        print(f"U^-T e_p from position {p}:", tm(ut))
    S2 = B._copy(S)
    print("a fresh factorization:", tm(lambda: K._factor(fk, prob, tab, D, S2, tol[K.T_RANK],
                                                         tol[K.T_THRESH], False), 5),
          f"(L + U {S2[0][SL.H_LAST]}, tail {S2[0][SL.H_TAIL]})")
    b = B._copy(a)
    lim2 = b[7]
    lim2[K.L_CHUNK] = 20
    nf0 = int(b[3][0][K.I_NFAC])
    t = time.perf_counter()
    K.run_pivots(*b[:8], b[-2], b[-1])
    el = time.perf_counter() - t
    print(f"20 pivots: {el / 20 * 1e6:.1f} us a pivot, "
          f"{int(b[3][0][K.I_NFAC]) - nf0} factorizations")


if __name__ == "__main__":
    c = long_path()
    chunks(c)
    parts(c, int(sys.argv[1]) if len(sys.argv) > 1 else 2000)
