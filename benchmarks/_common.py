"""Shared helpers of the benchmark scripts (bench_lcp.py, bench_thesis.py, bench_small.py, ...).

* :func:`natural_residual` -- the independent success test every benchmark applies to the
  returned point of BOTH solvers: ``||z - clip(z - F(z), l, u)||_inf <= SUCCESS_TOL``.
* :class:`Worker` -- runs solve tasks in a child process.  A solve that ignores its own
  time limit (or hangs) is killed after a hard timeout and recorded as a failure; the
  benchmark goes on with a fresh child.  Times are measured inside the child, so the
  pipe between the processes is not timed.
* :class:`CsvLog` -- appends one row per solve and flushes, so partial results survive an
  interrupted run.
* :func:`machine_info` -- date, cores, versions, git revision: recorded with every result.
* :func:`choose_path_source` / :func:`path_reference` -- PATH's figures from a live run, or
  where GAMS cannot run (or ``--path recorded``) from the recorded rows of
  ``benchmarks/reference/`` (reference/README.md), with a line that says which.

Only the public API of compass_sparse is used.
"""
from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import multiprocessing as mp
import os
import platform
import statistics
import subprocess
import sys
import time
import traceback
from pathlib import Path

import numpy as np

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
SUCCESS_TOL = 1e-6
"""A point counts as a solution when its natural residual is at most this."""


# --------------------------------------------------------------------------- residuals
def natural_residual(z, f, lb, ub) -> float:
    """||z - clip(z - f, lb, ub)||_inf (inf when anything is not finite)."""
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    if z.size == 0:
        return 0.0
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(f))):
        return math.inf
    return float(np.max(np.abs(z - np.clip(z - f, lb, ub))))


def ours_record(res, f, lb, ub, wall) -> dict:
    """Flatten a compass_sparse Result into a row; success from OUR recomputed residual."""
    nat = natural_residual(res.x, f, lb, ub)
    passes = getattr(res, "passes", {}) or {}
    ran = [k for k, v in passes.items() if getattr(v, "ran", False)]
    return dict(
        solver="compass_sparse",
        success=bool(nat <= SUCCESS_TOL),
        reported_success=bool(res.success),
        status=getattr(res.status, "name", str(res.status)),
        natural=nat,
        fb_norm=float(res.residual.fb_norm) if res.residual is not None else math.nan,
        time=float(wall),
        wall=float(wall),
        major=int(res.nit),
        minor=int(res.minor_iterations),
        crash=int(getattr(res, "crash_iterations", 0)),
        factorizations=int(res.factorizations),
        restarts=int(getattr(res, "restarts", 0)),
        passes="+".join(ran),
        pass_times=";".join(f"{k}={v.time:.4g}" for k, v in passes.items()
                            if getattr(v, "ran", False)),
        error="",
    )


def path_record(run, lb, ub) -> dict:
    """Flatten a PathRun; success from OUR recomputed residual of F(x) in float64."""
    nat = natural_residual(run.x, run.f, lb, ub)
    pt = run.path_time
    return dict(
        solver="PATH",
        success=bool(nat <= SUCCESS_TOL),
        reported_success=bool(run.success),
        status=str(run.exit_message or run.solver_status),
        natural=nat,
        fb_norm=float(run.residual) if run.residual is not None else math.nan,
        # PATH's own Total Time (GAMS process overhead excluded); wall time if not reported
        time=float(pt) if pt is not None else float(run.wall_time),
        wall=float(run.wall_time),
        major=int(run.major_iterations or 0),
        minor=int(run.minor_iterations or 0),
        crash=int(run.crash_iterations or 0),
        factorizations=-1,
        restarts=int(run.restarts or 0),
        passes="",
        pass_times="",
        error="",
    )


def failure_record(solver: str, error: str, wall: float = math.nan) -> dict:
    return dict(solver=solver, success=False, reported_success=False, status="exception",
                natural=math.inf, fb_norm=math.nan, time=wall, wall=wall, major=-1, minor=-1,
                crash=-1, factorizations=-1, restarts=-1, passes="", pass_times="",
                error=error.strip().splitlines()[-1][:200] if error.strip() else "error")


# --------------------------------------------------------------------------- PATH
_SESSIONS: dict = {}


def path_available() -> bool:
    try:
        from compass_sparse.interfaces.path_gamspy import path_available as pa
    except Exception:
        return False
    try:
        return bool(pa())
    except Exception:
        return False


def why_path_cannot_run() -> str | None:
    """None when PATH can run here; otherwise why not, in one line (GAMS' probe's reason)."""
    if path_available():
        return None
    try:
        from compass_sparse.interfaces.gams_state import gams_state

        st = gams_state()
    except Exception as exc:  # pragma: no cover - the probe itself failed
        return f"GAMS' state could not be probed ({type(exc).__name__}: {exc})"
    if not st.runs:
        return f"GAMS cannot run: {st.reason}"
    return "PATH is not among GAMS' solvers"


# --------------------------------------------------------------------------- PATH, recorded
REFERENCE = HERE / "reference"
"""PATH 5.2's recorded rows, one file per suite (reference/README.md)."""
PATH_MODES = ("auto", "live", "recorded")


class PathReference:
    """PATH's recorded rows of one suite (``reference/<suite>.csv`` with its sidecar JSON).

    ``rows`` maps the suite's key (a tuple in the order of ``key_fields``, each value of
    the type the JSON declares) to a row dict whose values are typed like
    :func:`read_csv`'s and which carries ``path_source`` = ``"recorded <date> <rev>"``
    of the run it comes from.  :meth:`get` looks a key up by field name."""

    def __init__(self, suite: str, directory: Path = REFERENCE):
        self.suite = suite
        self.csv_path = Path(directory) / f"{suite}.csv"
        self.meta = json.loads(self.csv_path.with_suffix(".json").read_text())
        self.key_types = dict(self.meta["key"])
        self.key_fields = list(self.key_types)
        self.runs = self.meta["runs"]
        self.absent = {self.key(**a["key"]): a["reason"] for a in self.meta.get("absent", [])}
        self.rows: dict = {}
        for r in read_csv(self.csv_path):
            k = self.key(**{f: r[f] for f in self.key_fields})
            if k in self.rows:
                raise ValueError(f"{self.csv_path}: key {k} appears twice")
            run = self.runs[r["run"]]
            r["path_source"] = f"recorded {run['date']} {run['revision']}"
            self.rows[k] = r

    def key(self, **fields) -> tuple:
        """The lookup key of a problem, from its fields (extra fields are an error)."""
        if set(fields) != set(self.key_fields):
            raise KeyError(f"{self.suite}: a key has the fields {self.key_fields}, "
                           f"not {sorted(fields)}")
        conv = {"int": int, "float": float, "str": str}
        return tuple(conv[self.key_types[f]](fields[f]) for f in self.key_fields)

    def get(self, **fields) -> dict | None:
        """A copy of the recorded row of that problem, or None when PATH was not recorded
        on it."""
        r = self.rows.get(self.key(**fields))
        return dict(r) if r is not None else None

    def runs_of(self, keys=None) -> list[str]:
        """The runs the given keys' rows come from (all runs of the file without keys), in
        the JSON's order."""
        if keys is None:
            used = {r["run"] for r in self.rows.values()}
        else:
            used = {self.rows[k]["run"] for k in keys if k in self.rows}
        return [rid for rid in self.runs if rid in used]

    def describe(self, keys=None) -> str:
        """'<date> at rev <rev>[, ...] (benchmarks/reference/<suite>.csv)'."""
        runs = self.runs_of(keys) or list(self.runs)
        text = ", ".join(f"{self.runs[r]['date']} at rev {self.runs[r]['revision']}"
                         for r in runs)
        where = self.csv_path.relative_to(HERE.parent) if self.csv_path.is_relative_to(
            HERE.parent) else self.csv_path
        many = "; each row's run in its path_source" if len(runs) > 1 else ""
        return f"{text} ({where}{many})"


_REFERENCES: dict = {}


def path_reference(suite: str) -> PathReference:
    """PATH's recorded rows of ``suite`` ("small", "thesis", "lcp", "cge", "links"),
    read once per process."""
    if suite not in _REFERENCES:
        _REFERENCES[suite] = PathReference(suite)
    return _REFERENCES[suite]


class PathSource:
    """Where a benchmark takes PATH's figures from: ``mode`` is "live" (PATH runs now),
    "recorded" (``reference``: the suite's recorded rows) or "none" (PATH left out);
    ``why`` says why PATH does not run live."""

    def __init__(self, mode: str, reference: PathReference | None = None, why: str = ""):
        self.mode, self.reference, self.why = mode, reference, why

    @property
    def live(self) -> bool:
        return self.mode == "live"

    @property
    def recorded(self) -> bool:
        return self.mode == "recorded"

    def line(self, keys=None) -> str:
        """The one line a benchmark prints first about PATH's figures."""
        if self.live:
            try:
                import gamspy

                via = f" through gamspy {gamspy.__version__}"
            except Exception:  # pragma: no cover
                via = ""
            return f"# PATH: live run (PATH{via}; time = PATH's own Total Time)"
        if self.recorded:
            return (f"# PATH: recorded {self.reference.describe(keys)}; {self.why}; ratios "
                    f"against PATH compare with a run of another day")
        return f"# PATH: not run ({self.why})"

    def lookup(self, **fields) -> dict | None:
        """The recorded row of a problem (None: not in the reference); recorded mode only."""
        return self.reference.get(**fields)


def choose_path_source(suite: str, mode: str = "auto", no_path: bool = False) -> PathSource:
    """PATH's source for a benchmark run.  ``mode``: "auto" (live when PATH can run here,
    else the recorded rows), "live" (PATH must run: exits with the reason when it cannot),
    "recorded" (the recorded rows even where PATH runs).  ``no_path`` leaves PATH out."""
    if mode not in PATH_MODES:
        raise ValueError(f"PATH's source is one of {PATH_MODES}, not {mode!r}")
    if no_path:
        return PathSource("none", why="--no-path")
    if mode == "recorded":
        return PathSource("recorded", path_reference(suite), "--path recorded asked")
    why = why_path_cannot_run()
    if why is None:
        return PathSource("live")
    if mode == "live":
        raise SystemExit(f"--path live: PATH cannot run here ({why}); "
                         f"--path recorded (or auto) uses PATH's recorded figures")
    return PathSource("recorded", path_reference(suite), why)


def add_path_argument(ap):
    """The ``--path`` option of the side-by-side benchmarks."""
    ap.add_argument("--path", choices=PATH_MODES, default="auto", dest="path_mode",
                    help="PATH's figures: a live run where GAMS can run, else the recorded "
                         "ones of benchmarks/reference/ (auto, the default); live only; or "
                         "the recorded ones even where GAMS runs")


def recorded_mark(row) -> str:
    """' (recorded)' for a PATH row from the reference, '' otherwise."""
    return " (recorded)" if row and str(row.get("path_source", "")).startswith("recorded") else ""


def any_recorded(rows) -> bool:
    return any(str(r.get("path_source", "")).startswith("recorded") for r in rows if r)


RECORDED_NOTE = ("PATH's figures marked recorded come from benchmarks/reference/ (measured "
                 "before GAMS' demo licence expired, on the date and revision in each row's "
                 "path_source): a ratio against them compares our time today with PATH's "
                 "time on another day, under another load and possibly on another machine "
                 "(the reference's JSON names the run's machine).")


def path_session(n: int, quadratic: bool):
    """One reusable PATH container per (n, quadratic) in this process."""
    from compass_sparse.interfaces.path_gamspy import PathSession

    key = (int(n), bool(quadratic))
    if key not in _SESSIONS:
        _SESSIONS[key] = PathSession(int(n), quadratic=bool(quadratic))
    return _SESSIONS[key]


# --------------------------------------------------------------------------- warm-up
def warm_up(with_path: bool = False):
    """Compile numba kernels (cached on disk) and load gamspy before anything is timed."""
    import scipy.sparse as sp

    from compass_sparse import solve_lcp, solve_mcp
    from compass_sparse.generators import obstacle_problem, p_matrix_lcp, thesis_family

    for st in ("grid", "banded"):
        g = p_matrix_lcp(400, st, seed=12345, bounds="mixed")
        M, q, lb, ub = g.lcp
        solve_lcp(M, q, lb, ub, g.problem.x0, options={"time_limit": 30})
        solve_lcp(M, q, lb, ub, g.problem.x0, options={"time_limit": 30, "crash_method": "none"})
    g = obstacle_problem(12, seed=12345)
    M, q, lb, ub = g.lcp
    solve_lcp(M, q, lb, ub, g.problem.x0, options={"time_limit": 30})
    for n in (10, 30):  # dense basis (small n) and the NMS machinery
        solve_mcp(thesis_family(n, 1, 12345).problem, options={"time_limit": 30})
    if with_path:
        from compass_sparse.interfaces.path_gamspy import solve_lcp_with_path

        solve_lcp_with_path(sp.identity(1, format="csr"), [-1.0], [0.0], [np.inf])


# --------------------------------------------------------------------------- worker
def _child_main(conn, warmup, warmup_kwargs):
    try:
        if warmup is not None:
            warmup(**(warmup_kwargs or {}))
        conn.send(("ready", None))
    except Exception:
        conn.send(("warmup-error", traceback.format_exc()))
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        fn, kwargs = msg
        try:
            out = fn(**kwargs)
            conn.send(("ok", out))
        except BaseException:  # a failing solve is a data point
            conn.send(("error", traceback.format_exc()))


class Worker:
    """A child process that runs ``fn(**kwargs)`` tasks with a hard wall-clock timeout.

    ``fn`` must be a module-level function (it is pickled by reference) returning a small
    picklable object.  On timeout the child is killed and a new one is started (and warmed
    up again) for the next task.
    """

    def __init__(self, warmup=warm_up, warmup_kwargs=None):
        self._ctx = mp.get_context("fork")
        self._warmup = warmup
        self._warmup_kwargs = warmup_kwargs
        self.proc = None
        self.conn = None
        self.restarts = 0
        self._start()

    def _start(self):
        parent, child = self._ctx.Pipe()
        self.proc = self._ctx.Process(target=_child_main,
                                      args=(child, self._warmup, self._warmup_kwargs),
                                      daemon=True)
        self.proc.start()
        self.conn = parent
        tag, payload = self.conn.recv()
        if tag != "ready":
            raise RuntimeError(f"benchmark worker failed to warm up:\n{payload}")

    def _kill(self):
        if self.proc is not None and self.proc.is_alive():
            self.proc.kill()
            self.proc.join(5)
        self.proc = None
        try:
            self.conn.close()
        except Exception:
            pass

    def run(self, fn, timeout: float, /, **kwargs):
        """Return ``("ok", value)``, ``("error", traceback)`` or ``("timeout", seconds)``."""
        t0 = time.perf_counter()
        try:
            self.conn.send((fn, kwargs))
            if self.conn.poll(timeout):
                return self.conn.recv()
        except (EOFError, BrokenPipeError, OSError):
            self._kill()
            self.restarts += 1
            self._start()
            return ("error", "worker process died (out of memory?)")
        self._kill()
        self.restarts += 1
        self._start()
        return ("timeout", time.perf_counter() - t0)

    def close(self):
        if self.proc is not None and self.proc.is_alive():
            try:
                self.conn.send(None)
            except Exception:
                pass
            self.proc.join(5)
            if self.proc.is_alive():
                self.proc.kill()
        self.proc = None


def run_task(worker: Worker, fn, solver: str, timeout: float, /, **kwargs) -> dict:
    """Run one solve task; exceptions and hard timeouts become failure rows."""
    tag, payload = worker.run(fn, timeout, **kwargs)
    if tag == "ok":
        return payload
    if tag == "timeout":
        rec = failure_record(solver, f"killed after a hard timeout of {timeout:.0f} s", payload)
        rec["status"] = "hard-timeout"
        return rec
    return failure_record(solver, str(payload))


# --------------------------------------------------------------------------- output
class CsvLog:
    """Append rows to a CSV file (header written once), flushing after every row."""

    def __init__(self, path: Path, fields: list[str], append: bool = False):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fields = list(fields)
        exists = self.path.exists() and self.path.stat().st_size > 0
        self._fh = open(self.path, "a" if append else "w", newline="")
        self._w = csv.DictWriter(self._fh, fieldnames=self.fields, extrasaction="ignore")
        if not (append and exists):
            self._w.writeheader()
            self._fh.flush()

    def write(self, row: dict):
        self._w.writerow({k: _fmt_csv(row.get(k, "")) for k in self.fields})
        self._fh.flush()

    def close(self):
        self._fh.close()


def _fmt_csv(v):
    if isinstance(v, float):
        return repr(v)
    return v


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        for k, v in list(r.items()):
            if v in ("True", "False"):
                r[k] = v == "True"
            else:
                try:
                    r[k] = int(v)
                except (TypeError, ValueError):
                    try:
                        r[k] = float(v)
                    except (TypeError, ValueError):
                        pass
    return rows


def machine_info() -> dict:
    """Where and when the numbers were measured."""
    import numba
    import scipy

    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=HERE.parent, capture_output=True,
                                  text=True, timeout=10).stdout.strip()
        except Exception:
            return ""

    cpu = ""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        import gamspy

        gp = gamspy.__version__
    except Exception:
        gp = "not installed"
    return dict(
        date=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        cores=os.cpu_count(), cpu=cpu, platform=platform.platform(),
        python=platform.python_version(), numpy=np.__version__, scipy=scipy.__version__,
        numba=numba.__version__, gamspy=gp,
        git=git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain",
                                                                     "compass_sparse") else ""),
        command=" ".join([os.path.basename(sys.executable)] + sys.argv),
    )


def write_json(path: Path, obj):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        json.dump(obj, fh, indent=1, default=_json_default)


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def median(xs):
    xs = [x for x in xs if x is not None and not (isinstance(x, float) and math.isnan(x))]
    return statistics.median(xs) if xs else math.nan


def fmt_time(t) -> str:
    """Seconds -> a short human string (ms below 1 s)."""
    if t is None or (isinstance(t, float) and (math.isnan(t) or math.isinf(t))):
        return "–"
    if t < 1.0:
        return f"{1e3 * t:.3g} ms"
    return f"{t:.3g} s"


def fmt_e(x) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.1e}"


def md_table(header: list[str], rows: list[list]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def print_machine(info: dict):
    print(f"# {info['date']}  |  {info['cores']} cores ({info['cpu']})  |  "
          f"Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, "
          f"numba {info['numba']}, gamspy {info['gamspy']}  |  git {info['git']}", flush=True)
    print(f"# command: {info['command']}", flush=True)
