"""Solutions, benchmark replication and reports.

Quantities reported per unit of activity are MPSGE's *compensated demands*: for sector s
and commodity c, Σ of x_e over the sector's leaves of c (inputs, or outputs with
``output=True``), x_e as in :mod:`.structure`.  Final demand of consumer h for c is
(M_h / V_h) x_e summed over h's leaves of c.

Equivalent variation: utility is homothetic, u_h = M_h / (V_h π_h(p)) with π_h the
consumer's root price index (1 at the reference prices), so the income that buys the new
utility at the old prices is M_h^1 π_h(p^0) / π_h(p^1), and

    EV_h = M_h^1 π_h(p^0) / π_h(p^1) - M_h^0.
"""
from __future__ import annotations

import numpy as np

from .declare import DeclarationError
from .expr import Context, as_expr

__all__ = ["BenchmarkCheck", "Solution", "UnbalancedBenchmark"]

_ROW_KIND = {"sector": "zero_profit", "commodity": "market", "consumer": "income",
             "auxiliary": "constraint"}


class UnbalancedBenchmark(DeclarationError):
    """The reference point does not solve the model: the data are not a balanced SAM."""


def _kind_of_rows(model, st):
    kind = np.empty(st.n, dtype=object)
    for vs in model.sets:
        kind[vs.cols] = _ROW_KIND[vs.kind]
    kind[st.node_col] = "nest"
    return kind


class _Point:
    def __init__(self, model, st, eq, x):
        self.model, self.st, self.eq, self.x = model, st, eq, np.asarray(x, float)

    def value(self, ref):
        """Values of a variable reference or an expression at this point (an array; a
        float for one element)."""
        v = as_expr(ref).evaluate(Context(self.x, self.model.params, False))[0]
        return float(v[0]) if v.shape[0] == 1 else v

    def _leaf_quantities(self):
        ctx = Context(self.x, self.model.params, False)
        ell, _ = self.eq.leaf_prices(self.x, ctx)
        st = self.st
        pin = np.maximum(self.x[st.node_col], 1e-300)
        logx = (np.log(st.leaf_q) + st.leaf_a * np.log(np.maximum(ell, 1e-300))
                + np.bincount(st.pair_leaf, weights=st.pair_coef * np.log(pin[st.pair_node]),
                              minlength=st.n_leaves))
        return np.exp(logx)

    def _select(self, owner, commodity, tree, nest):
        st = self.st
        own = np.asarray(as_expr(owner).cols)
        com = np.asarray(as_expr(commodity).cols)
        if own.size != 1 or com.size != 1:
            raise DeclarationError("give one owner and one commodity")
        sel = (st.leaf_owner == own[0]) & (st.leaf_comm == com[0]) & (st.leaf_tree == tree)
        if nest is not None:
            sel &= self._under(nest)
        return sel

    def _under(self, nest):
        """Leaves with a nest called ``nest`` on their chain."""
        st = self.st
        blocks = self.model.blocks
        hit = np.array([list(blocks[b].nests)[k] == nest for b, k in
                        zip(st.node_block.tolist(), st.node_nest.tolist())], bool)
        out = np.zeros(st.n_leaves, bool)
        out[st.pair_leaf[hit[st.pair_node]]] = True
        return out

    def compensated_demand(self, sector, commodity, nest=None, output=False):
        """Quantity of ``commodity`` per unit of ``sector``'s activity (an input; an
        output with ``output=True``), optionally only beneath ``nest``."""
        sel = self._select(sector, commodity, 1 if output else 0, nest)
        return float(self._leaf_quantities()[sel].sum())

    def final_demand(self, consumer, commodity):
        """Final demand of ``commodity`` by ``consumer`` (a quantity)."""
        sel = self._select(consumer, commodity, 2, None)
        st = self.st
        act = self.x[st.leaf_owner] * st.leaf_scale
        return float((act * self._leaf_quantities())[sel].sum())

    def price_index(self, consumer):
        """The consumer's root price index π_h (1 at reference prices)."""
        st = self.st
        owners, nodes = st.demand_root
        col = int(as_expr(consumer).cols[0])
        return float(self.x[st.node_col[nodes[np.flatnonzero(owners == col)[0]]]])


class BenchmarkCheck(_Point):
    """Residuals F at the reference point, by block: ``by_block`` maps zero_profit,
    market, income, constraint, nest to (max |F|, name of the worst row)."""

    def __init__(self, model, st, eq, x):
        super().__init__(model, st, eq, x)
        F, _ = eq.evaluate(self.x, deriv=False)
        self.F = F
        kind = _kind_of_rows(model, st)
        _, eqn = model.names(st)
        self.by_block = {}
        for k in ("zero_profit", "market", "income", "constraint", "nest"):
            rows = np.flatnonzero(kind == k)
            if rows.size:
                i = rows[np.argmax(np.abs(F[rows]))]
                self.by_block[k] = (float(abs(F[i])), eqn[i])
        self.max = max((v[0] for v in self.by_block.values()), default=0.0)

    def ok(self, tol=1e-8):
        return self.max <= tol

    def require(self, tol=1e-8):
        """Raise UnbalancedBenchmark naming the worst rows when max |F| > tol."""
        if not self.ok(tol):
            bad = [f"{k}: {v[0]:.3g} at {v[1]}" for k, v in self.by_block.items() if v[0] > tol]
            raise UnbalancedBenchmark("the benchmark is not balanced (|F| > "
                                      f"{tol:g}): " + "; ".join(bad))
        return self

    def __repr__(self):
        lines = [f"benchmark residuals (max {self.max:.3g})"]
        lines += [f"  {k:<12s} {v[0]:10.3g}  {v[1]}" for k, v in self.by_block.items()]
        return "\n".join(lines)


class Solution(_Point):
    """A solved model: ``x``, the solver's ``result``, values, demands and reports."""

    def __init__(self, model, st, eq, x, result):
        super().__init__(model, st, eq, x)
        self.result = result
        self.success = bool(result.success)

    def residual(self):
        """max |F| over the rows whose variable is strictly inside its bounds, and the
        complementarity violation at a bound (recomputed here, not taken from the solver);
        rows of fixed variables are not conditions (a fixing removes its row)."""
        F, _ = self.eq.evaluate(self.x, deriv=False)
        lb, ub = self.result.lb, self.result.ub
        x = self.x
        r = np.where(x <= lb, np.minimum(F, 0.0), np.where(x >= ub, np.maximum(F, 0.0), F))
        r[lb == ub] = 0.0
        return float(np.max(np.abs(r))) if r.size else 0.0

    def equivalent_variation(self, baseline):
        """EV per consumer column (money at the baseline's prices), see module doc."""
        st = self.st
        cons, nodes = st.demand_root
        p1 = self.x[st.node_col[nodes]]
        p0 = baseline.x[baseline.st.node_col[nodes]]
        return self.x[cons] * p0 / p1 - baseline.x[cons]

    def report(self, baseline):
        """Rows (name, kind, baseline value, value, % change) for sectors, commodities and
        consumers, plus ('EV[name]', 'ev', M0, EV, EV as % of M0) for every consumer."""
        rows = []
        for vs in self.model.sets:
            if vs.kind == "auxiliary":
                continue
            for k in range(vs.n):
                c = int(vs.cols[k])
                v0, v1 = float(baseline.x[c]), float(self.x[c])
                pct = 100.0 * (v1 / v0 - 1.0) if v0 != 0 else float("nan")
                rows.append((vs.element_name(k), vs.kind, v0, v1, pct))
        ev = self.equivalent_variation(baseline)
        names = {int(c): n for vs in self.model.sets for c, n in
                 zip(vs.cols.tolist(), (vs.element_name(k) for k in range(vs.n)))}
        for c, e in zip(self.st.demand_root[0].tolist(), ev.tolist()):
            m0 = float(baseline.x[c])
            rows.append((f"EV[{names[c]}]", "ev", m0, e, 100.0 * e / m0 if m0 else float("nan")))
        return rows
