"""The worker side of a batch: one task is a path of the scenario tree, solved in order,
each scenario from its parent's solution and basis (or the predictor's point), into one
result row each; a scenario that fails is a row with its status and message."""
from __future__ import annotations

import hashlib
import json
import logging
import os
import pickle
import time

import numpy as np

from ..merit import fb_phi
from ..path.outcome import WarmBasis
from ..sensitivity import tangent_predictor
from ..solve import solve_mcp
from ..status import Status
from .models import build
from .scenarios import plain, scenario_key

logger = logging.getLogger("compass_sparse")

__all__ = ["failure_row", "solve_segment"]

_WORKER_MODELS: dict = {}
"""The models a worker process unpickled, by the hash of their pickle (at most four)."""


def _load_model(blob: bytes):
    key = hashlib.sha1(blob).hexdigest()
    if key not in _WORKER_MODELS:
        if len(_WORKER_MODELS) >= 4:
            _WORKER_MODELS.pop(next(iter(_WORKER_MODELS)))
        _WORKER_MODELS[key] = pickle.loads(blob)
    return _WORKER_MODELS[key]


def solve_segment(blob: bytes, task: dict) -> list[dict]:
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
    t0 = time.perf_counter()
    row = {"index": idx, "parent": parent, "start": "cold", "predicted": False,
           "worker": f"{os.uname().nodename}:{os.getpid()}"}
    try:
        problem = build(builder, params)
    except Exception as exc:  # a model that cannot be built is a failed scenario
        return failure_row(row, params, f"building the model failed: {exc!r}", t0)
    x0, basis = None, None
    if state is not None and np.size(state[0]) != problem.n:
        # A model whose size depends on its parameters: the parent's point and basis do
        # not fit this problem, so this scenario starts cold (solve_mcp would refuse them).
        logger.info("scenario %d: its parent's solution has %d variables and this problem "
                    "%d: started cold", idx, np.size(state[0]), problem.n)
        state = None
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
        return failure_row(row, params, f"the solver raised {exc!r}", t0)
    if res.status is Status.USER_INTERRUPT:
        # Ctrl-C stops the batch: the scenario is not finished, and a row would keep it
        # from being solved when the batch is resumed.
        raise KeyboardInterrupt
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
    out = {"params": json.dumps({k: plain(v) for k, v in params.items()}, sort_keys=True),
           "key": scenario_key(params)}
    for k, v in params.items():
        if np.ndim(v) == 0 and isinstance(plain(v), (int, float)):
            out[f"param.{k}"] = float(v)
    return out


def failure_row(row, params, message, t0):
    row.update(_param_columns(params))
    row.update(status=Status.ERROR.name, status_code=int(Status.ERROR), success=False,
               point_status="", message=message, residual=float("nan"),
               natural_residual=float("nan"), nit=0, minor_iterations=0, nfev=0, njev=0,
               solve_time=0.0, time=time.perf_counter() - t0, x=None, basis=None)
    return row
