"""Options of the preprocessor: one frozen dataclass, one switch per pass.

Every field is documented with its default and valid range; ``PresolveOptions.from_dict``
rejects unknown keys.  The tolerances follow PATH's hidden preprocessor options
(``presolve_zero_tolerance 1e-12``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .._options_base import OptionsMixin, keyword_checked, normalized
from ..exceptions import OptionError

__all__ = ["PresolveOptions"]


@keyword_checked
@dataclass(frozen=True)
class PresolveOptions(OptionsMixin):
    """Switches and tolerances of :func:`compass_sparse.presolve.presolve`.

    Pass switches (all ``True`` by default; each pass is described in its module):

    ``fixed_variables``   remove z_j with l_j = u_j (no linearity needed).
    ``empty_rows``        a linear row with no remaining entry: F_i is a constant.
    ``empty_columns``     a boxed variable that no remaining row depends on.
    ``isolated_pairs``    a variable and its row that no other row or variable touches
                          (declared pattern), solved at the start value: kept there.
    ``singleton_rows``    a linear row with one remaining entry.
    ``column_singletons`` a variable appearing in one row only, with a constant
                          coefficient (covers doubleton rows with a column singleton).
    ``forcing_rows``      a linear row that can only be complementary with all its
                          variables at bounds.
    ``duplicate_rows``    proportional linear rows (hashing); sign implications.
    ``range_fixing``      phase two: fix z_i at a bound when F_i has a strict sign on the box.

    Other fields:

    ``verify_linear = True``   evaluate F and J at two more points of the box and stop
        trusting declared-constant entries (and affine rows) that disagree.  It can only
        *remove* linear information, never add it.
    ``max_rounds = 50``        rounds of all passes (>= 1); presolve stops earlier at a
        fixed point (a round without reductions).
    ``zero_tolerance = 1e-12`` a declared-constant Jacobian entry with |a_ij| <= this is
        treated as a structural zero [>= 0].
    ``feasibility_tolerance = 1e-9``  a sign is "strict" only beyond this, relative to the
        row's magnitude (1 + |c_i| + sum |a_ij b_j|); violations up to it are not reported
        as infeasibility; a forcing row needs its extreme activity within it of 0 [> 0].
    ``structural_check = True``  run :func:`structural_rank_check` on the reduced problem
        and log a warning when it is structurally singular.
    ``seed = 0``               seed of the points used by ``verify_linear``.
    """

    fixed_variables: bool = True
    empty_rows: bool = True
    empty_columns: bool = True
    isolated_pairs: bool = True
    singleton_rows: bool = True
    column_singletons: bool = True
    forcing_rows: bool = True
    duplicate_rows: bool = True
    range_fixing: bool = True
    verify_linear: bool = True
    max_rounds: int = 50
    zero_tolerance: float = 1e-12
    feasibility_tolerance: float = 1e-9
    structural_check: bool = True
    seed: int = 0

    def __post_init__(self):
        for f in dataclasses.fields(self):
            kind = "bool" if f.type in ("bool", bool) else "int" if f.type in ("int", int) \
                else "float"
            object.__setattr__(self, f.name, normalized(f.name, getattr(self, f.name), kind,
                                                        what="presolve option"))
        if not isinstance(self.max_rounds, int) or isinstance(self.max_rounds, bool) \
                or self.max_rounds < 1:
            raise OptionError(f"presolve option max_rounds={self.max_rounds!r}: expected an "
                              "integer >= 1")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise OptionError(f"presolve option seed={self.seed!r}: expected an integer >= 0")
        for name, lo_open in (("zero_tolerance", False), ("feasibility_tolerance", True)):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or math.isnan(v) \
                    or v < 0 or (lo_open and v == 0) or math.isinf(v):
                raise OptionError(f"presolve option {name}={v!r}: expected a finite number "
                                  f"{'>' if lo_open else '>='} 0")

    _what = "presolve option"

    @property
    def pass_switches(self) -> dict:
        return {name: getattr(self, name) for name in PASS_NAMES}



PASS_NAMES = (
    "fixed_variables",
    "empty_rows",
    "empty_columns",
    "isolated_pairs",
    "singleton_rows",
    "column_singletons",
    "forcing_rows",
    "duplicate_rows",
    "range_fixing",
)
