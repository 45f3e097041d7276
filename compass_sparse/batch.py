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
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .options import Options
from .status import Status

logger = logging.getLogger("compass_sparse")

__all__ = [
    "BatchResult",
    "CGEScenarioModel",
    "grid",
    "parse_axis",
    "read_results",
    "read_scenarios",
    "scenario_key",
    "scenario_tree",
    "solve_batch",
]

RESULTS_FILE = "results.parquet"


# ---------------------------------------------------------------------------- scenarios
def grid(**axes) -> list[dict]:
    """The Cartesian product of parameter axes, the last axis varying fastest:
    ``grid(tariff=[0, .1], sigma_armington=[1, 2])`` -> 4 dicts."""
    names = list(axes)
    values = [list(np.atleast_1d(np.asarray(axes[k], dtype=float))) for k in names]
    out = [{}]
    for k, vals in zip(names, values):
        out = [{**d, k: float(v)} for d in out for v in vals]
    return out


def parse_axis(text: str) -> tuple[str, np.ndarray]:
    """``'name=start:stop:count'`` (count points, both ends included), ``'name=v1,v2,...'``
    or ``'name=value'`` -> (name, values)."""
    from .exceptions import OptionError

    name, sep, spec = text.partition("=")
    name = name.strip()
    if not sep or not name or not spec:
        raise OptionError(f"scenario axis {text!r}: expected name=start:stop:count or "
                          "name=v1,v2,...")
    try:
        if ":" in spec:
            a, b, c = spec.split(":")
            count = int(c)
            if count < 1:
                raise ValueError
            return name, np.linspace(float(a), float(b), count)
        return name, np.array([float(v) for v in spec.split(",")])
    except ValueError:
        raise OptionError(f"scenario axis {text!r}: start, stop must be numbers and count a "
                          "positive integer (name=start:stop:count)") from None


def read_scenarios(path) -> list[dict]:
    """Scenarios from a file: JSON (a list of parameter dicts) or CSV (a header of parameter
    names, one scenario per row, numbers)."""
    import csv

    from .exceptions import ProblemError

    with open(path, newline="") as fh:
        text = fh.read()
    if str(path).endswith(".json") or text.lstrip().startswith("["):
        data = json.loads(text)
        if not isinstance(data, list) or not all(isinstance(d, dict) for d in data):
            raise ProblemError(f"{path}: a JSON scenario file is a list of parameter objects")
        return data
    rows = list(csv.DictReader(text.splitlines()))
    try:
        return [{k.strip(): float(v) for k, v in r.items()} for r in rows]
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"{path}: every CSV entry must be a number ({exc})") from None


def _plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_plain(u) for u in v]
    return v


def scenario_key(params: dict) -> str:
    """A stable identifier of a scenario: a hash of its parameters (canonical JSON)."""
    text = json.dumps({k: _plain(v) for k, v in params.items()}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


# ---------------------------------------------------------------------------- models
class CGEScenarioModel:
    """Scenario parameters -> MCP for a CGE generator model.

    Parameters named like an elasticity argument of the static generator
    (``sigma_va``, ``sigma_armington``, ``sigma_consumer``; scalar or array) rebuild the
    model from its SAM with those elasticities (cached per worker); all others are passed to
    ``with_shock`` (static: ``tariff`` — a scalar is the rate on every import link —,
    ``output_tax``, ``endowment``, ``balance``, ``productivity``)."""

    ELASTICITIES = ("sigma_va", "sigma_armington", "sigma_consumer")

    def __init__(self, model):
        self.model = model
        self._bases = {}

    def cge(self, **params):
        """The CGE model (not only its MCP) of a scenario."""
        params = dict(params)
        el = {k: params.pop(k) for k in self.ELASTICITIES if k in params}
        base = self._base(el) if el else self.model
        return base.with_shock(**params) if params else base

    def __call__(self, **params):
        return self.cge(**params).problem

    def _base(self, el):
        key = scenario_key(el)
        if key not in self._bases:
            info = self.model.info
            if info.get("family") != "static_cge":
                raise ValueError("elasticity scenarios need a static CGE model")
            from .generators.cge import static_from_sam

            num = info.get("numeraire_index")
            numeraire = None if num is None else ("income", self.model.names[num])
            if num is not None and num not in range(self.model.blocks["M"].start,
                                                    self.model.blocks["M"].stop):
                numeraire = ("price", self.model.names[num])
            kw = {k: info[k] for k in self.ELASTICITIES}
            kw.update({k: np.broadcast_to(np.asarray(v, float), np.shape(info[k])).copy()
                       for k, v in el.items()})
            if len(self._bases) >= 16:  # a grid visits few elasticity values per worker
                self._bases.pop(next(iter(self._bases)))
            self._bases[key] = static_from_sam(
                info["sam"], numeraire=numeraire, price_lb=info["price_lb"],
                income_free=info["income_free"], policy=info["policy"],
                start=self.model.benchmark, **kw)
        return self._bases[key]


def _as_builder(model):
    if hasattr(model, "with_shock") and hasattr(model, "problem"):
        return CGEScenarioModel(model)
    if callable(model):
        return model
    raise TypeError("model must be a callable params -> MCP or a CGE model with with_shock")


def _build(builder, params):
    from .problem.mcp import MCP

    out = builder(**params)
    if not isinstance(out, MCP):
        out = getattr(out, "problem", out)
    if not isinstance(out, MCP):
        raise TypeError(f"the model returned {type(out).__name__}, not an MCP")
    return out


# ---------------------------------------------------------------------------- the tree
def _param_matrix(scenarios):
    """(N, d) float matrix of the scalar parameters scaled to [0, 1], or None when some
    parameter is not a number."""
    names = sorted({k for s in scenarios for k in s})
    try:
        P = np.array([[float(s.get(k, np.nan)) for k in names] for s in scenarios], float)
    except (TypeError, ValueError):
        return None
    if P.size == 0 or not np.all(np.isfinite(P)):
        return None
    lo, hi = P.min(axis=0), P.max(axis=0)
    keep = hi > lo
    return (P[:, keep] - lo[keep]) / (hi[keep] - lo[keep])


def scenario_tree(scenarios) -> np.ndarray:
    """parent[i] of every scenario in the warm-start tree (-1 at the root); see the module
    docstring.  Non-numeric parameters: a chain in the given order."""
    N = len(scenarios)
    parent = np.full(N, -1, dtype=np.int64)
    if N <= 1:
        return parent
    P = _param_matrix(scenarios)
    if P is None:
        parent[1:] = np.arange(N - 1)
        return parent
    if P.shape[1] == 0:  # all scenarios equal: a star around the first
        parent[1:] = 0
        return parent
    uniq = [np.unique(P[:, a]) for a in range(P.shape[1])]
    coords = np.column_stack([np.searchsorted(u, P[:, a]) for a, u in enumerate(uniq)])
    lengths = np.array([u.size for u in uniq])
    if (np.prod(lengths.astype(float)) == N
            and len({tuple(c) for c in coords.tolist()}) == N):
        return _comb_tree(coords, lengths)
    return _mst_tree(P)


def _comb_tree(coords, lengths):
    """Branches along the longest axis, hanging from a spine along the next, and so on."""
    order = np.argsort(-lengths, kind="stable")
    index = {tuple(c): i for i, c in enumerate(coords.tolist())}
    parent = np.full(len(coords), -1, dtype=np.int64)
    for i, c in enumerate(coords.tolist()):
        for a in order:
            if c[a] > 0:
                p = list(c)
                p[a] -= 1
                parent[i] = index[tuple(p)]
                break
    return parent


def _mst_tree(P):
    """Minimum spanning tree of the k-nearest-neighbour graph (components joined in
    order), rooted at scenario 0."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import (
        breadth_first_order,
        connected_components,
        minimum_spanning_tree,
    )
    from scipy.spatial import cKDTree

    N = P.shape[0]
    k = min(N - 1, 10)
    dist, nb = cKDTree(P).query(P, k=k + 1)
    rows = np.repeat(np.arange(N), k)
    # +1e-12: csgraph drops zero weights, and equal scenarios are neighbours too.
    W = sp.csr_matrix((dist[:, 1:].ravel() + 1e-12, (rows, nb[:, 1:].ravel())), shape=(N, N))
    W = W.maximum(W.T)
    ncomp, lab = connected_components(W, directed=False)
    if ncomp > 1:
        firsts = [int(np.flatnonzero(lab == c)[0]) for c in range(ncomp)]
        extra = sp.csr_matrix((np.ones(ncomp - 1), (firsts[:-1], firsts[1:])), shape=(N, N))
        W = W + extra + extra.T
    T = minimum_spanning_tree(W)
    T = T + T.T
    _, pred = breadth_first_order(T, 0, directed=False, return_predecessors=True)
    parent = np.asarray(pred, dtype=np.int64)
    parent[parent < 0] = -1
    return parent


def _paths(parent, todo, chunk_size):
    """Cut the tree restricted to ``todo`` into paths of at most chunk_size nodes, each
    following its largest subtree; returns [(nodes, subtree size of the head)]."""
    todo_set = {int(i) for i in todo}
    children = {i: [] for i in todo_set}
    for i in sorted(todo_set):
        p = int(parent[i])
        if p in todo_set:
            children[p].append(i)
    heads = [i for i in sorted(todo_set) if int(parent[i]) not in todo_set]
    size = {}
    stack = list(heads)
    order = []
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(children[i])
    for i in reversed(order):
        size[i] = 1 + sum(size[c] for c in children[i])
    out = []
    queue = list(heads)
    while queue:
        h = queue.pop()
        path, cur = [h], h
        while children[cur]:
            kids = sorted(children[cur], key=lambda c: (-size[c], c))
            queue.extend(kids[1:])
            if len(path) == chunk_size:
                queue.append(kids[0])
                break
            cur = kids[0]
            path.append(cur)
        out.append((path, size[h]))
    return out


# ---------------------------------------------------------------------------- worker side
_WORKER_MODELS: dict = {}


def _load_model(blob: bytes):
    key = hashlib.sha1(blob).hexdigest()
    if key not in _WORKER_MODELS:
        import pickle

        if len(_WORKER_MODELS) >= 4:
            _WORKER_MODELS.pop(next(iter(_WORKER_MODELS)))
        _WORKER_MODELS[key] = pickle.loads(blob)
    return _WORKER_MODELS[key]


def _solve_segment(blob: bytes, task: dict) -> list[dict]:
    """Solve the scenarios of one path in order, each from the last solved state."""
    builder = _load_model(blob)
    state = task["start"]
    rows = []
    for (idx, params), parent in zip(task["nodes"], task["parents"]):
        row = _solve_one(builder, idx, params, parent, state if task["warm"] else None, task)
        rows.append(row)
        if row["success"] and row["x"] is not None:
            state = (row["x"], row["basis"])
    if task["record"] is not None:  # only the named variables leave the worker
        for row in rows:
            row["x"] = row["basis"] = None
    return rows


def _solve_one(builder, idx, params, parent, state, task) -> dict:
    from .merit import fb_phi
    from .path.outcome import WarmBasis
    from .sensitivity import tangent_predictor
    from .solve import solve_mcp

    t0 = time.perf_counter()
    row = {"index": idx, "parent": parent, "start": "cold", "predicted": False,
           "worker": f"{os.uname().nodename}:{os.getpid()}"}
    try:
        problem = _build(builder, params)
    except Exception as exc:  # a model that cannot be built is a failed scenario
        return _failure_row(row, params, f"building the model failed: {exc!r}", t0)
    x0, basis = None, None
    if state is not None:
        x0 = state[0]
        basis = WarmBasis(np.frombuffer(state[1], dtype=np.int8).copy()) \
            if state[1] is not None else None
        row["start"] = "warm"
        if task["predictor"]:
            try:
                f = problem.F_uncounted(x0)
                xp = tangent_predictor(problem, x0, f=f)
                if xp is not None:
                    fp = problem.F_uncounted(xp)
                    if (np.all(np.isfinite(fp)) and np.linalg.norm(fb_phi(xp, fp, problem.lb,
                        problem.ub)) < np.linalg.norm(fb_phi(x0, f, problem.lb, problem.ub))):
                        x0 = xp
                        row["start"], row["predicted"] = "predicted", True
            except Exception as exc:  # the predictor is an optimization: never fatal
                logger.info("scenario %d: predictor skipped (%r)", idx, exc)
    try:
        prob = problem.with_start(x0) if x0 is not None else problem
        res = solve_mcp(prob, options=task["options"], basis=basis)
    except Exception as exc:
        return _failure_row(row, params, f"the solver raised {exc!r}", t0)
    rep = res.residual
    row.update(_param_columns(params))
    row.update(
        status=res.status.name, status_code=int(res.status), success=bool(res.success),
        point_status=res.point_status.name, message=res.message,
        residual=float(rep.fb_norm) if rep is not None else float("nan"),
        natural_residual=float(rep.natural) if rep is not None else float("nan"),
        nit=int(res.nit), minor_iterations=int(res.minor_iterations), nfev=int(res.nfev),
        njev=int(res.njev), solve_time=float(res.time), time=time.perf_counter() - t0)
    x = np.asarray(res.x, dtype=float)
    row["x"] = x
    row["basis"] = res.basis.basic.astype(np.int8).tobytes() if res.basis is not None else None
    if task["record"] is not None:
        pos = {s: i for i, s in enumerate(problem.var_names or [])}
        for s in task["record"]:
            row[f"var.{s}"] = float(x[pos[s]]) if s in pos else float("nan")
    return row


def _param_columns(params):
    out = {"params": json.dumps({k: _plain(v) for k, v in params.items()}, sort_keys=True),
           "key": scenario_key(params)}
    for k, v in params.items():
        if np.ndim(v) == 0 and isinstance(_plain(v), (int, float)):
            out[f"param.{k}"] = float(v)
    return out


def _failure_row(row, params, message, t0):
    row.update(_param_columns(params))
    row.update(status=Status.ERROR.name, status_code=int(Status.ERROR), success=False,
               point_status="", message=message, residual=float("nan"),
               natural_residual=float("nan"), nit=0, minor_iterations=0, nfev=0, njev=0,
               solve_time=0.0, time=time.perf_counter() - t0, x=None, basis=None)
    return row


# ---------------------------------------------------------------------------- storage
def _schema(rows):
    import pyarrow as pa

    fixed = [("index", pa.int64()), ("key", pa.string()), ("params", pa.string()),
             ("status", pa.string()), ("status_code", pa.int64()), ("success", pa.bool_()),
             ("point_status", pa.string()), ("message", pa.string()),
             ("residual", pa.float64()), ("natural_residual", pa.float64()),
             ("nit", pa.int64()), ("minor_iterations", pa.int64()), ("nfev", pa.int64()),
             ("njev", pa.int64()), ("solve_time", pa.float64()), ("time", pa.float64()),
             ("start", pa.string()), ("predicted", pa.bool_()), ("parent", pa.int64()),
             ("worker", pa.string()), ("x", pa.list_(pa.float64())), ("basis", pa.binary())]
    names = {f for f, _ in fixed}
    extra = sorted({k for r in rows for k in r if k not in names})
    return pa.schema(fixed + [(k, pa.float64()) for k in extra])


class ResultStore:
    """A directory of Parquet files, one per finished task, merged at the end."""

    def __init__(self, path):
        try:
            import pyarrow
            import pyarrow.parquet  # noqa: F401
        except ImportError:  # pragma: no cover - CI installs the extra
            raise ImportError("writing batch results needs pyarrow: pip install "
                              "'compass-sparse[batch]'") from None
        self.path = os.fspath(path)
        os.makedirs(self.path, exist_ok=True)
        self._seq = 0

    def files(self):
        names = sorted(f for f in os.listdir(self.path) if f.endswith(".parquet"))
        return [os.path.join(self.path, f) for f in names]

    def load(self) -> dict:
        """key -> row of every finished scenario on disk (first copy wins)."""
        import pyarrow.parquet as pq

        out = {}
        for f in self.files():
            for r in pq.read_table(f).to_pylist():
                out.setdefault(r["key"], r)
        return out

    def write(self, rows):
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not rows:
            return
        table = pa.Table.from_pylist([_storable(r) for r in rows], schema=_schema(rows))
        self._seq += 1
        name = f"part-{time.time_ns():020d}-{os.getpid()}-{self._seq:06d}.parquet"
        tmp = os.path.join(self.path, "." + name + ".tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, os.path.join(self.path, name))

    def compact(self):
        """Merge every file into results.parquet (rename first, then delete the parts: a
        kill in between leaves duplicates that load() ignores)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        files = self.files()
        if not files:
            return
        rows = sorted(self.load().values(), key=lambda r: r["index"])
        table = pa.Table.from_pylist(rows, schema=_schema(rows))
        tmp = os.path.join(self.path, "." + RESULTS_FILE + ".tmp")
        pq.write_table(table, tmp)
        final = os.path.join(self.path, RESULTS_FILE)
        os.replace(tmp, final)
        for f in files:
            if f != final:
                os.remove(f)


def _storable(row):
    r = dict(row)
    if isinstance(r.get("x"), np.ndarray):
        r["x"] = r["x"].tolist()
    return r


def read_results(path):
    """The rows of a results directory as a pyarrow Table, ordered by scenario index."""
    rows = sorted(ResultStore(path).load().values(), key=lambda r: r["index"])
    import pyarrow as pa

    return pa.Table.from_pylist(rows, schema=_schema(rows))


# ---------------------------------------------------------------------------- progress
class Progress:
    """Counts, failures, rate and time left: a bar redrawn in place when the stream is a
    terminal, a log line every ``every`` seconds otherwise."""

    def __init__(self, total: int, done: int = 0, stream=None, every: float = 10.0,
                 live: bool = True):
        self.total, self.start_done, self.done, self.failed = total, done, done, 0
        self.stream = sys.stderr if stream is None else stream
        self.tty = live and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.periodic = live and not self.tty
        self.every = every
        self.t0 = self._last = time.perf_counter()

    def line(self) -> str:
        el = time.perf_counter() - self.t0
        new = self.done - self.start_done
        rate = new / el if el > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else float("nan")
        eta = f"{left / 60:.0f} min" if left > 600 else f"{left:.0f} s"
        return (f"{self.done}/{self.total} scenarios  failed {self.failed}  "
                f"{rate:.2f}/s  time left {eta if np.isfinite(left) else '?'}")

    def update(self, solved: int, failed: int):
        self.done += solved
        self.failed += failed
        now = time.perf_counter()
        if self.tty:
            width = 30
            k = int(width * self.done / max(self.total, 1))
            self.stream.write(f"\r[{'#' * k}{'.' * (width - k)}] {self.line()}   ")
            self.stream.flush()
        elif self.periodic and now - self._last >= self.every:
            logger.info("batch: %s", self.line())
            self._last = now

    def close(self):
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
        logger.info("batch: %s", self.line())


# ---------------------------------------------------------------------------- driver
@dataclass
class BatchResult:
    """Rows of every scenario (ordered like ``scenarios``), those solved now and those
    found finished on disk."""

    rows: list
    solved_now: int = 0
    resumed: int = 0
    wall_time: float = 0.0
    executor: str = ""
    path: str | None = None
    scenarios: list = field(default_factory=list)

    @property
    def statuses(self) -> list:
        return [r["status"] for r in self.rows]

    @property
    def failed(self) -> int:
        return sum(not r["success"] for r in self.rows)

    @property
    def x(self) -> np.ndarray:
        """(N, n) solutions (NaN rows where no point was recorded)."""
        n = max((len(r["x"]) for r in self.rows if r.get("x") is not None), default=0)
        out = np.full((len(self.rows), n), np.nan)
        for i, r in enumerate(self.rows):
            if r.get("x") is not None:
                out[i] = r["x"]
        return out

    def column(self, name) -> np.ndarray:
        return np.array([r.get(name, np.nan) for r in self.rows])

    def summary(self) -> str:
        nit = self.column("nit")
        return (f"{len(self.rows)} scenarios ({self.solved_now} solved now, {self.resumed} "
                f"resumed), {self.failed} failed, mean major iterations {np.mean(nit):.2f}, "
                f"{self.wall_time:.1f} s on {self.executor}")


def solve_batch(model, scenarios, *, options=None, executor=None, workers=None,
                output=None, warm_start: bool = True, predictor: bool = True,
                record=None, chunk_size: int = 8, retry_failed: bool = False,
                progress: bool | None = True, compact: bool = True) -> BatchResult:
    """Solve one MCP per scenario.

    Parameters
    ----------
    model : callable ``model(**params) -> MCP`` or a CGE model (see the module docstring).
    scenarios : sequence of parameter dicts (e.g. from :func:`grid`).
    options : Options or dict for every solve.
    executor : None (a local process pool over ``workers`` processes, default every core),
        a ``concurrent.futures.Executor``, or a ``dask.distributed.Client``.
    workers : pool size; 0 solves in this process.
    output : directory for the Parquet results; a rerun resumes from it.
    warm_start : start each scenario from its tree parent's solution and basis (False: every
        scenario from the model's start point, no basis).
    predictor : refine a warm start by the first-order (implicit-function) predictor.
    record : None stores the whole solution (and the basis, for resuming warm); a list of
        variable names stores only those (columns ``var.<name>``, NaN for a name the
        problem does not have).
    chunk_size : scenarios per task (at most).
    retry_failed : on a rerun, solve again the scenarios stored as failed.
    progress : True draws a bar on a terminal stderr (a log line every 10 s otherwise);
        False logs only the final counts; None nothing.
    """
    t0 = time.perf_counter()
    scenarios = [dict(s) for s in scenarios]
    N = len(scenarios)
    opt = Options.coerce(options)
    if chunk_size < 1:
        from .exceptions import OptionError

        raise OptionError(f"chunk_size must be >= 1, got {chunk_size}")
    keys = [scenario_key(s) for s in scenarios]
    store = ResultStore(output) if output is not None else None
    on_disk = store.load() if store is not None else {}
    rows: dict[int, dict] = {}
    for i, k in enumerate(keys):
        r = on_disk.get(k)
        if r is not None and (r["success"] or not retry_failed):
            rows[i] = {**r, "index": i}
    todo = [i for i in range(N) if i not in rows]
    parent = scenario_tree(scenarios) if warm_start else np.full(N, -1, dtype=np.int64)
    if warm_start:
        paths = _paths(parent, todo, chunk_size)
    else:
        paths = [(todo[a:a + chunk_size], 0) for a in range(0, len(todo), chunk_size)]
    # Largest subtrees first: they hold the critical path.
    paths.sort(key=lambda p: (-p[1], p[0][0]))
    prog = Progress(N, len(rows), live=bool(progress)) if progress is not None else None
    import pickle

    try:
        import cloudpickle as _pickler  # lambdas and closures as models
    except ImportError:  # pragma: no cover - installed with dask
        _pickler = pickle
    blob = _pickler.dumps(_as_builder(model), protocol=pickle.HIGHEST_PROTOCOL)
    from .executors import make_executor

    ex = make_executor(executor, workers) if todo else None
    task_base = {"options": opt, "warm": warm_start, "predictor": predictor and warm_start,
                 "record": None if record is None else list(record)}

    def start_state(head):
        """(ready, state): the nearest solved ancestor's (x, basis), None for cold."""
        j = int(parent[head])
        while j >= 0:
            if j not in rows:
                return False, None
            r = rows[j]
            if r["success"] and r.get("x") is not None:
                return True, (np.asarray(r["x"], float), r.get("basis"))
            j = int(parent[j])
        return True, None

    solved_now = 0
    inflight = {}
    pending = [(nodes, sz, 0) for nodes, sz in paths]
    try:
        ref = ex.share(blob) if ex is not None else None
        limit = 2 * ex.workers + 1 if ex is not None else 0
        while pending or inflight:
            still = []
            # A task that failed as a whole (a worker died under it, perhaps killed by
            # another task) is tried once more, alone, so that only its own crash can
            # fail it again.
            isolating = any(t for _, _, t in inflight.values())
            for nodes, sz, tries in pending:
                if isolating or len(inflight) >= limit or (tries and inflight):
                    still.append((nodes, sz, tries))
                    continue
                ready, state = start_state(nodes[0])
                if not ready:
                    still.append((nodes, sz, tries))
                    continue
                task = dict(task_base, start=state,
                            nodes=[(i, scenarios[i]) for i in nodes],
                            parents=[int(parent[i]) for i in nodes])
                inflight[ex.submit(_solve_segment, ref, task)] = (nodes, sz, tries)
                isolating = bool(tries)
            pending = still
            if not inflight:
                raise RuntimeError("batch scheduling stalled: a path waits for a scenario "
                                   "that is never solved")  # pragma: no cover
            for fut in ex.wait_any(inflight):
                nodes, sz, tries = inflight.pop(fut)
                try:
                    new = fut.result()
                except Exception as exc:  # a lost worker: retry once, then rows with the error
                    if tries == 0:
                        logger.info("batch: a task of %d scenarios failed (%r); retrying it "
                                    "alone", len(nodes), exc)
                        pending.append((nodes, sz, 1))
                        continue
                    new = [_failure_row({"index": i, "parent": int(parent[i]), "start": "",
                                         "predicted": False, "worker": ""}, scenarios[i],
                                        f"the task failed: {exc!r}", time.perf_counter())
                           for i in nodes]
                if store is not None:
                    store.write(new)
                for r in new:
                    rows[r["index"]] = r
                solved_now += len(new)
                if prog is not None:
                    prog.update(len(new), sum(not r["success"] for r in new))
    except BaseException:
        if ex is not None:
            ex.close(cancel=True)
        raise
    if ex is not None:
        ex.close()
    if prog is not None:
        prog.close()
    if store is not None and compact:
        store.compact()
    return BatchResult(rows=[rows[i] for i in range(N)], solved_now=solved_now,
                       resumed=N - len(todo), wall_time=time.perf_counter() - t0,
                       executor=ex.name if ex is not None else "none (all resumed)",
                       path=store.path if store is not None else None, scenarios=scenarios)
