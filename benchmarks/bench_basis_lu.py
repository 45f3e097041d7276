"""LU backends and orderings of the basis manager on CGE Jacobian blocks: where they cross.

For each model and size, the free block of the Jacobian at the shocked start is factored by
every backend/ordering of :mod:`compass_sparse.basis.backends` through ``backend.factor``
(the call the basis manager makes, factors extracted):

* ``first``: a fresh backend (ordering / symbolic analysis computed),
* ``again``: the same pattern with new values (ordering or symbolic analysis reused),

medians over ``--repeats`` runs, seconds, with nnz(L + U) and the estimate of the ordering.

    python benchmarks/bench_basis_lu.py --sizes 300 1000 3000 10000 --families static dynamic
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine_info, print_machine  # noqa: E402

CONFIGS = {
    "superlu:colamd": dict(name="superlu", ordering="colamd"),
    "superlu:amd": dict(name="superlu", ordering="amd"),
    "superlu:metis": dict(name="superlu", ordering="metis"),
    "superlu:auto": dict(name="superlu", ordering="auto"),
    "umfpack": dict(name="umfpack", ordering="auto"),
}


def jacobian_block(family, n):
    from compass_sparse.generators import cge

    if family == "static":
        m = cge.static_cge(**cge.size_for(n)).with_shock(tariff=(0, 0.25))
    else:
        m = cge.ramsey_cge(**cge.ramsey_size_for(n)).with_shock(capital_tax=0.25)
    J = m.J(m.benchmark).tocsc()
    free = np.flatnonzero(m.lb < m.ub)
    return sp.csc_matrix(J[free][:, free])


def measure(K, cfg, repeats):
    from compass_sparse.basis.backends import make_backend

    first, again, rec = [], [], {}
    K2 = K.copy()
    K2.data = K2.data * np.random.default_rng(0).uniform(0.9, 1.1, K2.nnz)
    for _ in range(repeats):
        b = make_backend(**cfg)
        t = time.perf_counter()
        f = b.factor(K)
        first.append(time.perf_counter() - t)
        t = time.perf_counter()
        b.factor(K2)
        again.append(time.perf_counter() - t)
        rec = dict(ordering=b.last.ordering, nnz_lu=int(f.L.nnz + f.U.nnz),
                   est_nnz_lu=b.last.est_nnz_lu)
    rec.update(first=float(np.median(first)), again=float(np.median(again)))
    return rec


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[300, 1000, 3000, 10000])
    ap.add_argument("--families", nargs="+", default=["static", "dynamic"])
    ap.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    print_machine(machine_info())
    from compass_sparse.basis.ordering import compute_ordering
    compute_ordering(sp.csc_matrix(sp.eye(50) + sp.eye(50, k=1)), "amd")   # compile
    for fam in args.families:
        for n in args.sizes:
            K = jacobian_block(fam, int(n))
            for name in args.configs:
                rec = dict(family=fam, n=K.shape[0], nnz=int(K.nnz), config=name)
                rec.update(measure(K, CONFIGS[name], args.repeats))
                print(json.dumps(rec), flush=True)


if __name__ == "__main__":
    main()
