"""The model: declare, generate the MCP, solve, and re-solve after a change of data.

    m = Model()
    Y = m.sectors("Y", ["agr", "man"]);  P = m.commodities("P", ["agr", "man", "lab"])
    H = m.consumers("H")
    m.production(Y, s=1.0).output(P[["agr", "man"]], [10, 20]).input(P["lab"], [10, 20])
    m.demand(H).final(P[["agr", "man"]], [10, 20]).endowment(P["lab"], 30)
    sol = m.solve()

The MCP is generated from the declarations at each :meth:`Model.mcp` call, so parameters,
bounds and fixings changed since the last solve take effect without rebuilding anything
by hand; the last solution is the next solve's start (a warm start).
"""
from __future__ import annotations

import dataclasses

import numpy as np

import compass_sparse as cs

from .declare import DeclarationError, Demand, Parameter, Production, VarRef, VarSet, labels_of
from .equations import Equations
from .expr import Context, as_expr
from .report import BenchmarkCheck, Solution
from .structure import Structure

__all__ = ["Model"]

_BOUNDS = {"sector": (0.0, np.inf), "commodity": (0.0, np.inf),
           "consumer": (0.0, np.inf), "auxiliary": (-np.inf, np.inf)}


class Model:
    """A general-equilibrium model in MPSGE's terms (see :mod:`compass_sparse.mge`)."""

    def __init__(self, name="model", prune=False):
        """``prune``: sectors and commodities whose data are all zero are dropped (held
        at their start values) instead of being declaration errors, as data-driven
        models need (a commodity a dataset happens not to trade, an empty sector)."""
        self.name = name
        self.prune = prune
        self.sets = []
        self.blocks = []
        self.constraints = []
        self.params = {}
        self._param_objs = {}
        self.ncols = 0
        self._start, self._lb, self._ub = [], [], []
        self._fixed = {}
        self._auto_income = []   # consumer columns whose start is computed
        self.last = None         # the last Solution
        self._x_last = None

    # ------------------------------------------------------------------ variables
    def _declare(self, name, kind, index, start, lower, upper):
        if any(s.name == name for s in self.sets) or name in self.params:
            raise DeclarationError(f"the name {name!r} is already used in this model")
        labels = labels_of(index)
        vs = VarSet(self, name, kind, labels, self.ncols)
        self.sets.append(vs)
        self.ncols += vs.n
        lo, hi = _BOUNDS[kind]
        lo = lo if lower is None else lower
        hi = hi if upper is None else upper
        self._lb.append(np.broadcast_to(np.asarray(lo, float), (vs.n,)))
        self._ub.append(np.broadcast_to(np.asarray(hi, float), (vs.n,)))
        if kind == "consumer" and start is None:
            self._auto_income.extend(vs.cols.tolist())
            start = 0.0
        self._start.append(np.broadcast_to(np.asarray(start, float), (vs.n,)))
        return vs

    def sectors(self, name, index=None, start=1.0, lower=None, upper=None) -> VarSet:
        """Activity levels (one per label of ``index``; a scalar sector without it)."""
        return self._declare(name, "sector", index, start, lower, upper)

    def commodities(self, name, index=None, start=1.0, lower=None, upper=None) -> VarSet:
        """Prices, 1 at the benchmark unless ``start`` says otherwise."""
        return self._declare(name, "commodity", index, start, lower, upper)

    def consumers(self, name, index=None, start=None, lower=None, upper=None) -> VarSet:
        """Incomes; by default the start is the income at the start point."""
        return self._declare(name, "consumer", index, start, lower, upper)

    def auxiliaries(self, name, index=None, start=0.0, lower=None, upper=None) -> VarSet:
        """Auxiliary variables (free unless bounded); each needs a :meth:`constraint`."""
        return self._declare(name, "auxiliary", index, start, lower, upper)

    sector, commodity, consumer, auxiliary = sectors, commodities, consumers, auxiliaries

    def parameter(self, name, value, index=None) -> Parameter:
        """Data that may change between solves (``p.set(v)``); use it in blocks and
        constraints like a number."""
        if name in self.params or any(s.name == name for s in self.sets):
            raise DeclarationError(f"the name {name!r} is already used in this model")
        p = Parameter(self, name, value, labels_of(index))
        self._param_objs[name] = p
        return p

    # ------------------------------------------------------------------ blocks
    def production(self, sector, s=0.0, t=0.0, nests=None) -> Production:
        """The production block of ``sector`` (a set or some of its elements): input
        nest ``s`` (elasticity of substitution), output nest ``t`` (transformation)."""
        blk = Production(self, sector, s=s, t=t, nests=nests)
        self.blocks.append(blk)
        return blk

    def demand(self, consumer, s=1.0, nests=None) -> Demand:
        """The demand block of ``consumer``: final demand nest ``s`` and endowments."""
        blk = Demand(self, consumer, s=s, nests=nests)
        self.blocks.append(blk)
        return blk

    def constraint(self, aux, expr):
        """The condition paired with auxiliary ``aux``: expr(x) = 0 if aux is free (>= 0
        at its lower bound, <= 0 at its upper bound)."""
        if not isinstance(aux, VarRef) or aux.set.kind != "auxiliary" or aux.set.model is not self:
            raise DeclarationError(f"a constraint is paired with an auxiliary of this model, "
                                   f"not {aux!r}")
        e = as_expr(expr)
        if e.size not in (1, aux.size):
            raise DeclarationError(f"the constraint of {aux!r} has {e.size} rows, expected "
                                   f"{aux.size}")
        if e.size != aux.size:
            e = e[np.zeros(aux.size, np.int64)]
        for other, _ in self.constraints:
            if np.intersect1d(other.cols, aux.cols).size:
                raise DeclarationError(f"{aux!r} already has a constraint")
        self.constraints.append((aux, e))

    # ------------------------------------------------------------------ bounds, starts
    def fix(self, ref, value):
        """Fix variables at ``value`` (a numeraire, a closure); :meth:`unfix` frees them."""
        vals = np.broadcast_to(np.asarray(value, float), (ref.size,))
        for c, v in zip(ref.cols.tolist(), vals.tolist()):
            self._fixed[c] = v

    def unfix(self, ref):
        for c in ref.cols.tolist():
            self._fixed.pop(c, None)

    def set_bounds(self, ref, lower=None, upper=None):
        lb, ub = np.concatenate(self._lb), np.concatenate(self._ub)
        if lower is not None:
            lb[ref.cols] = lower
        if upper is not None:
            ub[ref.cols] = upper
        self._lb, self._ub = [lb], [ub]

    def set_start(self, ref, value):
        """Start values (used by the next solve instead of the last solution)."""
        x = self.start_point()
        x[ref.cols] = value
        self._x_last = x

    def reset_start(self):
        """Forget the last solution: the next solve starts from the declared starts."""
        self._x_last = None

    # ------------------------------------------------------------------ the MCP
    def compile(self):
        """(Structure, Equations) at the current parameter values."""
        st = Structure(self)
        return st, Equations(st, self.params)

    def start_point(self, eq=None):
        """The start: the last solution if any, else the declared starts; nest prices and
        unset incomes computed from the rest."""
        if eq is None:
            eq = self.compile()[1]
        x = np.zeros(eq.n)
        if self._x_last is not None and self._x_last.shape[0] >= self.ncols:
            x[:self.ncols] = self._x_last[:self.ncols]
            auto = []
        else:
            x[:self.ncols] = np.concatenate(self._start) if self._start else []
            auto = self._auto_income
        for c, v in self._fixed.items():
            x[c] = v
        eq.start_nest_prices(x)
        if auto:
            cols = np.array([c for c in auto if c not in self._fixed], np.int64)
            x[cols] = 0.0
            F, _ = eq.evaluate(x, deriv=False)
            x[cols] = -F[cols]
        return x

    def bounds(self, n):
        lb = np.full(n, -np.inf)
        ub = np.full(n, np.inf)
        lb[:self.ncols] = np.concatenate(self._lb)
        ub[:self.ncols] = np.concatenate(self._ub)
        for c, v in self._fixed.items():
            lb[c] = ub[c] = v
        return lb, ub

    def names(self, st):
        decl = [vs.element_name(k) for vs in self.sets for k in range(vs.n)]
        var = decl + st.node_names()
        kind = {"sector": "zero_profit", "commodity": "market", "consumer": "income",
                "auxiliary": "constraint"}
        eqn = [f"{kind[vs.kind]}:{vs.element_name(k)}" for vs in self.sets for k in range(vs.n)]
        eqn += [f"nest:{n}" for n in st.node_names()]
        return var, eqn

    def mcp(self, x0=None, numeraire=True):
        """The MCP at the current data: ``compass_sparse.MCP`` with exact sparse J, names,
        bounds (fixings included) and the start point.  Returns (MCP, Structure, Equations).

        With ``numeraire`` and nothing fixed among sectors, prices and incomes, the consumer
        with the largest start income is fixed there (MPSGE's default normalization)."""
        st, eq = self.compile()
        x = self.start_point(eq) if x0 is None else np.asarray(x0, float).copy()
        lb, ub = self.bounds(eq.n)
        lb[st.pruned] = ub[st.pruned] = x[st.pruned]
        self._normalize(st, x, lb, ub, numeraire)
        var, eqn = self.names(st)

        def F(z):
            return eq.evaluate(z, deriv=False)[0]

        def J(z):
            return eq.jacobian(z)[1]

        problem = cs.MCP(F, J, lb, ub, x, jac_sparsity=eq.sparsity(x), var_names=var,
                         eqn_names=eqn)
        return problem, st, eq

    def _normalize(self, st, x, lb, ub, numeraire):
        if not numeraire:
            return
        decl = np.concatenate([vs.cols for vs in self.sets if vs.kind != "auxiliary"])
        decl = np.setdiff1d(decl, st.pruned)
        if np.any(lb[decl] == ub[decl]):
            return
        cons = st.demand_root[0]
        if cons.size:
            c = cons[np.argmax(x[cons])]
            lb[c] = ub[c] = x[c]

    def solve(self, options=None, x0=None, numeraire=True) -> Solution:
        """Solve at the current data; the solution becomes the next start.  ``options``
        (a dict or ``compass_sparse.Options``) go to the solver; the default convergence
        tolerance here is 1e-10, so that values match published ones to 1e-8."""
        problem, st, eq = self.mcp(x0=x0, numeraire=numeraire)
        opts = {"convergence_tolerance": 1e-10}
        if options is not None:
            opts.update(options if isinstance(options, dict) else dataclasses.asdict(options))
        res = cs.solve_mcp(problem, options=opts)
        sol = Solution(self, st, eq, res.x.copy(), res)
        if res.success:
            self._x_last = res.x.copy()
        self.last = sol
        return sol

    def benchmark(self, x0=None) -> BenchmarkCheck:
        """Residuals at the reference (start) point, by block (see BenchmarkCheck)."""
        st, eq = self.compile()
        x = self.start_point(eq) if x0 is None else np.asarray(x0, float)
        return BenchmarkCheck(self, st, eq, x)

    def scenario(self, **fixed_options):
        """A callable ``model(**params) -> MCP`` for ``compass_sparse.batch.solve_batch``:
        each call sets the named parameters and returns the MCP at those data."""
        def build(**params):
            for k, v in params.items():
                if k not in self._param_objs:
                    raise DeclarationError(f"the model has no parameter {k!r}")
                self._param_objs[k].set(v)
            return self.mcp(**fixed_options)[0]
        return build

    def value(self, ref, x=None):
        """Values of ``ref`` (a variable reference or an expression) at x (default: the
        last solution)."""
        x = self._x_last if x is None else x
        e = as_expr(ref)
        return e.evaluate(Context(x, self.params, False))[0]
