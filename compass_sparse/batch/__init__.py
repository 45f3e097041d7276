"""Scenario batches: many MCPs from one model, warm-started along the scenario grid.

A scenario is data: a dict of parameters in, a row of results out.  ``model`` turns the
parameters into an MCP: a callable ``model(**params) -> MCP`` (or a CGE model object with
a ``.problem``), or a CGE generator model, whose parameters are its ``with_shock``
keywords plus the elasticities ``sigma_va``, ``sigma_armington``, ``sigma_consumer``
(see :class:`CGEScenarioModel`).

Warm starts along the grid
--------------------------
The scenarios are the nodes of a tree (:func:`scenario_tree`) in which every scenario's
parent is a near neighbour in parameter space (parameters scaled to [0, 1] by their
range).  A Cartesian grid gets a comb: branches along its longest axis hanging from a
spine along the others, so that the branches run in parallel; other sets of scenarios get
the minimum spanning tree of their nearest-neighbour graph.  A scenario starts from its
parent's solution and final basis (``Result.basis``) or, with ``predictor=True``, from the
first-order prediction of the implicit function theorem on the parent's active set
(:func:`compass_sparse.sensitivity.tangent_predictor`), kept only when its residual on the
new problem is below the parent point's.  If the parent failed, its nearest solved ancestor
gives the start; the root starts from the model's own start point ("cold").

The tree is cut into paths of at most ``chunk_size`` scenarios (a path follows the largest
subtree, so the long spine is one chain and the branches are many); a path is one task and
becomes ready when the scenario its head hangs from is finished.  Every scenario's start is
a function of the tree alone, never of timing, so the in-process runner, the local process
pool and Dask give the same results, and so does a resumed batch.

Results that are never lost
---------------------------
With ``output=DIR`` every finished task's rows are written at once as one Parquet file
``DIR/part-*.parquet`` (written to a temporary name and renamed, so a killed batch leaves
only whole files); at the end the parts are merged into ``DIR/results.parquet``.  A batch
run again with the same ``output`` reads the finished scenarios (identified by a hash of
their parameters), solves only the others and starts them from the stored solutions.  A
failed scenario (any status but SOLVED, or an exception in the model or the solver) is a
row with its status and message; it never stops the batch.  A task whose worker dies (a
crash in user code, a lost Dask worker) is tried once more, alone, so that only a scenario
that kills its worker again becomes an ERROR row; what a lost task had solved was not yet
written and is solved again (``chunk_size`` bounds that loss).

Modules: ``scenarios`` (grids, axes, CSV files, scenario keys), ``models`` (what is solved:
a callable or a CGE model), ``tree`` (the scenario tree and its paths), ``worker`` (a task's
solves), ``store`` (the Parquet results), ``executors`` (in-process, local pool, Dask),
``runner`` (:func:`solve_batch`).
"""
from .models import CGEScenarioModel
from .runner import BatchResult, solve_batch
from .scenarios import grid, parse_axis, read_scenarios, scenario_key
from .store import read_results
from .tree import scenario_tree

__all__ = ["BatchResult", "CGEScenarioModel", "grid", "parse_axis", "read_results",
           "read_scenarios", "scenario_key", "scenario_tree", "solve_batch"]
