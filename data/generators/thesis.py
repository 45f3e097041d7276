"""The random quadratic families of the COMPASS thesis, §4.3 (Tables 4.1 and 4.3).

F(z) = D z^2 + A z + b, D diagonal (applied elementwise to z^2), A dense n x n, all
entries uniform.  The boxes are bounded, so a solution always exists (F is continuous on a
compact box); it is not known in closed form.  PATH often fails on these (13 % success at
n = 200, 0 % at n = 500), so every failure is the algorithm's.

===========  ===================  ======================
setting      family 1 (Tab. 4.1)  family 2 (Tab. 4.3)
===========  ===================  ======================
D_ii         U[-1, 1]             U[-2, 2]
A_ij         U[-1, 1]             U[-5, 5]
b_i          U[-1, 1]             U[-7, 7]
x0_i         U[-1, 2]             U[-10, 20]
l_i          U[-1, 1]             U[-10, 10]
u_i          U[l_i, l_i + 1]      U[l_i, l_i + 10]
===========  ===================  ======================
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from compass_sparse.problem import MCP

__all__ = ["thesis_family", "THESIS_SETTINGS"]

THESIS_SETTINGS = {
    1: dict(D=1.0, A=1.0, b=1.0, x0=(-1.0, 2.0), l=(-1.0, 1.0), width=1.0),
    2: dict(D=2.0, A=5.0, b=7.0, x0=(-10.0, 20.0), l=(-10.0, 10.0), width=10.0),
}


def thesis_family(n: int, family: int = 1, seed=0):
    """One instance of the thesis' family 1 or 2 of dimension n.

    The Jacobian diag(2 D z) + A is returned as a CSC matrix with the full n x n pattern
    (built from fixed index arrays, so an entry of A that happens to be 0 stays stored).
    ``info`` holds the raw data D, A (dense), b, lb, ub, x0 so that another solver can
    rebuild the instance, plus the family's settings.  ``solution`` is None.
    """
    from . import GeneratedProblem
    from .sparse import QuadraticF

    if family not in THESIS_SETTINGS:
        raise ValueError("family must be 1 (thesis Table 4.1) or 2 (Table 4.3)")
    n = int(n)
    s = THESIS_SETTINGS[family]
    rng = np.random.default_rng(seed)
    D = rng.uniform(-s["D"], s["D"], n)
    A = rng.uniform(-s["A"], s["A"], (n, n))
    b = rng.uniform(-s["b"], s["b"], n)
    x0 = rng.uniform(*s["x0"], n)
    lb = rng.uniform(*s["l"], n)
    ub = lb + rng.uniform(0.0, s["width"], n)

    # full pattern in CSC order: column j holds rows 0..n-1
    indptr = np.arange(0, n * n + 1, n, dtype=np.int64)
    indices = np.tile(np.arange(n, dtype=np.int64), n)
    Acsc = sp.csc_matrix((A.ravel(order="F"), indices, indptr), shape=(n, n))
    qf = QuadraticF(D, Acsc, b)
    problem = MCP(qf.F, qf.jac, lb, ub, x0, constant_jac=qf.constant_pattern())
    info = dict(family=family, seed=seed, settings=dict(s), D=D, A=A, b=b, lb=lb, ub=ub, x0=x0)
    return GeneratedProblem(
        name=f"thesis{family}(n={n}, seed={seed})", problem=problem, solution=None, info=info
    )
