"""The problem: MCP(F, [l, u]) and the one owner of the user's F and J.

``mcp``            :class:`MCP`, the problem definition and its validation (bounds, start
                   point, names, the sparse-Jacobian API);
``evaluator``      :class:`Evaluator`, the only code that calls the user's functions
                   (copies of x, counts, a memo, NaN/Inf and exceptions turned into
                   rejected points, J put on its pattern), and the evaluators of the
                   preprocessor's reduced problem and of the scaled problem;
``memo``           the evaluator's counters and one-point memo;
``pattern_cache``  objects computed from a Jacobian pattern alone, kept with it.
"""
from .evaluator import Evaluator
from .mcp import INFINITY, MCP, as_bounds, as_real
from .memo import EvalCounters

__all__ = ["INFINITY", "MCP", "EvalCounters", "Evaluator", "as_bounds", "as_real"]
