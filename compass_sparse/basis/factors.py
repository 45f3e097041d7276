"""The factors of the basis manager: the LU of B over positions and its Forrest-Tomlin
row etas (the mathematics: :mod:`compass_sparse.basis.manager`).

:class:`UpdatedFactors` holds L, U (with room for the updates' appended columns and a
dead-column mask), the row etas R_1 ... R_k, the row and column permutations (positions
of rows and of slots) and the row scaling S; it solves with B (FTRAN) and B^T (BTRAN) and
makes one Forrest-Tomlin update -- or declines it, for the basis manager, which owns the
slot table and decides what a declined update costs (a refusal, or a fresh
factorization).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels as kern

__all__ = ["UpdatedFactors"]

_I = np.int64


class UpdatedFactors:
    """L and U of ``S P B Q = L U`` over positions, and the row etas of the updates since.

    Built from the assembled CSC arrays of a fresh factorization: ``n`` the order, ``m1``
    the unit slots (the first positions), ``rowpos`` the position of each row, ``slot_at``
    the slot at each position, ``Ud`` U's diagonal, ``rscale`` the row scaling S (or
    None), ``L`` and ``U`` (x, i, p) arrays over positions, ``update_limit`` the updates
    to make room for."""

    def __init__(self, n, m1, rowpos, slot_at, Ud, rscale, L, U, update_limit):
        Lx, Li, Lp = L
        Ux, Ui, Up = U
        cap_cols = n + update_limit + 2
        self.n = n
        self.Lp, self.Li, self.Lx = Lp, Li, Lx
        nnzu = int(Up[n])
        cap = max(2 * nnzu + 4 * n, 1024)
        self.Ui = np.zeros(cap, dtype=_I)
        self.Ux = np.zeros(cap)
        self.Ui[:nnzu] = Ui
        self.Ux[:nnzu] = Ux
        self.Us = np.zeros(cap_cols, dtype=_I)
        self.Ue = np.zeros(cap_cols, dtype=_I)
        self.Us[:n] = Up[:-1]
        self.Ue[:n] = Up[1:]
        self.Us[n:] = nnzu
        self.Ue[n:] = nnzu
        self.Ufree = nnzu
        # Row forms of L and U (for BTRAN and the update's U^{-T} e_p) are built on first
        # use: a path without pivots never needs them (0.4 s each at n = 1e5).
        self.row_forms = None
        self.LU0 = (Lx, Li, Lp, Ux, Ui, Up)
        self.dead = np.zeros(cap_cols, dtype=np.bool_)
        self.Ud = np.ones(cap_cols)
        self.Ud[:n] = Ud
        rcap = max(4 * n, 1024)
        self.Rs = np.zeros(cap_cols + 1, dtype=_I)
        self.Ri = np.zeros(rcap, dtype=_I)
        self.Rx = np.zeros(rcap)
        self.Rpos = np.zeros(cap_cols, dtype=_I)
        self.Rq = np.zeros(cap_cols, dtype=_I)
        self.k = 0  #: updates since the factorization
        self.m1 = m1
        self.rowpos = rowpos
        self.rscale = rscale
        self.slot_at = np.concatenate((slot_at, np.full(cap_cols - n, -1, dtype=_I)))
        self.pos_of_slot = np.empty(n, dtype=_I)
        self.pos_of_slot[slot_at] = np.arange(n, dtype=_I)
        self.nnzL = int(Lp[n])
        self.nnzU = int(nnzu) + n
        self.nnzR = 0
        self.nnz_base = self.nnzL + self.nnzU

    def work(self):
        return np.zeros(self.n + self.k + 1)

    def scatter_rhs(self, w, rows, vals):
        if self.rscale is not None:
            vals = vals * self.rscale[rows]
        w[self.rowpos[rows]] = vals

    def ftran_work(self, w, keep_spike):
        """w holds S P a; returns (x over slots, spike or None)."""
        kern.lsolve(self.Lp, self.Li, self.Lx, w, self.m1)
        kern.apply_etas(self.Rs, self.Ri, self.Rx, self.Rpos, self.Rq, self.k, w)
        N = self.n + self.k
        spike = w[:N].copy() if keep_spike else None
        kern.usolve(self.Us, self.Ue, self.Ui, self.Ux, self.Ud, w, N)
        return w[self.pos_of_slot], spike

    def rows(self):
        """(Lrp, Lri, Lrx, Urp, Urj, Urx): CSR arrays of L and of U as factored (built once
        per factorization, on first use)."""
        if self.row_forms is None:
            n = self.n
            Lx, Li, Lp, Ux, Ui, Up = self.LU0
            out = []
            for (x, i, p) in ((Lx, Li, Lp), (Ux, Ui, Up)):
                R = sp.csc_matrix((x, i, p), shape=(n, n)).tocsr()
                out += [R.indptr.astype(_I, copy=False), R.indices.astype(_I, copy=False),
                        R.data]
            self.row_forms = tuple(out)
        return self.row_forms

    def utsolve(self, w, start, N):
        _, _, _, Urp, Urj, Urx = self.rows()
        kern.utsolve(Urp, Urj, Urx, self.dead, self.n, self.Us,
                     self.Ue, self.Ui, self.Ux, self.Ud, w, start, N)

    def btran_work(self, c):
        N = self.n + self.k
        w = self.work()
        w[self.pos_of_slot] = c
        self.utsolve(w, 0, N)
        kern.apply_etas_t(self.Rs, self.Ri, self.Rx, self.Rpos, self.Rq, self.k, w)
        Lrp, Lri, Lrx = self.rows()[:3]
        kern.ltsolve(Lrp, Lri, Lrx, w, self.m1)
        y = w[self.rowpos]
        if self.rscale is not None:
            y = y * self.rscale
        return y

    def solve(self, v):
        """B^{-1} v over slots, without counts or checks (a preconditioner's solve; the
        columns of a 2-d v one at a time)."""
        if v.ndim == 2:   # several right-hand sides (lockstep GMRES)
            return np.column_stack([self.solve(v[:, c]) for c in range(v.shape[1])])
        w = self.work()
        self.scatter_rhs(w, np.arange(self.n), np.asarray(v, float).ravel())
        return self.ftran_work(w, False)[0]

    def update(self, slot, spike, d, pivot_tolerance, stability_tolerance, fill_factor):
        """Replace the column of ``slot`` by the column whose spike (the FTRAN stopped
        before U) is ``spike`` and whose FTRAN is ``d``: "ok" when done; "refused" when the
        new pivot is relatively tiny (the new basis would be singular or nearly so:
        nothing changed); "unstable" when the two computations of the new diagonal differ
        by more than ``stability_tolerance`` (relative), "fill" when L, U and the etas would
        exceed ``fill_factor`` times the factorization's entries -- both unchanged too,
        for a refactorization."""
        n, k = self.n, self.k
        N = n + k
        p = int(self.pos_of_slot[slot])
        s = spike
        alpha = d[slot]
        upp = self.Ud[p]
        d1 = alpha * upp
        snorm = np.abs(s).max() if s.size else 0.0
        dnorm = np.abs(d).max()
        ptol = pivot_tolerance
        if (not np.isfinite(d1) or not np.isfinite(dnorm) or abs(d1) <= ptol * snorm
                or abs(alpha) <= ptol * dnorm or d1 == 0.0):
            return "refused"
        y = np.zeros(N)
        y[p] = 1.0
        self.utsolve(y, p, N)
        d2 = upp * kern.dot_from(y, s, p)
        if not np.isfinite(d2) or abs(d1 - d2) > stability_tolerance * abs(d1):
            return "unstable"
        if abs(d2) <= ptol * snorm:
            return "refused"
        eta_i = (p + 1 + np.flatnonzero(y[p + 1:])).astype(_I)
        eta_x = -upp * y[eta_i]
        col_i = np.flatnonzero(s).astype(_I)
        col_i = col_i[col_i != p]
        col_x = s[col_i]
        old_len = int(self.Ue[p] - self.Us[p])
        new_total = (self.nnzL + self.nnzU - old_len + col_i.size + self.nnzR
                     + eta_i.size)
        if new_total > fill_factor * self.nnz_base:
            return "fill"
        self._commit(p, N, slot, d2, col_i, col_x, eta_i, eta_x, old_len)
        return "ok"

    def _commit(self, p, q, slot, d2, col_i, col_x, eta_i, eta_x, old_len):
        """Append the spike as column q, kill column p, store the row eta."""
        k = self.k
        need = self.Ufree + col_i.size
        if need > self.Ui.size:
            newcap = max(2 * self.Ui.size, need + 1024)
            self.Ui = np.concatenate((self.Ui, np.zeros(newcap - self.Ui.size, _I)))
            self.Ux = np.concatenate((self.Ux, np.zeros(newcap - self.Ux.size)))
        f = self.Ufree
        self.Ui[f:f + col_i.size] = col_i
        self.Ux[f:f + col_i.size] = col_x
        self.Us[q], self.Ue[q] = f, f + col_i.size
        self.Ufree = f + col_i.size
        self.Ud[q] = d2
        self.Ue[p] = self.Us[p]
        self.Ud[p] = 1.0
        self.dead[p] = True
        r0 = self.Rs[k]
        need = r0 + eta_i.size
        if need > self.Ri.size:
            newcap = max(2 * self.Ri.size, need + 1024)
            self.Ri = np.concatenate((self.Ri, np.zeros(newcap - self.Ri.size, _I)))
            self.Rx = np.concatenate((self.Rx, np.zeros(newcap - self.Rx.size)))
        self.Ri[r0:need] = eta_i
        self.Rx[r0:need] = eta_x
        self.Rs[k + 1] = need
        self.Rpos[k] = p
        self.Rq[k] = q
        self.k = k + 1
        self.slot_at[p] = -1
        self.slot_at[q] = slot
        self.pos_of_slot[slot] = q
        self.nnzU += col_i.size - old_len
        self.nnzR += eta_i.size
