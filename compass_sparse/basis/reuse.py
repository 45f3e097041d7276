"""Reused factors: the solves of a basis on the LU of an older one, by GMRES.

Successive Newton steps factor bases with the same slot table whose M columns have moved a
little.  After ``set_matrix`` with an unchanged pattern, a ``factor`` with the slot table of
the held factors keeps them: they are the LU of an older basis P, and each solve with the
new B runs GMRES preconditioned by P (:mod:`compass_sparse.basis.krylov`).  The crash's
last reduced Jacobian can be offered the same way, as the factors of a basis whose M
columns are its labels (:meth:`FactorReuse.offer`).  A solve is accepted only when its
true backward error is at most ``reuse_tolerance``; otherwise the manager factors afresh
(see :mod:`compass_sparse.basis.manager`).
"""
from __future__ import annotations

import logging

import numpy as np

from ..linalg.blas import single_threaded_blas
from .backends import BYTES_PER_ENTRY
from .krylov import preconditioned_gmres
from .types import KIND_M, KIND_UNIT

__all__ = ["FactorReuse"]

_I = np.int64

log = logging.getLogger("compass_sparse.basis.manager")


class FactorReuse:
    """The factors a basis manager ``bm`` may solve on instead of factoring: its own held
    ones (of an older basis with the same slot table) or offered ones (a principal block
    of M, e.g. the crash's).  ``psolve`` is the preconditioner's solve of the factors in
    use; ``aged`` says that a slow convergence asks the next factor() to factor afresh."""

    def __init__(self, bm):
        self.bm = bm
        self.options = bm.options
        self.held = None     # (kinds, indices, signs) of the basis of the held factors
        self.aged = False
        self.offered = None  # (labels, HeldLU) of a principal block of M, e.g. the crash's
        self.psolve = bm.solve_quiet

    def reset(self):
        """Fresh factors: nothing held, nothing offered."""
        self.held = None
        self.offered = None
        self.psolve = self.bm.solve_quiet
        self.aged = False

    def can_reuse(self, factors) -> bool:
        """Whether the held factors (``factors``, the manager's) serve its current slot
        table."""
        bm = self.bm
        h = self.held
        ok = (self.options.reuse_factors and h is not None and not self.aged
              and factors.nnz_base >= self.options.reuse_min_nnz
              and np.array_equal(h[0], bm.kinds) and np.array_equal(h[1], bm.indices)
              and np.array_equal(h[2], bm.signs))
        if ok:
            self.psolve = bm.solve_quiet
        return ok

    def offer(self, labels, held):
        """Offer the LU ``held`` (a :class:`~compass_sparse.basis.backends.HeldLU`) of a
        matrix close to the principal block ``M[labels, labels]`` (increasing labels), e.g.
        the crash's last reduced Jacobian: a later :meth:`factor` of a basis whose M
        columns are exactly ``labels`` and whose unit columns cover the other rows solves
        on it by GMRES instead of factoring (``reuse_factors``; the same fallbacks)."""
        bm = self.bm
        labels = np.asarray(labels, dtype=_I)
        if not (self.options.reuse_factors and held is not None and held.n == labels.size
                and labels.size and np.all(np.diff(labels) > 0) and labels[-1] < bm.n):
            return
        est, nnz = held.ordering.nnz_lu, int(getattr(held.lu, "nnz", 0))
        if nnz < self.options.reuse_min_nnz:
            return      # a fresh factorization is cheaper than GMRES on these
        if est > 0 and nnz > est:
            # Pivoting left the diagonal the ordering counted on (the crash's points are
            # far from the solution): each solve with these factors costs more than with
            # a fresh factorization of the basis (2x fill measured on the static CGE model
            # at n = 3e4, tax abolition; the solve took 16 s with them, 13 s without).
            return
        self.offered = (labels, held)

    def offer_fits(self) -> bool:
        """Whether the offered factors serve the manager's current slot table."""
        bm = self.bm
        if self.offered is None or self.aged or not self.options.reuse_factors:
            return False
        labels = self.offered[0]
        k, i = bm.kinds, bm.indices
        km, ku = k == KIND_M, k == KIND_UNIT
        if not np.all(km | ku) or km.sum() != labels.size:
            return False
        if not np.array_equal(np.sort(i[km]), labels):
            return False
        cov = np.zeros(bm.n, dtype=bool)
        cov[i[ku]] = True
        if cov.sum() != ku.sum() or cov[labels].any():
            return False
        self.psolve = self.offered_solve
        # the factors in use are the offered ones: report their figures
        held, st = self.offered[1], bm.stats
        o = held.ordering
        st.backend, st.ordering = "superlu", o.method
        st.est_nnz_lu = max(st.est_nnz_lu, o.nnz_lu)
        st.est_flops = max(st.est_flops, o.flops)
        if o.nnz_lu >= 0:
            st.est_bytes = max(st.est_bytes, BYTES_PER_ENTRY * o.nnz_lu)
        st.max_nnz_lu = max(st.max_nnz_lu, int(getattr(held.lu, "nnz", 0)))
        return True

    def offered_solve(self, v):
        """P^{-1} v for P the current basis with its M block on ``labels`` replaced by the
        offered matrix: the M columns on the labelled rows first, then the unit columns
        (they cover the other rows)."""
        bm = self.bm
        labels, held = self.offered
        k, i, g = bm.kinds, bm.indices, bm.signs
        g = g if v.ndim == 1 else g[:, None]      # (v may hold several right-hand sides)
        y = held.solve(v[labels])                 # (M_LL) y = v_L, y by label
        x = np.empty(v.shape)
        km = np.flatnonzero(k == KIND_M)
        x[km] = y[np.searchsorted(labels, i[km])] / g[km]
        ku = np.flatnonzero(k == KIND_UNIT)
        if ku.size:
            yfull = np.zeros(v.shape)
            yfull[labels] = y
            t = bm.matrix @ yfull
            x[ku] = (v[i[ku]] - t[i[ku]]) / g[ku]
        return x

    def solve(self, rhs, more=()):
        """x with B x = rhs by GMRES on the held factors, or None when it does not reach
        ``reuse_tolerance`` (backward error) within ``reuse_iterations`` steps.  With
        ``more`` (other right-hand sides), the list of the solutions of all, solved in
        lockstep (one preconditioner solve of all per step)."""
        bm = self.bm
        o = self.options
        nb = bm.norm_inf_B()
        cols = [rhs, *more]
        bns = [float(np.abs(c).max()) if bm.n else 0.0 for c in cols]

        # GMRES's 2-norm target is a guide (||x|| is estimated by ||x0||, x0 = P^{-1} rhs;
        # the 2-norm bounds the inf-norm); the check below decides.  Its vector operations
        # are level-1 BLAS: threads only slow them (10x measured at n = 3e4, busy machine).
        def target(bn):
            return lambda x0: 0.5 * o.reuse_tolerance * (bn + nb * float(np.abs(x0).max()))

        def berr(x, c):
            if not np.all(np.isfinite(x)):
                return np.inf, np.inf
            res = float(np.abs(bm.matvec(x) - cols[c]).max()) if bm.n else 0.0
            den = bns[c] + nb * (float(np.abs(x).max()) if bm.n else 0.0)
            return (res / den if den > 0 else res), den

        st = bm.stats
        st.reuse_solves += len(cols)
        with single_threaded_blas():
            X, steps, _ = preconditioned_gmres(
                bm.matvec, self.psolve, cols[0] if not more else np.column_stack(cols),
                target(bns[0]) if not more else [target(b) for b in bns],
                o.reuse_iterations)
            X = [X] if not more else [X[:, c] for c in range(len(cols))]
            out = []
            for c, x in enumerate(X):
                err, den = berr(x, c)
                if o.reuse_tolerance < err <= 1e3 * o.reuse_tolerance \
                        and steps < o.reuse_iterations:
                    # One restart: GMRES's own residual estimate may end just short of
                    # the true backward error (2.9e-12 for 1e-12 measured at n = 1e5);
                    # when it is that close, a correction continues from x with the
                    # steps left instead of factoring afresh.
                    dx, k, _ = preconditioned_gmres(bm.matvec, self.psolve,
                                                    cols[c] - bm.matvec(x),
                                                    0.1 * o.reuse_tolerance * den,
                                                    o.reuse_iterations - steps)
                    st.reuse_steps += k
                    x = x + dx
                    err, _ = berr(x, c)
                log.debug("solve on reused factors: %d GMRES steps, backward error %.1e",
                          steps, err)
                out.append(x if err <= o.reuse_tolerance else None)
        st.reuse_steps += steps
        if steps > o.reuse_iterations // 2:
            self.aged = True    # the next factor() call factors afresh
        return out if more else out[0]
