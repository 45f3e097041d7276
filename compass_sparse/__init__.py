"""compass_sparse: a sparse, large-scale solver for mixed complementarity problems.

Solve MCP(F, [l, u]) — find l <= z <= u with F_i(z) = 0 where l_i < z_i < u_i, F_i(z) >= 0
where z_i = l_i and F_i(z) <= 0 where z_i = u_i — by PATH's method: a normal-map Newton
method whose every major iteration walks a Lemke-type pivotal path on a sparse basis with
Forrest–Tomlin updates, stabilized by a non-monotone watchdog scheme on the
Fischer–Burmeister merit function.

Public names::

    solve_mcp, solve_lcp, MCPSolver      entry points
    MCP                                  problem definition (sparse Jacobian API)
    Options                              solver options (frozen dataclass)
    check_jacobian                       J against finite differences of F, by name
    Result, Status, PointStatus          outcome (Iteration: one entry of Result.history)
    plot                                 convergence plots (needs matplotlib)
    exceptions                           CompassError and subclasses
"""
import logging as _logging

from .exceptions import (BoundsError, CompassError, EvaluationError, JacobianPatternError,
                         OptionError, ProblemError, ShapeError, StartPointError)
from .options import Options
from .problem.mcp import MCP
from .result import Result
from .status import IntermediateResult, Iteration, PassStats, PointStatus, Status
from .lcp import solve_lcp
from .solve import MCPSolver, solve_mcp
from .diagnostics import JacobianCheck, check_jacobian

__version__ = "0.1.0"

# A library only emits log records; handlers, levels and propagation are the application's.
_logging.getLogger("compass_sparse").addHandler(_logging.NullHandler())

__all__ = [
    "solve_mcp", "solve_lcp", "MCPSolver", "MCP", "Options", "Result", "Status",
    "PointStatus", "PassStats", "IntermediateResult", "Iteration", "CompassError", "ProblemError",
    "ShapeError", "BoundsError", "StartPointError", "EvaluationError",
    "JacobianPatternError", "OptionError", "check_jacobian", "JacobianCheck", "__version__",
]
