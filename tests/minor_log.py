"""Reading the pivotal path's minor log (``minor <pivot> t <t> ...`` lines) in tests."""
import re

_T = re.compile(r" t \S+")
_STATUS = re.compile(r" \((OK|REFUSED|REFACTORED|REPAIRED)\)$")


def pivot_ts(lines):
    """t after each pivot of a minor log (printed to 7 digits)."""
    return [float(s.split()[3]) for s in lines if s.startswith("minor")]


def pivots_without_t(lines):
    """The pivots without t (equal to rounding) and the update's outcome (which two
    factorizations may decide differently: a refactorization instead of an update
    changes no pivot)."""
    return [_STATUS.sub("", _T.sub("", s)) for s in lines]
