"""Run the PATH solver (through GAMSPy) on MCP instances generated in Python.

This is a reference adapter for side-by-side benchmarks of compass_sparse against
PATH 5.2.  It covers two problem families:

* linear (box-)MCPs  ``F(z) = M z + q``                      -> :func:`solve_lcp_with_path`
* the COMPASS random quadratic family
  ``F_i(z) = D_i z_i**2 + (A z)_i + b_i``                     -> :func:`solve_quadratic_mcp_with_path`

with bounds ``lb <= z <= ub`` (entries may be ``-inf``/``+inf``; ``lb == ub`` fixes a
variable).

GAMSPy is an optional dependency (``pip install compass-sparse[gams]``).  It is
imported lazily, so this module can be imported without it; use
:func:`path_available` to check.  GAMS runs only under a valid licence (the demo licence
bundled with GAMSPy is time-limited; the free GAMSPy licence limits MCPs to 1000
rows/columns): where GAMS refuses, every entry point raises
:class:`~compass_sparse.exceptions.GamsLicenseError` quoting GAMS' licence lines (see
:mod:`compass_sparse.interfaces.gams_state`).

Model formulation
-----------------
The model is written as::

    z(i)   free variable, with z.lo = lb, z.up = ub, z.l = x0
    f(i)   =n=   d(i)*sqr(z(i)) + sum(j, A(i,j)*z(j)) + b(i)
    Model  MCP with f matched to z

A nonbinding (``=n=``) equation imposes no sign by itself; complementarity with
the bounds of the matched variable defines the MCP, so every bound type
(free, lower, upper, boxed, fixed) is handled uniformly.  Only the nonzeros of
``A`` are sent.  GAMS rejects an MCP row that contains no variable at all
("empty equation") unless the matched variable is fixed, so a missing diagonal
entry is sent as the GAMS special value EPS: a structural nonzero whose numerical
value is 0.
"""

from __future__ import annotations

import io
import logging
import math
import re
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..exceptions import GamsLicenseError
from .gams_state import gams_refusals, gams_state, require_gams

__all__ = [
    "PathLicenseError",
    "PathRun",
    "PathSession",
    "natural_residual",
    "parse_path_log",
    "path_available",
    "solve_lcp_with_path",
    "solve_quadratic_mcp_with_path",
]

#: Size limit of the free (demo) GAMSPy licence for MCP models (rows = columns).
FREE_LICENSE_MAX_SIZE = 1000


#: The name this module gave the licence error before GamsLicenseError existed.
PathLicenseError = GamsLicenseError


# --------------------------------------------------------------------------- #
# availability
# --------------------------------------------------------------------------- #
def path_available() -> bool:
    """True when GAMS runs here (installed, licence accepted: :func:`gams_state`) and PATH is
    among its solvers."""
    if not gams_state().runs:
        return False
    try:
        # (GAMSPy: an optional extra)
        import gamspy  # noqa: F401
    except Exception:
        return False
    try:
        # (GAMSPy: an optional extra)
        from gamspy import utils

        solvers = [s.upper() for s in utils.getInstalledSolvers()]
    except Exception:  # pragma: no cover - very old/new gamspy API
        return True
    return "PATH" in solvers


# --------------------------------------------------------------------------- #
# result object
# --------------------------------------------------------------------------- #
@dataclass
class PathRun:
    """Outcome of one PATH solve.

    ``x`` and ``f`` always have length ``n`` (fixed variables included).
    ``f`` is F(x) recomputed in float64 from the problem data; ``f_reported`` is F
    as returned by GAMS/PATH (the variable marginals).  Counters parsed from the
    PATH log are ``None`` when the log lacks them (e.g. GAMS presolve decided the
    model before PATH iterated).
    """

    x: np.ndarray
    f: np.ndarray
    solver_status: str
    solver_status_code: int
    model_status: str
    model_status_code: int
    success: bool
    residual: float | None = None  # PATH's final residual (2-norm of Fischer-Burmeister fct)
    major_iterations: int | None = None
    minor_iterations: int | None = None
    crash_iterations: int | None = None
    restarts: int | None = None
    gradient_steps: int | None = None
    fevals: int | None = None
    jevals: int | None = None
    basis_time: float | None = None
    path_time: float | None = None  # PATH's own "Total Time" [s]
    wall_time: float = math.nan  # whole model.solve() call incl. GAMS process [s]
    build_time: float = math.nan  # setting the GAMSPy records before the solve [s]
    exit_message: str | None = None  # e.g. "solution found", "other error", "infeasible"
    natural_residual: float = math.nan  # ||x - clip(x - f, lb, ub)||_inf with recomputed f
    f_reported: np.ndarray | None = None
    major_residuals: list[float] = field(default_factory=list)  # major iteration log
    crash_residuals: list[float] = field(default_factory=list)  # crash log
    path_size: tuple[int, int] | None = None  # (rows/cols, nonzeros) PATH saw
    log: str = ""

    def summary(self) -> str:
        return (
            f"PATH {self.exit_message or self.model_status}: success={self.success} "
            f"res={self.residual} nat={self.natural_residual:.2e} "
            f"major={self.major_iterations} minor={self.minor_iterations} "
            f"crash={self.crash_iterations} restarts={self.restarts} "
            f"path_time={self.path_time} wall_time={self.wall_time:.3f}"
        )


def natural_residual(x, f, lb, ub) -> float:
    """Inf-norm of the natural (normal/min-map) residual ``x - clip(x - f, lb, ub)``."""
    x = np.asarray(x, dtype=float)
    f = np.asarray(f, dtype=float)
    if x.size == 0:
        return 0.0
    r = x - np.clip(x - f, lb, ub)
    return float(np.max(np.abs(r)))


# --------------------------------------------------------------------------- #
# log parsing
# --------------------------------------------------------------------------- #
_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?inf|nan)"
_SUMMARY_FIELDS = {
    "major_iterations": ("Major Iterations", int),
    "minor_iterations": ("Minor Iterations", int),
    "restarts": ("Restarts", int),
    "crash_iterations": ("Crash Iterations", int),
    "gradient_steps": ("Gradient Steps", int),
    "fevals": ("Function Evaluations", int),
    "jevals": ("Gradient Evaluations", int),
    "basis_time": ("Basis Time", float),
    "path_time": ("Total Time", float),
    "residual": ("Residual", float),
}


def parse_path_log(log: str) -> dict[str, Any]:
    """Extract the summary counters, exit message and residual histories of a PATH log.

    If the log contains several PATH runs, the last one is used.
    """
    out: dict[str, Any] = {}
    start = log.rfind("Path 5.")
    if start < 0:
        start = log.rfind("Path ")
    text = log[start:] if start >= 0 else log
    for key, (label, typ) in _SUMMARY_FIELDS.items():
        # summary lines look like "Major Iterations. . . . 12"
        mt = re.findall(rf"^\s*{re.escape(label)}[ .]*?\.\s+{_NUM}\s*$", text, flags=re.M)
        if mt:
            try:
                out[key] = typ(float(mt[-1])) if typ is int else float(mt[-1])
            except ValueError:
                pass
    mt = re.findall(r"\*\* EXIT - (.*?)\.?\s*$", text, flags=re.M)
    if mt:
        out["exit_message"] = mt[-1].strip()
    mt = re.search(r"^(\d+) row/cols, (\d+) non-zeros", log[: start if start > 0 else len(log)],
                   flags=re.M)
    if mt is None:
        mt = re.search(r"^(\d+) row/cols, (\d+) non-zeros", log, flags=re.M)
    if mt:
        out["path_size"] = (int(mt.group(1)), int(mt.group(2)))
    out["crash_residuals"] = _parse_table(text, "Crash Log", residual_col=4)
    out["major_residuals"] = _parse_table(text, "Major Iteration Log", residual_col=4)
    return out


def _parse_table(text: str, title: str, residual_col: int) -> list[float]:
    """Residual column of the crash / major iteration table.

    Crash:  ``major func diff size residual step prox (label)``; the first row
    (iteration 0) omits diff and size.  Major: ``major minor func grad residual
    step type prox inorm (label)``.  Restart-log blocks may interrupt the major
    table; rows are recognised as lines starting with integers.
    """
    res: list[float] = []
    pos = text.find(title)
    if pos < 0:
        return res
    lines = text[pos:].splitlines()[2:]
    for line in lines:
        s = line.strip()
        if not s:
            if title == "Crash Log":
                break
            continue
        if s.startswith(("FINAL STATISTICS", "pn_search", "Crash Log", "Major Iteration Log")):
            if s.startswith("FINAL") or (title == "Crash Log" and s.startswith("pn_search")):
                break
            continue
        toks = s.split()
        if not toks[0].isdigit():
            continue  # restart log lines, header repeats, ...
        # residual = first token in scientific notation (columns before it are integers)
        for t in toks[1:]:
            if re.fullmatch(r"[-+]?\d\.\d+e[-+]\d+", t):
                res.append(float(t))
                break
    return res


# --------------------------------------------------------------------------- #
# input normalisation
# --------------------------------------------------------------------------- #
def _as_coo(A, n: int, *, add_diagonal: bool):
    """Return (rows, cols, vals) of the nonzeros of A; optionally (explicit) zeros on
    a missing diagonal (vals=0 there, sent later as EPS)."""
    if sp.issparse(A):
        shape = A.shape
        C = sp.coo_matrix(A)
        C.sum_duplicates()
        r, c, v = C.row.astype(np.int64), C.col.astype(np.int64), C.data.astype(float)
    else:
        Ad = np.asarray(A, dtype=float)
        if Ad.ndim != 2:
            raise ValueError("matrix must be 2-D")
        shape = Ad.shape
        r, c = np.nonzero(Ad)
        v = Ad[r, c]
        r = r.astype(np.int64)
        c = c.astype(np.int64)
    if tuple(shape) != (n, n):
        raise ValueError(f"matrix has shape {tuple(shape)}, expected {(n, n)}")
    if not np.all(np.isfinite(v)):
        raise ValueError("matrix contains non-finite entries")
    keep = v != 0.0
    r, c, v = r[keep], c[keep], v[keep]
    if add_diagonal:
        has = np.zeros(n, dtype=bool)
        has[r[r == c]] = True
        miss = np.flatnonzero(~has)
        if miss.size:
            r = np.concatenate([r, miss])
            c = np.concatenate([c, miss])
            v = np.concatenate([v, np.zeros(miss.size)])
    return r, c, v


def _vec(v, n: int, name: str, default: float | None = None) -> np.ndarray:
    if v is None:
        if default is None:
            raise ValueError(f"{name} is required")
        return np.full(n, default, dtype=float)
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    a = a.reshape(-1)
    if a.size != n:
        raise ValueError(f"{name} has length {a.size}, expected {n}")
    return a.copy()


# --------------------------------------------------------------------------- #
# the reusable model
# --------------------------------------------------------------------------- #
class PathSession:
    """A GAMSPy container holding the MCP model for size ``n``; reusable across solves.

    Building the container and the model declaration happens once; each
    :meth:`solve` replaces the data records (matrix nonzeros, vectors, bounds,
    start) and calls PATH.  GAMS regenerates the model on every solve, so the
    sparsity pattern may change between solves.

    ``quadratic=True`` includes the diagonal term ``D_i z_i**2``.
    """

    def __init__(self, n: int, *, quadratic: bool = False):
        self.n = int(n)
        if self.n < 1:
            raise ValueError("n must be positive")
        self.quadratic = bool(quadratic)
        require_gams("run PATH")
        # (GAMSPy: an optional extra)
        import gamspy as gp

        self._gp = gp
        with gams_refusals("run PATH"):
            self._declare(gp)

    def _declare(self, gp):
        """The container, the symbols and the MCP model (each assignment is a GAMS job)."""
        self._labels = np.array([str(k) for k in range(self.n)], dtype=object)
        m = gp.Container()
        self.container = m
        i = gp.Set(m, "i", records=list(self._labels))
        j = gp.Alias(m, "j", i)
        self._A = gp.Parameter(m, "A", domain=[i, j])
        self._b = gp.Parameter(m, "b", domain=i)
        self._z = gp.Variable(m, "z", domain=i, type="free")
        self._f = gp.Equation(m, "f", domain=i, type="nonbinding")
        expr = gp.Sum(j, self._A[i, j] * self._z[j]) + self._b[i]
        if self.quadratic:
            self._d = gp.Parameter(m, "d", domain=i)
            expr = self._d[i] * gp.math.sqr(self._z[i]) + expr
        else:
            self._d = None
        self._f[i] = expr
        self.model = gp.Model(m, "mcp", problem="MCP", matches={self._f: self._z})

    # ------------------------------------------------------------------ #
    def _set_records(self, A, b, lb, ub, x0, D):
        # (pandas: an optional extra, with GAMSPy)
        import pandas as pd

        gp = self._gp
        n = self.n
        lab = self._labels
        r, c, v = _as_coo(A, n, add_diagonal=True)
        v = v.copy()
        v[v == 0.0] = gp.SpecialValues.EPS  # structural zero (see module docstring)
        self._A.setRecords(pd.DataFrame({"i": lab[r], "j": lab[c], "value": v}))
        nzb = np.flatnonzero(b)
        self._b.setRecords(pd.DataFrame({"i": lab[nzb], "value": b[nzb]}))
        if self._d is not None:
            nzd = np.flatnonzero(D)
            self._d.setRecords(pd.DataFrame({"i": lab[nzd], "value": D[nzd]}))
        self._z.setRecords(
            pd.DataFrame(
                {
                    "i": lab,
                    "level": x0,
                    "marginal": np.zeros(n),
                    "lower": lb,
                    "upper": ub,
                    "scale": np.ones(n),
                }
            )
        )

    def _read_vector(self, sym, column: str, default: float) -> np.ndarray:
        out = np.full(self.n, default, dtype=float)
        rec = sym.records
        if rec is None or len(rec) == 0:
            return out
        idx = rec.iloc[:, 0].astype(str).astype(np.int64).to_numpy()
        out[idx] = rec[column].to_numpy(dtype=float)
        return out

    # ------------------------------------------------------------------ #
    def solve(
        self,
        A,
        b,
        lb,
        ub,
        x0=None,
        D=None,
        *,
        convergence_tolerance: float = 1e-6,
        options: dict | None = None,
        time_limit: float | None = None,
        output=None,
    ) -> PathRun:
        """Solve MCP(F, [lb, ub]) with F(z) = D*z**2 + A z + b (D only if quadratic).

        ``options`` are PATH options (e.g. ``{"crash_method": "none"}``);
        ``convergence_tolerance`` is passed as the PATH option of that name.
        ``time_limit`` (seconds) becomes the GAMS resource limit (PATH's time_limit).
        ``output``: optional text stream that additionally receives the log.
        """
        gp = self._gp
        b, lb, ub, x0v, Dv, fixed = self._checked_data(b, lb, ub, x0, D)
        t0 = time.perf_counter()
        with gams_refusals("run PATH"):
            self._set_records(A, b, lb, ub, x0v, Dv)
        build_time = time.perf_counter() - t0

        solver_options = {"convergence_tolerance": float(convergence_tolerance)}
        if options:
            solver_options.update(options)
        gopts = gp.Options(time_limit=float(time_limit)) if time_limit is not None else None
        log, wall = self._run_path(solver_options, gopts)
        if output is not None:
            output.write(log)
        return self._run_result(A, b, lb, ub, Dv, fixed, log, wall, build_time)

    def _checked_data(self, b, lb, ub, x0, D):
        """(b, lb, ub, x0, D, fixed) as vectors of the session's order, checked."""
        n = self.n
        b = _vec(b, n, "b")
        lb = _vec(lb, n, "lb", default=-np.inf)
        ub = _vec(ub, n, "ub", default=np.inf)
        x0v = _vec(x0, n, "x0", default=0.0)
        if np.any(np.isnan(lb)) or np.any(np.isnan(ub)):
            raise ValueError("bounds must not be NaN")
        if np.any(lb > ub):
            raise ValueError("inconsistent bounds: lb > ub")
        if np.any(np.isinf(lb) & (lb > 0)) or np.any(np.isinf(ub) & (ub < 0)):
            raise ValueError("lb = +inf or ub = -inf is not allowed")
        if not np.all(np.isfinite(b)) or not np.all(np.isfinite(x0v)):
            raise ValueError("b and x0 must be finite")
        if self.quadratic:
            Dv = _vec(D, n, "D")
            if not np.all(np.isfinite(Dv)):
                raise ValueError("D must be finite")
        else:
            if D is not None:
                raise ValueError("D given but the session is linear (quadratic=False)")
            Dv = None
        fixed = lb == ub
        x0v[fixed] = lb[fixed]
        return b, lb, ub, x0v, Dv, fixed

    def _run_path(self, solver_options, gopts):
        """(log, wall time) of one PATH run on the session's model."""
        from gamspy.exceptions import GamspyException  # (GAMSPy: an optional extra)

        buf = io.StringIO()
        # GAMSPy logs a warning for every non-normal solve status; PathRun carries the status.
        model_logger = logging.getLogger("MODEL")
        old_level = model_logger.level
        model_logger.setLevel(logging.ERROR)
        t1 = time.perf_counter()
        try:
            with gams_refusals("run PATH", log=buf.getvalue):
                self.model.solve(
                    solver="PATH", solver_options=solver_options, options=gopts, output=buf
                )
        except GamspyException as exc:
            log = buf.getvalue()
            raise RuntimeError(
                f"GAMS failed before/while running PATH: {exc}\n--- log tail ---\n{log[-3000:]}"
            ) from exc
        finally:
            model_logger.setLevel(old_level)
        return buf.getvalue(), time.perf_counter() - t1

    def _run_result(self, A, b, lb, ub, Dv, fixed, log, wall, build_time) -> PathRun:
        """The PathRun of a run: x read back, F recomputed, the log parsed."""
        x = self._read_vector(self._z, "level", 0.0)
        x[fixed] = lb[fixed]
        f_rep = self._read_vector(self._z, "marginal", 0.0)

        Ax = _matvec(A, x)
        f = Ax + b
        if Dv is not None:
            f = f + Dv * x * x

        ms = self.model.status
        ss = self.model.solve_status
        info = parse_path_log(log)
        exit_msg = info.get("exit_message")
        solved_status = ss is not None and ss.value == 1 and ms is not None and ms.value in (1, 2)
        if exit_msg is not None:
            success = exit_msg.startswith("solution found") and solved_status
        else:
            success = solved_status

        return PathRun(
            x=x,
            f=f,
            solver_status=ss.name if ss is not None else "unknown",
            solver_status_code=int(ss.value) if ss is not None else -1,
            model_status=ms.name if ms is not None else "unknown",
            model_status_code=int(ms.value) if ms is not None else -1,
            success=bool(success),
            residual=info.get("residual"),
            major_iterations=info.get("major_iterations"),
            minor_iterations=info.get("minor_iterations"),
            crash_iterations=info.get("crash_iterations"),
            restarts=info.get("restarts"),
            gradient_steps=info.get("gradient_steps"),
            fevals=info.get("fevals"),
            jevals=info.get("jevals"),
            basis_time=info.get("basis_time"),
            path_time=info.get("path_time"),
            wall_time=wall,
            build_time=build_time,
            exit_message=exit_msg,
            natural_residual=natural_residual(x, f, lb, ub),
            f_reported=f_rep,
            major_residuals=info.get("major_residuals", []),
            crash_residuals=info.get("crash_residuals", []),
            path_size=info.get("path_size"),
            log=log,
        )


def _matvec(A, x: np.ndarray) -> np.ndarray:
    if sp.issparse(A):
        return np.asarray(A @ x, dtype=float).reshape(-1)
    return np.asarray(A, dtype=float) @ x


# --------------------------------------------------------------------------- #
# one-shot entry points
# --------------------------------------------------------------------------- #
def _session_for(n: int, quadratic: bool, session: PathSession | None) -> PathSession:
    """The given session if it fits (size and model form), else a new one."""
    if session is None:
        return PathSession(n, quadratic=quadratic)
    if session.n != n or session.quadratic != quadratic:
        raise ValueError("session does not match (size or quadratic flag)")
    return session


def solve_lcp_with_path(
    M,
    q,
    lb,
    ub,
    x0=None,
    *,
    convergence_tolerance: float = 1e-6,
    options: dict | None = None,
    time_limit: float | None = None,
    session: PathSession | None = None,
) -> PathRun:
    """Solve the box-LCP / linear MCP ``lb <= z <= ub  _|_  F(z) = M z + q`` with PATH.

    ``M`` may be dense or scipy.sparse; only its nonzeros are sent to GAMS.
    ``lb``/``ub`` may contain ``-inf``/``+inf`` (None means free); ``x0`` defaults to 0
    (PATH projects the start onto the box).  Pass ``session=PathSession(n)`` to reuse a
    container across solves of the same size.
    """
    qv = np.asarray(q, dtype=float).reshape(-1)
    n = qv.size
    session = _session_for(n, False, session)
    return session.solve(
        M, qv, lb, ub, x0,
        convergence_tolerance=convergence_tolerance, options=options, time_limit=time_limit,
    )


def solve_quadratic_mcp_with_path(
    Ddiag,
    A,
    b,
    lb,
    ub,
    x0=None,
    *,
    convergence_tolerance: float = 1e-6,
    options: dict | None = None,
    time_limit: float | None = None,
    session: PathSession | None = None,
) -> PathRun:
    """Solve MCP(F, [lb, ub]) with ``F_i(z) = D_i z_i**2 + (A z)_i + b_i`` with PATH."""
    bv = np.asarray(b, dtype=float).reshape(-1)
    n = bv.size
    session = _session_for(n, True, session)
    return session.solve(
        A, bv, lb, ub, x0, Ddiag,
        convergence_tolerance=convergence_tolerance, options=options, time_limit=time_limit,
    )
