"""The fingerprint of a batch's model: what a results folder records so that a resume with
another model is refused instead of reporting the first model's numbers.

The model is a function of the scenario's parameters, so it is fingerprinted at one
scenario, the folder's *reference scenario* (the first scenario of the run that created the
folder, stored with the fingerprint; a resume rebuilds the model there).  The fingerprint
of the MCP built there holds

* its order n, and digests of its variable and equation names (the first names are kept
  for the message);
* its bounds and start point, and F at two points: the start x0 and a fixed nearby point
  x1 = clip(x0 + 1e-2 (1 + |x0|) u, l, u) (u drawn once from a fixed seed).  F(x0) alone
  is blind to data that leave the start a solution (a CGE model's elasticities at its
  calibrated benchmark), F(x1) is not;
* the options that change what a stored row means: the convergence tolerance and the
  batch's ``record`` (which variables a row keeps).

A vector v is kept as its signature: where it is +inf, -inf or NaN (a digest of the three
masks, compared exactly), and K = 4 weighted sums s_k = w_k . v over its finite entries
with fixed weights w_k in [-1, 1], compared to within ``FINGERPRINT_RTOL`` times the
larger of the two sum |v_i|: a model rebuilt on another machine (another BLAS, another
summation order) matches, one whose data changed in the 9th significant digit or more does
not.  F that fails at a point is recorded as failing there.
"""
from __future__ import annotations

import hashlib
import math

import numpy as np

from ..exceptions import CompassError
from .models import build

__all__ = ["FINGERPRINT_RTOL", "compare", "fingerprint_at", "model_fingerprint"]

FINGERPRINT_RTOL = 1e-9
"""Largest difference of a weighted sum of a vector's finite entries, relative to the sum of
their magnitudes, of two vectors taken as equal."""

FORMAT = 1
"""The fingerprint's layout; a folder with another is compared by its order n alone."""

_SEED = 20261128
_K = 4
_STEP = 1e-2


def _digest(text: str) -> str:
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def _weights(n: int) -> np.ndarray:
    return np.random.default_rng(_SEED).uniform(-1.0, 1.0, size=(_K, n))


def signature(v) -> dict:
    """The signature of a float vector (see the module docstring)."""
    v = np.asarray(v, dtype=float).ravel()
    masks = np.concatenate([np.isposinf(v), np.isneginf(v), np.isnan(v)])
    fin = np.where(np.isfinite(v), v, 0.0)
    return {"masks": hashlib.sha1(np.packbits(masks).tobytes()).hexdigest()[:16],
            "sums": [float(s) for s in _weights(v.size) @ fin],
            "scale": float(np.abs(fin).sum())}


def _same_signature(a, b) -> bool:
    if not (isinstance(a, dict) and isinstance(b, dict)):
        return a == b
    if a.get("masks") != b.get("masks") or len(a.get("sums", ())) != len(b.get("sums", ())):
        return False
    tol = FINGERPRINT_RTOL * max(a["scale"], b["scale"])
    return all(abs(x - y) <= tol or (math.isnan(x) and math.isnan(y))
               for x, y in zip(a["sums"], b["sums"]))


def _names(names):
    if names is None:
        return None
    return {"digest": _digest("\n".join(names)), "first": list(names[:3])}


def _F_at(problem, x):
    try:
        f = problem.F_uncounted(x)
    except CompassError:
        raise
    except Exception as exc:  # the user's F fails there: recorded as failing
        return f"fails ({type(exc).__name__})"
    return signature(f)


def model_fingerprint(problem, tolerance: float, record=None) -> dict:
    """The fingerprint of ``problem`` (the model's MCP at the reference scenario)."""
    n = problem.n
    x0 = np.asarray(problem.x0, dtype=float)
    u = np.random.default_rng(_SEED + 1).uniform(-1.0, 1.0, n)
    x1 = np.clip(x0 + _STEP * (1.0 + np.abs(x0)) * u, problem.lb, problem.ub)
    return {"format": FORMAT, "n": int(n), "var_names": _names(problem.var_names),
            "eqn_names": _names(problem.eqn_names), "lb": signature(problem.lb),
            "ub": signature(problem.ub), "x0": signature(x0), "F(x0)": _F_at(problem, x0),
            "F(x1)": _F_at(problem, x1), "convergence_tolerance": float(tolerance),
            "record": None if record is None else list(record)}


def fingerprint_at(builder, params, tolerance: float, record=None) -> dict:
    """The fingerprint of the model ``builder`` at the scenario ``params``; a model that
    cannot be built there is recorded as such (and compared by that alone)."""
    try:
        problem = build(builder, params)
    except CompassError:
        raise
    except Exception as exc:  # the model fails at the reference scenario
        return {"format": FORMAT, "build": f"fails ({type(exc).__name__})",
                "convergence_tolerance": float(tolerance),
                "record": None if record is None else list(record)}
    return model_fingerprint(problem, tolerance, record)


_WHAT = {"build": "the model at the reference scenario", "n": "variables (n)", "var_names": "variable names", "eqn_names": "equation names",
         "lb": "lower bounds", "ub": "upper bounds", "x0": "start point",
         "F(x0)": "F at the start point", "F(x1)": "F near the start point",
         "convergence_tolerance": "convergence_tolerance", "record": "record"}


def _show(key, v):
    if v is None:
        return "none"
    if key in ("var_names", "eqn_names") and isinstance(v, dict):
        return ", ".join(v["first"]) + (", ..." if v["first"] else "")
    return str(v)


_VECTORS = ("lb", "ub", "x0", "F(x0)", "F(x1)")


def compare(here: dict, stored: dict) -> list[tuple[str, str, str]]:
    """What differs between two fingerprints: [(what, here, in the folder)], empty when
    they match; a vector that differs is (what, "differs", "").  Models of different
    orders are told apart by n alone; a fingerprint of another layout is compared by n
    alone."""
    keys = list(_WHAT) if stored.get("format") == FORMAT else ["n"]
    out = []
    for k in keys:
        a, b = here.get(k), stored.get(k)
        if k == "build":
            if a != b:
                out.append((_WHAT[k], a or "builds", b or "builds"))
                break  # nothing else to compare against a model that was not built
            continue
        if k in ("var_names", "eqn_names"):
            same = (a is None and b is None) or (a is not None and b is not None
                                                 and a["digest"] == b["digest"])
        elif k == "convergence_tolerance":
            same = a is not None and b is not None and float(a) == float(b)
        else:
            same = _same_signature(a, b)
        if same:
            continue
        if k in _VECTORS:
            out.append((_WHAT[k], "differs", ""))
        else:
            out.append((_WHAT[k], _show(k, a), _show(k, b)))
        if k == "n":
            break  # every vector differs too: n says it
    return out
