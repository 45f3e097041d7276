"""The MCP preprocessor (thesis §2.4; Ferris & Munson, "Preprocessing complementarity
problems", 2001): reduction passes, each in its own module, pushing reversible records on
one postsolve stack, iterated to a fixed point.

    res = presolve(problem)            # PresolveResult
    y = some_solver(res.reduced).x     # solve the reduced MCP
    x = res.postsolve(y)               # a solution of the original MCP

Reductions use only linear information: Jacobian entries declared constant by the user
(``MCP(constant_jac=...)``).  See each pass module for its validity conditions.
"""
from ._onedim import solve_1d
from ._work import InfeasibilityDiagnostic
from .core import (ReductionStats, PostsolvedSolution, PresolveResult, PresolveStats, presolve,
                   solve_with_presolve)
from .options import PASS_NAMES, PresolveOptions
from .postsolve import (DiagonalColumnSingletons, EmptyColumns, FixByEquation, FixVariables,
                        ForcingRows, FreeColumnSingletons, PostsolveStack, Record)
from .structural import StructuralReport, structural_rank_check

__all__ = [
    "presolve",
    "solve_with_presolve",
    "structural_rank_check",
    "PresolveOptions",
    "PresolveResult",
    "PresolveStats",
    "ReductionStats",
    "PostsolvedSolution",
    "PostsolveStack",
    "InfeasibilityDiagnostic",
    "StructuralReport",
    "Record",
    "FixVariables",
    "FixByEquation",
    "EmptyColumns",
    "DiagonalColumnSingletons",
    "FreeColumnSingletons",
    "ForcingRows",
    "PASS_NAMES",
    "solve_1d",
]
