"""Declarations: variables, parameters, production and demand blocks.

A model has four kinds of variables, each an indexed set (a scalar set has one element):

* sectors Y (activity levels, >= 0), paired with zero-profit conditions;
* commodities P (prices, >= 0), paired with market clearance;
* consumers M (incomes, >= 0), paired with income balance;
* auxiliaries A (free by default), paired with the constraints the modeller writes.

Blocks are declared for a whole set of sectors (or consumers) at once, with data as arrays,
so that a model with 1e5 variables is declared by a few dozen calls, not 1e5.  Data is a
number, an array, or an expression of parameters (re-read at every solve); tax rates and
endowments may also depend on auxiliary variables.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..exceptions import ModelError
from .expr import Expr, ParamLeaf, VarLeaf, as_expr

__all__ = ["DeclarationError", "Demand", "Parameter", "Production", "VarRef", "VarSet"]

KINDS = ("sector", "commodity", "consumer", "auxiliary")


class DeclarationError(ModelError):
    """A block, a variable or a datum is declared in a way that cannot define a model."""


def labels_of(index):
    if index is None:
        return None
    labels = [str(v) for v in index]
    if len(set(labels)) != len(labels):
        raise DeclarationError(f"index {labels[:5]}... has repeated labels")
    return labels


class VarRef(VarLeaf):
    """Some elements of one variable set: usable in blocks and in expressions."""

    def __init__(self, vset, pos):
        self.set = vset
        self.pos = np.asarray(pos, dtype=np.int64).reshape(-1)
        super().__init__(vset.first_col + self.pos)

    @property
    def names(self):
        return [self.set.element_name(int(p)) for p in self.pos]

    def __repr__(self):
        names = self.names
        return names[0] if len(names) == 1 else f"{self.set.name}[{len(names)} elements]"


class VarSet(VarRef):
    """A declared set of variables of one kind; ``S[label]`` (or a list, a boolean mask,
    integer positions) selects elements."""

    def __init__(self, model, name, kind, labels, first_col):
        self.model, self.name, self.kind, self.labels = model, name, kind, labels
        self.n = 1 if labels is None else len(labels)
        self.first_col = first_col
        self._where = {} if labels is None else {lab: k for k, lab in enumerate(labels)}
        super().__init__(self, np.arange(self.n))

    def element_name(self, k):
        return self.name if self.labels is None else f"{self.name}[{self.labels[k]}]"

    def positions(self, key):
        if isinstance(key, slice):
            return np.arange(self.n)[key]
        arr = np.asarray(key)
        if arr.dtype == bool:
            if arr.shape != (self.n,):
                raise DeclarationError(f"a mask on {self.name} must have length {self.n}")
            return np.flatnonzero(arr)
        if np.issubdtype(arr.dtype, np.integer):
            return arr.reshape(-1)
        keys = [str(k) for k in np.atleast_1d(arr).tolist()]
        missing = [k for k in keys if k not in self._where]
        if missing:
            raise DeclarationError(f"{self.name} has no element {missing[0]!r}")
        return np.array([self._where[k] for k in keys], dtype=np.int64)

    def __getitem__(self, key):
        return VarRef(self, self.positions(key))

    def __repr__(self):
        return f"{self.kind} {self.name}" + ("" if self.labels is None else f"[{self.n}]")


class Parameter(ParamLeaf):
    """Data that may change between solves: ``p.set(values)``, ``p.get()``; ``p[label]``
    selects elements by label."""

    def __init__(self, model, name, value, labels):
        self.model, self.name, self.labels = model, name, labels
        n = int(np.size(value)) if labels is None else len(labels)
        model.params[name] = np.broadcast_to(np.asarray(value, float), (n,)).copy()
        super().__init__(name, np.arange(n))
        self._where = {} if labels is None else {lab: k for k, lab in enumerate(labels)}

    def get(self):
        """The current values (a float for a scalar parameter)."""
        v = self.model.params[self.name]
        return float(v[0]) if v.shape[0] == 1 and self.labels is None else v.copy()

    def set(self, value, at=None):
        """Set the values (all, or those of the labels ``at``)."""
        cur = self.model.params[self.name]
        if at is None:
            cur[:] = np.broadcast_to(np.asarray(value, float), cur.shape)
        else:
            cur[self._pos(at)] = value

    def _pos(self, key):
        keys = [str(k) for k in np.atleast_1d(key).tolist()]
        return np.array([self._where[k] for k in keys], dtype=np.int64)

    def __getitem__(self, key):
        if isinstance(key, str) or (isinstance(key, (list, tuple)) and key
                                    and all(isinstance(k, str) for k in key)):
            return ParamLeaf(self.name, self._pos(key))
        return super().__getitem__(key)  # positions: an expression's elements


def _as_ref(model, ref, kind, what):
    if not isinstance(ref, VarRef) or ref.set.model is not model:
        raise DeclarationError(f"{what}: {ref!r} is not a {kind} of this model")
    if ref.set.kind != kind:
        raise DeclarationError(f"{what}: {ref!r} is a {ref.set.kind}, not a {kind}")
    return ref


class _Block:
    """What production and demand blocks share: an owner set, named nests, netputs."""

    def __init__(self, model, owner, kind, roots, nests):
        self.model = model
        self.owner = _as_ref(model, owner, kind, f"a {self.WHAT} block")
        self.n = self.owner.size
        self.nests = {}       # name -> (parent name or None, elasticity Expr, tree)
        for name, (tree, sigma) in roots.items():
            self.nests[name] = (None, self._data(sigma, "elasticity of " + name), tree)
        for name, spec in (nests or {}).items():
            if name in self.nests:
                raise DeclarationError(f"{self.location()}: nest {name!r} is declared twice")
            try:
                parent, sigma = spec
            except (TypeError, ValueError):
                raise DeclarationError(f"{self.location()}: nest {name!r} must be given as "
                                       "(parent name, elasticity)") from None
            if parent not in self.nests:
                raise DeclarationError(f"{self.location()}: nest {name!r} has unknown parent "
                                       f"{parent!r} (declare parents first)")
            self.nests[name] = (parent, self._data(sigma, "elasticity of " + name),
                                self.nests[parent][2])
        self.netputs = []

    def location(self):
        return f"{self.WHAT} block of {self.owner!r}"

    def _data(self, value, what, allow_variables=False):
        e = as_expr(value)
        if not allow_variables and e.has_variables():
            raise DeclarationError(f"{self.location()}: the {what} cannot depend on variables")
        if e.size not in (1, self.n):
            raise DeclarationError(f"{self.location()}: the {what} has {e.size} values; "
                                   f"expected 1 or {self.n} (one per element)")
        return e

    def _netput(self, tree, commodity, quantity, nest, price, taxes):
        where = self.location()
        c = _as_ref(self.model, commodity, "commodity", where)
        if nest is None:
            nest = next(k for k, v in self.nests.items() if v[0] is None and v[2] == tree)
        if nest not in self.nests:
            raise DeclarationError(f"{where}: unknown nest {nest!r} for {c!r}")
        if self.nests[nest][2] != tree:
            raise DeclarationError(f"{where}: nest {nest!r} belongs to the {self.nests[nest][2]} "
                                   f"tree, not the {tree} tree ({c!r})")
        pairs = _pairing(self.n, c.size, quantity, where, c)
        q = _flat(_values(quantity), pairs, where, f"quantity of {c!r}")
        p = _flat(_values(price), pairs, where, f"reference price of {c!r}")
        tx = []
        for tax in taxes or ():
            try:
                agent, rate = tax
            except (TypeError, ValueError):
                raise DeclarationError(f"{where}: a tax is (consumer, rate)") from None
            agent = _as_ref(self.model, agent, "consumer", f"{where}, tax on {c!r}")
            own, m = pairs[0], pairs[0].shape[0]
            if agent.size == 1:
                cols = np.full(m, agent.cols[0])
            elif agent.size == self.n:
                cols = agent.cols[own]         # one receiving consumer per owner
            elif agent.size == m:
                cols = agent.cols              # one per (owner, commodity) entry
            else:
                raise DeclarationError(f"{where}: the tax on {c!r} goes to {agent.size} "
                                       f"consumers; expected 1, {self.n} (one per owner) or {m}")
            tx.append((cols, _flat(_values(rate), pairs, where, f"tax on {c!r}", True)))
        self.netputs.append({"tree": tree, "comm": c, "nest": nest, "pairs": pairs, "q": q, "p": p, "taxes": tx})
        return self


def _values(value):
    """A scipy.sparse datum as the vector of its entries in row-major order."""
    if sp.issparse(value):
        csr = sp.csr_matrix(value)
        csr.sort_indices()
        return csr.data
    return value


def _pairing(n, k, quantity, where, c):
    """(owner positions, commodity positions, shape) of a netput declaration.

    A quantity of shape (n, k) pairs every owner with every commodity; a scipy.sparse
    (n, k) matrix pairs the owners and commodities of its stored entries (row-major order;
    other data of the netput are then per owner or per entry); a vector or a scalar pairs
    owner i with commodity i when k == n, or every owner with the single commodity when
    k == 1."""
    if sp.issparse(quantity):
        if quantity.shape != (n, k):
            raise DeclarationError(f"{where}: quantity of {c!r} has shape {quantity.shape}, "
                                   f"expected ({n}, {k})")
        csr = sp.csr_matrix(quantity)
        csr.sort_indices()
        own = np.repeat(np.arange(n), np.diff(csr.indptr))
        return own, csr.indices.astype(np.int64), "sparse", n
    if isinstance(quantity, Expr):
        shape = (quantity.size,) if quantity.size > 1 else ()
    else:
        shape = np.shape(quantity)
    if len(shape) == 2:
        if shape != (n, k):
            raise DeclarationError(f"{where}: quantity of {c!r} has shape {shape}, "
                                   f"expected ({n}, {k})")
        return np.repeat(np.arange(n), k), np.tile(np.arange(k), n), "matrix", n
    if k == 1:
        return np.arange(n), np.zeros(n, np.int64), "vector", n
    if k == n:
        return np.arange(n), np.arange(n), "vector", n
    if shape == (n * k,):
        return np.repeat(np.arange(n), k), np.tile(np.arange(k), n), "matrix", n
    raise DeclarationError(f"{where}: {c!r} has {k} elements for {n} owners; give the "
                           f"quantity as an ({n}, {k}) array")


def _flat(value, pairs, where, what, allow_variables=False):
    """Data as an expression with one value per (owner, commodity) pair: a scalar, one
    value per owner, or one per pair."""
    own, _com, _form, n = pairs
    m = own.shape[0]
    e = as_expr(np.asarray(value, float).reshape(-1) if not isinstance(value, Expr) else value)
    if e.has_variables() and not allow_variables:
        raise DeclarationError(f"{where}: the {what} cannot depend on variables")
    if e.size in (1, m):
        return e
    if e.size == n:
        return e[own]
    raise DeclarationError(f"{where}: the {what} has {e.size} values; expected 1, {n} "
                           f"(one per owner) or {m}")


class Production(_Block):
    """A production block: ``input``/``output`` netputs in nested CES (inputs) and CET
    (outputs) trees.  Roots: ``s`` (inputs, elasticity of substitution) and ``t``
    (outputs, elasticity of transformation); further nests as
    ``nests={"va": ("s", 1.0)}`` (name: (parent, elasticity))."""

    WHAT = "production"

    def __init__(self, model, sector, s=0.0, t=0.0, nests=None, s_name="s", t_name="t"):
        super().__init__(model, sector, "sector", {s_name: ("input", s), t_name: ("output", t)},
                         nests)

    def input(self, commodity, quantity, nest=None, price=1.0, taxes=()):
        """Input of ``commodity``: reference ``quantity`` at reference ``price`` (the price
        the producer pays, taxes included); ``taxes`` are (consumer, ad-valorem rate), the
        consumer one, one per owner or one per entry."""
        return self._netput("input", commodity, quantity, nest, price, taxes)

    def output(self, commodity, quantity, nest=None, price=1.0, taxes=()):
        """Output of ``commodity``: reference ``quantity`` at reference ``price`` (what the
        producer receives, net of taxes)."""
        return self._netput("output", commodity, quantity, nest, price, taxes)


class Demand(_Block):
    """A consumer's demand block: final demands in a nested CES tree (root ``s``) and
    endowments (quantities that may depend on auxiliary variables)."""

    WHAT = "demand"

    def __init__(self, model, consumer, s=1.0, nests=None, s_name="s"):
        super().__init__(model, consumer, "consumer", {s_name: ("demand", s)}, nests)
        self.endowments = []

    def final(self, commodity, quantity, nest=None, price=1.0):
        """Final demand of ``commodity``: reference ``quantity`` at reference ``price``."""
        return self._netput("demand", commodity, quantity, nest, price, ())

    def endowment(self, commodity, quantity):
        """Endowment of ``commodity`` (negative for a net demand); it may depend on
        auxiliary variables, e.g. ``120 - 100 * U``."""
        where = self.location()
        c = _as_ref(self.model, commodity, "commodity", where)
        pairs = _pairing(self.n, c.size, quantity, where, c)
        q = _flat(_values(quantity), pairs, where, f"endowment of {c!r}", allow_variables=True)
        self.endowments.append({"comm": c, "pairs": pairs, "q": q})
        return self
