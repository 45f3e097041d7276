"""The dense factors of the small-problem engine (compass_sparse.path._dense_lu): LU
with partial pivoting and Forrest-Tomlin column replacements, against numpy.

Tolerance checked everywhere: the backward error of a solve,
``||B x - b||_inf / (||B||_inf ||x||_inf + ||b||_inf)`` and the same for ``B^T y = c``, is at
most ``BACKWARD_TOL`` = 1e-12 (a few hundred units of roundoff) however many updates the
factors carry.  Each tolerance of the update (pivot tolerance, stability tolerance, growth
limit) is driven across its threshold on a constructed case and pushed to its extreme on a
long random sequence.
"""
from __future__ import annotations

import numpy as np
import pytest

from compass_sparse.path import _dense_lu as K
from compass_sparse.path._kernels import VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z

BACKWARD_TOL = 1e-12
UPDATE_TOL, STAB_TOL, GROWTH = 1e-11, 1e-8, 100.0  # the engine's defaults
_UNIT = (VAR_W, VAR_V, VAR_A)


def _column(kind, idx, M, r):
    if kind == VAR_Z:
        return M[:, idx].copy()
    if kind == VAR_T:
        return r.copy()
    c = np.zeros(M.shape[0])
    c[idx] = -1.0 if kind in (VAR_W, VAR_S) else 1.0
    return c


class Factors:
    """A test driver of the kernels: the slot table, its factors and the update rule of
    the pivot loop (replace, or refactorize when the update is declined)."""

    def __init__(self, M, r, sk, si, limit, update_tol=UPDATE_TOL, stab_tol=STAB_TOL,
                 growth=GROWTH):
        self.M, self.r = np.asfortranarray(M, dtype=float), np.asarray(r, dtype=float)
        self.sk, self.si = np.array(sk, np.int64), np.array(si, np.int64)
        self.n = n = self.sk.size
        self.tols = (update_tol, stab_tol, growth)
        self.L, self.U, self.R, self.perm, self.fw = K.allocate_factors(n, limit)
        self.d = np.zeros(n)
        self.outcomes = []
        assert self.refactor() == 0

    def basis(self, sk=None, si=None):
        sk = self.sk if sk is None else sk
        si = self.si if si is None else si
        return np.column_stack([_column(k, i, self.M, self.r) for k, i in zip(sk, si)])

    def refactor(self):
        n = self.n
        nrep = K.lu_factor(self.M, self.r, self.sk, self.si, np.ones(n, np.int64), self.L,
                           self.U, self.perm, self.fw, 1e-9)
        self.k = 0
        return nrep

    def ftran(self, b, keep=False):
        x = np.zeros(self.n)
        K.ftran(self.L, self.U, self.R, self.perm, self.k, np.asarray(b, float), x,
                self.fw[0], self.fw[1], keep)
        return x

    def btran(self, c):
        y = np.zeros(self.n)
        K.btran(self.L, self.U, self.R, self.perm, self.k, np.asarray(c, float), y,
                self.fw[0])
        return y

    def d_of(self, kind, idx):
        return self.ftran(_column(kind, idx, self.M, self.r), keep=True)

    def replace(self, slot, kind, idx):
        """Replace slot's column; returns the update outcome (the factors represent the
        new basis in every case: a declined update is followed by a refactorization)."""
        d = self.d_of(kind, idx)
        upd = K.replace_column(self.U, self.R, self.perm, self.k, slot, d, self.fw[1],
                               self.fw[2], *self.tols)
        self.sk[slot], self.si[slot] = kind, idx
        if upd == K.UPD_OK:
            self.k += 1
        else:
            assert self.refactor() == 0
        self.outcomes.append(upd)
        return upd


def backward_errors(f, rng):
    B = f.basis()
    b, c = rng.standard_normal(f.n), rng.standard_normal(f.n)
    x, y = f.ftran(b), f.btran(c)
    nb = np.abs(B).sum(axis=1).max()
    ex = np.abs(B @ x - b).max() / (nb * np.abs(x).max() + np.abs(b).max())
    nbt = np.abs(B).sum(axis=0).max()
    ey = np.abs(B.T @ y - c).max() / (nbt * np.abs(y).max() + np.abs(c).max())
    return ex, ey


def _random_table(n, rng):
    sk = rng.choice([VAR_Z, VAR_W, VAR_V], size=n).astype(np.int64)
    sk[rng.integers(n)] = VAR_T
    return sk, np.arange(n, dtype=np.int64)


@pytest.mark.parametrize("n,seed", [(1, 0), (5, 1), (30, 2), (80, 3)])
def test_fresh_factors_solve_B_and_BT_against_numpy(n, seed):
    rng = np.random.default_rng(seed)
    M, r = rng.standard_normal((n, n)), rng.standard_normal(n)
    f = Factors(M, r, *_random_table(n, rng), limit=5)
    B = f.basis()
    b, c = rng.standard_normal(n), rng.standard_normal(n)
    assert np.allclose(f.ftran(b), np.linalg.solve(B, b), rtol=1e-9, atol=1e-9)
    assert np.allclose(f.btran(c), np.linalg.solve(B.T, c), rtol=1e-9, atol=1e-9)
    assert max(backward_errors(f, rng)) <= BACKWARD_TOL


def _entering(f, rng):
    """A random entering column not in the basis: an M column, a slack or t."""
    while True:
        u = rng.random()
        if u < 0.6:
            kind, idx = VAR_Z, int(rng.integers(f.n))
        elif u < 0.95:
            kind, idx = (VAR_W, VAR_V)[int(rng.integers(2))], int(rng.integers(f.n))
        else:
            kind, idx = VAR_T, 0
        clash = (f.sk == kind) & ((f.si == idx) | (kind == VAR_T))
        if kind in _UNIT:  # one unit column per row
            clash |= np.isin(f.sk, _UNIT) & (f.si == idx)
        if not clash.any():
            return kind, idx


def _random_sequence(f, rng, steps, thr=1e-3):
    """``steps`` replacements, the leaving slot random among those with |d_s| > thr
    ||d||_inf; returns the worst backward error met and the longest run of updates."""
    worst, longest = 0.0, 0
    for _ in range(steps):
        kind, idx = _entering(f, rng)
        d = f.d_of(kind, idx)
        ok = np.flatnonzero(np.abs(d) > thr * np.abs(d).max())
        f.replace(int(rng.choice(ok)), kind, idx)
        worst = max(worst, *backward_errors(f, rng))
        longest = max(longest, f.k)
    return worst, longest


@pytest.mark.parametrize("n,seed", [(8, 0), (40, 1), (120, 2)])
def test_forrest_tomlin_solves_stay_accurate_over_long_replacement_sequences(n, seed):
    """600 replacements in random slots (any slot the pivot test accepts, not the best
    one, so multipliers grow as they may along a path), update limit 50: after every
    replacement B x = b and B^T y = c are solved to the backward tolerance."""
    rng = np.random.default_rng(seed)
    M, r = rng.standard_normal((n, n)), rng.standard_normal(n)
    f = Factors(M, r, *_random_table(n, rng), limit=50)
    worst, longest = _random_sequence(f, rng, 600)
    assert worst <= BACKWARD_TOL
    counts = np.bincount(f.outcomes, minlength=5)
    assert counts[K.UPD_OK] >= 500 and longest >= 40  # long runs of updates were solved


@pytest.mark.parametrize("eps", [1e-13, 1e-15, 0.0])
def test_near_singular_replacement_is_refused_and_the_new_basis_is_repaired(eps):
    """The entering column is another basic column plus eps: the replacement is refused
    by the pivot test (factors unchanged, still solving the old basis) and the factorization
    of the new table finds the dependent slot, which the path repairs with an artificial."""
    n = 12
    rng = np.random.default_rng(5)
    M = rng.standard_normal((n, n))
    sk, si = np.full(n, VAR_Z, np.int64), np.arange(n, dtype=np.int64)
    sk[:4] = VAR_W
    M[:, 2] = M[:, 7] + eps * rng.standard_normal(n)  # z_2 enters, parallel to z_7
    f = Factors(M, rng.standard_normal(n), sk, si, limit=50)
    for _ in range(5):  # carry a few updates first
        kind, idx = _entering(f, rng)
        if kind == VAR_Z and idx == 2:
            continue
        d = f.d_of(kind, idx)
        f.replace(int(np.argmax(np.abs(d))), kind, idx)
    assert f.k > 0 and 7 in f.si[f.sk == VAR_Z]  # updates carried, z_7 still basic
    old = f.basis()
    slot = int(np.flatnonzero(f.sk == VAR_Z)[0])
    if f.si[slot] == 7:
        slot = int(np.flatnonzero(f.sk == VAR_Z)[1])
    d = f.d_of(VAR_Z, 2)
    k0 = f.k
    upd = K.replace_column(f.U, f.R, f.perm, f.k, slot, d, f.fw[1], f.fw[2], *f.tols)
    assert upd == K.UPD_REFUSED
    b = rng.standard_normal(n)
    assert f.k == k0 and np.abs(old @ f.ftran(b) - b).max() <= 1e-10
    f.sk[slot], f.si[slot] = VAR_Z, 2
    assert f.refactor() >= 1  # z_2 and z_7 basic together: singular, the path repairs it


def test_update_pivot_tolerance_decides_at_its_threshold():
    """|d_s| / ||d||_inf = 1e-9: accepted (and accurate) under update_tol 1e-11, refused
    under update_tol 1e-8."""
    n = 6
    rng = np.random.default_rng(7)
    M = rng.standard_normal((n, n))
    sk, si = np.full(n, VAR_Z, np.int64), np.arange(n, dtype=np.int64)
    sk[5], si[5] = VAR_W, 5
    f0 = Factors(M, np.zeros(n), sk, si, limit=10)
    B = f0.basis()
    coef = rng.standard_normal(n)
    coef[2] = 1e-9 * np.abs(coef).max()
    a = B @ coef  # d = coef for the entering w column below
    for tol, expect in ((1e-11, K.UPD_OK), (1e-8, K.UPD_REFUSED)):
        f = Factors(M, np.zeros(n), sk, si, limit=10, update_tol=tol)
        f.M[:, 5] = a  # z_5 (not basic) enters with column a
        d = f.d_of(VAR_Z, 5)
        assert np.allclose(d, coef, rtol=1e-6, atol=1e-15)
        upd = K.replace_column(f.U, f.R, f.perm, f.k, 2, d, f.fw[1], f.fw[2], *f.tols)
        assert upd == expect
        if upd == K.UPD_OK:
            f.k += 1
            f.sk[2], f.si[2] = VAR_Z, 5
            assert max(backward_errors(f, rng)) <= BACKWARD_TOL


def _grown_factors(growth):
    """B = [[1, 1e6], [0, 1]] (U = B) and the column (1, 1) replacing slot 0: the row
    eta multiplier is 1e6."""
    M = np.array([[1.0, 1e6, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    f = Factors(M, np.zeros(3), [VAR_Z, VAR_Z, VAR_W], [0, 1, 2], limit=5,
                growth=growth)
    return f, f.d_of(VAR_Z, 2)


def test_growth_limit_declines_an_update_with_a_large_multiplier():
    for growth, expect in ((GROWTH, K.UPD_GROWTH), (1e10, K.UPD_OK)):
        f, d = _grown_factors(growth)
        U0 = f.U.copy()
        upd = K.replace_column(f.U, f.R, f.perm, f.k, 0, d, f.fw[1], f.fw[2], *f.tols)
        assert upd == expect
        if upd == K.UPD_GROWTH:
            assert np.array_equal(f.U, U0) and f.perm[K.P_SLOT, 3] == -1  # untouched
        else:
            f.k += 1
            f.sk[0], f.si[0] = VAR_Z, 2
            b = np.array([1.0, 2.0, 3.0])
            assert np.allclose(f.basis() @ f.ftran(b), b, rtol=0, atol=1e-6)


def test_stability_tolerance_declines_an_update_whose_two_diagonals_disagree():
    """d1 = d_s u_pp comes from the FTRAN column, d2 from the row eta: a relative
    disagreement of 1e-6 (here planted in d_s) is declined under stab_tol 1e-8 and
    accepted under 1e-4; the factors are untouched when declined."""
    n = 10
    rng = np.random.default_rng(3)
    M = rng.standard_normal((n, n))
    sk, si = _random_table(n, rng)
    for tol, expect in ((1e-8, K.UPD_UNSTABLE), (1e-4, K.UPD_OK)):
        f = Factors(M, rng.standard_normal(n), sk, si, limit=5, stab_tol=tol)
        kind, idx = _entering(f, np.random.default_rng(1))
        d = f.d_of(kind, idx)
        slot = int(np.argmax(np.abs(d)))
        d[slot] *= 1.0 + 1e-6
        U0 = f.U.copy()
        upd = K.replace_column(f.U, f.R, f.perm, f.k, slot, d, f.fw[1], f.fw[2], *f.tols)
        assert upd == expect
        if upd == K.UPD_UNSTABLE:
            assert np.array_equal(f.U, U0)


@pytest.mark.parametrize("tols", [{"stab_tol": 0.0}, {"growth": 1.0},
                                  {"update_tol": 1e-2}])
def test_extreme_update_tolerances_keep_the_solves_accurate(tols):
    """Each safeguard at its extreme (every tiny disagreement of the two diagonals, every
    multiplier above 1, every pivot under 1% declined): the factors fall back to
    refactorizations where they must and the solves stay within the backward tolerance."""
    n = 40
    rng = np.random.default_rng(11)
    M, r = rng.standard_normal((n, n)), rng.standard_normal(n)
    f = Factors(M, r, *_random_table(n, rng), limit=30, **tols)
    worst, _ = _random_sequence(f, rng, 200)
    assert worst <= BACKWARD_TOL
    counts = np.bincount(f.outcomes, minlength=5)
    declined = {"stab_tol": K.UPD_UNSTABLE, "growth": K.UPD_GROWTH,
                "update_tol": K.UPD_REFUSED}[next(iter(tols))]
    assert counts[declined] >= 5
