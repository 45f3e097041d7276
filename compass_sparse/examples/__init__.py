"""Equilibrium models written three ways: Pyomo, GAMSPy and numpy callables.

* :mod:`.cournot` — Nash–Cournot oligopoly (n = 5 * markets)
* :mod:`.spatial` — spatial price equilibrium on a network (n = nodes + arcs)
* :mod:`.cge` — a small calibrated CGE model in MPSGE-like algebraic form (n = 2 S + 5)

Each module has ``data(...)``, ``callables(d)`` (keyword arguments for ``solve_mcp``),
``pyomo_model(d)`` and ``gamspy_model(d)``, and helpers that read the solution of each
route in the same variable order, so the three can be compared entry by entry.
"""
