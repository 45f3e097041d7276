"""Shared construction rules of the option dataclasses: build from a dict (unknown keys
raise OptionError with a did-you-mean hint), coerce None/dict/instance, replace fields."""
from __future__ import annotations

import dataclasses
import difflib
from typing import Any, Mapping

from .exceptions import OptionError


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
