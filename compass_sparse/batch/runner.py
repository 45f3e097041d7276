"""The batch's driver: the scenarios on disk skipped, the tree cut into tasks, the tasks
handed to an executor as they become ready (a path's head waits for the scenario it
hangs from), the rows written as tasks finish, and the progress line.  A task whose
worker dies is tried once more, alone.  See :mod:`compass_sparse.batch`."""
from __future__ import annotations

import logging
import os
import pickle
import time
from dataclasses import dataclass, field

import numpy as np

from ..exceptions import ModelMismatchError, OptionError
from ..options import Options
from ..progress import Progress
from .executors import make_executor
from .fingerprint import compare, fingerprint_at
from .lock import FolderLock
from .models import as_builder
from .scenarios import scenario_key
from .store import ResultStore
from .tree import paths, scenario_tree
from .worker import failure_row, solve_segment

try:
    import cloudpickle as _pickler  # (an optional extra, installed with dask: lambdas and
except ImportError:  # pragma: no cover  closures as models; plain pickle otherwise)
    _pickler = pickle

logger = logging.getLogger("compass_sparse")

__all__ = ["BatchResult", "solve_batch"]


class _Counts:
    """The batch's counts and the progress line made of them (a bar on a terminal)."""

    def __init__(self, total: int, done: int, display: Progress):
        self.total, self.start_done, self.done, self.failed = total, done, done, 0
        self.display = display
        self.t0 = time.perf_counter()

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
        d = self.display
        if d.tty:
            width = 30
            k = int(width * self.done / max(self.total, 1))
            d.show(f"[{'#' * k}{'.' * (width - k)}] {self.line()}   ")
        elif d.periodic:
            d.show(f"batch: {self.line()}")

    def close(self):
        if self.display.tty:
            self.display.stream.write("\n")
            self.display.stream.flush()
        logger.info("batch: %s", self.line())


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
                progress: bool | None = True, compact: bool = True,
                on_mismatch: str = "refuse", lock_timeout: float = 0.0) -> BatchResult:
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
    compact : merge the parts into ``output/results.parquet`` at the end.
    on_mismatch : what to do when ``output`` holds the results of another model (its
        fingerprint differs, see :mod:`compass_sparse.batch.fingerprint`): ``"refuse"``
        raises :class:`~compass_sparse.exceptions.ModelMismatchError` naming what
        differs; ``"new"`` moves those results into ``output/previous-<time>/`` and solves
        into the emptied folder.
    lock_timeout : seconds to wait for a folder another batch is writing to, before
        :class:`~compass_sparse.exceptions.FolderLockedError` (0: at once; inf: wait).
    """
    t0 = time.perf_counter()
    scenarios = [dict(s) for s in scenarios]
    opt = Options.coerce(options)
    if chunk_size < 1:
        raise OptionError(f"chunk_size must be >= 1, got {chunk_size}")
    if on_mismatch not in ("refuse", "new"):
        raise OptionError(f"on_mismatch must be 'refuse' or 'new', got {on_mismatch!r}")
    builder = as_builder(model)
    if output is None:
        return _run(builder, scenarios, opt, None, t0, executor=executor, workers=workers,
                    warm_start=warm_start, predictor=predictor, record=record,
                    chunk_size=chunk_size, retry_failed=retry_failed, progress=progress)
    os.makedirs(output, exist_ok=True)
    with FolderLock(output, lock_timeout):
        store = ResultStore(output)
        store.clean_temporary()
        _check_model(store, builder, scenarios, opt, record, on_mismatch)
        return _run(builder, scenarios, opt, store, t0, executor=executor, workers=workers,
                    warm_start=warm_start, predictor=predictor, record=record,
                    chunk_size=chunk_size, retry_failed=retry_failed, progress=progress,
                    compact=compact)


def _check_model(store, builder, scenarios, opt, record, on_mismatch):
    """Compare the model with the one whose results ``store`` holds; record it in a new
    folder.  Raises ModelMismatchError, or sets the old results aside ("new")."""
    stored = store.model()
    if stored is None and not store.has_results():
        if scenarios:
            ref = scenarios[0]
            store.set_model(fingerprint_at(builder, ref, opt.convergence_tolerance, record),
                            ref)
        return
    if stored is None:  # results written before folders had a fingerprint
        diffs = [("model fingerprint", "present", "none (an older version wrote it)")]
    else:
        ref = stored.get("reference", {})
        here = fingerprint_at(builder, ref, opt.convergence_tolerance, record)
        diffs = compare(here, stored.get("fingerprint", {}))
        if not diffs:
            return
    if on_mismatch == "new":
        dest = store.set_aside()
        logger.warning("batch: %s held the results of another model (%s): moved to %s",
                       store.path, _differences(diffs), dest)
        _check_model(store, builder, scenarios, opt, record, on_mismatch)
        return
    raise ModelMismatchError(
        f"the results in {store.path} are of another model ({_differences(diffs)}): "
        "resume with the model that wrote them, write to another folder, or move them "
        "aside and solve afresh (on_mismatch='new'; the command line's --fresh)", diffs)


def _differences(diffs) -> str:
    return "; ".join(f"{what} {here}" if here == "differs" else
                     f"{what}: {here} here, {there} in the folder"
                     for what, here, there in diffs)


def _run(builder, scenarios, opt, store, t0, *, executor, workers, warm_start, predictor,
         record, chunk_size, retry_failed, progress, compact=True) -> BatchResult:
    """The batch on a checked (and locked) store, or on none."""
    N = len(scenarios)
    rows = _finished_rows(scenarios, store, retry_failed)
    todo = [i for i in range(N) if i not in rows]
    parent = scenario_tree(scenarios) if warm_start else np.full(N, -1, dtype=np.int64)
    if warm_start:
        tasks = paths(parent, todo, chunk_size)
    else:
        tasks = [(todo[a:a + chunk_size], 0) for a in range(0, len(todo), chunk_size)]
    # Largest subtrees first: they hold the critical path.
    tasks.sort(key=lambda p: (-p[1], p[0][0]))
    counts = (_Counts(N, len(rows), Progress(bool(progress), after=0.0, every=10.0))
              if progress is not None else None)
    blob = _pickler.dumps(builder, protocol=pickle.HIGHEST_PROTOCOL)
    ex = make_executor(executor, workers) if todo else None
    task_base = {"options": opt, "warm": warm_start, "predictor": predictor and warm_start,
                 "record": None if record is None else list(record)}
    run = _Schedule(scenarios, parent, rows, task_base, store, counts)
    try:
        if ex is not None:
            run.run(ex, blob, tasks)
    except BaseException:
        if ex is not None:
            ex.close(cancel=True)
        raise
    if ex is not None:
        ex.close()
    if counts is not None:
        counts.close()
    if store is not None and compact:
        store.compact()
    return BatchResult(rows=[rows[i] for i in range(N)], solved_now=run.solved_now,
                       resumed=N - len(todo), wall_time=time.perf_counter() - t0,
                       executor=ex.name if ex is not None else "none (all resumed)",
                       path=store.path if store is not None else None, scenarios=scenarios)


def _finished_rows(scenarios, store, retry_failed) -> dict:
    """The rows of the scenarios found finished in ``store`` (by index; failed ones only
    when they are not to be tried again)."""
    on_disk = store.load() if store is not None else {}
    rows: dict[int, dict] = {}
    for i, s in enumerate(scenarios):
        r = on_disk.get(scenario_key(s))
        if r is not None and (r["success"] or not retry_failed):
            rows[i] = {**r, "index": i}
    return rows


class _Schedule:
    """The tasks of a batch on an executor: each submitted when the scenario its head hangs
    from is finished (its start is then a function of the tree alone, never of timing),
    at most ``2 workers + 1`` at a time, a failed one retried alone."""

    def __init__(self, scenarios, parent, rows, task_base, store, counts):
        self.scenarios, self.parent, self.rows = scenarios, parent, rows
        self.task_base, self.store, self.counts = task_base, store, counts
        self.solved_now = 0

    def start_state(self, head):
        """(ready, state): the nearest solved ancestor's (x, basis), None for cold."""
        rows, parent = self.rows, self.parent
        j = int(parent[head])
        while j >= 0:
            if j not in rows:
                return False, None
            r = rows[j]
            if r["success"] and r.get("x") is not None:
                return True, (np.asarray(r["x"], float), r.get("basis"))
            j = int(parent[j])
        return True, None

    def run(self, ex, blob, tasks):
        inflight = {}
        pending = [(nodes, sz, 0) for nodes, sz in tasks]
        ref = ex.share(blob)
        limit = 2 * ex.workers + 1
        while pending or inflight:
            pending = self._submit(ex, ref, pending, inflight, limit)
            if not inflight:
                raise RuntimeError("batch scheduling stalled: a path waits for a scenario "
                                   "that is never solved")  # pragma: no cover
            for fut in ex.wait_any(inflight):
                self._finished(fut, inflight.pop(fut), pending)

    def _submit(self, ex, ref, pending, inflight, limit):
        """Submit the ready tasks of ``pending``; returns those left waiting."""
        still = []
        # A task that failed as a whole (a worker died under it, perhaps killed by
        # another task) is tried once more, alone, so that only its own crash can
        # fail it again.
        isolating = any(t for _, _, t in inflight.values())
        for nodes, sz, tries in pending:
            if isolating or len(inflight) >= limit or (tries and inflight):
                still.append((nodes, sz, tries))
                continue
            ready, state = self.start_state(nodes[0])
            if not ready:
                still.append((nodes, sz, tries))
                continue
            task = dict(self.task_base, start=state,
                        nodes=[(i, self.scenarios[i]) for i in nodes],
                        parents=[int(self.parent[i]) for i in nodes])
            inflight[ex.submit(solve_segment, ref, task)] = (nodes, sz, tries)
            isolating = bool(tries)
        return still

    def _finished(self, fut, task, pending):
        """A task's rows (written, counted), or its retry, or its failure rows."""
        nodes, sz, tries = task
        try:
            new = fut.result()
        except Exception as exc:  # a lost worker: retry once, then rows with the error
            if tries == 0:
                logger.info("batch: a task of %d scenarios failed (%r); retrying it "
                            "alone", len(nodes), exc)
                pending.append((nodes, sz, 1))
                return
            new = [failure_row({"index": i, "parent": int(self.parent[i]), "start": "",
                                "predicted": False, "worker": ""}, self.scenarios[i],
                               f"the task failed: {exc!r}", time.perf_counter())
                   for i in nodes]
        if self.store is not None:
            self.store.write(new)
        for r in new:
            self.rows[r["index"]] = r
        self.solved_now += len(new)
        if self.counts is not None:
            self.counts.update(len(new), sum(not r["success"] for r in new))
