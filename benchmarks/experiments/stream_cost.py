"""What one pass over a triangular factor costs on this machine (an experiment; not part
of the suite): a unit lower triangle of n(n-1)/2 entries solved column by column, stored
dense (contiguous columns, as the sparse engine stores its dense tail) and through row
indices (int64 and int32), ns an entry, minimum of 20.

    python benchmarks/experiments/stream_cost.py
"""
import numpy as np, time
from numba import njit
@njit(cache=False)
def lsolve(vals, w, n):
    e = 0
    for j in range(n):
        x = w[j]
        m = n - 1 - j
        if x != 0.0:
            dst = w[j+1:j+1+m]; src = vals[e:e+m]
            for r in range(m):
                dst[r] -= src[r] * x
        e += m
    return e
@njit(cache=False)
def idxsolve(Li, Lx, Lp, w, n):
    for j in range(n):
        x = w[j]
        if x != 0.0:
            for p in range(Lp[j], Lp[j+1]):
                w[Li[p]] -= Lx[p] * x
for n in (300, 700, 1000, 1400):
    m = n*(n-1)//2
    vals = np.random.rand(m) * 1e-3
    w = np.random.rand(n)
    lsolve(vals, w.copy(), n)
    ts=[]
    for _ in range(20):
        ww = w.copy(); t=time.perf_counter(); lsolve(vals, ww, n); ts.append(time.perf_counter()-t)
    Lp = np.zeros(n+1, np.int64); Li = np.empty(m, np.int64)
    e=0
    for j in range(n):
        Lp[j]=e; Li[e:e+n-1-j]=np.arange(j+1,n); e+=n-1-j
    Lp[n]=e
    Li32 = Li.astype(np.int32)
    idxsolve(Li, vals, Lp, w.copy(), n); idxsolve(Li32, vals, Lp, w.copy(), n)
    t2=[];t3=[]
    for _ in range(20):
        ww=w.copy(); t=time.perf_counter(); idxsolve(Li, vals, Lp, ww, n); t2.append(time.perf_counter()-t)
        ww=w.copy(); t=time.perf_counter(); idxsolve(Li32, vals, Lp, ww, n); t3.append(time.perf_counter()-t)
    print(n, m, "dense ns/entry %.3f" % (min(ts)/m*1e9), "idx64 %.3f" % (min(t2)/m*1e9), "idx32 %.3f" % (min(t3)/m*1e9))
