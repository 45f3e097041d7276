"""Compile the numba kernels ahead of the first solve: ``compass-sparse warmup``.

The solver's hot loops are numba kernels compiled on first use and cached on disk
(``cache=True``: beside the package's modules in ``__pycache__``, or under
``NUMBA_CACHE_DIR`` when it is set).  A fresh installation has no cache, so its first solve
of each kind compiles for a minute or more (benchmarks/first_run.md).  The warm-up makes
that happen during set-up (``scripts/setup.sh`` runs it), by small representative solves
that take every route a solve can take, each in a process with ``COMPASS_SPARSE_JIT=always``.

numba compiles under one lock per process, so one process compiles one kernel at a time;
the workloads therefore run in processes of their own, ``jobs`` at a time (default: one
per available core), the longest ready one first.  Processes that compile at the same time
share the on-disk cache safely (:func:`compass_sparse._jit._lock_cache`); a kernel that
two running workloads need may be compiled by both, which costs time, not correctness, so
a workload that shares a big kernel with another waits for it and loads the kernel from
the cache.  The dense route (a small problem's crash, major iterations and pivotal paths,
and homotopy) is most of the work, so it is split into three workloads that each compile
one of its big kernels.  A last check in this process runs the demos' solves and reports
what they still had to compile (nothing, when the workloads cover their routes).

Ctrl-C stops the warm-up: its workers run in sessions of their own, so that the terminal's
interrupt reaches the warm-up alone, which stops them (no worker prints a traceback); the
cache keeps the kernels they finished.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np

from . import _jit
from .crash import crash
from .generators import obstacle_problem, structured_quadratic, thesis_family
from .generators.cge import size_for, static_cge
from .lcp import solve_lcp
from .options import Options
from .solve import solve_mcp

__all__ = ["WORKLOADS", "default_jobs", "run_workloads", "warm_up"]


def _thesis():
    # the problem of ``compass-sparse demo --problem thesis``
    return thesis_family(50, 1, 0).problem


def _dense_paths():
    # the compiled major iterations and the dense engine's paths, without the crash and
    # the homotopy (other workloads compile those at the same time)
    solve_mcp(_thesis(), options={"crash_method": "none", "homotopy": "off"})


def _dense_crash():
    # the crash pass alone (its entry function), on the compiled route of a small problem
    p = _thesis()
    f0, J0 = p.evaluator.fj(p.x0)
    crash(p.evaluator, p.x0, p.lb, p.ub, Options(), f0=f0, J0=J0)


def _dense_homotopy():
    solve_mcp(_thesis(), options={"homotopy": "only"})


def _sparse():
    # the route of ``compass-sparse demo`` (n = 1e5): the sparse engine, the Python major
    # iterations (n > 5000); its kernels' signatures do not depend on n
    solve_mcp(structured_quadratic(6000, seed=0).problem)


def _medium():
    # a CGE model of n ~ 1000: the preprocessor, the sparse basis with the compiled major
    # iterations (500 < n <= 5000), KLU direct steps
    solve_mcp(static_cge(**size_for(1000)).with_shock(output_tax=0.0).problem)


def _small_models():
    # ``compass-sparse demo --problem cge`` and an LCP: the preprocessor on small models,
    # the pivotal path of solve_lcp on the sparse engine (n = 900)
    solve_mcp(static_cge(seed=0).with_shock(output_tax=0.0).problem)
    M, q, lb, ub = obstacle_problem(30, seed=0).lcp
    solve_lcp(M, q, lb, ub)


WORKLOADS = {
    # name: (what it compiles, seconds of one core measured cold (benchmarks/first_run.md),
    #        the workload, the workloads to finish first: they compile kernels this one
    #        shares, which it then loads from the cache instead of compiling them again)
    "dense paths": ("compiled major iterations, dense engine", 50.0, _dense_paths, ()),
    "dense crash": ("compiled crash", 26.0, _dense_crash, ()),
    "dense homotopy": ("compiled homotopy", 17.0, _dense_homotopy, ()),
    "sparse": ("sparse engine, Python major iterations", 23.0, _sparse, ()),
    "medium": ("preprocessor, sparse basis with compiled major iterations", 25.0, _medium,
               ("dense paths",)),
    "small models": ("small CGE model, LCP", 10.0, _small_models,
                     ("dense paths", "dense crash")),
}
"""The warm-up's workloads, each run in a process of its own."""


def _check():
    """The demos' solves (``compass-sparse demo`` at a smaller n): what they compile after
    the workloads is what the workloads missed."""
    solve_mcp(_thesis())
    solve_mcp(structured_quadratic(6000, seed=0).problem)
    solve_mcp(static_cge(seed=0).with_shock(output_tax=0.0).problem)
    M, q, lb, ub = obstacle_problem(30, seed=0).lcp
    solve_lcp(M, q, lb, ub)


def default_jobs() -> int:
    """Processes of the warm-up: the cores this process may run on, at most one per
    workload."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, len(WORKLOADS)))


def _next(pending, done):
    """The longest pending workload whose predecessors are done (None: none is ready)."""
    ready = [w for w in pending if all(d in done for d in WORKLOADS[w][3])]
    return max(ready, key=lambda w: WORKLOADS[w][1]) if ready else None


def run_workloads(names, stream=sys.stdout):
    """Run the named workloads in this process, one line each: its time and how many
    kernels it compiled.  (The warm-up's worker processes run this.)"""
    _jit.end_cold_start()
    _jit.quiet_compile_notice()
    for name in names:
        t, k = time.perf_counter(), _jit.compilations()
        with np.errstate(all="ignore"):
            WORKLOADS[name][2]()
        stream.write(json.dumps({"workload": name, "seconds": time.perf_counter() - t,
                                 "compiled": _jit.compilations() - k}) + "\n")
        stream.flush()


def _run_all(jobs, env, running, stream) -> list:
    """The workloads in worker processes, ``jobs`` at a time (``running``: name -> the
    running process, for :func:`_stop`); returns the names of those that failed."""
    pending, done, failed = list(WORKLOADS), set(), []
    while pending or running:
        while len(running) < jobs:
            name = _next(pending, done)
            if name is None:
                break
            pending.remove(name)
            # (a session of its own: Ctrl-C on the terminal reaches the warm-up alone,
            # which stops its workers itself, without a worker's traceback)
            running[name] = subprocess.Popen(
                [sys.executable, "-m", "compass_sparse.warmup", name], stdout=subprocess.PIPE,
                text=True, env=env, start_new_session=True)
        time.sleep(0.1)
        for name, proc in list(running.items()):
            if proc.poll() is None:
                continue
            del running[name]
            done.add(name)
            out = proc.stdout.read()
            proc.stdout.close()
            if proc.returncode != 0:
                failed.append(name)
                stream.write(f"  {name:15s} failed (exit code {proc.returncode}; its error "
                             "is above)\n")
                continue
            for r in (json.loads(line) for line in out.splitlines() if line.startswith("{")):
                what = (f"{r['compiled']} kernels compiled" if r["compiled"]
                        else "all from the cache")
                stream.write(f"  {r['workload']:15s} {r['seconds']:7.1f} s  {what}\n")
            stream.flush()
    return failed


STOP_WAIT = 10.0
"""Seconds the warm-up waits for its stopped workers before it kills them."""


def _stop(running):
    """Stop the running workers (Ctrl-C in the warm-up): SIGTERM, then SIGKILL after
    ``STOP_WAIT`` seconds.  The on-disk cache stays whole: numba writes a kernel's data file
    and then its index, each under a temporary name renamed into place, and the cache's
    lock (compass_sparse._jit) is released when its holder dies."""
    for proc in running.values():
        proc.terminate()
    for proc in running.values():
        try:
            proc.wait(timeout=STOP_WAIT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    running.clear()


def warm_up(jobs: int | None = None, stream=sys.stdout) -> int:
    """Compile every kernel the solver's routes use: each workload in a process of its own,
    up to ``jobs`` at a time (default :func:`default_jobs`), the longest ready one first;
    then check the demos' solves.  Says what it did on ``stream``.  Returns the number of
    kernels the check still had to compile (0 when the cache covers the demos), or -1 when
    a workload failed."""
    jobs = default_jobs() if jobs is None else max(1, int(jobs))
    t0 = time.perf_counter()
    total = sum(w[1] for w in WORKLOADS.values())
    stream.write(f"compiling the solver's kernels, {jobs} process{'es' if jobs > 1 else ''} "
                 f"at a time (~{total:.0f} s of one core on an idle machine; nothing to do "
                 "when they are cached already)\n")
    stream.flush()
    env = {**os.environ, "COMPASS_SPARSE_JIT": "always"}
    running = {}
    try:
        failed = _run_all(jobs, env, running, stream)
    except KeyboardInterrupt:
        _stop(running)
        raise
    if failed:
        stream.write(f"the warm-up failed: {', '.join(failed)}\n")
        return -1
    _jit.end_cold_start()
    _jit.quiet_compile_notice()
    k = _jit.compilations()
    t = time.perf_counter()
    with np.errstate(all="ignore"):
        _check()
    missed = _jit.compilations() - k
    stream.write(f"  {'check (demos)':15s} {time.perf_counter() - t:7.1f} s  "
                 + (f"{missed} kernels compiled that the workloads missed\n" if missed
                    else "all from the cache\n"))
    stream.write(f"warm-up done in {time.perf_counter() - t0:.1f} s\n")
    stream.flush()
    return missed


if __name__ == "__main__":  # a worker process of warm_up
    run_workloads(sys.argv[1:])
