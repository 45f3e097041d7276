"""Solver options: one frozen dataclass.

Names follow PATH 5.2's option names where PATH has the option (see the option table in
PATH's manual); defaults are PATH's unless stated.  Build from keywords, from a dict
(``Options.from_dict``; unknown keys raise :class:`OptionError`) or modify with
``opts.replace(name=value)``.  Every field documents its default and valid range, and
``validate`` checks them.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

from ._options_base import OptionsMixin, keyword_checked, normalized
from .exceptions import OptionError

__all__ = ["Options", "PATH_NAMES", "HOMOTOPY_DENSE_MAX_N", "HOMOTOPY_DENSE_DENSITY"]

# PATH 5.2's name of every option whose name is not PATH's own (None: PATH has no such
# option).  Every other field carries PATH's name; the option table in the docs and
# ``Options.path_name`` read this one map.
PATH_NAMES: dict[str, str | None] = {
    "pivot_tolerance": "expand_pivot_tolerance",  # the same role in PATH's EXPAND ratio test
    "ratio_tolerance": "expand_delta",  # PATH's working feasibility tolerance of EXPAND
    "presolve": "preprocess",
    "verbosity": "output",  # PATH: on/off; our levels select the summary and the logs
    "lm_fallback": None,
    "homotopy": None,  # PATH has no homotopy fallback
    "homotopy_after_restarts": None,
    "homotopy_stationary_limit": None,
    "homotopy_start": None,
    "homotopy_path_limit": None,
    "homotopy_step_limit": None,
    "homotopy_smoothing": None,
    "homotopy_initial_step": None,
    "homotopy_maximum_step": None,
    "homotopy_step_minimum": None,
    "homotopy_end_lambda": None,
    "homotopy_divergence_bound": None,
    "lm_initial_mu": None,
    "seed": None,
    "progress": None,
    "scaling": None,  # PATH's hidden model-scaling switches are defined otherwise
    "factor_reuse": None,  # PATH factors every basis afresh
    "lu_backend": "factorization_method",  # PATH's basis package (lusol, umfpack, ...)
    "lu_ordering": None,  # PATH's packages order by themselves
    "engine": None,  # which implementation of our loops runs (compass_sparse.routes)
    "path_basis": None,
}


HOMOTOPY_DENSE_MAX_N = 300
"""Up to this order the homotopy factors its bordered systems densely (and so above it
when J holds at least ``HOMOTOPY_DENSE_DENSITY * n^2`` entries)."""
HOMOTOPY_DENSE_DENSITY = 0.1


def _opt(default, doc: str, *, lo=None, hi=None, choices=None, lo_open=False, nullable=False,
         inf_ok=False):
    return field(
        default=default,
        metadata={"doc": doc, "lo": lo, "hi": hi, "choices": choices, "lo_open": lo_open,
                  "nullable": nullable, "inf_ok": inf_ok},
    )


_PLAIN = {"bool": bool, "int": int, "float": float}


@functools.lru_cache(maxsize=None)
def _field_rules(cls):
    """(name, kind, metadata) of every field, kind one of choice/bool/int/float: read once
    per class (options are built on every solve)."""
    rules = []
    for f in dataclasses.fields(cls):
        m = f.metadata
        kind = ("choice" if m.get("choices") is not None
                else "bool" if isinstance(f.default, bool) or f.type in ("bool",)
                else "int" if "int" in str(f.type) else "float")
        rules.append((f.name, kind, m))
    return tuple(rules)


@keyword_checked
@dataclass(frozen=True)
class Options(OptionsMixin):
    """Options of :func:`compass_sparse.solve_mcp` and :func:`compass_sparse.solve_lcp`.

    Every field: ``name = default`` — meaning [valid range].  See ``Options.describe()``.
    """

    # --- stopping --------------------------------------------------------------------
    convergence_tolerance: float = _opt(
        1e-6, "stop when ||Phi_FB(z)||_2 <= this (PATH's measure)", lo=0.0, lo_open=True)
    major_iteration_limit: int = _opt(
        500, "maximum major (Newton) iterations; 0 only evaluates the start point", lo=0)
    minor_iteration_limit: int | None = _opt(
        None, "maximum pivots in one pivotal path; None = max(2n, 100) (PATH: 2n)", lo=1,
        nullable=True)
    cumulative_iteration_limit: int | None = _opt(
        None, "maximum pivots over the whole solve; None = max(100000, 100n)", lo=1,
        nullable=True)
    time_limit: float = _opt(math.inf, "wall-clock seconds for the solve (inf: none)", lo=0.0,
                             lo_open=True, inf_ok=True)

    # --- crash (projected Newton, thesis §2.5) -----------------------------------------
    crash_method: str = _opt("pnewton", "crash pass: 'pnewton' or 'none'",
                             choices=("pnewton", "none"))
    crash_iteration_limit: int = _opt(50, "maximum crash iterations", lo=0)
    crash_minimum_dimension: int = _opt(
        1, "skip the crash below this dimension (PATH's default 1; the thesis' n_min is 10)",
        lo=0)
    crash_nbchange_limit: int = _opt(
        1, "stop the crash when at most this many active-set changes occur", lo=0)
    crash_perturb: bool = _opt(True, "perturb a singular reduced Jacobian by eps*I")
    crash_sigma: float = _opt(0.05, "sufficient decrease of ||F_B|| in the crash (thesis 0.05)",
                              lo=0.0, hi=1.0, lo_open=True)
    crash_stepsize_minimum: float = _opt(2.0 ** -12, "smallest crash step (thesis 2^-12)",
                                         lo=0.0, hi=1.0, lo_open=True)
    crash_searchtype: str = _opt(
        "arc", "crash search: 'arc' (the projected path pi(z - alpha d), thesis (2.5.5)) or "
        "'line' (the segment from z to pi(z - d))", choices=("line", "arc"))

    # --- pivotal path (thesis §3.3) ----------------------------------------------------
    lemke_start: str = _opt(
        "automatic", "'automatic' (warm basis, Lemke ray start as fallback), 'first' (ray "
        "start in the first major iteration only), 'always' (ray start every time)",
        choices=("automatic", "first", "always"))
    lemke_cycle_limit: int = _opt(
        20, "a variable entering the basis more often than this in one path signals cycling",
        lo=1)
    pivot_tolerance: float = _opt(
        1e-9, "smallest |pivot| (relative to the entering column's norm) allowed in the "
        "ratio test", lo=0.0, lo_open=True)
    ratio_tolerance: float = _opt(
        1e-9, "Harris tolerance: bound violations up to this (relative) are allowed in the "
        "first ratio-test pass so that the largest pivot among near ties is chosen",
        lo=0.0)
    factorization_update_limit: int | None = _opt(
        None, "most Forrest–Tomlin updates before a fresh factorization (capped at "
        "max(n, 50)); None = automatic: the sparse path engine refactorizes when that "
        "costs less per pivot than further updates (work counted in entries of the "
        "factors, at most 250 updates), the dense engine and the basis manager every 50 "
        "updates (PATH's default).  An integer is the limit on every route; the sparse "
        "engine's rule still refactorizes earlier where that pays", lo=1, nullable=True)
    factor_reuse: bool = _opt(
        True, "a pivotal path whose start basis has the slot table of the previous path's "
        "factors (or, first, the crash's last reduced Jacobian as its M block) solves with "
        "GMRES preconditioned by those factors instead of factoring (on the sparse basis "
        "manager's route, see path_basis; falls back to a fresh factorization when a solve "
        "does not reach a backward error of 1e-12 in 30 steps, and before any pivot)")
    lu_backend: str = _opt(
        "auto", "sparse LU of the basis manager (problems above n = 500; below, the "
        "compiled dense engine; a value other than 'auto' keeps the paths off the sparse "
        "engine, whose LU is its own) and of the crash's reduced Jacobians (above order 200; below, dense LU): "
        "'superlu' (scipy) with the ordering of lu_ordering, 'umfpack' (SuiteSparse "
        "through kvxopt; orders by itself, so lu_ordering must be 'auto'), or 'auto' "
        "(SuperLU; with 'auto' for both options the Newton steps that need no pivot "
        "(orders 50-2000) and the crash's sparse blocks of at most 2000 rows and 6250 "
        "entries are factored by KLU when kvxopt is installed, without the time and memory "
        "estimates of the SuperLU route; the environment variable "
        "COMPASS_SPARSE_LU='backend[:ordering]' replaces 'auto' values)",
        choices=("auto", "superlu", "umfpack"))
    lu_ordering: str = _opt(
        "auto", "fill-reducing column ordering for SuperLU: 'colamd', 'amd' or 'metis' "
        "(nested dissection; both on the symmetrized pattern after a zero-free-diagonal row "
        "matching), or 'auto' (COLAMD below 400 columns, above it AMD or METIS, whichever "
        "a symbolic estimate of the factorization's flops prefers; computed once per "
        "pattern)", choices=("auto", "colamd", "amd", "metis"))

    # --- non-monotone stabilization (thesis §3.4) ---------------------------------------
    nms: bool = _opt(True, "non-monotone stabilization (False: a monotone line search: "
                     "every step must decrease the merit of the current point)")
    nms_memory_size: int = _opt(10, "checkpoint merits kept for the reference value", lo=1)
    nms_mstep_frequency: int = _opt(10, "at most this many d-steps between m-steps", lo=1)
    nms_initial_reference_factor: float = _opt(
        20.0, "initial reference value = factor * Psi(z0)", lo=1.0)
    nms_searchtype: str = _opt("line", "watchdog search: 'line' or 'arc'",
                               choices=("line", "arc"))
    nms_maximum_watchdogs: int = _opt(5, "watchdog returns before a gradient step", lo=0)
    nms_sigma: float = _opt(1e-4, "sufficient-decrease constant", lo=0.0, hi=1.0, lo_open=True)
    nms_shrink_factor: float = _opt(0.8, "step shrink factor of the watchdog search",
                                    lo=0.0, hi=1.0, lo_open=True)
    nms_stepsize_minimum: float = _opt(1e-8, "smallest watchdog step", lo=0.0, hi=1.0,
                                       lo_open=True)
    nms_delta_shrink_factor: float = _opt(0.9, "d-step radius shrink factor per d-step",
                                          lo=0.0, hi=1.0, lo_open=True)
    nms_delta_min: float = _opt(1e-15, "smallest d-step radius", lo=0.0)

    # --- projected gradient and Levenberg–Marquardt fallbacks ---------------------------
    gradient_step_limit: int = _opt(5, "projected-gradient steps per fallback", lo=0)
    gradient_searchtype: str = _opt("arc", "'arc' (project the ray) or 'line'",
                                    choices=("line", "arc"))
    gradient_sigma: float = _opt(1e-4, "sufficient decrease in gradient steps", lo=0.0,
                                 hi=1.0, lo_open=True)
    gradient_shrink_factor: float = _opt(0.8, "gradient step shrink", lo=0.0, hi=1.0,
                                         lo_open=True)
    gradient_stepsize_minimum: float = _opt(1e-15, "smallest gradient step", lo=0.0)
    lm_fallback: bool = _opt(
        True, "try a Levenberg–Marquardt step on Psi before projected-gradient steps")
    lm_initial_mu: float = _opt(1e-3, "initial LM damping relative to ||H^T Phi||",
                                lo=0.0, lo_open=True)

    # --- proximal perturbation (Billups) -----------------------------------------------
    proximal_perturbation: float = _opt(
        0.0, "initial eps in M = J + eps*I; 0 uses eps only where needed (singular basis)",
        lo=0.0)
    proximal_shrink_factor: float = _opt(0.4, "eps shrink per major iteration", lo=0.0,
                                         hi=1.0)
    proximal_increase_factor: float = _opt(10.0, "eps growth on failure", lo=1.0)

    # --- restarts -------------------------------------------------------------------
    restart_limit: int = _opt(
        50, "restarts when progress stops: PATH's three configurations, then alternately "
        "crash + NMS from a random point of the box and a perturbed restart near the best "
        "point", lo=0)
    restart_stationary_limit: int = _opt(
        3, "restart when in this many major iterations the best merit has not improved by "
        "0.1% and no checkpoint has fallen 0.1% below its reference value (the latter counts "
        "within 5 major iterations of the best merit's last improvement: an accepted "
        "non-monotone excursion is not a stall).  PATH: 10; 3 measured best on the thesis "
        "families: same successes, restarts 3-8x cheaper; waiting 10 in the first four runs "
        "solved a few more instances but tripled the median time of a success", lo=1)
    seed: int = _opt(0, "seed of the random restart points", lo=0)

    # --- homotopy fallback (Billups & Watson 2002; module compass_sparse.homotopy) --------
    homotopy: str = _opt(
        "auto", "probability-one homotopy on the smoothed normal map: 'auto' (entered when "
        "NMS stalls, before or after restarts: see homotopy_after_restarts), 'off', or "
        "'only' (the homotopy alone, with its Newton end game, instead of NMS)",
        choices=("auto", "off", "only"))
    homotopy_after_restarts: int | None = _opt(
        None, "'auto' enters the homotopy after this many restarts failed; later restarts "
        "continue if it fails.  None = 0 where the homotopy's linear systems are dense "
        "(order <= 300 or nnz(J) >= 0.1 n^2: on the thesis families n = 10 ... 500 the "
        "restarts before it never solved an instance it then could not, and cost ~40% of "
        "the time), 3 otherwise (after PATH's three restart configurations)", lo=0,
        nullable=True)
    homotopy_stationary_limit: int = _opt(
        2, "in the run of NMS that 'auto' follows with the homotopy, the homotopy starts when "
        "the best merit has not improved by 0.1% in this many major iterations (in place of "
        "restart_stationary_limit; on the 171 thesis and known problems, 82 of which reach "
        "the homotopy, 2 instead of 3 saved one major iteration on each of the 82, every "
        "instance solved with both)", lo=1)
    homotopy_start: str = _opt(
        "best", "where the first homotopy path of 'auto' starts: 'best' (the best point the "
        "stabilized Newton method found before it stalled: on the 105 thesis instances, n = "
        "10 ... 200, that reached the homotopy, 15% fewer path steps and 16% fewer F "
        "evaluations than 'start', every instance solved with both) or 'start' (the user's "
        "start point); later paths start from random points around the start point.  "
        "homotopy = 'only' always starts at the start point",
        choices=("best", "start"))
    homotopy_path_limit: int = _opt(
        3, "paths followed per homotopy pass: the first from homotopy_start's point, the "
        "others from random points of the box around the start point", lo=1)
    homotopy_step_limit: int = _opt(
        3000, "accepted predictor-corrector steps per path", lo=1)
    homotopy_smoothing: float = _opt(
        1.0, "initial smoothing mu0 of the projection, relative to the median finite box "
        "width; mu = mu0 (1 - lam) goes to 0 at the end of the path (on the thesis families "
        "at n = 100, 1.0 took 3-7x fewer steps than 0.1 and 0.01; 3 and 10 were alike)",
        lo=0.0, lo_open=True)
    homotopy_initial_step: float = _opt(
        0.1, "first arclength step, relative to 1 + ||a||_inf (a step the corrector cannot "
        "follow is halved)", lo=0.0, lo_open=True)
    homotopy_maximum_step: float = _opt(
        1.0, "largest arclength step, relative to 1 + ||x||_inf", lo=0.0, lo_open=True)
    homotopy_step_minimum: float = _opt(
        1e-10, "a path whose corrector fails at this step (relative to 1 + ||a||_inf) ends",
        lo=0.0, lo_open=True)
    homotopy_end_lambda: float = _opt(
        0.9, "from this lam on every path point is handed to Newton's method on the normal "
        "map (Speight's hybrid); a miss moves the switch to 1 - (1 - lam) / 10",
        lo=0.0, hi=1.0)
    homotopy_divergence_bound: float = _opt(
        1e4, "a path with ||x||_inf above this times (1 + ||a||_inf) has diverged", lo=1.0)

    # --- passes -------------------------------------------------------------------------
    presolve: bool = _opt(True, "run the preprocessor when the problem has linear structure")
    scaling: bool = _opt(
        True, "row and column equilibration of J(x0) when its row or column norms spread "
        "over more than 1e2 (the tolerance still applies to the user's F)")

    # --- routes (compass_sparse.routes: which implementation runs, chosen once per solve) --
    engine: str = _opt(
        "auto", "'auto': compiled loops where they apply -- the stabilized Newton method's "
        "bookkeeping (up to n = 5000, on a problem the scaling pass left unscaled), the crash "
        "(when every block is dense, n <= 200), the homotopy's path tracker (n <= 300) and a "
        "small problem's path start and dense direct step in one call (n < 150); "
        "'reference': their Python loops, which compute the same points bit for bit (the "
        "tests hold the two against each other).  Result.routes records what ran",
        choices=("auto", "reference"))
    path_basis: str = _opt(
        "auto", "the basis the pivotal paths run on: 'auto' (the compiled dense engine, a dense "
        "LU with Forrest-Tomlin updates, up to n = 500; above, the compiled sparse engine, a "
        "sparse LU with Forrest-Tomlin updates, for Jacobians of at most 8 entries per "
        "column when lu_backend and lu_ordering are 'auto'; for denser ones up to n = 5000 "
        "the sparse basis manager until a path makes max(100, n/10) pivots, then the sparse "
        "engine; else the sparse basis manager), "
        "'dense' (the Python pivot loop on the dense reference basis, an explicit inverse "
        "with rank-one updates, up to n = 300; the sparse basis manager above) or 'sparse' "
        "(the Python pivot loop on the sparse basis manager at every order) or 'sparse engine' "
        "(the compiled sparse engine at every order, whatever the Jacobian's density, from "
        "the first path; it needs lu_backend and lu_ordering 'auto' and engine 'auto'); "
        "they take the same pivots up to rounding",
        choices=("auto", "dense", "sparse", "sparse engine"))

    # --- output ---------------------------------------------------------------------
    verbosity: int = _opt(0, "0 silent, 1 summary, 2 major-iteration log, 3 minor log (one "
                          "line per pivot, from the same pivots a silent solve makes: the "
                          "log never changes which arithmetic runs)", lo=0, hi=3)
    progress: bool = _opt(False, "one-line progress display on stderr for solves longer "
                          "than a second, shown only when stderr is a terminal")

    def __post_init__(self):
        self.validate()

    # ---------------------------------------------------------------------------------
    def validate(self):
        """Check every field against its documented range and store it as a plain bool,
        int or float (NumPy scalars, integral floats for integers); raise OptionError."""
        for name, kind, m in _field_rules(type(self)):
            v = getattr(self, name)
            if v is None:
                if m.get("nullable"):
                    continue
                raise OptionError(f"option {name} may not be None")
            if kind == "choice":
                if not isinstance(v, str) or v not in m["choices"]:
                    raise OptionError(f"option {name}={v!r}: expected one of {m['choices']}")
                continue
            if type(v) is not _PLAIN[kind]:  # already a plain value: nothing to convert
                v = normalized(name, v, kind, allow_inf=m.get("inf_ok", False))
                object.__setattr__(self, name, v)
            elif kind == "float" and not math.isfinite(v):
                normalized(name, v, kind, allow_inf=m.get("inf_ok", False))  # NaN raises
            if kind == "bool":
                continue
            lo, hi = m.get("lo"), m.get("hi")
            if lo is not None and (v < lo or (m.get("lo_open") and v == lo)):
                op = ">" if m.get("lo_open") else ">="
                raise OptionError(f"option {name}={v!r}: must be {op} {lo}")
            if hi is not None and v > hi:
                raise OptionError(f"option {name}={v!r}: must be <= {hi}")
        if self.path_basis == "sparse engine" and (
                self.engine != "auto" or self.lu_backend != "auto"
                or self.lu_ordering != "auto"):
            raise OptionError(
                "option path_basis='sparse engine': the compiled sparse engine factors its "
                "bases with its own LU, so it needs engine, lu_backend and lu_ordering 'auto' "
                f"(got engine={self.engine!r}, lu_backend={self.lu_backend!r}, "
                f"lu_ordering={self.lu_ordering!r})")
        if self.lu_backend == "umfpack" and self.lu_ordering != "auto":
            raise OptionError(f"option lu_ordering={self.lu_ordering!r}: UMFPACK orders by "
                              "itself; use lu_backend='superlu' to force an ordering")

    def minor_limit(self, n: int) -> int:
        return self.minor_iteration_limit or max(2 * n, 100)

    def cumulative_limit(self, n: int) -> int:
        return self.cumulative_iteration_limit or max(100000, 100 * n)

    def restarts_before_homotopy(self, n: int, nnz: int) -> int:
        """``homotopy_after_restarts`` for a problem of order n whose Jacobian holds nnz
        entries (see the option)."""
        if self.homotopy_after_restarts is not None:
            return self.homotopy_after_restarts
        dense = n <= HOMOTOPY_DENSE_MAX_N or nnz >= HOMOTOPY_DENSE_DENSITY * n * n
        return 0 if dense else 3

    @classmethod
    def path_name(cls, name: str) -> str | None:
        """PATH 5.2's name of option ``name`` (None when PATH has no such option)."""
        cls.check_names([name])
        return PATH_NAMES.get(name, name)

    @classmethod
    def describe(cls) -> str:
        """A table of every option with its default and meaning."""
        rows = []
        for f in dataclasses.fields(cls):
            rows.append(f"{f.name:36s} {f.default!r:>12}  {f.metadata['doc']}")
        return "\n".join(rows)

ALIASES: dict[str, str] = {
    **{path.lower(): ours for ours, path in PATH_NAMES.items() if path is not None},
    # scipy.optimize's, GAMS' and other solvers' words for the same settings
    "tol": "convergence_tolerance", "ftol": "convergence_tolerance",
    "fatol": "convergence_tolerance", "gtol": "convergence_tolerance",
    "tolerance": "convergence_tolerance", "eps": "convergence_tolerance",
    "maxiter": "major_iteration_limit", "max_iter": "major_iteration_limit",
    "maxit": "major_iteration_limit", "iterlim": "major_iteration_limit",
    "max_iterations": "major_iteration_limit", "maxfev": "major_iteration_limit",
    "reslim": "time_limit", "timelimit": "time_limit", "max_time": "time_limit",
    "time": "time_limit", "verbose": "verbosity", "disp": "verbosity",
    "print_level": "verbosity", "random_state": "seed",
}
"""The names users bring from elsewhere (PATH's own, where ours differs; scipy's ``tol``,
``maxiter``; GAMS' ``iterlim``, ``reslim``): an unknown option or keyword so named gets
the hint of the option it means."""
Options._aliases = ALIASES
