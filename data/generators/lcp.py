"""Sparse linear complementarity problems F(z) = M z + q with manufactured solutions.

Manufactured solutions: pick z* in the box and multipliers w* >= 0 (nonzero only where
z*_i = l_i), v* >= 0 (nonzero only where z*_i = u_i), and set q = w* - v* - M z*.  Then
F(z*) = w* - v*, so z* solves the LCP.

Exactness: matrix entries, bounds, z*, w*, v* are rounded to multiples of powers of two
(``MAT_QUANTUM`` = 2^-10 for M, ``VEC_QUANTUM`` = 2^-20 for vectors) with small magnitudes,
so every product and partial sum in M z* + q is a multiple of 2^-30 well below 2^53 of
them: floating point computes F(z*) = w* - v* *exactly*, and the natural residual at z*
is 0, at any n (including the obstacle problem with its 1/h^2 scaling).

Every generator returns a GeneratedProblem with ``lcp = (M, q, lb, ub)`` (M CSC) and an
MCP whose Jacobian is the constant M (declared through ``constant_jac``).
"""
from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

from compass_sparse.problem import MCP

from .manufactured import manufactured_point, quantize
from .sparse import _band_pairs, _grid_pairs

__all__ = [
    "lcp_problem",
    "p_matrix_lcp",
    "monotone_lcp",
    "obstacle_problem",
    "infeasible_lcp",
    "duplicated_columns_lcp",
    "brute_force_lcp",
    "MAT_QUANTUM",
    "VEC_QUANTUM",
]

MAT_QUANTUM = 2.0**-10
VEC_QUANTUM = 2.0**-20


class _Affine:
    """F(z) = M z + q with constant Jacobian M (picklable)."""

    def __init__(self, M, q):
        self.M = M
        self.q = q

    def F(self, z):
        return self.M @ z + self.q

    def jac(self, z):
        return self.M


def lcp_problem(M, q, lb=0.0, ub=np.inf, x0=None, *, name="lcp", solution=None, info=None,
                var_names=None):
    """Wrap F(z) = M z + q, l <= z <= u as a GeneratedProblem with ``lcp`` set."""
    from . import GeneratedProblem

    M = sp.csc_matrix(M, dtype=float)
    M.sum_duplicates()
    M.sort_indices()
    n = M.shape[0]
    q = np.asarray(q, dtype=float).reshape(n)
    lb = np.array(np.broadcast_to(np.asarray(lb, dtype=float), (n,)))
    ub = np.array(np.broadcast_to(np.asarray(ub, dtype=float), (n,)))
    aff = _Affine(M, q)
    problem = MCP(aff.F, aff.jac, lb, ub, x0, constant_jac=M, var_names=var_names)
    return GeneratedProblem(name=name, problem=problem, solution=solution,
                            info=dict(info or {}), lcp=(M, q, lb, ub))


def _lcp_bounds(n, rng, bounds, bound_mix=(0.25, 0.25, 0.25, 0.25)):
    """Quantized bounds: 'ncp' ([0, inf)), 'box' (l in [-1, 0], width in [0.5, 2]) or
    'mixed' (free / lower / upper / boxed per bound_mix)."""
    lo = quantize(rng.uniform(-1.0, 0.0, n), VEC_QUANTUM)
    wd = quantize(rng.uniform(0.5, 2.0, n), VEC_QUANTUM)
    if bounds == "ncp":
        return np.zeros(n), np.full(n, np.inf)
    if bounds == "box":
        return lo, lo + wd
    if bounds == "mixed":
        p = np.cumsum(np.asarray(bound_mix, dtype=float) / np.sum(bound_mix))
        kind = np.searchsorted(p, rng.random(n), side="right").clip(0, 3)
        lb = np.where((kind == 1) | (kind == 3), lo, -np.inf)
        ub = np.where(kind == 2, lo + 1.0, np.where(kind == 3, lo + wd, np.inf))
        return lb, ub
    raise ValueError("bounds must be 'ncp', 'box' or 'mixed'")


def _manufacture_lcp(M, lb, ub, rng, active_fraction, degenerate_fraction, name, info,
                     x0=None):
    a = float(active_fraction)
    pt = manufactured_point(lb, ub, rng, mix=(1.0 - a, a / 2, a / 2),
                            degenerate_fraction=degenerate_fraction, quantum=VEC_QUANTUM)
    q = pt.w - pt.v - M @ pt.z
    info = dict(info)
    info.update(w_star=pt.w, v_star=pt.v, kind=pt.kind, degenerate=pt.degenerate)
    if x0 is None:
        x0 = np.clip(np.zeros(M.shape[0]), lb, ub)
    return lcp_problem(M, q, lb, ub, x0, name=name, solution=pt.z.copy(), info=info)


def _grid_laplacian(n, rng, shift, random_weights=True):
    """Weighted graph Laplacian of the first n nodes of a grid + shift * I (SPD)."""
    r, c, m = _grid_pairs(n)
    half = r.size // 2  # pairs come as (a, b) then (b, a)
    wts = quantize(rng.uniform(0.5, 1.5, half), MAT_QUANTUM) if random_weights else np.ones(half)
    wts = np.concatenate([wts, wts])
    deg = np.bincount(r, weights=wts, minlength=n)
    rows = np.concatenate([np.arange(n), r])
    cols = np.concatenate([np.arange(n), c])
    data = np.concatenate([deg + shift, -wts])
    return sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsc(), m


def _dominant_banded(n, rng, bandwidth, margin):
    """Non-symmetric banded matrix, strictly diagonally dominant with positive diagonal
    (a P-matrix), quantized."""
    r, c = _band_pairs(n, bandwidth)
    off = quantize(rng.uniform(-1.0, 1.0, r.size), MAT_QUANTUM)
    rowabs = np.bincount(r, weights=np.abs(off), minlength=n)
    rows = np.concatenate([np.arange(n), r])
    cols = np.concatenate([np.arange(n), c])
    data = np.concatenate([rowabs + margin, off])
    return sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsc()


def p_matrix_lcp(n: int, structure: str = "grid", seed=0, bounds: str = "ncp",
                 degenerate_fraction: float = 0.0, *, active_fraction: float = 0.5,
                 shift: float = 0.5, bandwidth: int = 2):
    """A sparse P-matrix LCP with a manufactured (hence, P-matrix: unique) solution.

    structure : 'grid' -- symmetric positive definite weighted 5-point grid Laplacian
        (edge weights U[0.5, 1.5]) + shift * I; 'banded' -- non-symmetric banded matrix,
        strictly diagonally dominant with positive diagonal (margin ``shift``).
    bounds : 'ncp' (z >= 0), 'box', or 'mixed' (free / lower / upper / boxed).
    degenerate_fraction : fraction of the active rows with zero multiplier (z*_i at a bound
        and F_i(z*) = 0: strict complementarity fails there).
    """
    n = int(n)
    rng = np.random.default_rng(seed)
    shift = float(quantize(shift, MAT_QUANTUM))
    if structure == "grid":
        M, m = _grid_laplacian(n, rng, shift)
    elif structure == "banded":
        M, m = _dominant_banded(n, rng, bandwidth, shift), None
    else:
        raise ValueError("structure must be 'grid' or 'banded'")
    lb, ub = _lcp_bounds(n, rng, bounds)
    info = dict(n=n, structure=structure, seed=seed, bounds=bounds, grid_width=m,
                degenerate_fraction=degenerate_fraction, shift=shift)
    return _manufacture_lcp(M, lb, ub, rng, active_fraction, degenerate_fraction,
                            f"p_matrix_lcp({structure}, {bounds}, n={n}, seed={seed})", info)


def monotone_lcp(n: int, seed=0, *, rank: int | None = None, skew: float = 1.0,
                 bounds: str = "ncp", active_fraction: float = 0.5,
                 degenerate_fraction: float = 0.0):
    """A monotone LCP: M = B B^T + (S - S^T), positive semidefinite, singular allowed.

    B is n x rank (default n // 2, so B B^T is singular) with 3 entries per row in a
    local (banded) pattern; S has random entries on the first two super-diagonals scaled
    by ``skew``.  z^T M z = |B^T z|^2 >= 0.  The LCP is feasible by construction (a
    manufactured solution); the solution set of a monotone LCP may be a continuum, and
    ``solution`` is one of its points.
    """
    n = int(n)
    rng = np.random.default_rng(seed)
    r = max(1, n // 2) if rank is None else max(1, min(int(rank), n))
    per = min(3, r)
    base = (np.arange(n) * r) // n
    bc = (base[:, None] + np.arange(per)) % r
    bv = quantize(rng.uniform(-1.0, 1.0, (n, per)), 2.0**-4)
    B = sp.coo_matrix((bv.ravel(), (np.repeat(np.arange(n), per), bc.ravel())),
                      shape=(n, r)).tocsr()
    P = (B @ B.T).tocoo()
    sr, sc = [], []
    for off in (1, 2):
        i = np.arange(max(n - off, 0))
        sr.append(i)
        sc.append(i + off)
    sr, sc = np.concatenate(sr), np.concatenate(sc)
    sv = quantize(rng.uniform(-1.0, 1.0, sr.size) * skew, 2.0**-8)
    rows = np.concatenate([P.row, sr, sc])
    cols = np.concatenate([P.col, sc, sr])
    data = np.concatenate([P.data, sv, -sv])
    M = sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsc()
    lb, ub = _lcp_bounds(n, rng, bounds)
    info = dict(n=n, seed=seed, rank=r, skew=skew, bounds=bounds, B=B)
    return _manufacture_lcp(M, lb, ub, rng, active_fraction, degenerate_fraction,
                            f"monotone_lcp({bounds}, n={n}, rank={r}, seed={seed})", info)


def obstacle_problem(m: int, seed=0, *, degenerate_fraction: float = 0.0,
                     membrane_height: float | None = None):
    """The 2-D obstacle problem on the unit square, an m x m interior grid (n = m^2).

    M = (1/h^2) * 5-point Laplacian (h = 1/(m+1), zero Dirichlet boundary), lower bound =
    obstacle psi (a paraboloid bump with random centre, radius and height), no upper bound.
    Manufactured discrete solution z* = max(psi, g) with the membrane
    g = c sin(pi x) sin(pi y) lower than the bump's top, so the contact set {psi >= g} is a
    non-trivial blob.  On the contact set F(z*) = w* > 0 (``degenerate_fraction`` of the
    contact points get w* = 0), elsewhere F(z*) = 0.  Exact in floating point up to
    m = 1000 (n = 1e6).  ``info`` holds psi, g, the contact mask and m, h.
    """
    m = int(m)
    n = m * m
    rng = np.random.default_rng(seed)
    h = 1.0 / (m + 1)
    s = float((m + 1) ** 2)  # exactly representable integer 1/h^2
    T = sp.diags([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1],
                 shape=(m, m), format="csr")
    I = sp.identity(m, format="csr")
    M = (s * (sp.kron(I, T) + sp.kron(T, I))).tocsc()
    t = np.arange(1, m + 1) * h
    X, Y = np.meshgrid(t, t, indexing="xy")
    X, Y = X.ravel(), Y.ravel()
    cx, cy = rng.uniform(0.35, 0.65, 2)
    rad = rng.uniform(0.2, 0.3)
    top = rng.uniform(0.6, 1.0)
    c = top * 0.6 if membrane_height is None else float(membrane_height)
    psi = top * (1.0 - ((X - cx) ** 2 + (Y - cy) ** 2) / rad**2) - 0.1
    g = c * np.sin(np.pi * X) * np.sin(np.pi * Y)
    psi, g = quantize(psi, VEC_QUANTUM), quantize(g, VEC_QUANTUM)
    contact = psi >= g
    z = np.where(contact, psi, g)
    w = quantize(rng.uniform(1.0, 10.0, n), VEC_QUANTUM)
    cidx = np.flatnonzero(contact)
    k = int(round(degenerate_fraction * cidx.size))
    degenerate = np.zeros(n, dtype=bool)
    if k:
        degenerate[rng.choice(cidx, size=k, replace=False)] = True
    w = np.where(contact & ~degenerate, w, 0.0)
    q = w - M @ z
    lb, ub = psi.copy(), np.full(n, np.inf)
    info = dict(m=m, n=n, h=h, seed=seed, psi=psi, g=g, contact=contact, w_star=w,
                v_star=np.zeros(n), degenerate=degenerate, center=(cx, cy), radius=rad,
                height=top)
    return lcp_problem(M, q, lb, ub, np.maximum(psi, 0.0),
                       name=f"obstacle(m={m}, n={n}, seed={seed})", solution=z, info=info)


def infeasible_lcp(n: int, seed=0, *, skew: float = 0.5):
    """An NCP (z >= 0, Mz + q >= 0, z'(Mz + q) = 0) with copositive-plus M and NO solution.

    M = L + skew (P - P^T): L is the weighted Laplacian of a connected graph (a path plus
    random chords), positive semidefinite with L e = 0; P is the cyclic shift, so
    S = P - P^T is skew-symmetric with S e = 0 and S^T e = 0.  Hence z' M z = z' L z >= 0
    and z' M z = 0 implies L z = 0, i.e. (M + M^T) z = 0: M is copositive-plus.
    q is random with sum(q) = -n/2 < 0.  Then for every z >= 0,
    e^T (M z + q) = (M^T e)^T z + e^T q = e^T q < 0, so M z + q >= 0 is impossible: the LCP
    is infeasible (Farkas certificate y = e >= 0, M^T y = 0, y^T q < 0), and Lemke's method,
    which for copositive-plus M terminates at a solution iff one exists, must end in a
    secondary ray.  ``solution`` is None; info holds the certificate y.
    """
    n = int(n)
    if n < 2:
        raise ValueError("infeasible_lcp needs n >= 2")
    rng = np.random.default_rng(seed)
    a = np.arange(n - 1)
    ch = max(1, n // 5)
    ca = rng.integers(0, n, ch)
    cb = (ca + rng.integers(1, n, ch)) % n
    er = np.concatenate([a, ca])
    ec = np.concatenate([a + 1, cb])
    wt = quantize(rng.uniform(0.5, 1.5, er.size), MAT_QUANTUM)
    sh = float(quantize(skew, MAT_QUANTUM))
    nxt = (np.arange(n) + 1) % n
    rows = np.concatenate([er, ec, er, ec, np.arange(n), np.arange(n), nxt])
    cols = np.concatenate([ec, er, er, ec, np.arange(n), nxt, np.arange(n)])
    data = np.concatenate([-wt, -wt, wt, wt, np.zeros(n), np.full(n, sh), np.full(n, -sh)])
    M = sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsc()
    qr = rng.uniform(-1.0, 1.0, n)
    q = qr - qr.mean() - 0.5
    info = dict(n=n, seed=seed, certificate=np.ones(n), skew=sh)
    return lcp_problem(M, q, 0.0, np.inf, np.zeros(n),
                       name=f"infeasible_lcp(n={n}, seed={seed})", solution=None, info=info)


def duplicated_columns_lcp(n: int, seed=0, *, n_duplicates: int | None = None,
                           bounds: str = "box", active_fraction: float = 0.5,
                           bandwidth: int = 2):
    """A rank-deficient LCP: some columns of M are exact copies of others.

    Start from a strictly diagonally dominant banded matrix and overwrite
    ``n_duplicates`` (default max(1, n // 10)) columns j2 with a column j1 (j1 never
    itself overwritten).  M is singular (rank <= n - n_duplicates), yet the manufactured
    z* is a solution; it need not be unique (moving mass between z_j1 and z_j2 leaves M z
    unchanged).  info['duplicates'] lists the (j2, j1) pairs.
    """
    n = int(n)
    if n < 2:
        raise ValueError("duplicated_columns_lcp needs n >= 2")
    rng = np.random.default_rng(seed)
    base = _dominant_banded(n, rng, bandwidth, 0.5)
    k = max(1, n // 10) if n_duplicates is None else int(n_duplicates)
    k = min(k, n // 2)
    perm = rng.permutation(n)
    targets, sources = perm[:k], perm[k:2 * k]
    cols = np.arange(n)
    cols[targets] = sources
    M = base[:, cols].tocsc()
    lb, ub = _lcp_bounds(n, rng, bounds)
    info = dict(n=n, seed=seed, bounds=bounds, duplicates=list(zip(targets.tolist(),
                                                                  sources.tolist())))
    return _manufacture_lcp(M, lb, ub, rng, active_fraction, 0.0,
                            f"duplicated_columns_lcp(n={n}, k={k}, seed={seed})", info)


def brute_force_lcp(M, q, lb=0.0, ub=np.inf, *, tol: float = 1e-9, max_n: int = 10):
    """All solutions of the box LCP  lb <= z <= ub  _|_  M z + q, by enumeration (n <= 10).

    Every index is free, at its lower or at its upper bound (3^n choices; choices at an
    infinite bound are skipped).  For each free set I the system
    M_II z_I = -(q_I + M_IN z_N) is solved for all bound assignments of the rest at once,
    and the candidate is kept when it lies in the box and F has the right signs (within
    ``tol``, relative to the data's scale).  Returns a list of distinct solutions (arrays).

    A singular M_II is solved in the least-squares sense and its candidate kept only if
    the system is consistent; then only the minimum-norm point of a solution continuum on
    that face is tested, so continua may be represented by few (or, rarely, no) points.
    """
    M = M.toarray() if sp.issparse(M) else np.asarray(M, dtype=float)
    n = M.shape[0]
    if n > max_n:
        raise ValueError(f"brute_force_lcp enumerates 3^n active sets; n = {n} > {max_n}")
    q = np.asarray(q, dtype=float).reshape(n)
    lb = np.array(np.broadcast_to(np.asarray(lb, dtype=float), (n,)))
    ub = np.array(np.broadcast_to(np.asarray(ub, dtype=float), (n,)))
    scale = max(1.0, float(np.abs(M).max(initial=0.0)), float(np.abs(q).max(initial=0.0)),
                float(np.abs(np.where(np.isfinite(lb), lb, 0)).max(initial=0.0)),
                float(np.abs(np.where(np.isfinite(ub), ub, 0)).max(initial=0.0)))
    tl = tol * scale
    sols: list[np.ndarray] = []
    for free in itertools.product((False, True), repeat=n):
        free = np.array(free, dtype=bool)
        I = np.flatnonzero(free)
        N = np.flatnonzero(~free)
        # every bound assignment of the non-free indices: 0 = lower, 1 = upper
        choices = np.array(list(itertools.product((0, 1), repeat=N.size)), dtype=np.int8)
        choices = choices.reshape(2**N.size, N.size)
        if N.size:
            vals = np.where(choices == 0, lb[N], ub[N])
            ok = np.all(np.isfinite(vals), axis=1)
            choices, vals = choices[ok], vals[ok]
            if not len(vals):
                continue
        else:
            vals = np.zeros((1, 0))
        k = vals.shape[0]
        Z = np.empty((k, n))
        Z[:, N] = vals
        if I.size:
            rhs = -(q[I][:, None] + M[np.ix_(I, N)] @ vals.T)
            A = M[np.ix_(I, I)]
            try:
                sol = np.linalg.solve(A, rhs)
                if not np.all(np.isfinite(sol)) or np.linalg.cond(A) > 1e12:
                    raise np.linalg.LinAlgError
            except np.linalg.LinAlgError:
                sol = np.linalg.lstsq(A, rhs, rcond=None)[0]
            Z[:, I] = sol.T
        F = Z @ M.T + q
        inbox = np.all((Z >= lb - tl) & (Z <= ub + tl), axis=1)
        okI = np.all(np.abs(F[:, I]) <= tl, axis=1)
        if N.size:
            sgn = np.where(choices == 0, F[:, N] >= -tl, F[:, N] <= tl)
            okN = np.all(sgn, axis=1)
        else:
            okN = np.ones(k, dtype=bool)
        for z in Z[inbox & okI & okN]:
            z = np.clip(z, lb, ub)
            if not any(np.max(np.abs(z - s)) <= 1e3 * tl for s in sols):
                sols.append(z)
    return sols
