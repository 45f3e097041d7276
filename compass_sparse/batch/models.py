"""What a batch solves: a callable ``model(**params) -> MCP`` (or a CGE model object with a
``.problem``), or a CGE generator model whose parameters are its ``with_shock`` keywords
plus the elasticities (:class:`CGEScenarioModel`)."""
from __future__ import annotations

import numpy as np

from ..generators.cge import static_from_sam
from ..problem.mcp import MCP
from .scenarios import scenario_key

__all__ = ["CGEScenarioModel", "as_builder", "build"]


# ---------------------------------------------------------------------------- models
class CGEScenarioModel:
    """Scenario parameters -> MCP for a CGE generator model.

    Parameters named like an elasticity argument of the static generator
    (``sigma_va``, ``sigma_armington``, ``sigma_consumer``; scalar or array) rebuild the
    model from its SAM with those elasticities (cached per worker); all others are passed to
    ``with_shock`` (static: ``tariff`` — a scalar is the rate on every import link —,
    ``output_tax``, ``endowment``, ``balance``, ``productivity``)."""

    ELASTICITIES = ("sigma_va", "sigma_armington", "sigma_consumer")

    def __init__(self, model):
        self.model = model
        self._bases = {}

    def cge(self, **params):
        """The CGE model (not only its MCP) of a scenario."""
        params = dict(params)
        el = {k: params.pop(k) for k in self.ELASTICITIES if k in params}
        base = self._base(el) if el else self.model
        return base.with_shock(**params) if params else base

    def __call__(self, **params):
        return self.cge(**params).problem

    def _base(self, el):
        key = scenario_key(el)
        if key not in self._bases:
            info = self.model.info
            if info.get("family") != "static_cge":
                raise ValueError("elasticity scenarios need a static CGE model")
            num = info.get("numeraire_index")
            numeraire = None if num is None else ("income", self.model.names[num])
            if num is not None and num not in range(self.model.blocks["M"].start,
                                                    self.model.blocks["M"].stop):
                numeraire = ("price", self.model.names[num])
            kw = {k: info[k] for k in self.ELASTICITIES}
            kw.update({k: np.broadcast_to(np.asarray(v, float), np.shape(info[k])).copy()
                       for k, v in el.items()})
            if len(self._bases) >= 16:  # a grid visits few elasticity values per worker
                self._bases.pop(next(iter(self._bases)))
            self._bases[key] = static_from_sam(
                info["sam"], numeraire=numeraire, price_lb=info["price_lb"],
                income_free=info["income_free"], policy=info["policy"],
                start=self.model.benchmark, **kw)
        return self._bases[key]


def as_builder(model):
    if hasattr(model, "with_shock") and hasattr(model, "problem"):
        return CGEScenarioModel(model)
    if callable(model):
        return model
    raise TypeError("model must be a callable params -> MCP or a CGE model with with_shock")


def build(builder, params):
    out = builder(**params)
    if not isinstance(out, MCP):
        out = getattr(out, "problem", out)
    if not isinstance(out, MCP):
        raise TypeError(f"the model returned {type(out).__name__}, not an MCP")
    return out
