"""The :class:`CGEModel` container returned by the CGE generators, and model diagnostics."""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from compass_sparse.merit import fb_phi, natural_residual, residual_report
from compass_sparse.problem import MCP

__all__ = ["CGEModel", "homogeneity_check", "walras_check", "benchmark_residuals"]


@dataclass
class CGEModel:
    """A calibrated CGE model as an MCP, with its benchmark point and block structure.

    Attributes
    ----------
    problem : MCP
        ``lb <= z <= ub  _|_  F(z)`` with analytic sparse Jacobian of fixed pattern; its start
        point ``problem.x0`` is ``benchmark``.
    benchmark : ndarray
        The benchmark point z-bar.  For a calibrated (unshocked) model it is an exact
        equilibrium; for a shocked model it is the pre-shock equilibrium (the start point of
        the counterfactual), and ``info['benchmark_is_solution']`` is False.
    names, row_names : list of str
        Variable names such as ``'Y[r1,s3]'`` and row names such as ``'prf_Y[r1,s3]'``; row i
        is complementary to variable i.
    blocks : dict
        Block name -> slice of z (e.g. 'Y', 'A', 'P', 'PA', 'W', 'M').
    block_shapes : dict
        Block name -> shape used by :meth:`block` to reshape (e.g. (regions, sectors)).
    degree : ndarray
        Homogeneity degree in (prices, incomes) of every row (1: zero-profit and income
        rows, 0: market rows).
    ray : ndarray of bool
        Variables on the homogeneity ray (prices and incomes; quantities are False).
    info : dict
        Sizes, nnz, numeraire text, calibration data, shock description.
    """

    problem: MCP
    benchmark: np.ndarray
    names: list
    row_names: list
    blocks: dict
    block_shapes: dict
    degree: np.ndarray
    ray: np.ndarray
    info: dict
    _rebuild: Callable = field(repr=False, default=None)
    _jac_fn: Callable = field(repr=False, default=None)
    #: the model's evaluator (its calibrated data: the GAMSPy writer reads them)
    evaluator: object = field(repr=False, default=None)

    # -- basic access --------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.problem.n

    @property
    def nnz(self) -> int:
        return int(self.info["nnz"])

    @property
    def lb(self) -> np.ndarray:
        return self.problem.lb

    @property
    def ub(self) -> np.ndarray:
        return self.problem.ub

    def F(self, z) -> np.ndarray:
        """F(z) without touching the problem's evaluation counters."""
        return self.problem.F_uncounted(z)

    def J(self, z):
        """J(z) (CSC, fixed pattern) without touching the evaluation counters."""
        return self._jac_fn(np.array(z, dtype=float, copy=True)).tocsc()

    def index(self, name: str) -> int:
        """Position of the variable called ``name``."""
        if not hasattr(self, "_name_index"):
            self._name_index = {s: i for i, s in enumerate(self.names)}
        return self._name_index[name]

    def block(self, z, name: str) -> np.ndarray:
        """The values of block ``name`` in z, reshaped to ``block_shapes[name]``."""
        return np.asarray(z)[self.blocks[name]].reshape(self.block_shapes[name])

    def results(self, z) -> dict:
        """Every block of z, reshaped (dict name -> array)."""
        return {b: self.block(z, b) for b in self.blocks}

    def residual(self, z=None, k_worst: int = 5):
        """Residual report (||Phi||_2, natural residual, worst rows) at z (default benchmark)."""
        z = self.benchmark if z is None else np.asarray(z, dtype=float)
        return residual_report(z, self.F(z), self.lb, self.ub, names=self.row_names,
                               k_worst=k_worst)

    def natural_residual(self, z=None) -> float:
        z = self.benchmark if z is None else np.asarray(z, dtype=float)
        return natural_residual(z, self.F(z), self.lb, self.ub)

    def fb_norm(self, z=None) -> float:
        z = self.benchmark if z is None else np.asarray(z, dtype=float)
        return float(np.linalg.norm(fb_phi(z, self.F(z), self.lb, self.ub)))

    # -- derived models ----------------------------------------------------------------------
    def with_shock(self, start=None, **shock) -> "CGEModel":
        """A counterfactual model with the same variables, rows and Jacobian pattern.

        Its benchmark (start point) is ``start`` (default: this model's benchmark, i.e. the
        pre-shock equilibrium).  Keywords depend on the model family; see the generator's
        documentation (static: output_tax, tariff, endowment, balance, productivity;
        dynamic: capital_tax, labour).
        """
        if self._rebuild is None:
            raise NotImplementedError("this model cannot be rebuilt")
        if not shock:
            raise ValueError("no shock given")
        z0 = self.benchmark if start is None else np.asarray(start, dtype=float)
        return self._rebuild(shock=shock, start=z0)

    def with_numeraire(self, numeraire="keep", *, value=None, scale=None) -> "CGEModel":
        """The same model with another numeraire or numeraire value.

        ``numeraire``: 'keep' (default), 'auto', None, ('price', name), ('income', name).
        ``value`` fixes the numeraire at that value; ``scale`` at ``scale`` times its value
        in this model's benchmark.  With ``scale`` the new benchmark is this benchmark with
        every price and income multiplied by ``scale`` (an exact solution again when this
        benchmark is one, by homogeneity).
        """
        if self._rebuild is None:
            raise NotImplementedError("this model cannot be rebuilt")
        return self._rebuild(numeraire=numeraire, value=value, scale=scale)

    def scaled_point(self, z, scale: float) -> np.ndarray:
        """z with every price and income multiplied by ``scale`` (quantities kept)."""
        z = np.array(z, dtype=float, copy=True)
        z[self.ray] *= scale
        return z

    def summary(self) -> str:
        i = self.info
        return (f"{i.get('family', 'cge')}: n = {self.n}, nnz = {self.nnz}, "
                f"numeraire: {i.get('numeraire')}")

    def __repr__(self):
        return f"CGEModel({self.summary()})"


def homogeneity_check(model: CGEModel, z=None) -> dict:
    """Evidence of degree-0 homogeneity of the model in (prices, incomes).

    With v = (0 on quantities, z on prices and incomes), Euler's theorem gives the identity
    J(z) v = deg * F(z) (deg = 1 on zero-profit and income rows, 0 on market rows), so at
    every equilibrium J(z) v = 0: the Jacobian of the unnormalised model is singular along
    the price ray.  Returns

    * ``ray_norm``: ||J(z) v||_2, the direct evidence (0 at equilibria);
    * ``ray_relative``: ||J(z) v|| / (||J||_F ||v||);
    * ``euler_error``: ||J(z) v - deg * F(z)||_inf (roundoff: checks the identity anywhere);
    * ``fixed_on_ray``: names of fixed variables on the ray (a numeraire breaks the ray).
    """
    z = model.benchmark if z is None else np.asarray(z, dtype=float)
    J = model.J(z)
    f = model.F(z)
    v = np.where(model.ray, z, 0.0)
    Jv = J @ v
    fixed = np.flatnonzero((model.lb == model.ub) & model.ray)
    nJ = float(np.sqrt(np.sum(J.data ** 2)))
    nv = float(np.linalg.norm(v))
    return {
        "ray_norm": float(np.linalg.norm(Jv)),
        "ray_relative": float(np.linalg.norm(Jv) / max(nJ * nv, 1e-300)),
        "euler_error": float(np.max(np.abs(Jv - model.degree * f))) if f.size else 0.0,
        "fixed_on_ray": [model.names[i] for i in fixed],
    }


def walras_check(model: CGEModel, z=None) -> dict:
    """The row complementary to the numeraire (dropped by fixing its variable) at z.

    By Walras' law it vanishes at any point where all other rows hold with complementarity.
    Returns ``{'row': name, 'value': F_row(z)}`` (value None without a numeraire).
    """
    z = model.benchmark if z is None else np.asarray(z, dtype=float)
    k = model.info.get("numeraire_index")
    if k is None:
        return {"row": None, "value": None}
    return {"row": model.row_names[k], "value": float(model.F(z)[k])}


def benchmark_residuals(model: CGEModel, z=None) -> dict:
    """Natural residual, ||Phi||_2 and the largest |F_i| by block at z (default benchmark)."""
    z = model.benchmark if z is None else np.asarray(z, dtype=float)
    f = model.F(z)
    by_block = {b: float(np.max(np.abs(f[s]))) if f[s].size else 0.0
                for b, s in model.blocks.items()}
    return {
        "natural": natural_residual(z, f, model.lb, model.ub),
        "fb_norm": float(np.linalg.norm(fb_phi(z, f, model.lb, model.ub))),
        "max_abs_F_by_block": by_block,
    }


def fix_numeraire(lb, ub, x0, num_idx, how, value, names, row_names):
    """Fix variable ``num_idx`` (a price or an income) at ``value`` (default: its start
    value): homogeneity of degree 0 makes the Jacobian singular along the price ray, and
    fixing one price or income removes that direction; Walras' law makes its row implied.
    Returns the start point with the fixed value and the description for ``info``."""
    val = float(x0[num_idx]) if value is None else float(value)
    lb[num_idx] = ub[num_idx] = val
    x0 = x0.copy()
    x0[num_idx] = val
    return x0, (f"{names[num_idx]} fixed at {val:.12g} ({how}); its row "
                f"{row_names[num_idx]} is implied by Walras' law")


def quiet(fn):
    """``fn`` without numpy's floating-point warnings.  At a trial point outside the model's
    domain (a negative price under a CES power, a zero income) F or J comes out NaN or Inf:
    the solver rejects such a point and shortens its step, so a warning printed for it
    (thousands in a hard solve) says nothing to the user but alarms."""
    @functools.wraps(fn)
    def f(z):
        with np.errstate(all="ignore"):
            return fn(z)
    return f


def assemble_model(ev, *, lb, ub, x0, names, row_names, degree, ray, num_idx, info,
                   spec, shock_text) -> CGEModel:
    """The CGEModel of evaluator ``ev`` (static or dynamic) with the given bounds, start,
    numeraire and info, and its ``rebuild`` for shocks, new starts and numeraires.

    ``ev`` provides ``eval_F``, ``eval_J``, ``pat``, ``blocks``, ``shapes``,
    ``make_model(...)`` and ``after_shock(shock) -> (evaluator, description)``."""
    F, J = quiet(ev.eval_F), quiet(ev.eval_J)
    problem = MCP(F, J, lb, ub, x0, var_names=names, eqn_names=row_names,
                  constant_jac=ev.pat.constant_pattern())
    model = CGEModel(problem=problem, benchmark=x0.copy(), names=names, row_names=row_names,
                     blocks=dict(ev.blocks), block_shapes=dict(ev.shapes), degree=degree,
                     ray=ray, info=info, _jac_fn=J, evaluator=ev)

    def rebuild(shock=None, start=None, numeraire="keep", value=None, scale=None):
        text = shock_text
        z0 = model.benchmark.copy()
        nval = float(lb[num_idx]) if num_idx is not None else None
        new = ev.after_shock(None)[0]
        if shock:
            new, desc = ev.after_shock(shock)
            text = desc if shock_text is None else f"{shock_text}; {desc}"
            z0 = np.asarray(start, dtype=float).copy()
        num = spec["numeraire"] if numeraire == "keep" else numeraire
        if numeraire != "keep":
            nval = None
        if scale is not None:
            z0 = model.scaled_point(z0, scale)
            if nval is not None:
                nval *= scale
        if value is not None:
            nval = float(value)
        return new.make_model(numeraire=num, price_lb=spec["price_lb"],
                              income_free=spec["income_free"], start=z0,
                              numeraire_value=nval, shock_text=text)

    model._rebuild = rebuild
    return model
