"""Shared construction rules of the option dataclasses: build from a dict (unknown keys
raise OptionError with a did-you-mean hint), coerce None/dict/instance, replace fields."""
from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
from collections.abc import Mapping  # (typing's alias costs ~3 us per isinstance)
from typing import Any

import numpy as np

from .exceptions import OptionError


def keyword_checked(cls):
    """Class decorator (after ``@dataclass``): unknown keywords and extra positional
    arguments raise OptionError instead of the constructor's TypeError."""
    init = cls.__init__
    n_fields = len(dataclasses.fields(cls))

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        cls.check_names(kwargs)
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


_BUILT: dict = {}
"""Frozen option instances built from dicts, by (class, the dict's items with types)."""
_BUILT_MAX = 64


@functools.lru_cache(maxsize=None)
def _field_names(cls) -> frozenset:
    return frozenset(f.name for f in dataclasses.fields(cls))


def suggest(name: str, names, aliases=None) -> str | None:
    """The option a misspelt or foreign ``name`` most likely means: its entry in
    ``aliases`` (the names other solvers use: ``tol``), else the closest of ``names``."""
    if aliases and name.lower() in aliases:
        return aliases[name.lower()]
    close = difflib.get_close_matches(name, sorted(names), n=1)
    return close[0] if close else None


class OptionsMixin:
    _what = "option"
    _aliases: dict = {}  # other solvers' names of our options (lower case) -> ours

    @classmethod
    def check_names(cls, keys):
        names = _field_names(cls)
        if names.issuperset(keys):
            return
        unknown = sorted(set(keys) - names)
        if unknown:
            hints = []
            for u in unknown:
                close = suggest(u, names, cls._aliases)
                hints.append(f"{u!r}" + (f" (did you mean {close!r}?)" if close else ""))
            raise OptionError(f"unknown {cls._what}(s): " + ", ".join(hints))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]):
        if not cls.__dataclass_params__.frozen:
            cls.check_names(d)
            return cls(**dict(d))
        # A frozen instance can be shared: a solve loop passing the same dict every time
        # gets the options built and validated once.  The key holds each value's type,
        # so that True and 1 (equal and of equal hash) stay apart, sorted by name (the
        # names are distinct: only they are compared); it is looked up before the names
        # are checked (a key found was built from valid names): ~1.5 us a solve where
        # checking first, and a generator, cost ~4.
        try:
            items = [(k, v.__class__, v) for k, v in d.items()]
            key = (cls, *(sorted(items) if len(items) > 1 else items))
            hit = _BUILT.get(key)
        except TypeError:  # an unhashable value: built (and rejected) as usual
            cls.check_names(d)
            return cls(**dict(d))
        if hit is None:
            cls.check_names(d)
            hit = cls(**dict(d))
            if len(_BUILT) >= _BUILT_MAX:
                _BUILT.clear()
            _BUILT[key] = hit
        return hit

    @classmethod
    def coerce(cls, options):
        """None, a dict or an instance -> an instance."""
        if options is None:
            return cls.from_dict({})
        if isinstance(options, cls):
            return options
        if isinstance(options, Mapping):
            return cls.from_dict(options)
        raise OptionError(
            f"{cls.__name__} expected: an instance, a dict or None, not {type(options)}")

    def replace(self, **changes):
        """A copy with some fields changed (unknown names raise OptionError).  A frozen
        instance's copies are shared as :meth:`from_dict`'s are: every restart of a solve
        replaces a few fields of the same options, and building and validating them cost
        ~0.15 ms per restart of a small problem."""
        self.check_names(changes)
        if not self.__dataclass_params__.frozen:
            return dataclasses.replace(self, **changes)
        try:
            key = ("replace", self) + tuple(sorted((k, type(v), v) for k, v in changes.items()))
            hash(key)
        except TypeError:  # an unhashable field or value: built as usual
            return dataclasses.replace(self, **changes)
        hit = _BUILT.get(key)
        if hit is None:
            hit = dataclasses.replace(self, **changes)
            if len(_BUILT) >= _BUILT_MAX:
                _BUILT.clear()
            _BUILT[key] = hit
        return hit
