"""Balanced random social accounting matrices (SAMs) for synthetic CGE models.

The SAM is balanced *by construction*: a productive sparse input-output matrix and positive
final demand determine gross output through the (multi-region) Leontief system, every other
account is defined as a residual or a share of a balanced total, and household demand is
fitted to its row (income) and column (final demand) totals by RAS / iterative proportional
fitting.

Multi-region data follow the Armington convention: each region r absorbs good i from itself
and from m trading partners with sourcing shares pi[i, s, r] (home bias on the diagonal), and
the regional current-account imbalance B_r (with sum_r B_r = 0) is paid to households as an
endowment of a numeraire good.

Everything is deterministic in ``seed``.  Flows are stored as flat arrays indexed by
``r * N + i`` (region-major), so a SAM with 1e5 accounts is cheap to hold.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

__all__ = ["SAM", "random_sam", "ras"]


@dataclass
class SAM:
    """A balanced multi-region SAM (value flows at benchmark prices, all prices 1).

    Flat index conventions: sector ``r*N + i``, factor ``r*F + f``, household ``r*H + h``.
    """

    R: int
    N: int
    F: int
    H: int
    # input-output flows Z[i, j] (good i used by sector j) as triplets, region-major
    io_r: np.ndarray
    io_i: np.ndarray
    io_j: np.ndarray
    io_Z: np.ndarray
    X: np.ndarray  # (R*N,) gross output value (at producer price, gross of output tax)
    t: np.ndarray  # (R*N,) output tax rates
    VA: np.ndarray  # (R*N,) value added
    FV: np.ndarray  # (R*N, F) factor payments
    FD: np.ndarray  # (R*N,) final demand (household consumption)
    U: np.ndarray  # (R*N,) Armington absorption = intermediate + final demand
    # bilateral trade links (good i, source s, destination r), home links included
    l_i: np.ndarray
    l_s: np.ndarray
    l_r: np.ndarray
    l_T: np.ndarray
    partners: list  # partners[r]: regions r imports from (excluding r)
    B: np.ndarray  # (R,) current-account imbalance paid to households
    E: np.ndarray  # (R*F,) factor endowments
    omega: np.ndarray  # (R*H, F) household share of each regional factor endowment
    tau: np.ndarray  # (R*H,) household share of regional tax revenue
    bshare: np.ndarray  # (R*H,) household share of the regional imbalance B_r
    M: np.ndarray  # (R*H,) household income
    D: np.ndarray  # (R*H, N) household demand
    TR: np.ndarray  # (R,) tax revenue
    seed: int = 0
    info: dict = field(default_factory=dict)

    def check(self) -> dict:
        """Largest absolute imbalance of every account (all should be ~1e-13 relative)."""
        R, N, F, H = self.R, self.N, self.F, self.H
        RN = R * N
        cols = np.bincount(self.io_r * N + self.io_j, self.io_Z, minlength=RN)
        rows = np.bincount(self.io_r * N + self.io_i, self.io_Z, minlength=RN)
        supply = np.bincount(self.l_s * N + self.l_i, self.l_T, minlength=RN)
        absorb = np.bincount(self.l_r * N + self.l_i, self.l_T, minlength=RN)
        hreg = np.arange(R * H) // H
        fin = np.zeros(RN)
        np.add.at(fin, (hreg[:, None] * N + np.arange(N)[None, :]).ravel(), self.D.ravel())
        inc = (
            np.einsum("hf,hf->h", self.omega, self.E.reshape(R, F)[hreg])
            + self.tau * self.TR[hreg]
            + self.bshare * self.B[hreg]
        )
        return {
            "zero_profit": float(np.max(np.abs(cols + self.VA + self.t * self.X - self.X))),
            "factor_split": float(np.max(np.abs(self.FV.sum(1) - self.VA))),
            "output_market": float(np.max(np.abs(supply - self.X))),
            "armington": float(np.max(np.abs(absorb - self.U))),
            "absorption": float(np.max(np.abs(rows + self.FD - self.U))),
            "final_demand": float(np.max(np.abs(fin - self.FD))),
            "income": float(np.max(np.abs(inc - self.M))),
            "expenditure": float(np.max(np.abs(self.D.sum(1) - self.M))),
            "balance_of_payments": float(abs(self.B.sum())),
        }


def ras(D0: np.ndarray, row: np.ndarray, col: np.ndarray, *, tol: float = 4e-16,
        maxiter: int = 5000) -> np.ndarray:
    """RAS / iterative proportional fitting of positive matrices, batched.

    ``D0`` has shape (..., H, N); ``row`` (..., H) and ``col`` (..., N) are the targets, with
    equal totals per batch.  Ends with a column scaling, so column sums are exact and the
    row-sum error is below ``tol`` (relative) on return.
    """
    D = np.array(D0, dtype=float, copy=True)
    best = np.inf
    stall = 0
    for _ in range(maxiter):
        D *= (row / D.sum(-1))[..., None]
        D *= (col / D.sum(-2))[..., None, :]
        err = np.max(np.abs(D.sum(-1) - row) / row)
        if err <= tol:
            break
        if err < 0.5 * best:
            best, stall = err, 0
        else:
            stall += 1
            if stall >= 5 and err < 1e-12:  # at rounding level
                break
    return D


def _rng(seed):
    return np.random.default_rng(np.random.SeedSequence(int(seed)))


def random_sam(
    regions: int = 1,
    sectors: int = 10,
    factors: int = 2,
    households: int = 1,
    *,
    trade_partners: int | None = None,
    io_density: int | float = 4,
    home_bias: tuple[float, float] = (0.6, 0.9),
    taxes: bool = True,
    max_tax: float = 0.15,
    colsum_range: tuple[float, float] = (0.2, 0.6),
    seed: int = 0,
) -> SAM:
    """Draw a balanced SAM.

    Parameters
    ----------
    regions, sectors, factors, households : sizes R, N, F, H (households per region).
    trade_partners : m, the number of regions each region imports from (default
        min(R - 1, 4)); each good is sourced from home plus these m partners.
    io_density : nonzeros k per column of the input-output matrix (an int), or a fraction
        of N (a float in (0, 1]).
    home_bias : range of the home sourcing share pi[i, r, r].
    taxes : draw output tax rates in [0, max_tax] (otherwise zero).
    colsum_range : range of the column sums of the input-output coefficient matrix.
    """
    R, N, F, H = int(regions), int(sectors), int(factors), int(households)
    if min(R, N, F, H) < 1:
        raise ValueError("regions, sectors, factors and households must all be >= 1")
    rng = _rng(seed)
    if isinstance(io_density, float) and io_density <= 1.0:
        k = max(1, int(round(io_density * N)))
    else:
        k = int(io_density)
    k = max(0, min(k, N))
    m = min(R - 1, 4) if trade_partners is None else int(trade_partners)
    if m < 0 or m > R - 1:
        raise ValueError(f"trade_partners must be in [0, {R - 1}] for {R} regions")
    RN = R * N

    # 1. sparse productive input-coefficient matrices, k nonzeros per column
    if k > 0:
        # k draws per column (with replacement), duplicates merged: about k distinct rows
        io_r = np.repeat(np.arange(R), N * k)
        io_j = np.tile(np.repeat(np.arange(N), k), R)
        io_i = rng.integers(0, N, size=R * N * k)
        key = np.unique((io_r * N + io_j) * N + io_i)
        io_i = key % N
        io_j = (key // N) % N
        io_r = key // (N * N)
        w = rng.random(io_r.size) + 0.1
        colsum = np.bincount(io_r * N + io_j, w, minlength=RN)
        target = rng.uniform(*colsum_range, size=RN)
        a = w * (target / colsum)[io_r * N + io_j]
    else:
        io_r = io_i = io_j = np.zeros(0, dtype=np.int64)
        a = np.zeros(0)

    # 2. final demand, 3. trade shares
    FD = rng.uniform(0.5, 1.5, size=RN) * (1.0 + rng.uniform(0, 1, size=R).repeat(N))
    # The first partner is the ring neighbour r+1, so the trade graph is connected: with
    # purely random partners it splits into clusters whose price levels are pinned only
    # through the numeraire-paid imbalances, and J becomes nearly singular (measured:
    # smallest singular value 4e-4 at R=39, m=1, on the incomes of a two-region cluster).
    partners = []
    for r in range(R):
        if not m:
            partners.append(np.zeros(0, dtype=np.int64))
            continue
        ring = (r + 1) % R
        others = np.array([s for s in range(R) if s != r and s != ring], dtype=np.int64)
        extra = rng.choice(others, size=m - 1, replace=False) if m > 1 else []
        partners.append(np.sort(np.concatenate([[ring], extra]).astype(np.int64)))
    l_i, l_s, l_r, l_pi = [], [], [], []
    for r in range(R):
        home = rng.uniform(*home_bias, size=N) if m else np.ones(N)
        l_i.append(np.arange(N)); l_s.append(np.full(N, r)); l_r.append(np.full(N, r))
        l_pi.append(home)
        if m:
            share = rng.dirichlet(np.ones(m), size=N) * (1.0 - home)[:, None]  # (N, m)
            for q, s in enumerate(partners[r]):
                l_i.append(np.arange(N)); l_s.append(np.full(N, s)); l_r.append(np.full(N, r))
                l_pi.append(share[:, q])
    l_i = np.concatenate(l_i).astype(np.int64)
    l_s = np.concatenate(l_s).astype(np.int64)
    l_r = np.concatenate(l_r).astype(np.int64)
    l_pi = np.concatenate(l_pi)
    src = l_s * N + l_i
    dst = l_r * N + l_i

    # 3'. gross output: X = Pi (A X + FD), i.e. (I - Pi A) X = Pi FD
    Amat = sp.csr_matrix((a, (io_r * N + io_i, io_r * N + io_j)), shape=(RN, RN))
    Pi = sp.csr_matrix((l_pi, (src, dst)), shape=(RN, RN))
    # fixed-point iteration: ||Pi A||_1 <= max column sum < 1, so it contracts
    PiA = (Pi @ Amat).tocsr()
    b = Pi @ FD
    Xs = b.copy()
    for _ in range(200):
        Xn = PiA @ Xs + b
        if np.max(np.abs(Xn - Xs)) <= 1e-14 * np.max(Xn):
            Xs = Xn
            break
        Xs = Xn

    # 4. flows from the solved outputs; every account is then exact by definition
    Z = a * Xs[io_r * N + io_j]
    U = np.bincount(io_r * N + io_i, Z, minlength=RN) + FD
    l_T = l_pi * U[dst]
    X = np.bincount(src, l_T, minlength=RN)

    # 5. output taxes and value added
    t = rng.uniform(0.0, max_tax, size=RN) if taxes else np.zeros(RN)
    VA = (1.0 - t) * X - np.bincount(io_r * N + io_j, Z, minlength=RN)
    if np.any(VA <= 0.05 * X):
        raise ValueError("value added too small; lower colsum_range or max_tax")

    # 6. factor split
    theta = rng.dirichlet(np.ones(F) * 2.0, size=RN) if F > 1 else np.ones((RN, 1))
    FV = VA[:, None] * theta
    E = FV.reshape(R, N, F).sum(1).ravel()
    TR = np.bincount(np.arange(RN) // N, t * X, minlength=R)

    # 7. households
    B = np.bincount(np.arange(RN) // N, FD - VA, minlength=R) - TR
    if R == 1:
        B[:] = 0.0  # closed economy: the imbalance is rounding noise
    omega = rng.dirichlet(np.ones(H), size=(R, F)).transpose(0, 2, 1).reshape(R * H, F) \
        if H > 1 else np.ones((R, F))
    tau = (rng.dirichlet(np.ones(H), size=R) if H > 1 else np.ones((R, 1))).ravel()
    hreg = np.arange(R * H) // H
    factor_inc = np.einsum("hf,hf->h", omega, E.reshape(R, F)[hreg])
    bshare = factor_inc / np.bincount(hreg, factor_inc, minlength=R)[hreg]
    M = factor_inc + tau * TR[hreg] + bshare * B[hreg]
    if np.any(M <= 0):
        raise ValueError("a household has nonpositive income; reduce trade imbalances")

    # 8. household demand by RAS (exact column sums, row sums to ~1e-15)
    D0 = rng.uniform(0.2, 1.0, size=(R, H, N))
    D = ras(D0, M.reshape(R, H), FD.reshape(R, N)).reshape(R * H, N)
    # incomes are redefined as the exact expenditures D.sum(1): they differ from the income
    # accounts only at rounding level (relative ~1e-15)
    M = D.sum(1)

    info = {"k": k, "m": m, "colsum_range": colsum_range, "home_bias": home_bias}
    sam = SAM(
        R=R, N=N, F=F, H=H, io_r=io_r, io_i=io_i, io_j=io_j, io_Z=Z, X=X, t=t, VA=VA, FV=FV,
        FD=FD, U=U, l_i=l_i, l_s=l_s, l_r=l_r, l_T=l_T, partners=partners, B=B, E=E,
        omega=omega, tau=tau, bshare=bshare, M=M, D=D, TR=TR, seed=int(seed), info=info,
    )
    return sam
