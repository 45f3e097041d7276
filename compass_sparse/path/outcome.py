"""What a pivotal path returns: its code (PATH's one-letter linear-solver codes), its end
point and counts (:class:`PathResult`), and the basis it ends in (:class:`WarmBasis`: which
variable of each index is basic, the warm start of the next path or of a later solve)."""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

__all__ = ["DIRECT_STEP_LINE", "HAND_OVER_LINE", "LinearCode", "PathResult",
           "WarmBasis"]

DIRECT_STEP_LINE = "minor       0 t 1.000000e+00 direct step (no pivot: one solve)"
"""The minor log's line for a path that the direct Newton step ended."""

HAND_OVER_LINE = "hand-over: the paths continue on the compiled sparse engine"
"""The minor log's line after a path on the basis manager stopped at the hand-over's
pivots (the linear MCP is then solved again on the engine, from its start)."""


class LinearCode(enum.Enum):
    """Outcome of one pivotal path: PATH's one-letter linear-solver codes."""

    SOLVED = "S"
    RAY = "R"
    CYCLE = "C"
    MINOR_LIMIT = "I"
    SINGULAR = "N"
    TOLERANCE = "T"
    ERROR = "E"


@dataclass
class WarmBasis:
    """Which variable of each index is basic at the end of a path: VAR_Z, VAR_W or VAR_V
    (VAR_S for fixed variables).  Artificials are not kept."""

    basic: np.ndarray


@dataclass
class PathResult:
    code: LinearCode
    z: np.ndarray
    w: np.ndarray
    v: np.ndarray
    t: float
    pivots: int = 0
    factorizations: int = 0
    updates: int = 0
    artificials: int = 0
    basis: WarmBasis | None = None
    ray_start: bool = False
    unbounded: bool = False  #: RAY because the entering variable grows without bound
    ray: np.ndarray | None = None  #: unbounded: direction of z along the ray
    ray_base: np.ndarray | None = None  #: unbounded: the z where the ray starts
    time: float = 0.0
    message: str = ""
    direct_lu_nnz: int = 0  #: entries of the direct step's LU (0: not tried)
    #: the path stopped at the hand-over's pivots (solve_linear_mcp's ``hand_over``): the
    #: caller runs the linear MCP again on the compiled sparse engine
    handed_over: bool = False

    @property
    def x(self) -> np.ndarray:
        return self.z - self.w + self.v
