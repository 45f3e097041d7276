"""Benchmark of the basis manager: Forrest-Tomlin update vs refactorization vs product form.

Usage:  python benchmarks/bench_basis.py [--sizes 1e4 1e5 1e6] [--pivots 150] [--repeats 3]

For each size n and pattern ("stencil": 2-D 5-point couplings with random coefficients on
a sqrt(n) grid plus a few long-range entries; "cge": diagonal blocks with a few dense rows
and columns), M is made diagonally dominant and the basis is a PATH-like mix: index j is
represented by M_j (half of the indices) or by the slack -e_j. A pivot swaps the two
representations of a random index (z_j enters for w_j or back), which keeps every basis
regular. Measured (wall clock, numba compiled beforehand):

* ft      : one pivot = ftran_column(entering) + replace(...) with Forrest-Tomlin updates
            (update_limit 50, so the median is an update and the mean includes the
            refactorization every 50 pivots);
* fresh   : one fresh factorization + one solve (refactor() + ftran());
* refac   : the baseline "refactorize every pivot" (update_limit=0): one pivot;
* pfi     : the baseline product-form (eta-only) update: B_k^{-1} = E_k^{-1}...E_1^{-1}B_0^{-1},
            one pivot = FTRAN through the fresh LU and all eta columns + storing the eta;
* memory  : nnz(L) + nnz(U) + nnz(etas) just before the 50th update (FT) and the
            nnz of the LU plus the stored eta columns (PFI) at the same point.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import scipy.sparse as sp

from compass_sparse.basis import KIND_M, KIND_UNIT, BasisManager, BasisOptions


# ------------------------------------------------------------------ generators
def dominate(A, rng):
    A = sp.csc_matrix(A)
    A.setdiag(0.0)
    A.eliminate_zeros()
    rs = np.asarray(abs(A).sum(axis=1)).ravel()
    cs = np.asarray(abs(A).sum(axis=0)).ravel()
    n = A.shape[0]
    return sp.csc_matrix(A + sp.diags((rs + cs + 1.0) * rng.choice([-1.0, 1.0], n)))


def stencil_matrix(n, rng):
    g = int(round(np.sqrt(n)))
    n = g * g
    idx = np.arange(n).reshape(g, g)
    rows, cols = [], []
    for a, b in ((idx[:, :-1], idx[:, 1:]), (idx[:-1, :], idx[1:, :])):
        rows += [a.ravel(), b.ravel()]
        cols += [b.ravel(), a.ravel()]
    nl = max(n // 200, 5)                              # a few long-range entries
    rows.append(rng.integers(0, n, nl))
    cols.append(rng.integers(0, n, nl))
    i = np.concatenate(rows)
    j = np.concatenate(cols)
    A = sp.csc_matrix((rng.uniform(-1, 1, i.size), (i, j)), shape=(n, n))
    return dominate(A, rng)


def cge_matrix(n, rng, block=100, per_col=4, dense_rows=4, dense_cols=4):
    nb = n // block
    n = nb * block
    # block-diagonal sparse sectors, then a few dense rows (price/income equations) and
    # dense columns (e.g. an exchange rate / numeraire) coupling everything
    b = np.repeat(np.arange(nb), block * per_col)
    i = b * block + rng.integers(0, block, b.size)
    j = np.repeat(np.arange(n), per_col)
    cross = rng.integers(0, n, n // 10)                    # light inter-block trade
    i = np.concatenate((i, cross))
    j = np.concatenate((j, rng.integers(0, n, cross.size)))
    dr = rng.choice(n, dense_rows, replace=False)
    dc = rng.choice(n, dense_cols, replace=False)
    i = np.concatenate((i, np.repeat(dr, n), np.tile(np.arange(n), dense_cols)))
    j = np.concatenate((j, np.tile(np.arange(n), dense_rows), np.repeat(dc, n)))
    A = sp.csc_matrix((rng.uniform(-1, 1, i.size), (i, j)), shape=(n, n))
    return dominate(A, rng)


# ------------------------------------------------------------------ baselines
class ProductForm:
    """Eta-only (product-form) update over a fresh factorization of the manager."""

    def __init__(self, bm):
        self.bm = bm
        self.etas = []          # (slot, pivot, idx, val)
        self.nnz = 0

    def ftran(self, kind, index, sign):
        x = self.bm.ftran_column(kind, index, sign)
        for (p, piv, ii, vv) in self.etas:
            xp = x[p] / piv
            if xp != 0.0:
                x[ii] -= vv * xp
            x[p] = xp
        return x

    def replace(self, slot, d):
        nz = np.flatnonzero(d)
        nz = nz[nz != slot]
        self.etas.append((slot, d[slot], nz, d[nz].copy()))
        self.nnz += nz.size + 1


def pivot_sequence(n, rng, S, count):
    """Indices j to swap (M_j <-> -e_j)."""
    return rng.integers(0, n, count)


def entering(bm, j):
    s = bm.slot_of_m(j)
    if s >= 0:
        return s, (KIND_UNIT, j, -1.0)
    return bm.slot_of_unit(j), (KIND_M, j, 1.0)


def start_table(n, rng):
    useM = rng.random(n) < 0.5
    kinds = np.where(useM, KIND_M, KIND_UNIT)
    signs = np.where(useM, 1.0, -1.0)
    return kinds, np.arange(n), signs


def bench_one(name, M, pivots, repeats, seed):
    n = M.shape[0]
    rng = np.random.default_rng(seed)
    kinds, idx, signs = start_table(n, rng)
    rhs = rng.standard_normal(n)
    out = {"pattern": name, "n": n, "nnz_M": M.nnz}

    # fresh factorization + solve
    bm = BasisManager(M, BasisOptions(update_limit=50, residual_check_frequency=0))
    t = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        bm.factor(kinds, idx, signs)
        bm.ftran(rhs)
        t.append(time.perf_counter() - t0)
    out["fresh"] = float(np.median(t))
    out["nnz_LU0"] = bm.stats.nnz_L + bm.stats.nnz_U

    # Forrest-Tomlin pivots
    seq = pivot_sequence(n, rng, None, pivots)
    tp, mem = [], 0
    for j in seq:
        s, col = entering(bm, int(j))
        t0 = time.perf_counter()
        bm.ftran_column(*col)
        st = bm.replace(s, *col)
        tp.append(time.perf_counter() - t0)
        if bm.num_updates == 49:
            mem = bm.stats.nnz_L + bm.stats.nnz_U + bm.stats.nnz_eta
        del st
    out["ft_median"] = float(np.median(tp))
    out["ft_mean"] = float(np.mean(tp))
    out["ft_mem"] = mem
    x = bm.ftran(rhs)
    out["ft_backward_error"] = bm.backward_error(x, rhs)

    # baseline: refactorize every pivot
    bm0 = BasisManager(M, BasisOptions(update_limit=0, residual_check_frequency=0))
    bm0.factor(kinds, idx, signs)
    t = []
    for j in seq[:repeats]:
        s, col = entering(bm0, int(j))
        t0 = time.perf_counter()
        bm0.ftran_column(*col)
        bm0.replace(s, *col)
        t.append(time.perf_counter() - t0)
    out["refac"] = float(np.median(t))

    # baseline: product form over a fresh LU, refactor every 50 pivots
    bmp = BasisManager(M, BasisOptions(residual_check_frequency=0))
    bmp.factor(kinds, idx, signs)
    pf = ProductForm(bmp)
    kin = bmp.kinds.copy()
    ind = bmp.indices.copy()
    sig = bmp.signs.copy()
    slot_of = {}
    t, memp = [], 0
    for j in seq:
        j = int(j)
        # the slot table is kept here (the manager's one stays at the last factor)
        s = slot_of.get(j)
        if s is None:
            s = bmp.slot_of_m(j) if bmp.slot_of_m(j) >= 0 else bmp.slot_of_unit(j)
        col = (KIND_UNIT, j, -1.0) if kin[s] == KIND_M else (KIND_M, j, 1.0)
        t0 = time.perf_counter()
        if len(pf.etas) >= 50:
            bmp.factor(kin, ind, sig)
            pf = ProductForm(bmp)
        d = pf.ftran(*col)
        pf.replace(s, d)
        t.append(time.perf_counter() - t0)
        kin[s], ind[s], sig[s] = col
        slot_of[j] = s
        if len(pf.etas) == 49:
            memp = bmp.stats.nnz_L + bmp.stats.nnz_U + pf.nnz
    out["pfi_median"] = float(np.median(t))
    out["pfi_mean"] = float(np.mean(t))
    out["pfi_mem"] = memp
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--patterns", nargs="+", default=["stencil", "cge"])
    ap.add_argument("--pivots", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    BasisManager(sp.eye(4, format="csc"))      # compile / load the numba kernels
    hdr = (f"{'pattern':8s} {'n':>8s} {'nnz(M)':>9s} {'fresh[s]':>9s} {'FT med[ms]':>10s} "
           f"{'FT mean':>8s} {'ratio':>6s} {'refac[s]':>9s} {'PFI med':>8s} {'PFI mean':>8s} "
           f"{'nnzLU0':>9s} {'mem FT':>9s} {'mem PFI':>9s} {'bwd err':>8s}")
    print(hdr)
    print("-" * len(hdr))
    rows = []
    for pat in args.patterns:
        for nf in args.sizes:
            n = int(nf)
            rng = np.random.default_rng(args.seed)
            t0 = time.perf_counter()
            M = stencil_matrix(n, rng) if pat == "stencil" else cge_matrix(n, rng)
            tgen = time.perf_counter() - t0
            r = bench_one(pat, M, args.pivots, args.repeats, args.seed)
            rows.append(r)
            print(f"{pat:8s} {r['n']:8d} {r['nnz_M']:9d} {r['fresh']:9.3f} "
                  f"{1e3 * r['ft_median']:10.3f} {1e3 * r['ft_mean']:8.2f} "
                  f"{r['fresh'] / r['ft_median']:6.0f} {r['refac']:9.3f} "
                  f"{1e3 * r['pfi_median']:8.2f} {1e3 * r['pfi_mean']:8.2f} "
                  f"{r['nnz_LU0']:9d} {r['ft_mem']:9d} {r['pfi_mem']:9d} "
                  f"{r['ft_backward_error']:8.1e}", flush=True)
            del M, tgen
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() is not None else 1)
