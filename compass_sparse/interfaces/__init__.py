"""Links to modelling languages and to the PATH reference solver.

Each link turns a model written elsewhere into an :class:`~compass_sparse.MCP` -- F row by
row, paired with its variable, with the exact sparse Jacobian -- solves it with
:func:`~compass_sparse.solve_mcp` and writes the solution back into the model:

* :mod:`~compass_sparse.interfaces.pyomo` -- Pyomo models with ``pyomo.mpec``
  complementarity conditions (``SolverFactory('compass_sparse')``);
* :mod:`~compass_sparse.interfaces.gamspy` -- GAMSPy ``Model(problem='MCP')``, F and J from
  GAMS' own evaluator;
* :mod:`~compass_sparse.interfaces.gams_state` -- whether GAMS runs here (installed, its
  licence accepted), probed once;
* :mod:`~compass_sparse.interfaces.path_gamspy` -- PATH itself run through GAMSPy on
  problems generated in Python, the reference of the benchmarks.

Pyomo, CasADi and GAMSPy are optional extras: ``import compass_sparse`` and this package
import without them, and each link imports its language when it is first used.
"""
