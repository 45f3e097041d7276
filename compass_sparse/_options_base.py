"""Shared construction rules of the option dataclasses: build from a dict (unknown keys
raise OptionError with a did-you-mean hint), coerce None/dict/instance, replace fields."""
from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
from typing import Any, Mapping

import numpy as np

from .exceptions import OptionError


def keyword_checked(cls):
    """Class decorator (after ``@dataclass``): unknown keywords and extra positional
    arguments raise OptionError instead of the constructor's TypeError."""
    init = cls.__init__
    n_fields = len(dataclasses.fields(cls))

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        cls._check_names(kwargs)
        if len(args) > n_fields:
            raise OptionError(f"{cls.__name__} takes at most {n_fields} values; give options "
                              "by name")
        init(self, *args, **kwargs)

    cls.__init__ = __init__
    return cls


def normalized(name: str, v, kind: str, *, allow_inf: bool = False, what: str = "option"):
    """v as a plain Python bool / int / float (NumPy scalars and integral floats accepted
    for integers); raises OptionError naming the option otherwise."""
    if kind == "bool":
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        raise OptionError(f"{what} {name}={v!r}: expected True or False")
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
        raise OptionError(f"{what} {name}={v!r}: expected a number")
    x = float(v)
    if math.isnan(x):
        raise OptionError(f"{what} {name} is NaN")
    if kind == "int":
        if not x.is_integer():
            raise OptionError(f"{what} {name}={v!r}: expected an integer")
        return int(v) if isinstance(v, numbers.Integral) else int(x)
    if math.isinf(x) and not allow_inf:
        raise OptionError(f"{what} {name}={v!r}: must be finite")
    return x


class OptionsMixin:
    _what = "option"

    @classmethod
    def _check_names(cls, keys):
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(keys) - names)
        if unknown:
            hints = []
            for u in unknown:
                close = difflib.get_close_matches(u, names, n=1)
                hints.append(f"{u!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
            raise OptionError(f"unknown {cls._what}(s): " + ", ".join(hints))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]):
        cls._check_names(d)
        return cls(**dict(d))

    @classmethod
    def coerce(cls, options):
        """None, a dict or an instance -> an instance."""
        if options is None:
            return cls()
        if isinstance(options, cls):
            return options
        if isinstance(options, Mapping):
            return cls.from_dict(options)
        raise OptionError(
            f"{cls.__name__} expected: an instance, a dict or None, not {type(options)}")

    def replace(self, **changes):
        """A copy with some fields changed (unknown names raise OptionError)."""
        self._check_names(changes)
        return dataclasses.replace(self, **changes)
