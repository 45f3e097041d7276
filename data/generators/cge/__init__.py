"""Calibrated CGE model generators with known benchmark equilibria.

* :func:`static_cge` - static multi-region, multi-household CGE model (Armington trade on a
  sparse trade graph, CES / Cobb-Douglas / Leontief nests, output taxes and tariffs), built
  from a balanced random SAM (:func:`random_sam`);
* :func:`ramsey_cge` - the dynamic Ramsey model of Lau, Pahlke & Rutherford (2002) with the
  terminal constraint on investment growth, one or several sectors.

Every generator returns a :class:`CGEModel` whose ``problem`` is a
:class:`compass_sparse.problem.MCP` with an analytic sparse Jacobian of fixed pattern, and
whose ``benchmark`` is an exact equilibrium (residual at rounding level).  Sizes:
``size_for(n)`` (static) and ``ramsey_size_for(n)`` (dynamic) give keyword arguments for a
target number of variables.  :func:`economics_report` tells what a counterfactual changed
(prices, quantities, incomes, each household's equivalent variation).
"""
from .dynamic import ramsey_cge, ramsey_size, ramsey_size_for
from .model import CGEModel, benchmark_residuals, homogeneity_check, walras_check
from .report import Change, EconomicsReport, Welfare, economics_report
from .sam import SAM, random_sam, ras
from .static import size_for, static_cge, static_from_sam, static_size

__all__ = [
    "CGEModel",
    "Change",
    "EconomicsReport",
    "Welfare",
    "economics_report",
    "SAM",
    "benchmark_residuals",
    "homogeneity_check",
    "ramsey_cge",
    "ramsey_size",
    "ramsey_size_for",
    "random_sam",
    "ras",
    "size_for",
    "static_cge",
    "static_from_sam",
    "static_size",
    "walras_check",
]
