"""The MCP of a model in MPSGE's form, F and its exact sparse Jacobian.

Rows are paired with variables (row i is the condition of variable i):

* zero profit of sector s:  V_in π_in(s) - V_out π_out(s) >= 0  _|_  Y_s >= 0
  (unit cost minus unit revenue at the root price indices, V the benchmark values);
* market clearance of commodity c:
  Σ_outputs Y x_e - Σ_inputs Y x_e - Σ_final (M/V) x_e + Σ endowments >= 0  _|_  p_c >= 0;
* income balance of consumer h:
  M_h - Σ_c p_c ω_hc - Σ_{taxes to h} t p Y x_e = 0  _|_  M_h >= 0;
* auxiliary constraints as written  _|_  the auxiliary;
* nest price indices:  π_n - CES_n(children's prices) = 0  _|_  π_n (free);

with leaf quantities x_e (capped at e^``LOGX_MAX`` times the reference quantity) and price indices as in :mod:`.structure`.  CES aggregates are
evaluated in log space (a log-sum-exp, so that large elasticities neither overflow nor
underflow).  Near Cobb–Douglas the log-sum-exp divided by ρ loses about eps/|ρ| to
rounding, so for |ρ| < ``RHO_CD`` = 1e-3 the aggregate is the cumulant expansion

    log π = μ + (ρ/2) κ2 + (ρ²/6) κ3,   μ = Σ θ l,  κ_k = Σ θ (l - μ)^k,

whose error is ρ³ κ4 / 24 (< 1e-11 for log prices within ±1 of each other), and its
exact derivative, θ_c (1 + ρ d_c + (ρ²/2)(d_c² - κ2)) with d = l - μ, is used in J.  Prices are floored at ``PRICE_FLOOR`` inside logarithms.

J is assembled from triplets whose positions are fixed at compilation: one ``bincount``
into the CSC data array per evaluation.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .expr import Context, triplets

RHO_CD = 1e-3
"""|ρ| below which a CES nest uses the expansion about Cobb–Douglas (ρ = 0)."""

PRICE_FLOOR = 1e-300
"""Prices below this are floored inside logarithms (a price of exactly 0 has no index)."""


LOGX_MAX = 300.0
"""Cap on log(quantity / reference quantity) of a netput: beyond it, far from a solution
with a huge elasticity, the quantity is held at e^300 times its reference (finite)."""


class Equations:
    """F(x) and J(x) of a compiled :class:`~.structure.Structure`."""

    def __init__(self, st, params):
        self.st, self.params = st, params
        self.n = st.n
        rho = st.node_rho
        self.tiny = np.abs(rho) < RHO_CD
        self.edge_rho = rho[st.edge_parent]
        self.edge_theta = np.exp(st.edge_logtheta)
        self._pattern = None

    # ------------------------------------------------------------------ pieces
    def _taxes(self, ctx):
        st = self.st
        if st.tax_rates is None:
            return np.zeros(0), None
        if not st.tax_variable:
            return st.tax_const, None
        v, t = st.tax_rates.evaluate(ctx)
        return v, triplets(t)

    def _endow(self, ctx):
        st = self.st
        if st.end_expr is None:
            return np.zeros(0), None
        if not st.end_variable:
            return st.end_const, None
        v, t = st.end_expr.evaluate(ctx)
        return v, triplets(t)

    def _nest_prices(self, lc, shares=False):
        """log π of every node from its children's log prices ``lc`` (by edge), and with
        ``shares`` the derivatives w = d log π_parent / d lc of every edge."""
        st = self.st
        rho, th = self.edge_rho, self.edge_theta
        starts = st.edge_starts
        parent = st.edge_parent
        z = st.edge_logtheta + rho * lc
        m = np.maximum.reduceat(z, starts) if z.size else z
        s = np.add.reduceat(np.exp(z - m[parent]), starts) if z.size else z
        node_rho = st.node_rho
        safe = np.where(self.tiny, 1.0, node_rho)
        logp = (m + np.log(s)) / safe
        w = th * np.exp(rho * (lc - logp[parent])) if shares else None
        if self.tiny.any():
            mu = np.add.reduceat(th * lc, starts)
            dev = lc - mu[parent]
            k2 = np.add.reduceat(th * dev ** 2, starts)
            k3 = np.add.reduceat(th * dev ** 3, starts)
            logp = np.where(self.tiny, mu + node_rho * (0.5 * k2 + node_rho * k3 / 6.0), logp)
            if shares:
                t = self.tiny[parent]
                w = np.where(t, th * (1.0 + rho * dev + 0.5 * rho ** 2 * (dev ** 2 - k2[parent])),
                             w)
        return (logp, w) if shares else logp

    def start_nest_prices(self, x):
        """Fill the nest prices of x bottom-up from the other variables (in place)."""
        st = self.st
        for _ in range(st.max_depth + 1):
            lc = self._child_logs(x, self.leaf_prices(x, Context(x, self.params, False))[0])
            x[st.node_col] = np.exp(self._nest_prices(lc))
        return x

    def leaf_prices(self, x, ctx):
        st = self.st
        t, tt = self._taxes(ctx)
        T = np.bincount(st.tax_leaf, weights=t, minlength=st.n_leaves) if t.size else 0.0
        mult = (1.0 + st.leaf_tax_sign * T) / st.leaf_pbar
        p = x[st.leaf_comm]
        return p * mult, (t, tt, mult, p)

    def _child_logs(self, x, ell):
        st = self.st
        lc = np.empty(st.edge_parent.shape[0])
        leaf = st.edge_leaf
        lc[leaf] = np.log(np.maximum(ell[st.edge_child[leaf]], PRICE_FLOOR))
        lc[~leaf] = np.log(np.maximum(x[st.node_col[st.edge_child[~leaf]]], PRICE_FLOOR))
        return lc

    # ------------------------------------------------------------------ F and J
    def evaluate(self, x, deriv=True):
        """F(x), and the Jacobian triplets (rows, cols, vals) when ``deriv``."""
        st = self.st
        ctx = Context(x, self.params, deriv)
        F = np.zeros(self.n)
        ell, (t, tt, mult, p) = self.leaf_prices(x, ctx)
        lc = self._child_logs(x, ell)
        logp, w = self._nest_prices(lc, shares=True)
        P = np.exp(logp)
        pin = x[st.node_col]
        # Nest rows: π_n - P_n.
        F[st.node_col] = pin - P
        # log x_e and x_e.
        lpin = np.log(np.maximum(pin, PRICE_FLOOR))
        lell = np.log(np.maximum(ell, PRICE_FLOOR))
        logx = (np.log(st.leaf_q) + st.leaf_a * lell
                + np.bincount(st.pair_leaf, weights=st.pair_coef * lpin[st.pair_node],
                              minlength=st.n_leaves))
        # Far from consistent nest prices a large elasticity can ask for exp(>709): the
        # quantity is capped (and its derivative is then that of the cap, zero).
        capped = logx > LOGX_MAX
        xq = np.exp(np.minimum(logx, LOGX_MAX))
        act = x[st.leaf_owner] * st.leaf_scale
        flow = st.leaf_flow_sign * act * xq
        F += np.bincount(st.leaf_comm, weights=flow, minlength=self.n)
        # Endowments: market supply, and income p ω.
        om, omt = self._endow(ctx)
        if om.size:
            F += np.bincount(st.end_comm, weights=om, minlength=self.n)
            F -= np.bincount(st.end_cons, weights=x[st.end_comm] * om, minlength=self.n)
        # Tax revenue t p Y x to its consumer.
        if t.size:
            e = st.tax_leaf
            Y = x[st.leaf_owner[e]]
            rev = t * p[e] * Y * xq[e]
            F -= np.bincount(st.tax_agent, weights=rev, minlength=self.n)
        # Income: M itself.
        cons = st.demand_root[0]
        F[cons] += x[cons]
        # Zero profit.
        (yin, nin), (yout, nout) = st.zp_in, st.zp_out
        F[yin] += st.node_value[nin] * pin[nin]
        F[yout] -= st.node_value[nout] * pin[nout]
        # Auxiliary constraints.
        at = None
        if st.aux_expr is not None:
            av, at = st.aux_expr.evaluate(ctx)
            F[st.aux_rows] += av
        if not deriv:
            return F, None
        return F, self._triplets(x, ell, t, tt, mult, p, w, P, pin, xq, capped, act, om, omt,
                                 at)

    def _triplets(self, x, ell, t, tt, mult, p, w, P, pin, xq, capped, act, om, omt, at):
        """The Jacobian's triplets from the intermediate values of :meth:`evaluate`."""
        st = self.st
        R, C, Vv = [], [], []

        def emit(r, c, v):
            R.append(r), C.append(c), Vv.append(v)

        # Gradient of the leaf price ℓ_e: (leaf, col, value).
        g_leaf = [np.arange(st.n_leaves)]
        g_col = [st.leaf_comm]
        g_val = [mult]
        if tt is not None:
            r, c, v = tt
            e = st.tax_leaf[r]
            g_leaf.append(e), g_col.append(c)
            g_val.append(st.leaf_tax_sign[e] * p[e] / st.leaf_pbar[e] * v)
        gl_leaf, gl_col, gl_val = map(np.concatenate, (g_leaf, g_col, g_val))
        # Nest rows.
        emit(st.node_col, st.node_col, np.ones(st.n_nodes))
        dP = -P[st.edge_parent] * w
        leaf_e = st.edge_leaf
        ch = st.edge_child
        nodes_e = ~leaf_e
        emit(st.node_col[st.edge_parent[nodes_e]], st.node_col[ch[nodes_e]],
             dP[nodes_e] / np.maximum(pin[ch[nodes_e]], PRICE_FLOOR))
        # Leaf-price part: edge (parent, leaf e) with factor dP/ℓ_e, spread over ℓ's gradient.
        dl = np.zeros(st.n_leaves)
        dl[ch[leaf_e]] = dP[leaf_e] / np.maximum(ell[ch[leaf_e]], PRICE_FLOOR)
        parent_of_leaf = st.node_col[st.leaf_parent]
        emit(parent_of_leaf[gl_leaf], gl_col, dl[gl_leaf] * gl_val)
        # Gradient of x_e: (leaf, col, value).
        x_leaf = np.concatenate([st.pair_leaf, gl_leaf])
        x_col = np.concatenate([st.node_col[st.pair_node], gl_col])
        x_val = np.concatenate([
            xq[st.pair_leaf] * st.pair_coef / np.maximum(pin[st.pair_node], PRICE_FLOOR),
            (xq * st.leaf_a / np.maximum(ell, PRICE_FLOOR))[gl_leaf] * gl_val])
        if capped.any():
            x_val[capped[x_leaf]] = 0.0
        # Market rows: flow = sign * act * x.
        emit(st.leaf_comm, st.leaf_owner, st.leaf_flow_sign * st.leaf_scale * xq)
        emit(st.leaf_comm[x_leaf], x_col, (st.leaf_flow_sign * act)[x_leaf] * x_val)
        if om.size:
            emit(st.end_cons, st.end_comm, -om)
            if omt is not None:
                r, c, v = omt
                emit(st.end_comm[r], c, v)
                emit(st.end_cons[r], c, -x[st.end_comm[r]] * v)
        if t.size:
            self._tax_jac(emit, x, t, tt, p, xq, x_leaf, x_col, x_val)
        cons = st.demand_root[0]
        (yin, nin), (yout, nout) = st.zp_in, st.zp_out
        emit(cons, cons, np.ones(cons.shape[0]))
        emit(yin, st.node_col[nin], st.node_value[nin])
        emit(yout, st.node_col[nout], -st.node_value[nout])
        if at is not None:
            r, c, v = triplets(at)
            emit(st.aux_rows[r], c, v)
        return np.concatenate(R), np.concatenate(C), np.concatenate(Vv)

    def _tax_jac(self, emit, x, t, tt, p, xq, x_leaf, x_col, x_val):
        """Derivatives of -t p Y x_e in the income row of the tax's consumer."""
        st = self.st
        e = st.tax_leaf
        own = st.leaf_owner[e]
        Y = x[own]
        a = st.tax_agent
        emit(a, st.leaf_comm[e], -t * Y * xq[e])
        emit(a, own, -t * p[e] * xq[e])
        if tt is not None:
            r, c, v = tt
            emit(a[r], c, -(p[e] * Y * xq[e])[r] * v)
        # x_e's gradient, once for every tax on leaf e.
        gather, k = self._tax_gather(x_leaf)
        emit(np.repeat(a, k), x_col[gather], np.repeat(-t * p[e] * Y, k) * x_val[gather])

    def _tax_gather(self, x_leaf):
        cached = getattr(self, "_gather", None)
        if cached is not None and cached[0] == x_leaf.shape[0]:
            return cached[1], cached[2]
        st = self.st
        order = np.argsort(x_leaf, kind="stable")
        counts = np.bincount(x_leaf, minlength=st.n_leaves)
        starts = np.concatenate(([0], np.cumsum(counts)))
        e = st.tax_leaf
        k = counts[e]
        offs = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
        gather = order[np.repeat(starts[e], k) + offs]
        self._gather = (x_leaf.shape[0], gather, k)
        return gather, k

    # ------------------------------------------------------------------ assembly
    def jacobian(self, x):
        """(F, J) with J a CSC matrix on the fixed pattern."""
        F, (r, c, v) = self.evaluate(x)
        if self._pattern is None or self._pattern[0] != r.shape[0]:
            self._pattern = self._make_pattern(r, c)
        _, slot, indices, indptr, nnz = self._pattern
        data = np.bincount(slot, weights=v, minlength=nnz)
        J = sp.csc_matrix((data, indices, indptr), shape=(self.n, self.n))
        return F, J

    def _make_pattern(self, r, c):
        n = self.n
        key = c.astype(np.int64) * n + r
        uniq, slot = np.unique(key, return_inverse=True)
        indices = (uniq % n).astype(np.int32)
        indptr = np.concatenate(([0], np.cumsum(np.bincount(uniq // n, minlength=n))))
        return (r.shape[0], slot, indices, indptr.astype(np.int32), uniq.shape[0])

    def sparsity(self, x):
        """The structural pattern (a CSC matrix of ones)."""
        _, J = self.jacobian(x)
        P = J.copy()
        P.data[:] = 1.0
        return P
