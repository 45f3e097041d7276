"""Scenarios: parameter dicts from a grid, an axis spec ("name=a:b:k" or "name=v1,v2") or a
CSV file, and the key that identifies a scenario across runs (a hash of its parameters)."""
from __future__ import annotations

import csv
import hashlib
import json

import numpy as np

from ..exceptions import OptionError, ProblemError

__all__ = ["grid", "parse_axis", "plain", "read_scenarios", "scenario_key"]


# ---------------------------------------------------------------------------- scenarios
def grid(**axes) -> list[dict]:
    """The Cartesian product of parameter axes, the last axis varying fastest:
    ``grid(tariff=[0, .1], sigma_armington=[1, 2])`` -> 4 dicts."""
    names = list(axes)
    values = [list(np.atleast_1d(np.asarray(axes[k], dtype=float))) for k in names]
    out = [{}]
    for k, vals in zip(names, values):
        out = [{**d, k: float(v)} for d in out for v in vals]
    return out


def parse_axis(text: str) -> tuple[str, np.ndarray]:
    """``'name=start:stop:count'`` (count points, both ends included), ``'name=v1,v2,...'``
    or ``'name=value'`` -> (name, values)."""
    name, sep, spec = text.partition("=")
    name = name.strip()
    if not sep or not name or not spec:
        raise OptionError(f"scenario axis {text!r}: expected name=start:stop:count or "
                          "name=v1,v2,...")
    try:
        if ":" in spec:
            a, b, c = spec.split(":")
            count = int(c)
            if count < 1:
                raise ValueError
            return name, np.linspace(float(a), float(b), count)
        return name, np.array([float(v) for v in spec.split(",")])
    except ValueError:
        raise OptionError(f"scenario axis {text!r}: start, stop must be numbers and count a "
                          "positive integer (name=start:stop:count)") from None


def read_scenarios(path) -> list[dict]:
    """Scenarios from a file: JSON (a list of parameter dicts) or CSV (a header of parameter
    names, one scenario per row, numbers)."""
    with open(path, newline="") as fh:
        text = fh.read()
    if str(path).endswith(".json") or text.lstrip().startswith("["):
        data = json.loads(text)
        if not isinstance(data, list) or not all(isinstance(d, dict) for d in data):
            raise ProblemError(f"{path}: a JSON scenario file is a list of parameter objects")
        return data
    rows = list(csv.DictReader(text.splitlines()))
    try:
        return [{k.strip(): float(v) for k, v in r.items()} for r in rows]
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"{path}: every CSV entry must be a number ({exc})") from None


def plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [plain(u) for u in v]
    return v


def scenario_key(params: dict) -> str:
    """A stable identifier of a scenario: a hash of its parameters (canonical JSON)."""
    text = json.dumps({k: plain(v) for k, v in params.items()}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]
