"""Pyomo link: solve a Pyomo model with ``pyomo.mpec`` complementarity conditions.

A Pyomo ``ConcreteModel`` states an MCP through ``Complementarity`` components
(``complements(a, b)``) and equality ``Constraint`` s.  This module turns it into
``MCP(F, [l, u])`` — row i of F paired with variable z_i — and back.

Each side of ``complements(a, b)`` is read as ``lo <= body <= up`` (an expression without
relation has no bounds; ``body == v`` is an equality).  With "var side" the side whose body
is a single variable v (``a*v + c`` with a constant a != 0 is accepted and the bounds are
mapped through it) the forms are

====================================  ==========================================  ==========
complements(...)                      MCP pair                                    F row
====================================  ==========================================  ==========
``v >= lo``, ``g >= 0``               v in [lo, +inf)                              g
``v <= up``, ``g >= 0``               v in (-inf, up]                             -g
``lo <= v <= up``, ``e``              v in [lo, up]                                e
``lo <= g <= up``, ``v``  (g no var)  auxiliary w in [lo, up]                      v
                                      and v (its own bounds, normally free)       w - g
``g == c``, ``v``                     v with its own bounds (normally free)        g - c
``g == c``, anything else             an equation matched like a Constraint        g - c
====================================  ==========================================  ==========

where the second side of the first two rows may also be ``g <= 0`` (then -g) and the
sides may come in either order.  As in ``pyomo.mpec``, a condition without an equality
needs exactly two finite bounds over its two sides.  Equality ``Constraint`` s (and
equality complementarities without a variable) are paired with the variables no
complementarity claims by a maximum bipartite matching on their incidence (the pairing
does not change the solutions of equations paired with free variables; it makes the
diagonal of J structurally nonzero).  Fixed variables and mutable ``Param`` s are data:
they enter F as parameters whose values are read at every solve, so a scenario loop that
changes them does not recompile.  A fixed variable claimed by a complementarity removes
its pair (PATH does the same: the row of a fixed variable is not enforced).

F and its exact sparse Jacobian are compiled once per model into a CasADi expression graph
(:mod:`._casadi_eval`); the README's "Modelling languages" section gives the measurement
behind that choice.  ``SolverFactory('compass_sparse')`` is registered when this module is
imported (``import compass_sparse.interfaces.pyomo``).  Pyomo and CasADi are optional
(``pip install compass-sparse[pyomo]``); the rest of the package never imports them.
"""
from __future__ import annotations

import logging
import sys
import time
import weakref
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .. import __version__
from ..exceptions import ModelError
from ..linalg.matching import matching
from ..problem.mcp import MCP
from ..solve import solve_mcp
from ..status import Status
from ._casadi_eval import UNARY, CompiledFJ

logger = logging.getLogger("compass_sparse")

__all__ = ["CompassSparseSolver", "PyomoMCP", "compiled", "pyomo_available", "solve_pyomo"]


def pyomo_available() -> bool:
    """True when Pyomo and CasADi (the evaluator) can be imported."""
    try:
        # (Pyomo and CasADi: optional extras)
        import casadi  # noqa: F401
        import pyomo.environ
        import pyomo.mpec  # noqa: F401
    except Exception:
        return False
    return True


# --------------------------------------------------------------------------- #
# Pyomo expression -> row signature and leaves (see _casadi_eval)
# --------------------------------------------------------------------------- #
class _Signatures:
    """Lift the leaves out of Pyomo expressions: ``(signature, leaves)`` per row.

    'x' leaves hold the Pyomo variable (or an auxiliary pair); mutable parameters and
    fixed variables become 'p' leaves (collected in ``data``, read at every solve);
    numbers become 'c' leaves.  Named expressions are inlined."""

    def __init__(self):
        # (Pyomo: an optional extra)
        import pyomo.core.expr.numeric_expr as N
        from pyomo.core.expr.relational_expr import EqualityExpression, InequalityExpression

        self._N = N
        self._unary = set(UNARY)
        self._order = [  # subclasses before their bases
            (N.AbsExpression, "abs"), (N.UnaryFunctionExpression, "u"),
            (N.ExternalFunctionExpression, "external"), (N.SumExpression, "sum"),
            (N.DivisionExpression, "div"), (N.ProductExpression, "prod"),
            (N.PowExpression, "pow"), (N.NegationExpression, "neg"),
            (N.MaxExpression, "max"), (N.MinExpression, "min"),
            (N.Expr_ifExpression, "if"), (InequalityExpression, "le"),
            (EqualityExpression, "eq"),
        ]
        # (Pyomo: an optional extra)
        from pyomo.core.expr.numvalue import native_numeric_types, value

        self._native = native_numeric_types
        self._value = value
        self._ops = {}
        self._kinds = {}
        self._named = {}
        self.shared = False  # a named expression occurs more than once
        self.data = []
        self._slot = {}
        self.where = ""

    def _op(self, cls):
        op = self._ops.get(cls)
        if op is None:
            op = next((o for c, o in self._order if issubclass(cls, c)), None)
            self._ops[cls] = op
        return op

    def parameter(self, obj) -> int:
        k = self._slot.get(id(obj))
        if k is None:
            k = self._slot[id(obj)] = len(self.data)
            self.data.append(obj)
        return k

    def __call__(self, e):
        leaves = []
        return self._walk(e, leaves), leaves

    def _kind(self, e):
        """What a node of this class is (cached per class: the walk is the build's hot loop)."""
        cls = e.__class__
        kind = self._kinds.get(cls)
        if kind is None:
            if cls in self._native:
                kind = "num"
            elif e.is_expression_type():
                kind = "named" if e.is_named_expression_type() else self._op(cls) or "bad"
            elif e.is_variable_type():
                kind = "var"
            elif e.is_parameter_type():
                kind = "param"
            else:
                kind = "other"
            self._kinds[cls] = kind
        return kind

    def _walk(self, e, leaves):
        kind = self._kinds.get(e.__class__) or self._kind(e)
        if kind == "num":
            leaves.append(("c", float(e)))
            return "c"
        if kind == "var":
            if e.fixed:
                leaves.append(("p", self.parameter(e)))
                return "p"
            leaves.append(("x", e))
            return "x"
        if kind == "named":  # walked once, its leaves reused at every occurrence
            hit = self._named.get(id(e))
            if hit is not None:
                self.shared = True
            else:
                sub = []
                hit = self._named[id(e)] = (self._walk(e.expr, sub), sub)
            leaves.extend(hit[1])
            return hit[0]
        if kind == "u":
            name = e.getname()
            if name not in self._unary:
                raise ModelError(f"{self.where}: the function {name}() is not supported")
            return ("u", name, self._walk(e.args[0], leaves))
        if kind in ("external", "bad"):
            raise ModelError(f"{self.where}: unsupported expression {type(e).__name__} "
                             "(F must be differentiable symbolically; external functions "
                             "are not)")
        if kind == "param" or (kind == "other" and not e.is_constant()
                               and not e.is_potentially_variable()):
            leaves.append(("p", self.parameter(e)))
            return "p"
        if kind == "other":
            leaves.append(("c", float(self._value(e))))
            return "c"
        if kind == "le" and getattr(e, "strict", False):
            kind = "lt"
        return (kind, tuple([self._walk(a, leaves) for a in e.args]))


# --------------------------------------------------------------------------- #
# reading the model
# --------------------------------------------------------------------------- #
@dataclass
class _Side:
    lo: object  # Pyomo expression / number or None
    body: object
    up: object
    equality: bool = False


def _is_fixed_expr(e) -> bool:
    # (Pyomo: an optional extra)
    from pyomo.core.expr.numvalue import native_numeric_types

    return e.__class__ in native_numeric_types or e.is_fixed()


def _is_var(e) -> bool:
    # (Pyomo: an optional extra)
    from pyomo.core.expr.numvalue import native_numeric_types

    return e.__class__ not in native_numeric_types and e.is_variable_type()


def _side(e) -> _Side:
    """``lo <= body <= up`` form of one argument of complements(a, b) (as pyomo.mpec reads it)."""
    # (Pyomo: an optional extra)
    from pyomo.core.expr.numvalue import native_numeric_types
    from pyomo.core.expr.relational_expr import (
        EqualityExpression,
        InequalityExpression,
        RangedExpression,
    )

    if isinstance(e, EqualityExpression):
        a, b = e.args
        if _is_var(b) and _is_fixed_expr(a):
            return _Side(a, b, a, True)
        if _is_fixed_expr(b):
            return _Side(b, a, b, True)
        if _is_fixed_expr(a):
            return _Side(a, b, a, True)
        return _Side(0.0, a - b, 0.0, True)
    if isinstance(e, InequalityExpression):
        a, b = e.args  # a <= b
        # cheap tests first (a number on one side), the expression walks of is_fixed last;
        # a fixed variable is still the body (x >= 0 with x fixed), not a bound
        if b.__class__ in native_numeric_types and not _is_var(a):
            return _Side(None, a, b)
        if a.__class__ in native_numeric_types:
            return _Side(a, b, None)
        if _is_var(b) and _is_fixed_expr(a):
            return _Side(a, b, None)
        if _is_fixed_expr(b):
            return _Side(None, a, b)
        if _is_fixed_expr(a):
            return _Side(a, b, None)
        return _Side(0.0, b - a, None)
    if isinstance(e, RangedExpression):
        return _Side(*e.args)
    return _Side(None, e, None)


def _single_variable(body):
    """(v, a, c) when body = a*v + c with constants a != 0 and c.  A plain variable may be
    fixed (its pair is dropped later); in a*v + c it must not be."""
    # (Pyomo: an optional extra)
    from pyomo.core.expr.numvalue import native_numeric_types

    if body.__class__ in native_numeric_types:
        return None
    if body.is_variable_type():
        return body, 1.0, 0.0
    if not body.is_potentially_variable():
        return None
    # (Pyomo: an optional extra)
    import pyomo.core.expr.numeric_expr as N

    if isinstance(body, N.MonomialTermExpression):
        a, v = body.args
        if a.__class__ in native_numeric_types and not v.fixed and a != 0:
            return v, float(a), 0.0
        return None
    # a*v + c has at most two terms; anything larger is an expression, not a variable side
    if not isinstance(body, (N.SumExpression, N.NegationExpression)) or body.nargs() > 2:
        return None
    # (Pyomo: an optional extra)
    from pyomo.repn.standard_repn import generate_standard_repn

    repn = generate_standard_repn(body, compute_values=True, quadratic=False)
    if repn.nonlinear_expr is not None or len(repn.linear_vars) != 1:
        return None
    a = float(repn.linear_coefs[0])
    if a == 0.0:
        return None
    return repn.linear_vars[0], a, float(repn.constant)


@dataclass
class _Pair:
    """One MCP pair before compilation: variable (or auxiliary), F row, bounds."""

    var: object  # VarData, or None for an auxiliary variable
    name: str  # variable name for logs
    row: object  # Pyomo expression of F, or ("aux_eq", g, auxiliary pair): the row w - g
    row_name: str
    lo: object = None  # bound expression (evaluated at each solve) or None
    up: object = None
    scale: float = 1.0  # the side is scale * v + shift: bounds map through it
    shift: float = 0.0
    use_var_bounds: bool = False  # equation pairs: the variable's own bounds
    signature: tuple | None = None  # (signature, leaves) of the row, see _Signatures


def _value(e):
    # (Pyomo: an optional extra)
    from pyomo.core.expr.numvalue import value

    return None if e is None else float(value(e))


class PyomoMCP:
    """A Pyomo model read as an MCP, with F and J compiled once.

    ``mcp()`` returns a :class:`compass_sparse.MCP` with the current values of mutable
    parameters, fixed variables and bounds; ``load(x)`` writes a point back into the
    model's variables.  ``stale()`` tells whether the model's structure changed since the
    compilation (new or deactivated components, variables fixed or unfixed).

    ``cse``: eliminate common subexpressions across rows in the compiled F and J (faster
    evaluation, slower build); None decides by the model: on when a named ``Expression``
    occurs in more than one place (terms shared between rows).
    """

    def __init__(self, model, *, cse: bool | None = None):
        # (Pyomo: an optional extra)
        from pyomo.core import Block, Constraint
        from pyomo.mpec import Complementarity

        t0 = time.perf_counter()
        self.model = model
        self._cse = cse
        comps = list(model.component_data_objects(Complementarity, active=True,
                                                  descend_into=Block))
        cons = list(model.component_data_objects(Constraint, active=True,
                                                 descend_into=Block))
        self._fingerprint = self._structure(comps, cons)
        pairs, eqs = [], []  # eqs: (expr, name) to be matched with unclaimed variables
        claimed = {}  # id(var) -> component name
        for cd in comps:
            self._read_complementarity(cd, pairs, eqs, claimed)
        for c in cons:
            if not c.equality:
                raise ModelError(
                    f"constraint {c.name} is an inequality: in an MCP every inequality is "
                    "paired with a variable; write it as complements(<inequality>, "
                    "<variable bound>) in a Complementarity")
            eqs.append((c.body - c.upper, c.name))
        # A fixed variable's pair is dropped (its row is not enforced).
        pairs = [p for p in pairs if p.var is None or not p.var.fixed]
        self._sig = _Signatures()
        for p in pairs:
            p.signature = self._row_signature(p.row, p.row_name)
        eq_sigs = [self._row_signature(e, nm) for e, nm in eqs]
        pairs += self._match_equations(eqs, eq_sigs, pairs, claimed)
        if not pairs:
            raise ModelError(f"model {model.name} has no unfixed variables: nothing to solve")
        self.pairs = pairs
        self.n = len(pairs)
        self.var_names = [p.name for p in pairs]
        self.eqn_names = [p.row_name for p in pairs]
        self._compile()
        self.build_time = time.perf_counter() - t0
        logger.debug("Pyomo model %s: %d pairs compiled in %.3f s", model.name, self.n,
                     self.build_time)

    # -- structure ----------------------------------------------------------------
    @staticmethod
    def _structure(comps, cons):
        # (Pyomo: an optional extra)
        from pyomo.core import Var

        fixed = []
        for blk in {id(c.model()): c.model() for c in comps + cons}.values():
            fixed += [id(v) for v in blk.component_data_objects(Var) if v.fixed]
        return ([id(c) for c in comps], [(id(c), id(c.expr)) for c in cons],
                frozenset(fixed))

    def stale(self) -> bool:
        # (Pyomo: an optional extra)
        from pyomo.core import Block, Constraint
        from pyomo.mpec import Complementarity

        comps = list(self.model.component_data_objects(Complementarity, active=True,
                                                       descend_into=Block))
        cons = list(self.model.component_data_objects(Constraint, active=True,
                                                      descend_into=Block))
        return self._structure(comps, cons) != self._fingerprint

    def _read_complementarity(self, cd, pairs, eqs, claimed):
        name = cd.name
        args = getattr(cd, "_args", None)
        if args is None or len(args) != 2:
            raise ModelError(f"complementarity {name} has no complements(a, b) expression")
        s = [_side(a) for a in args]
        for k in (0, 1):
            if s[k].equality:
                g = s[k].body - s[k].lo
                other = s[1 - k]
                sv = None
                if other.lo is None and other.up is None:
                    sv = _single_variable(other.body)
                if sv is not None and sv[1] == 1.0 and sv[2] == 0.0 and id(sv[0]) not in claimed:
                    v = sv[0]
                    claimed[id(v)] = name
                    pairs.append(_Pair(v, v.name, g, name, use_var_bounds=True))
                else:
                    eqs.append((g, name))
                return
        nbounds = sum(b is not None for sd in s for b in (sd.lo, sd.up))
        if nbounds != 2:
            raise ModelError(
                f"complementarity {name} has {nbounds} finite bound(s) over its two sides; "
                "it needs exactly two (one on each side, as in complements(x >= 0, f(x) >= 0), "
                "or a lower and an upper bound on one side with a free expression on the "
                "other, as in complements(l <= x <= u, f(x))): a bound is missing")
        # the side that carries the variable
        cands = []
        for k in (0, 1):
            if s[k].lo is None and s[k].up is None:
                continue  # the free expression of a ranged form
            sv = _single_variable(s[k].body)
            if sv is not None and id(sv[0]) not in claimed:
                cands.append((k, sv))
                break
        if not cands:
            self._ranged_with_free_variable(cd, s, pairs, claimed)
            return
        k, (v, a, c) = cands[0]
        vs, fs = s[k], s[1 - k]
        claimed[id(v)] = name
        if fs.lo is None and fs.up is None:  # lo <= a v + c <= up  _|_  e
            F = fs.body
            lo, up = vs.lo, vs.up
        else:  # one bound on each side
            F = fs.body - fs.lo if fs.lo is not None else fs.up - fs.body  # F >= 0 side
            if vs.lo is not None:
                lo, up = vs.lo, None
            else:
                lo, up = None, vs.up
                F = -F
        if a < 0:  # bounds of a v + c map to swapped bounds of v; F's sign flips
            lo, up = up, lo
            F = -F
        pairs.append(_Pair(v, v.name, F, name, lo, up, scale=a, shift=c))

    def _ranged_with_free_variable(self, cd, s, pairs, claimed):
        """``lo <= g <= up  _|_  v``: auxiliary w = g in [lo, up] paired with F = v, and the
        equation w - g = 0 paired with the (free) variable v."""
        name = cd.name
        for k in (0, 1):
            other = s[1 - k]
            if other.lo is None and other.up is None:
                sv = _single_variable(other.body)
                if sv is not None and id(sv[0]) not in claimed:
                    v = sv[0]
                    claimed[id(v)] = name
                    w = _Pair(None, f"{name}.aux", other.body, name, s[k].lo, s[k].up)
                    pairs.append(w)
                    pairs.append(_Pair(v, v.name, ("aux_eq", s[k].body, w), f"{name}.aux_def",
                                       use_var_bounds=True))
                    return
        raise ModelError(
            f"complementarity {name} has no variable on either side: one side of "
            "complements(a, b) must be a single unfixed variable (x >= 0, l <= x <= u, or x "
            "itself) not already claimed by another complementarity")

    def _row_signature(self, row, name):
        self._sig.where = name
        if isinstance(row, tuple):  # ("aux_eq", g, w): the row w - g(x)
            sig, leaves = self._sig(row[1])
            return ("sum", ("x", ("neg", (sig,)))), [("x", row[2])] + leaves
        return self._sig(row)

    def _match_equations(self, eqs, eq_sigs, pairs, claimed):
        free, free_index = [], {}
        seen_vars = set()
        for _, leaves in [p.signature for p in pairs] + eq_sigs:
            for kind, v in leaves:
                if kind != "x" or id(v) in seen_vars or isinstance(v, _Pair):
                    continue
                seen_vars.add(id(v))
                if id(v) not in claimed:
                    free_index[id(v)] = len(free)
                    free.append(v)
        if len(free) != len(eqs):
            if len(eqs) > len(free):
                extra = ", ".join(nm for _, nm in eqs[len(free):][:5])
                raise ModelError(
                    f"unmatched equations: {len(eqs)} equations but {len(free)} variables not "
                    f"claimed by a complementarity (equations without a partner include "
                    f"{extra}); an MCP is square")
            extra = ", ".join(v.name for v in free[len(eqs):][:5])
            raise ModelError(
                f"unmatched variables: {len(free)} variables not claimed by a complementarity "
                f"but only {len(eqs)} equations (e.g. {extra}): give each variable an equation "
                "or a complementarity, or fix it")
        if not eqs:
            return []
        rows, cols = [], []
        for i, (_, leaves) in enumerate(eq_sigs):
            for kind, v in leaves:
                j = free_index.get(id(v)) if kind == "x" else None
                if j is not None:
                    rows.append(i)
                    cols.append(j)
        G = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(eqs), len(free)))
        match = matching(G)[1]  # the variable matched to each equation
        bad = np.flatnonzero(match < 0)
        if bad.size:
            names = ", ".join(eqs[i][1] for i in bad[:5])
            raise ModelError(
                f"unmatched equations: {bad.size} equation(s) cannot be paired with a "
                f"distinct free variable they contain (structurally singular): {names}")
        out = []
        for i, (e, nm) in enumerate(eqs):
            v = free[match[i]]
            if v.has_lb() or v.has_ub():
                logger.warning(
                    "variable %s has bounds and is paired with the equation %s: the equation "
                    "holds only where %s is strictly inside its bounds", v.name, nm, v.name)
            pair = _Pair(v, v.name, e, nm, use_var_bounds=True)
            pair.signature = eq_sigs[i]
            out.append(pair)
        return out

    # -- compilation --------------------------------------------------------------
    def _compile(self):
        column = {id(p.var if p.var is not None else p): j for j, p in enumerate(self.pairs)}
        rows = []
        for p in self.pairs:
            sig, leaves = p.signature
            try:
                rows.append((sig, [(k, column[id(v)]) if k == "x" else (k, v)
                                   for k, v in leaves]))
            except KeyError:  # pragma: no cover - every unfixed variable has a pair
                raise ModelError(f"{p.row_name}: refers to a variable outside the MCP") from None
        self._data = self._sig.data
        cse = self._sig.shared if self._cse is None else self._cse
        self._fj = CompiledFJ(rows, self.n, len(self._data), cse=cse)

    # -- per-solve data -----------------------------------------------------------
    def parameter_values(self) -> np.ndarray:
        # (Pyomo: an optional extra)
        from pyomo.core.expr.numvalue import value

        return np.array([float(value(d)) for d in self._data], dtype=float)

    def bounds(self):
        lb = np.full(self.n, -np.inf)
        ub = np.full(self.n, np.inf)
        for j, p in enumerate(self.pairs):
            if p.use_var_bounds:
                lo, up = p.var.lb, p.var.ub
                lb[j] = -np.inf if lo is None else lo
                ub[j] = np.inf if up is None else up
                continue
            lo, up = _value(p.lo), _value(p.up)
            if p.scale != 1.0 or p.shift != 0.0:
                lo = None if lo is None else (lo - p.shift) / p.scale
                up = None if up is None else (up - p.shift) / p.scale
            lb[j] = -np.inf if lo is None else lo
            ub[j] = np.inf if up is None else up
            if p.var is not None:  # the variable's own domain narrows the box
                if p.var.lb is not None and p.var.lb > lb[j]:
                    logger.warning("variable %s: its bound %g is tighter than the one of %s",
                                   p.name, p.var.lb, p.row_name)
                    lb[j] = p.var.lb
                if p.var.ub is not None and p.var.ub < ub[j]:
                    logger.warning("variable %s: its bound %g is tighter than the one of %s",
                                   p.name, p.var.ub, p.row_name)
                    ub[j] = p.var.ub
        return lb, ub

    def start(self) -> np.ndarray:
        x0 = np.zeros(self.n)
        for j, p in enumerate(self.pairs):
            if p.var is not None and p.var.value is not None:
                x0[j] = p.var.value
        position = {id(p): j for j, p in enumerate(self.pairs)}
        defs = [(k, position[id(q.row[2])]) for k, q in enumerate(self.pairs)
                if isinstance(q.row, tuple)]
        if defs:  # start auxiliaries at the value of what they stand for: w = g(x)
            self._fj.set_parameters(self.parameter_values())
            f = self._fj.F(x0)
            for k, j in defs:
                x0[j] = x0[j] - f[k]
        return x0

    def mcp(self, x0=None):
        """The MCP with the model's current data (no recompilation)."""
        self._fj.set_parameters(self.parameter_values())
        lb, ub = self.bounds()
        if x0 is None:
            x0 = self.start()
        fj = self._fj
        return MCP(fj.F, fj.J, lb, ub, x0, var_names=self.var_names,
                   eqn_names=self.eqn_names, constant_jac=fj.constant)

    def load(self, x) -> None:
        """Write x into the model's variables (auxiliaries have no Pyomo variable)."""
        for j, p in enumerate(self.pairs):
            if p.var is not None:
                p.var.set_value(float(x[j]), skip_validation=True)

    # -- evaluation access (benchmarks, tests) -------------------------------------
    @property
    def evaluator(self):
        return self._fj


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def compiled(model, *, recompile: bool = False) -> PyomoMCP:
    """The model's compiled MCP, reused while its structure is unchanged."""
    pm = None if recompile else _CACHE.get(model)
    if pm is None or pm.stale():
        if pm is not None:
            logger.info("model %s changed structure: recompiling F and J", model.name)
        pm = PyomoMCP(model)
        _CACHE[model] = pm
    return pm


def solve_pyomo(model, options=None, *, load_solutions: bool = True, recompile: bool = False):
    """Solve the MCP stated by a Pyomo model; return the :class:`compass_sparse.Result`.

    ``options``: Options or a dict with PATH's option names.  The point is written back
    into the model's variables when ``load_solutions`` (also when the solve fails: the
    Result's point is the best one found, see ``result.status``).
    """
    pm = compiled(model, recompile=recompile)
    res = solve_mcp_from(pm, options)
    if load_solutions:
        pm.load(res.x)
    return res


# --------------------------------------------------------------------------- #
# SolverFactory('compass_sparse')
# --------------------------------------------------------------------------- #
def _termination(status):
    # (Pyomo: an optional extra)
    from pyomo.opt import SolverStatus
    from pyomo.opt import TerminationCondition as TC

    table = {
        Status.SOLVED: (SolverStatus.ok, TC.optimal),
        Status.NO_PROGRESS: (SolverStatus.warning, TC.other),
        Status.MAJOR_ITERATION_LIMIT: (SolverStatus.warning, TC.maxIterations),
        Status.MINOR_ITERATION_LIMIT: (SolverStatus.warning, TC.maxIterations),
        Status.TIME_LIMIT: (SolverStatus.warning, TC.maxTimeLimit),
        Status.USER_INTERRUPT: (SolverStatus.aborted, TC.userInterrupt),
        Status.CALLBACK_STOP: (SolverStatus.aborted, TC.userInterrupt),
        Status.BOUND_ERROR: (SolverStatus.error, TC.invalidProblem),
        Status.DOMAIN_ERROR: (SolverStatus.error, TC.solverFailure),
        Status.INFEASIBLE: (SolverStatus.warning, TC.infeasible),
        Status.ERROR: (SolverStatus.error, TC.internalSolverError),
        Status.MEMORY_LIMIT: (SolverStatus.aborted, TC.resourceInterrupt),
        Status.FLAT_RESIDUAL: (SolverStatus.warning, TC.other),
        Status.STATIONARY_POINT: (SolverStatus.warning, TC.noSolution),
    }
    return table.get(status, (SolverStatus.unknown, TC.unknown))


class CompassSparseSolver:
    """``SolverFactory('compass_sparse')``: the Pyomo solver interface.

    ``solve(model, tee=False, load_solutions=True, options=None, timelimit=None)``
    returns a ``pyomo.opt.SolverResults`` with the usual solver status and termination
    condition (``optimal`` when the MCP is solved); ``results.compass_result`` holds the
    :class:`compass_sparse.Result`.  Options use PATH's names, e.g.
    ``opt.options['convergence_tolerance'] = 1e-10`` or ``solve(m, options={...})``.
    """

    name = "compass_sparse"

    def __init__(self, **kwds):
        self.options = dict(kwds.pop("options", {}) or {})
        self._version = None

    # -- the methods Pyomo scripts call -------------------------------------------
    def available(self, exception_flag=True) -> bool:
        ok = pyomo_available()
        if not ok and exception_flag:
            raise RuntimeError("compass_sparse's Pyomo link needs pyomo and casadi: "
                               "pip install compass-sparse[pyomo]")
        return ok

    def license_is_valid(self) -> bool:
        return True

    def version(self):
        return tuple(int(t) for t in __version__.split(".")[:3])

    def warm_start_capable(self) -> bool:
        return True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def solve(self, model, *, tee: bool = False, load_solutions: bool = True, options=None,
              timelimit=None, recompile: bool = False, **kwds):
        # (Pyomo: an optional extra)
        from pyomo.opt import SolverResults

        opts = {str(k).lower(): v for k, v in self.options.items()}
        opts.update({str(k).lower(): v for k, v in (options or {}).items()})
        opts.update({str(k).lower(): v for k, v in kwds.pop("solver_options", {}).items()})
        if timelimit is not None:
            opts["time_limit"] = float(timelimit)
        if tee:
            opts["verbosity"] = max(int(opts.get("verbosity", 0)), 2)
        for k in ("keepfiles", "symbolic_solver_labels", "report_timing", "warmstart"):
            kwds.pop(k, None)
        if kwds:
            raise TypeError(f"unexpected keyword arguments: {sorted(kwds)}")
        t0 = time.perf_counter()
        handler = None
        if tee:
            handler = logging.StreamHandler(sys.stdout)
            handler.setFormatter(logging.Formatter("%(message)s"))
            logger.addHandler(handler)
            # The solver logs at INFO; tee asks to see it whatever the application's
            # logging level, for this call only.
            level = logger.level
            logger.setLevel(logging.INFO)
        try:
            pm = compiled(model, recompile=recompile)
            res = solve_mcp_from(pm, opts)
        finally:
            if handler is not None:
                logger.removeHandler(handler)
                logger.setLevel(level)
        if load_solutions:
            pm.load(res.x)
        results = SolverResults()
        status, tc = _termination(res.status)
        results.solver.name = self.name
        results.solver.status = status
        results.solver.termination_condition = tc
        results.solver.message = res.message
        results.solver.return_code = int(res.status.path_code())
        results.solver.wallclock_time = time.perf_counter() - t0
        results.solver.time = res.time
        results.problem.name = model.name
        results.problem.number_of_variables = pm.n
        results.problem.number_of_constraints = pm.n
        results.problem.number_of_nonzeros = int(pm.evaluator.pattern.nnz)
        results.compass_result = res
        return results


def solve_mcp_from(pm: PyomoMCP, options):
    return solve_mcp(pm.mcp(), options=options)


def _register() -> None:
    try:
        # (Pyomo: an optional extra)
        from pyomo.opt import SolverFactory
    except Exception:  # pragma: no cover - Pyomo absent: nothing to register
        return
    if "compass_sparse" not in SolverFactory:
        SolverFactory.register(
            "compass_sparse",
            doc="compass_sparse: sparse MCP solver (PATH's method) for pyomo.mpec models",
        )(CompassSparseSolver)


_register()
