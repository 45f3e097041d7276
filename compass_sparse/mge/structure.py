"""From declarations to flat arrays: leaves, nest nodes, edges and chains.

Every netput (an input, an output or a final demand of one owner) is a *leaf*; every nest
of every owner that has leaves beneath it is a *node* with a price-index variable π_n
(MPSGE's "virtual" cost-function variable).  With ρ = 1 - σ for input and demand nests
and ρ = 1 + τ for output (CET) nests, node n with children c of benchmark values v_c
(v = reference quantity x reference price for a leaf, the sum beneath for a node),
θ_c = v_c / Σ v, satisfies

    π_n = ( Σ_c θ_c π_c^ρ )^(1/ρ)          (ρ = 0: Π_c π_c^θ_c, Cobb–Douglas)

where a leaf's price index is ℓ_e = p_c (1 + T_e) / p̄_e for an input (T_e the sum of its
ad-valorem tax rates), p_c (1 - T_e) / p̄_e for an output, p_c / p̄_e for a final demand.
The quantity of leaf e per unit of its owner's activity, with chain n_1 (parent), ...,
n_K (root), is

    x_e = q_e (ℓ_e / π_{n_1})^(ρ_{n_1} - 1) Π_{k<K} (π_{n_k} / π_{n_{k+1}})^(ρ_{n_{k+1}} - 1),

that is log x_e = log q_e + a_e log ℓ_e + Σ_k c_k log π_{n_k}, with a_e = ρ_{n_1} - 1,
c_k = ρ_{n_{k+1}} - ρ_{n_k} (k < K) and c_K = 1 - ρ_{n_K}.  A demand leaf has one more
factor, 1 / π_root (demand is income over the price of a unit of utility).

Elasticities: σ (or τ) = inf is replaced by ``SIGMA_INF``: the price index then differs
from the min (max for CET) of its children's prices by a factor θ^(1/(1-σ)), that is by
|log θ| / SIGMA_INF in relative terms.
"""
from __future__ import annotations

import numpy as np

from .declare import DeclarationError
from .expr import Context, concat, triplets

SIGMA_INF = 1e4
"""Elasticity used for σ = inf (perfect substitutes) and τ = inf (perfect transformation)."""

TREES = {"input": 0, "output": 1, "demand": 2}


class Structure:
    """The flat arrays of a model at the current parameter values (see module doc)."""

    def __init__(self, model):
        self.model = model
        params = model.params
        self.n_decl = model.ncols
        self.pruned = []   # columns of sectors and commodities without data (prune=True)
        self._leaves(params)
        self._nodes(params)
        self._edges_and_chains()
        self._endowments(params)
        self._aux()
        self._check_markets()
        self.pruned = np.array(sorted(set(self.pruned)), dtype=np.int64)
        self.n = self.n_decl + self.n_nodes

    # ------------------------------------------------------------------ leaves
    def _leaves(self, params):
        cols = {k: [] for k in ("owner", "comm", "q", "pbar", "tree", "block", "pos", "nest")}
        tax_leaf, tax_agent, tax_expr = [], [], []
        count = 0
        for b, blk in enumerate(self.model.blocks):
            names = list(blk.nests)
            for np_ in blk.netputs:
                own, com = np_["pairs"][:2]
                q = np.broadcast_to(np_["q"].value(params), own.shape).astype(float)
                p = np.broadcast_to(np_["p"].value(params), own.shape).astype(float)
                bad = np.flatnonzero(q < 0)
                if bad.size:
                    i = bad[0]
                    raise DeclarationError(
                        f"{blk.location()[:-len(repr(blk.owner))]}{blk.owner.names[own[i]]}: "
                        f"negative reference quantity {q[i]:g} of "
                        f"{np_['comm'].names[com[i]]} (a {np_['tree']}); a netput quantity "
                        "must be >= 0 (use an output for a negative input)")
                bad = np.flatnonzero((p <= 0) & (q > 0))
                if bad.size:
                    i = bad[0]
                    raise DeclarationError(
                        f"{blk.WHAT} block of {blk.owner.names[own[i]]}: reference price "
                        f"{p[i]:g} of {np_['comm'].names[com[i]]} must be > 0")
                keep = np.flatnonzero(q > 0)
                cols["owner"].append(blk.owner.cols[own[keep]])
                cols["comm"].append(np_["comm"].cols[com[keep]])
                cols["q"].append(q[keep])
                cols["pbar"].append(p[keep])
                cols["tree"].append(np.full(keep.size, TREES[np_["tree"]]))
                cols["block"].append(np.full(keep.size, b))
                cols["pos"].append(own[keep])
                cols["nest"].append(np.full(keep.size, names.index(np_["nest"])))
                for agent, rate in np_["taxes"]:
                    r = rate if rate.size == 1 else rate[keep]
                    tax_leaf.append(count + np.arange(keep.size))
                    tax_agent.append(np.asarray(agent, np.int64)[keep])
                    tax_expr.append(r[np.zeros(keep.size, np.int64)] if rate.size == 1 else r)
                count += keep.size
        cat = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in cols.items()}
        self.leaf_owner = cat["owner"].astype(np.int64)
        self.leaf_comm = cat["comm"].astype(np.int64)
        self.leaf_q, self.leaf_pbar = cat["q"], cat["pbar"]
        self.leaf_tree = cat["tree"].astype(np.int64)
        self._leaf_block = cat["block"].astype(np.int64)
        self._leaf_pos = cat["pos"].astype(np.int64)
        self._leaf_nest = cat["nest"].astype(np.int64)
        self.n_leaves = count
        # Taxes raise an input's price index and lower an output's.
        self.leaf_tax_sign = np.choose(self.leaf_tree, [1.0, -1.0, 0.0]) if count else cat["q"]
        self.leaf_flow_sign = np.where(self.leaf_tree == 1, 1.0, -1.0)
        self.tax_leaf = np.concatenate(tax_leaf) if tax_leaf else np.zeros(0, np.int64)
        self.tax_agent = np.concatenate(tax_agent) if tax_agent else np.zeros(0, np.int64)
        rates = concat(tax_expr) if tax_expr else None
        self.tax_rates = rates
        self.tax_variable = rates is not None and rates.has_variables()
        self.tax_const = (rates.value(params) if rates is not None and not self.tax_variable
                          else None)

    # ------------------------------------------------------------------ nodes
    def _nodes(self, params):
        """One node per (block, nest, owner) with leaves beneath it."""
        model = self.model
        node_block, node_nest, node_pos = [], [], []
        self._node_id = []
        total = 0
        ids = []
        for b, blk in enumerate(model.blocks):
            names = list(blk.nests)
            alive = np.zeros((len(names), blk.n), bool)
            sel = self._leaf_block == b
            alive[self._leaf_nest[sel], self._leaf_pos[sel]] = True
            for k in range(len(names) - 1, -1, -1):  # children are declared after parents
                parent = blk.nests[names[k]][0]
                if parent is not None:
                    alive[names.index(parent)] |= alive[k]
            self._check_roots(blk, names, alive)
            table = np.full((len(names), blk.n), -1, np.int64)
            for k in range(len(names)):
                pos = np.flatnonzero(alive[k])
                table[k, pos] = total + np.arange(pos.size)
                node_block.append(np.full(pos.size, b))
                node_nest.append(np.full(pos.size, k))
                node_pos.append(pos)
                total += pos.size
            ids.append(table)
        self._node_id = ids
        self.n_nodes = total
        self.node_block = np.concatenate(node_block).astype(np.int64)
        self.node_nest = np.concatenate(node_nest).astype(np.int64)
        self.node_pos = np.concatenate(node_pos).astype(np.int64)
        self.node_col = self.n_decl + np.arange(total)
        rho = np.empty(total)
        parent = np.full(total, -1, np.int64)
        tree = np.empty(total, np.int64)
        for b, blk in enumerate(model.blocks):
            names = list(blk.nests)
            for k, name in enumerate(names):
                par, sigma, tr = blk.nests[name]
                sel = (self.node_block == b) & (self.node_nest == k)
                pos = self.node_pos[sel]
                s = np.broadcast_to(sigma.value(params), (blk.n,))[pos]
                if np.any(s < 0) or np.any(np.isnan(s)):
                    raise DeclarationError(f"{blk.location()}: elasticity of nest {name!r} "
                                           "must be >= 0")
                s = np.minimum(s, SIGMA_INF)
                rho[sel] = 1.0 + s if tr == "output" else 1.0 - s
                tree[sel] = TREES[tr]
                if par is not None:
                    parent[sel] = ids[b][names.index(par), pos]
        self.node_rho, self.node_parent, self.node_tree = rho, parent, tree
        owners = [blk.owner.cols for blk in model.blocks]
        self.node_owner = _owner_cols(owners, self.node_block, self.node_pos)
        self.leaf_parent = _lookup(ids, self._leaf_block, self._leaf_nest, self._leaf_pos)

    def _check_roots(self, blk, names, alive):
        empty = ~alive.any(axis=0)
        if self.model.prune and blk.WHAT == "production":
            # An owner without any data is dropped (MPSGE prunes it): fixed at its start.
            self.pruned.extend(blk.owner.cols[empty].tolist())
        for k, name in enumerate(names):
            par, _, tree = blk.nests[name]
            if par is None:
                dead = np.flatnonzero(~alive[k] & ~(empty & self.model.prune
                                                   & (blk.WHAT == "production")))
                if dead.size:
                    what = {"input": "no inputs", "output": "no outputs",
                            "demand": "no final demand"}[tree]
                    raise DeclarationError(
                        f"{blk.WHAT} block of {blk.owner.names[dead[0]]} has {what} "
                        f"(all its {tree} quantities are zero or none were declared)")

    # ------------------------------------------------------------------ edges, chains
    def _edges_and_chains(self):
        L, N = self.n_leaves, self.n_nodes
        val = self.leaf_q * self.leaf_pbar
        # Benchmark value of every node: leaves' values summed up the tree.
        depth = np.zeros(N, np.int64)
        cur = self.node_parent.copy()
        while np.any(cur >= 0):
            live = cur >= 0
            depth[live] += 1
            cur[live] = self.node_parent[cur[live]]
        self.max_depth = int(depth.max()) if N else 0
        V = np.bincount(self.leaf_parent, weights=val, minlength=N)
        for d in range(self.max_depth, 0, -1):
            sel = np.flatnonzero(depth == d)
            np.add.at(V, self.node_parent[sel], V[sel])
        self.node_value, self.node_depth = V, depth
        child_nodes = np.flatnonzero(self.node_parent >= 0)
        e_parent = np.concatenate([self.leaf_parent, self.node_parent[child_nodes]])
        e_child = np.concatenate([np.arange(L), child_nodes])
        e_leaf = np.concatenate([np.ones(L, bool), np.zeros(child_nodes.size, bool)])
        e_val = np.concatenate([val, V[child_nodes]])
        order = np.argsort(e_parent, kind="stable")
        self.edge_parent, self.edge_child = e_parent[order], e_child[order]
        self.edge_leaf = e_leaf[order]
        self.edge_logtheta = np.log(e_val[order] / V[self.edge_parent])
        self.edge_starts = np.flatnonzero(np.r_[True, np.diff(self.edge_parent) != 0])
        # Chains: (leaf, node, coefficient of log π_node in log x_leaf).
        rho = self.node_rho
        self.leaf_a = rho[self.leaf_parent] - 1.0
        pl, pn, pc = [], [], []
        leaf = np.arange(L)
        node = self.leaf_parent.copy()
        while leaf.size:
            par = self.node_parent[node]
            root = par < 0
            c = np.where(root, 1.0 - rho[node], rho[np.where(root, 0, par)] - rho[node])
            c = np.where(root & (self.leaf_tree[leaf] == 2), c - 1.0, c)
            pl.append(leaf), pn.append(node), pc.append(c)
            leaf, node = leaf[~root], par[~root]
        self.pair_leaf = np.concatenate(pl) if pl else np.zeros(0, np.int64)
        self.pair_node = np.concatenate(pn) if pn else np.zeros(0, np.int64)
        self.pair_coef = np.concatenate(pc) if pc else np.zeros(0)
        # Activity of a leaf's owner: Y for a sector, M / V_root for a consumer.
        root_of_leaf = self.pair_node[self._root_pair_index()]
        self.leaf_scale = np.where(self.leaf_tree == 2, 1.0 / V[root_of_leaf], 1.0)
        self.zp_in, self.zp_out = self._roots(0), self._roots(1)
        self.demand_root = self._roots(2)

    def _root_pair_index(self):
        """For every leaf, the position of its root pair in the pair arrays."""
        is_root = self.node_parent[self.pair_node] < 0
        idx = np.empty(self.n_leaves, np.int64)
        idx[self.pair_leaf[is_root]] = np.flatnonzero(is_root)
        return idx

    def _roots(self, tree):
        sel = np.flatnonzero((self.node_parent < 0) & (self.node_tree == tree))
        return self.node_owner[sel], sel

    # ------------------------------------------------------------------ endowments, aux
    def _endowments(self, params):
        cons, comm, exprs = [], [], []
        for blk in self.model.blocks:
            for en in getattr(blk, "endowments", ()):
                own, com = en["pairs"][:2]
                q = en["q"]
                if not q.has_variables():
                    v = np.broadcast_to(q.value(params), own.shape)
                    keep = np.flatnonzero(v != 0)
                    own, com = own[keep], com[keep]
                    q = concat([np.asarray(v[keep], float)]) if keep.size else None
                    if q is None:
                        continue
                elif q.size == 1:
                    q = q[np.zeros(own.size, np.int64)]
                cons.append(blk.owner.cols[own])
                comm.append(en["comm"].cols[com])
                exprs.append(q)
        self.end_cons = np.concatenate(cons) if cons else np.zeros(0, np.int64)
        self.end_comm = np.concatenate(comm) if comm else np.zeros(0, np.int64)
        self.end_expr = concat(exprs) if exprs else None
        self.end_variable = self.end_expr is not None and self.end_expr.has_variables()
        self.end_const = (self.end_expr.value(params) if self.end_expr is not None
                          and not self.end_variable else None)

    def _aux(self):
        model = self.model
        rows, exprs = [], []
        for aux, expr in model.constraints:
            rows.append(aux.cols)
            exprs.append(expr)
        self.aux_rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        self.aux_expr = concat(exprs) if exprs else None

    def _check_markets(self):
        model = self.model
        seen = np.zeros(self.n_decl, bool)
        seen[self.leaf_comm] = True
        seen[self.end_comm] = True
        owned = np.zeros(self.n_decl, bool)
        owned[self.node_owner] = True
        covered = np.zeros(self.n_decl, bool)
        covered[self.aux_rows] = True
        for vs in model.sets:
            cols = vs.cols
            if vs.kind == "commodity":
                bad = np.flatnonzero(~seen[cols])
                msg = "has no market: no block supplies, demands or endows it"
            elif vs.kind in ("sector", "consumer"):
                bad = np.flatnonzero(~owned[cols])
                msg = ("has no production block" if vs.kind == "sector"
                       else "has no demand block")
            else:
                bad = np.flatnonzero(~covered[cols])
                msg = "has no constraint (declare one with Model.constraint)"
            if bad.size and model.prune and vs.kind == "commodity":
                self.pruned.extend(cols[bad].tolist())
                continue
            if vs.kind == "sector" and model.prune:
                bad = np.setdiff1d(cols[bad], self.pruned)
                bad = np.searchsorted(cols, bad)
            if bad.size:
                raise DeclarationError(f"{vs.element_name(int(bad[0]))} {msg} "
                                       f"({bad.size} such elements of {vs.name})")

    # ------------------------------------------------------------------ naming
    def node_names(self):
        """'owner.nest' for every node (one pass per block)."""
        out = np.empty(self.n_nodes, dtype=object)
        for b, blk in enumerate(self.model.blocks):
            sel = np.flatnonzero(self.node_block == b)
            if sel.size:
                owners = blk.owner.names
                nests = list(blk.nests)
                out[sel] = [f"{owners[p]}.{nests[k]}" for p, k in
                            zip(self.node_pos[sel].tolist(), self.node_nest[sel].tolist())]
        return out.tolist()


def _owner_cols(owners, block, pos):
    out = np.empty(block.shape[0], np.int64)
    for b, cols in enumerate(owners):
        sel = block == b
        out[sel] = cols[pos[sel]]
    return out


def _lookup(ids, block, nest, pos):
    out = np.empty(block.shape[0], np.int64)
    for b, table in enumerate(ids):
        sel = block == b
        out[sel] = table[nest[sel], pos[sel]]
    return out


def structural_triplets(expr, x, params):
    """The (rows, cols) of an expression's Jacobian (values ignored)."""
    _, t = expr.evaluate(Context(x, params))
    r, c, _ = triplets(t)
    return r, c
