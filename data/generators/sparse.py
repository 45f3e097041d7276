"""Sparse quadratic MCPs F(z) = D z^2 + A z + b (the thesis' family made sparse).

* :func:`sparse_quadratic` -- A with k entries per row in a random pattern.

  Warning: random sparsity patterns fill in catastrophically under sparse LU.  At
  n = 1e4 with 5 entries per row, SuperLU's L + U held 2.5e7 nonzeros (a dense-like
  factor), so this family is for small and medium n and for stress tests; use
  :func:`structured_quadratic` for large n.

* :func:`structured_quadratic` -- A on a 2-D 5-point grid stencil or a band, plus a few
  long-range entries, controllable diagonal dominance, mixed bound types and a
  manufactured known solution.  Builds n = 1e6 in seconds (everything is vectorized).

* :class:`BandedNonlinear`, :func:`tridiagonal_ncp` -- F(z) = A z + a sin(z) + 0.1 z^3 (- b)
  with A tridiagonal and diagonally dominant (a discretized 1-D obstacle problem with a
  nonlinear term): the suite's manufactured nonlinear cases and the time-limit benchmark.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from compass_sparse.problem import MCP

from .manufactured import manufacture, manufactured_point

__all__ = ["BandedNonlinear", "QuadraticF", "sparse_quadratic", "structured_quadratic",
           "draw_bounds", "tridiagonal_ncp"]


class QuadraticF:
    """F(z) = D * z**2 + A @ z + b with A sparse.

    A is stored in canonical CSC form with every diagonal entry present (explicit zeros
    kept), so J(z) = A + diag(2 D z) always has the same pattern: :meth:`jac` only changes
    the data array at the precomputed diagonal positions.
    """

    def __init__(self, D, A, b):
        A = sp.csc_matrix(A, dtype=float)
        n = A.shape[0]
        if A.shape != (n, n):
            raise ValueError("A must be square")
        A.sum_duplicates()
        A.sort_indices()
        col = np.repeat(np.arange(n), np.diff(A.indptr))
        diag = np.flatnonzero(A.indices == col)
        if diag.size != n:  # add the missing diagonal entries as explicit zeros
            coo = A.tocoo()
            rows = np.concatenate([coo.row, np.arange(n)])
            cols = np.concatenate([coo.col, np.arange(n)])
            data = np.concatenate([coo.data, np.zeros(n)])
            A = sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsc()
            A.sum_duplicates()
            A.sort_indices()
            col = np.repeat(np.arange(n), np.diff(A.indptr))
            diag = np.flatnonzero(A.indices == col)
        self.n = n
        self.A = A
        self.D = np.asarray(D, dtype=float).reshape(n)
        self.b = np.asarray(b, dtype=float).reshape(n)
        self.diagpos = diag

    def F(self, z):
        return self.D * z * z + self.A @ z + self.b

    def jac(self, z):
        data = self.A.data.copy()
        data[self.diagpos] += 2.0 * self.D * z
        return sp.csc_matrix((data, self.A.indices, self.A.indptr), shape=(self.n, self.n))

    def constant_pattern(self) -> sp.csc_matrix:
        """Entries of J that do not depend on z: all off-diagonal ones, and the diagonal
        ones where D_ii = 0 (structure only, data = 1)."""
        mask = np.ones(self.A.nnz, dtype=bool)
        mask[self.diagpos[self.D != 0]] = False
        col = np.repeat(np.arange(self.n), np.diff(self.A.indptr))
        return sp.csc_matrix(
            (np.ones(int(mask.sum())), (self.A.indices[mask], col[mask])), shape=(self.n, self.n)
        )


def draw_bounds(n, rng, bound_mix=(0.25, 0.25, 0.25, 0.25), low=(-1.0, 1.0), width=(0.0, 1.0)):
    """Bounds with a mix of (free, lower only, upper only, boxed) variables.

    Finite lower bounds are U[low]; an upper-only bound is U[low] too; a boxed variable
    has u = l + U[width].  Returns (lb, ub, kind) with kind 0..3 in the order of bound_mix.
    """
    p = np.asarray(bound_mix, dtype=float)
    if p.shape != (4,) or np.any(p < 0) or p.sum() <= 0:
        raise ValueError("bound_mix must be four non-negative fractions "
                         "(free, lower, upper, boxed)")
    p = np.cumsum(p / p.sum())
    kind = np.searchsorted(p, rng.random(n), side="right").clip(0, 3)
    lo = rng.uniform(low[0], low[1], n)
    wd = rng.uniform(width[0], width[1], n)
    lb = np.where((kind == 1) | (kind == 3), lo, -np.inf)
    ub = np.where(kind == 2, lo, np.where(kind == 3, lo + wd, np.inf))
    return lb, ub, kind


def _random_pattern(n, k, rng):
    """Row i gets the diagonal plus k - 1 distinct random off-diagonal columns."""
    k = max(1, min(int(k), n))
    rows = np.arange(n)
    if k == 1:
        return rows, rows.copy()
    # k-1 distinct offsets in [1, n-1]: sorted draws from [1, n-k+1] plus 0, 1, 2, ...
    offs = np.sort(rng.integers(1, n - k + 2, size=(n, k - 1)), axis=1) + np.arange(k - 1)
    cols = (rows[:, None] + offs) % n
    r = np.concatenate([rows, np.repeat(rows, k - 1)])
    c = np.concatenate([rows, cols.ravel()])
    return r, c


def sparse_quadratic(
    n: int,
    k: int = 5,
    seed=0,
    *,
    diag_shift: float = 0.0,
    bound_mix=(0.25, 0.25, 0.25, 0.25),
    manufactured: bool = False,
    active_fraction: float = 0.5,
):
    """F = D z^2 + A z + b with k stored entries per row of A in a random pattern.

    Entries of D, A, b ~ U[-1, 1] (thesis family 1), plus ``diag_shift`` on A's diagonal
    (a large shift makes the problem strongly monotone near 0).  Bounds follow
    ``bound_mix`` (free, lower only, upper only, boxed) with l ~ U[-1, 1] and boxes of
    width U[0, 1]; x0 ~ U[-1, 2].  Without bounds on every variable a solution need not
    exist; ``manufactured=True`` shifts F so that a drawn point is a known solution.

    WARNING: random patterns fill in catastrophically under sparse LU (n = 1e4 with 5 per
    row gave 2.5e7 nonzeros in L + U).  Use :func:`structured_quadratic` for large n.
    """
    from . import GeneratedProblem

    n = int(n)
    rng = np.random.default_rng(seed)
    r, c = _random_pattern(n, k, rng)
    vals = rng.uniform(-1.0, 1.0, r.size)
    vals[:n] += diag_shift  # the first n entries are the diagonal
    A = sp.coo_matrix((vals, (r, c)), shape=(n, n)).tocsc()
    D = rng.uniform(-1.0, 1.0, n)
    b = rng.uniform(-1.0, 1.0, n)
    lb, ub, kind = draw_bounds(n, rng, bound_mix)
    x0 = rng.uniform(-1.0, 2.0, n)
    qf = QuadraticF(D, A, b)
    info = dict(n=n, k=k, seed=seed, diag_shift=diag_shift, bound_mix=tuple(bound_mix),
                bound_kind=kind, D=D, A=qf.A, b=b, lb=lb, ub=ub, x0=x0)
    name = f"sparse_quadratic(n={n}, k={k}, seed={seed})"
    if manufactured:
        return manufacture(qf.F, qf.jac, None, lb, ub, rng, active_fraction=active_fraction,
                           x0=x0, name=name, info=info, constant_jac=qf.constant_pattern())
    problem = MCP(qf.F, qf.jac, lb, ub, x0, constant_jac=qf.constant_pattern())
    return GeneratedProblem(name=name, problem=problem, solution=None, info=info)


def _grid_pairs(n):
    """Directed neighbour pairs of the first n nodes of an m x m grid, m = ceil(sqrt n)."""
    m = int(np.ceil(np.sqrt(n)))
    i = np.arange(n)
    right = i[((i % m) < m - 1) & (i + 1 < n)]
    down = i[i + m < n]
    a = np.concatenate([right, down])
    b = np.concatenate([right + 1, down + m])
    return np.concatenate([a, b]), np.concatenate([b, a]), m


def _band_pairs(n, bandwidth):
    rs, cs = [], []
    for off in range(1, int(bandwidth) + 1):  # loop over the band, not over n
        i = np.arange(n - off)
        rs += [i, i + off]
        cs += [i + off, i]
    if not rs:
        return np.array([], dtype=int), np.array([], dtype=int)
    return np.concatenate(rs), np.concatenate(cs)


def structured_quadratic(
    n: int,
    seed=0,
    *,
    structure: str = "grid",
    bandwidth: int = 2,
    n_long_range: int = 8,
    dominance: float = 1.5,
    diag_floor: float = 0.1,
    quad_scale: float = 0.1,
    bound_mix=(0.1, 0.4, 0.1, 0.4),
    active_fraction: float = 0.5,
    degenerate_fraction: float = 0.0,
):
    """F~ = D z^2 + A z + b shifted to have a manufactured solution z*; scales to n = 1e6.

    structure : 'grid' -- A couples each node of a ceil(sqrt n)-wide 2-D grid with its
        4 neighbours (5-point stencil); 'banded' -- couplings within ``bandwidth`` of the
        diagonal.  Off-diagonal coefficients ~ U[-1, 1] (non-symmetric), plus
        ``n_long_range`` random long-range entries (border-like structure).
    dominance : A_ii = dominance * sum_j |A_ij| + diag_floor; >= 1 gives a strictly
        diagonally dominant (P-matrix) linear part, < 1 a harder indefinite one.
    quad_scale : D ~ U[-quad_scale, quad_scale] (the nonlinearity).
    bound_mix : fractions (free, lower only, upper only, boxed); l ~ U[-1, 1], boxes of
        width U[0.5, 2].
    active_fraction, degenerate_fraction : of z* (see :func:`manufactured_point`).

    The solution is known (``solution``); x0 is the projection of 0.
    """
    n = int(n)
    rng = np.random.default_rng(seed)
    if structure == "grid":
        r, c, m = _grid_pairs(n)
    elif structure == "banded":
        r, c = _band_pairs(n, bandwidth)
        m = None
    else:
        raise ValueError("structure must be 'grid' or 'banded'")
    if n_long_range > 0 and n > 1:
        lr = rng.integers(0, n, size=n_long_range)
        lc = (lr + rng.integers(1, n, size=n_long_range)) % n  # never on the diagonal
        r = np.concatenate([r, lr])
        c = np.concatenate([c, lc])
    off = rng.uniform(-1.0, 1.0, r.size)
    rowabs = np.bincount(r, weights=np.abs(off), minlength=n)
    diag = dominance * rowabs + diag_floor
    rows = np.concatenate([np.arange(n), r])
    cols = np.concatenate([np.arange(n), c])
    A = sp.coo_matrix((np.concatenate([diag, off]), (rows, cols)), shape=(n, n)).tocsc()
    D = rng.uniform(-quad_scale, quad_scale, n)
    b = rng.uniform(-1.0, 1.0, n)
    lb, ub, kind = draw_bounds(n, rng, bound_mix, low=(-1.0, 1.0), width=(0.5, 2.0))
    qf = QuadraticF(D, A, b)
    a = float(active_fraction)
    pt = manufactured_point(lb, ub, rng, mix=(1.0 - a, a / 2, a / 2),
                            degenerate_fraction=degenerate_fraction)
    x0 = np.clip(np.zeros(n), lb, ub)
    info = dict(n=n, seed=seed, structure=structure, grid_width=m, bandwidth=bandwidth,
                n_long_range=n_long_range, dominance=dominance, quad_scale=quad_scale,
                bound_kind=kind, D=D, A=qf.A, b=b)
    name = f"structured_quadratic({structure}, n={n}, seed={seed})"
    return manufacture(qf.F, qf.jac, pt.z, lb, ub, rng, w_star=pt.w, v_star=pt.v, x0=x0,
                       name=name, info=info, constant_jac=qf.constant_pattern())


class BandedNonlinear:
    """F(z) = A z + a sin(z) + 0.1 z^3 with A tridiagonal and diagonally dominant (diagonal
    3 + U(0, 1), off-diagonals U(-1, 1)) and a ~ U(0.1, 0.5), drawn in that order from
    ``default_rng(seed)``; J in CSC with a fixed pattern (only the diagonal's data
    change).  Strongly monotone on z >= 0."""

    def __init__(self, n, seed):
        self.rng = np.random.default_rng(seed)
        i = np.arange(n)
        rows = np.concatenate([i, i[:-1], i[1:]])
        cols = np.concatenate([i, i[1:], i[:-1]])
        vals = np.concatenate([3.0 + self.rng.uniform(0, 1, n),
                               self.rng.uniform(-1, 1, 2 * (n - 1))])
        A = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
        A.sort_indices()
        self.A = A
        self.n = n
        self.dpos = np.flatnonzero(A.indices == np.repeat(i, np.diff(A.indptr)))
        self.a = self.rng.uniform(0.1, 0.5, n)

    def F(self, z):
        return self.A @ z + self.a * np.sin(z) + 0.1 * z**3

    def J(self, z):
        d = self.A.data.copy()
        d[self.dpos] += self.a * np.cos(z) + 0.3 * z**2
        return sp.csc_matrix((d, self.A.indices, self.A.indptr), shape=(self.n, self.n))

    def FJ(self, z):
        return self.F(z), self.J(z)


def tridiagonal_ncp(n, seed=0):
    """(F, J, lb, ub, x0) of the NCP F(z) - b on z >= 0, F of :class:`BandedNonlinear` and b ~
    U(-1, 1) drawn after it from the same stream; x0 = 2."""
    base = BandedNonlinear(n, seed)
    b = base.rng.uniform(-1.0, 1.0, n)

    def F(z):
        return base.F(z) - b

    return F, base.J, np.zeros(n), np.full(n, np.inf), np.full(n, 2.0)
