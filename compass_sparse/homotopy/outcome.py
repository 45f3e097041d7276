"""How a homotopy pass ended (:class:`HomotopyStatus`) and what it did
(:class:`HomotopyOutcome`)."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

__all__ = ["HomotopyOutcome", "HomotopyStatus"]


class HomotopyStatus(enum.Enum):
    """How a homotopy pass ended."""

    SOLVED = "solved"  #: a point meeting the convergence tolerance was reached
    END_REACHED = "end reached"  #: lam = 1 reached but the end game missed the tolerance
    DIVERGED = "diverged"  #: ||x|| exceeded the divergence bound (unbounded curve)
    STEP_TOO_SMALL = "step too small"  #: the corrector failed down to the minimum step
    SINGULAR = "singular"  #: the augmented Jacobian [H_x, H_lam] lost rank (not a regular path)
    STEP_LIMIT = "step limit"  #: homotopy_step_limit steps without reaching lam = 1
    RETURNED = "returned"  #: the curve came back below lam = 0 (numerical failure)
    EVALUATION_ERROR = "evaluation error"  #: F or J undefined along the path
    TIME_LIMIT = "time limit"  #: the solve's deadline passed


@dataclass
class HomotopyOutcome:
    status: HomotopyStatus
    message: str
    z: np.ndarray | None = None  #: best point (lowest merit) of the pass
    lam: float = 0.0
    paths: int = 0
    steps: int = 0
    rejected: int = 0
    turning_points: int = 0
    newton_iterations: int = 0
    factorizations: int = 0
    path_status: list = field(default_factory=list)  #: status of each path
