"""What the evaluator remembers and counts: :class:`EvalCounters` (the calls of the user's F
and J, shared by every pass of a solve and by the preprocessor's reduced problem) and
:class:`Memo` (the last point and one pinned point, with their values)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..box import float_vector
from ._kernels import memo_key_kernel

__all__ = ["EvalCounters", "Memo"]


@dataclass
class EvalCounters:
    """Calls of the user's F and J (shared by every pass of a solve and by the reduced
    problem of the preprocessor)."""

    nfev: int = 0  #: F evaluations (finite-difference ones included)
    njev: int = 0  #: Jacobian evaluations
    nfev_fd: int = 0  #: of nfev: F calls spent on finite differences
    domain_errors: int = 0  #: guarded evaluations rejected (an exception or NaN/Inf)

    def reset(self):
        """All counts back to 0, in place (whoever holds this object sees the new counts)."""
        self.nfev = self.njev = self.nfev_fd = self.domain_errors = 0


class Memo:
    """The last point and its value, plus one pinned point (the start point, asked for
    again by the preprocessor, its reduced problem and every restart).

    Points are compared by ``==`` elementwise (so -0.0 equals 0.0 and a point with a NaN
    equals nothing), through a byte key made once per stored point: comparing the bytes
    of x + 0.0 (which turns -0.0 into 0.0) costs a fraction of an elementwise comparison
    for the short vectors of small problems, where the memo is asked several times per
    evaluation."""

    __slots__ = ("value", "key", "pvalue", "pkey")

    def __init__(self):
        self.clear()

    @staticmethod
    def key_of(x):
        """(shape, bytes, False) equal for two float arrays exactly when they are equal
        elementwise; None for an array with a NaN (equal to nothing)."""
        k = Memo.probe(x)
        return None if k[2] else k

    @staticmethod
    def probe(x):
        """The look-up key of a float64 array x: (shape, bytes of x + 0.0, has a NaN).
        Stored keys have no NaN, so a key with a NaN matches none of them.  A float
        vector in one compiled pass (x + 0.0 alone costs 1.4 us on a short vector, a
        NaN test one more)."""
        if float_vector(x):
            y = np.empty(x.shape[0])
            nan = memo_key_kernel(x, y)
            return x.shape, y.tobytes(), nan
        y = x + 0.0
        return x.shape, y.tobytes(), bool(np.isnan(y).any())

    def get(self, x, k=None):
        """The value at x, or None; ``k``: key_of(x) when the caller has it."""
        if self.key is None and self.pkey is None:
            return None
        if k is None:
            k = self.probe(x)
        if k == self.key:
            return self.value
        if k == self.pkey:
            return self.pvalue
        return None

    def put(self, x, value, k=None):
        """Store the value at x; ``k``: key_of(x) when the caller has it.  (Only the key
        is kept: it is a copy of the point's bytes.)"""
        self.key = self.key_of(np.asarray(x, dtype=float)) if k is None else k
        self.value = value
        if self.key is not None and self.key == self.pkey:
            self.pvalue = value

    def pin(self, x, k=None):
        """Keep the value at x (the last point) beyond the next evaluations; ``k``:
        key_of(x) when the caller has it."""
        if k is None:
            k = self.key_of(np.asarray(x, dtype=float))
        if k is not None and k == self.key:
            self.pvalue, self.pkey = self.value, self.key

    def clear(self):
        self.value = self.pvalue = self.key = self.pkey = None
