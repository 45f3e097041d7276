"""CGE models as MPSGE writes them: sectors, commodities, consumers, auxiliaries and
nested CES/CET production and demand blocks, turned into a mixed complementarity problem
with an exact sparse Jacobian and solved by :func:`compass_sparse.solve_mcp`.

Public names::

    Model                       declarations, the MCP, solve, benchmark check
    esum, exp, log              functions of expressions (auxiliary constraints)
    Solution, BenchmarkCheck    results: values, compensated demands, EV, reports
    DeclarationError, UnbalancedBenchmark   (subclasses of compass_sparse's ModelError)
    SIGMA_INF, RHO_CD           numerical thresholds (see structure.py, equations.py)
"""
from .declare import DeclarationError, Demand, Parameter, Production, VarRef, VarSet
from .equations import PRICE_FLOOR, RHO_CD
from .expr import Expr, esum, exp, log
from .model import Model
from .report import BenchmarkCheck, Solution, UnbalancedBenchmark
from .structure import SIGMA_INF

__all__ = [
           "PRICE_FLOOR",
           "RHO_CD",
           "SIGMA_INF",
           "BenchmarkCheck",
           "DeclarationError",
           "Demand",
           "Expr",
           "Model",
           "Parameter",
           "Production",
           "Solution",
           "UnbalancedBenchmark",
           "VarRef",
           "VarSet",
           "esum",
           "exp",
           "log",
]
