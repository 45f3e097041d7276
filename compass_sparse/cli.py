"""The ``compass-sparse`` command.

    compass-sparse demo [--problem obstacle|structured|thesis|kojshin|cge] [--n N] [-v]
    compass-sparse cge  [--regions R --sectors N --households H --shock ...] [--csv FILE]
    compass-sparse cge  ... --scenarios tariff=0:0.5:51 [sigma_armington=1,2,4]
                        [--scenarios-file FILE] [--output DIR] [--workers W] [--fresh]
    compass-sparse options          list every solver option with its default
    compass-sparse warmup [--jobs J] compile the solver's kernels ahead (set-up runs it)
    compass-sparse --version

A mistake on the command line (a bad number, a missing file, an output file or folder
that cannot be written, a scenario parameter the model does not have or a value it
refuses) is one line on stderr and exit code 2, found before any solving; Ctrl-C stops
with exit code 130 (a scenario batch says how many scenarios were saved and how to resume;
a single solve prints its summary first).
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import shutil
import sys
import textwrap
import time

import numpy as np

from . import __version__
from . import generators as gen
from .batch import CGEScenarioModel, grid, parse_axis, read_scenarios, scenario_key, solve_batch
from .batch.store import ResultStore
from .exceptions import CompassError
from .generators.cge import economics_report, static_cge
from .lcp import solve_lcp
from .options import Options
from .problem.mcp import MCP
from .solve import solve_mcp
from .status import Status
from .warmup import default_jobs, warm_up

EXIT_USAGE = 2
"""Exit code of a mistake on the command line (argparse's own)."""
EXIT_INTERRUPTED = 130
"""Exit code after Ctrl-C (128 + SIGINT, the shell's convention)."""


class UsageError(Exception):
    """A mistake on the command line: printed as one line, exit code 2."""


SCENARIO_PARAMETERS = ("tariff", "output_tax", "endowment", "balance",
                       "productivity") + CGEScenarioModel.ELASTICITIES
"""The parameters a CGE scenario may set (the static model's shocks and elasticities)."""


def _exit_code(res) -> int:
    """0 solved, 130 interrupted by Ctrl-C (the solve returns its best point then), 1
    not solved."""
    if res.status is Status.USER_INTERRUPT:
        return EXIT_INTERRUPTED
    return 0 if res.success else 1


def _opts(args):
    # The command prints the summary itself; -v adds the major-iteration log, -vv the
    # pivots of every path.
    d = {"verbosity": min(3, 1 + args.verbose) if args.verbose else 0,
         "convergence_tolerance": args.tol, "progress": args.progress}
    if args.time_limit:
        d["time_limit"] = args.time_limit
    return d


def _show_log(args):
    """The application side of logging: the library's records, as plain lines."""
    if args.verbose:
        logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)


def _print_result(name, n, res, problem=None, build_time=None, verbose=0):
    print(f"problem       {name} (n = {n})")
    if build_time is not None:
        print(f"built in      {build_time:.3f} s")
    if not verbose:  # with -v the solver's log has printed the summary already
        print(res.summary())
    if problem is not None:
        rep = res.check(problem)
        print(f"recomputed    natural residual {rep.natural:.3e} on the original problem")


def _demo(args) -> int:
    kind = args.problem
    t0 = time.perf_counter()
    if kind == "obstacle":
        m = int(round(np.sqrt(args.n or 40_000)))
        g = gen.obstacle_problem(m, seed=args.seed)
        M, q, lb, ub = g.lcp
        build = time.perf_counter() - t0
        res = solve_lcp(M, q, lb, ub, options=_opts(args))
    elif kind == "structured":
        g = gen.structured_quadratic(args.n or 100_000, seed=args.seed)
        build = time.perf_counter() - t0
        res = solve_mcp(g.problem, options=_opts(args))
    elif kind == "thesis":
        g = gen.thesis_family(args.n or 50, family=1, seed=args.seed)
        build = time.perf_counter() - t0
        res = solve_mcp(g.problem, options=_opts(args))
    elif kind == "cge":
        # the shocked model is the one solved, so it is the one the result is checked on
        g = static_cge(seed=args.seed).with_shock(output_tax=0.0)
        build = time.perf_counter() - t0
        res = solve_mcp(g.problem, options=_opts(args))
    else:  # kojshin
        def F(x):
            x1, x2, x3, x4 = x
            return np.array([3 * x1**2 + 2 * x1 * x2 + 2 * x2**2 + x3 + 3 * x4 - 6,
                             2 * x1**2 + x1 + x2**2 + 3 * x3 + 2 * x4 - 2,
                             3 * x1**2 + x1 * x2 + 2 * x2**2 + 2 * x3 + 3 * x4 - 1,
                             x1**2 + 3 * x2**2 + 2 * x3 + 3 * x4 - 3])

        def J(x):
            x1, x2, _, _ = x
            return np.array([[6 * x1 + 2 * x2, 2 * x1 + 4 * x2, 1, 3],
                             [4 * x1 + 1, 2 * x2, 3, 2],
                             [6 * x1 + x2, x1 + 4 * x2, 2, 3],
                             [2 * x1, 6 * x2, 2, 3]], dtype=float)

        prob = MCP(F, J, 0.0, np.inf, np.zeros(4))
        build = time.perf_counter() - t0
        res = solve_mcp(prob, options=_opts(args))
        _print_result("kojshin", 4, res, prob, build, args.verbose)
        return _exit_code(res)
    prob = g.problem
    _print_result(f"{kind} (seed {args.seed})", prob.n, res, prob, build, args.verbose)
    if getattr(g, "solution", None) is not None:
        print(f"known solution max |x - x*| = {np.max(np.abs(res.x - g.solution)):.3e}")
    return _exit_code(res)


def _check_common(args):
    """The mistakes in the options every solving command takes."""
    if args.time_limit is not None and not args.time_limit > 0:
        raise UsageError(f"--time-limit must be positive (got {args.time_limit})")
    if not args.tol > 0:
        raise UsageError(f"--tol must be positive (got {args.tol})")
    if getattr(args, "n", None) is not None and args.n < 1:
        raise UsageError(f"--n must be at least 1 (got {args.n})")


def _check_cge_args(args):
    """Every mistake the cge command can find before building and solving anything."""
    for name in ("regions", "sectors", "households"):
        if getattr(args, name) < 1:
            raise UsageError(f"--{name} must be at least 1 (got {getattr(args, name)})")
    if args.tariff is not None and args.regions < 2:
        raise UsageError("--tariff needs trade between regions: give --regions 2 or more")
    if args.top < 0:
        raise UsageError(f"--top must be 0 or more (got {args.top})")
    if args.scenarios_file and not os.path.isfile(args.scenarios_file):
        raise UsageError(f"--scenarios-file {args.scenarios_file}: no such file")
    if args.csv:
        _check_output_file("--csv", args.csv)
    if args.scenarios or args.scenarios_file:
        _check_output_folder("--output", args.output)
    if args.workers is not None and args.workers < 0:
        raise UsageError(f"--workers must be 0 or more (got {args.workers})")


def _check_output_file(flag, path):
    """A file the command will write: its folder exists and is writable, and the path is
    not a folder (found now, not after the solve)."""
    if os.path.isdir(path):
        raise UsageError(f"{flag} {path}: is a folder; give a file name")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"{flag} {path}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise UsageError(f"{flag} {path}: the folder {folder} is not writable")


def _check_output_folder(flag, path):
    """A folder the command will create or write into: a folder if it exists, else its
    nearest existing parent is a writable folder (it is created with its parents)."""
    if os.path.exists(path):
        if not os.path.isdir(path):
            raise UsageError(f"{flag} {path}: is a file, not a folder")
        if not os.access(path, os.W_OK):
            raise UsageError(f"{flag} {path}: the folder is not writable")
        return
    parent = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if not os.path.isdir(parent):
        raise UsageError(f"{flag} {path}: {parent} is a file, so the folder cannot be "
                         "created")
    if not os.access(parent, os.W_OK):
        raise UsageError(f"{flag} {path}: cannot create it in {parent} (not writable)")


def _scenario_list(args):
    """The scenarios of --scenarios and --scenarios-file (a bad spec is a UsageError)."""
    try:
        scenarios = (grid(**dict(parse_axis(a) for a in args.scenarios))
                     if args.scenarios else [])
        if args.scenarios_file:
            scenarios += read_scenarios(args.scenarios_file)
    except (CompassError, OSError, ValueError) as exc:
        raise UsageError(str(exc).splitlines()[0]) from None
    if not scenarios:
        raise UsageError("no scenarios: --scenarios and --scenarios-file give none")
    unknown = sorted({k for s in scenarios for k in s} - set(SCENARIO_PARAMETERS))
    if unknown:
        raise UsageError(f"unknown scenario parameter {', '.join(map(repr, unknown))}: the "
                         f"parameters are {', '.join(SCENARIO_PARAMETERS)}")
    return scenarios


def _check_scenario_values(model, scenarios):
    """Build the model at the smallest and the largest value of every parameter (the first
    value of an array-valued one), so that a value the model refuses (a tariff of -1, an
    output tax of 1) is a mistake found before solving, not a batch of failed rows."""
    builder = CGEScenarioModel(model)
    for name in sorted({k for s in scenarios for k in s}):
        values = [s[name] for s in scenarios if name in s]
        if all(np.ndim(v) == 0 for v in values):
            values = sorted({min(values), max(values)})
        for v in values[:2]:
            try:
                builder.cge(**{name: v})
            except (CompassError, ValueError, TypeError) as exc:
                shown = v if np.ndim(v) == 0 else "its first value"
                raise UsageError(f"scenario {name} = {shown}: {str(exc).splitlines()[0]}") \
                    from None


def _cge(args) -> int:
    _check_cge_args(args)
    scenarios = _scenario_list(args) if (args.scenarios or args.scenarios_file) else None
    t0 = time.perf_counter()
    model = static_cge(regions=args.regions, sectors=args.sectors, households=args.households,
                       seed=args.seed)
    build = time.perf_counter() - t0
    p = model.problem
    print(f"CGE model: {args.regions} region(s), {args.sectors} sectors, {args.households} "
          f"household(s): n = {p.n}, nnz(J) = {p.pattern.nnz}; built in {build:.2f} s")
    print(f"numeraire: {model.info.get('numeraire', 'none')}")
    rep = solve_mcp(p, options={**_opts(args), "major_iteration_limit": 0})
    print(f"benchmark replication (0 iterations): ||Phi||_2 = {rep.residual.fb_norm:.3e}, "
          f"natural residual = {rep.residual.natural:.3e}")
    if scenarios is not None:
        _check_scenario_values(model, scenarios)
        return _cge_scenarios(args, model, scenarios)
    shock = {}
    if args.output_tax is not None:
        shock["output_tax"] = args.output_tax
    if args.tariff is not None:
        shock["tariff"] = (0, args.tariff)  # region r1 (index 0)
    if args.productivity is not None:
        shock["productivity"] = args.productivity
    if args.endowment is not None:
        shock["endowment"] = args.endowment
    if not shock:
        shock = {"output_tax": 0.0}
    shocked = model.with_shock(**shock)
    print(f"shock: {shock}")
    res = solve_mcp(shocked.problem, options=_opts(args))
    _print_result("counterfactual", shocked.problem.n, res, shocked.problem,
                  verbose=args.verbose)
    if res.status is Status.USER_INTERRUPT:
        return EXIT_INTERRUPTED  # (no report of a point the user stopped)
    econ = economics_report(shocked, shocked.benchmark, res.x)
    print()
    print("economics of the counterfactual" + ("" if res.success else
                                               " (NOT an equilibrium: the best point found)"))
    print(econ.table(top=args.top))
    if args.csv:
        econ.to_csv(args.csv)
        print(f"\nwrote every variable and household to {args.csv}")
    return _exit_code(res)


def _saved_count(folder, scenarios):
    """How many of ``scenarios`` have a row in the results folder (None if unreadable)."""
    try:
        stored = ResultStore(folder, writer=False).load()
    except (OSError, ImportError, ValueError, CompassError):  # (only for a message)
        return None
    return sum(scenario_key(s) in stored for s in scenarios)


def _cge_scenarios(args, model, scenarios) -> int:
    """A scenario batch of the CGE model: results to Parquet, a table of headlines."""
    names = sorted({k for s in scenarios for k in s})
    if "tariff" in names and model.info["regions"] < 2:
        raise UsageError("tariff scenarios need trade between regions: give --regions 2 or "
                         "more")
    print(f"{len(scenarios)} scenarios over {', '.join(names)}; results in {args.output}/")
    try:
        out = solve_batch(model, scenarios, options=_opts(args), workers=args.workers,
                          output=args.output,
                          on_mismatch="new" if args.fresh else "refuse")
    except KeyboardInterrupt:
        saved = _saved_count(args.output, scenarios)
        what = ("the scenarios finished so far are saved" if saved is None else
                f"{saved} of {len(scenarios)} scenarios saved")
        print(f"\ninterrupted: {what} in {args.output}/; run the same command again to "
              "resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(out.summary())
    # Headlines of region r1: mean welfare index of its households, mean Armington price,
    # mean activity level, total household income (numeraire: see above).
    heads = {"welfare": ("U", np.mean), "price PA": ("PA", np.mean),
             "output Y": ("Y", np.mean), "income M": ("M", np.sum)}
    print("region r1: welfare = mean utility index U, price PA = mean Armington price, "
          "output Y = mean activity level, income M = household income")
    print("  ".join([f"{k:>15}" for k in names] + [f"{'status':>12}", f"{'its':>4}"]
                    + [f"{h:>10}" for h in heads]))
    rows = np.unique(np.linspace(0, len(out.rows) - 1, min(len(out.rows), 11)).astype(int))
    if rows.size < len(out.rows):
        print(f"({rows.size} of {len(out.rows)} scenarios shown, evenly spaced; every row is "
              f"in {args.output}/)")
    for i in rows:
        r, s = out.rows[i], out.scenarios[i]
        vals = [f"{float(s[k]):>15.6g}" if np.ndim(s.get(k, np.nan)) == 0 else f"{'array':>15}"
                for k in names]
        vals += [f"{r['status']:>12}", f"{r['nit']:>4d}"]
        x = r.get("x")
        for blk, agg in heads.values():
            v = agg(model.block(np.asarray(x), blk)[0]) if x is not None else np.nan
            vals.append(f"{v:>10.5g}")
        print("  ".join(vals))
    return 0 if out.failed == 0 else 1


def _options_table(width: int) -> str:
    """Every option with its default and meaning, wrapped to ``width`` columns: the meaning
    continues under itself, or (on a narrow terminal) under the option's line."""
    out = []
    for f in dataclasses.fields(Options):
        head = f"{f.name:36s} {f.default!r:>12}  "
        doc = " ".join(f.metadata["doc"].split())
        if len(head) + 30 <= width:
            out.append(textwrap.fill(doc, width, initial_indent=head,
                                     subsequent_indent=" " * len(head)))
        else:
            out.append(head.rstrip())
            out.append(textwrap.fill(doc, width, initial_indent=" " * 4,
                                     subsequent_indent=" " * 4))
    return "\n".join(out)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="compass-sparse",
        description="Sparse solver for mixed complementarity problems (PATH's method).",
        epilog="Exit codes: 0 solved, 1 not solved (the summary says why), 2 a mistake on "
        "the command line, 130 interrupted.")
    ap.add_argument("--version", action="version", version=f"compass-sparse {__version__}")
    ap.add_argument("-v", "--verbose", dest="global_verbose", action="count", default=0,
                    help="as -v after the command")
    sub = ap.add_subparsers(dest="cmd", metavar="{demo,cge,options,warmup}")

    def common(p):
        p.add_argument("--seed", type=int, default=0, help="generator seed (default 0)")
        p.add_argument("--tol", type=float, default=1e-6,
                       help="convergence tolerance on ||Phi_FB||_2 (default 1e-6)")
        p.add_argument("--time-limit", type=float, default=None,
                       help="seconds (default: none)")
        p.add_argument("-v", "--verbose", action="count", default=0,
                       help="print the crash and major-iteration log (-vv: every pivot)")
        p.add_argument("--progress", action="store_true",
                       help="one-line progress display on a terminal for long solves")

    d = sub.add_parser("demo", help="solve a bundled default problem and print the summary")
    d.add_argument("--problem", default="structured",
                   choices=["obstacle", "structured", "thesis", "kojshin", "cge"],
                   help="structured (default): a nonlinear MCP on a 2-D grid with long-range "
                   "couplings and mixed bounds, n = 100000, with a known solution; obstacle: "
                   "the obstacle problem, an LCP on an m x m grid (n = 40000); thesis: the "
                   "COMPASS thesis' random family 1 (n = 50); kojshin: the 4-variable "
                   "Kojima-Shindo NCP; cge: a static CGE model, abolishing its output taxes")
    d.add_argument("--n", type=int, default=None,
                   help="problem size (default: the problem's own, given above)")
    common(d)
    c = sub.add_parser("cge", help="run a CGE scenario: benchmark replication, then a shock")
    c.add_argument("--regions", type=int, default=1,
                   help="regions, named r1, r2, ... (default 1); 2 or more trade")
    c.add_argument("--sectors", type=int, default=10, help="sectors per region (default 10)")
    c.add_argument("--households", type=int, default=1,
                   help="households per region (default 1)")
    c.add_argument("--output-tax", type=float, default=None,
                   help="new uniform output tax rate (default shock: abolish output taxes)")
    c.add_argument("--tariff", type=float, default=None,
                   help="import tariff rate of region r1 (needs --regions 2 or more)")
    c.add_argument("--productivity", type=float, default=None,
                   help="productivity factor of every sector")
    c.add_argument("--endowment", type=float, default=None,
                   help="factor endowment scale")
    c.add_argument("--top", type=int, default=10,
                   help="largest price, quantity and income changes to print (default 10)")
    c.add_argument("--csv", default=None, metavar="FILE",
                   help="write the whole economics report (every variable, every household) "
                   "as CSV")
    c.add_argument("--scenarios", nargs="+", metavar="NAME=A:B:COUNT", default=None,
                   help="a scenario grid instead of one shock: axes name=start:stop:count or "
                   "name=v1,v2,...; names: tariff (on every import link), output_tax, "
                   "endowment, productivity, sigma_va, sigma_armington, sigma_consumer")
    c.add_argument("--scenarios-file", default=None, metavar="FILE",
                   help="scenarios from a CSV (header of names) or JSON (list of objects) file")
    c.add_argument("--output", default="cge-scenarios", metavar="DIR",
                   help="directory of the Parquet results (a rerun resumes; default "
                   "cge-scenarios)")
    c.add_argument("--fresh", action="store_true",
                   help="when --output holds the results of another model, move them into "
                   "DIR/previous-<time>/ and solve afresh (default: refuse)")
    c.add_argument("--workers", type=int, default=None,
                   help="worker processes (default: every core; 0: in this process)")
    common(c)
    sub.add_parser("options", help="list every solver option with its default")
    w = sub.add_parser("warmup", help="compile the solver's kernels now, so that the first "
                       "solves do not (once per installation; scripts/setup.sh runs it)")
    w.add_argument("--jobs", type=int, default=None,
                   help=f"processes compiling at once (default: the cores, here "
                   f"{default_jobs()})")
    return ap


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    if hasattr(args, "verbose"):
        args.verbose += args.global_verbose  # (compass-sparse -v demo == demo -v)
    try:
        if args.cmd in ("demo", "cge"):
            _check_common(args)
            _show_log(args)
        if args.cmd == "demo":
            return _demo(args)
        if args.cmd == "cge":
            return _cge(args)
        if args.cmd == "warmup":
            if args.jobs is not None and args.jobs < 1:
                raise UsageError(f"--jobs must be at least 1 (got {args.jobs})")
            return 0 if warm_up(args.jobs) >= 0 else 1
        if args.cmd == "options":
            width = shutil.get_terminal_size((100, 24)).columns
            print(_options_table(max(40, width - 1)))
            return 0
    except (UsageError, CompassError) as exc:
        # a CompassError here is bad input built from the arguments (a model the generator
        # refuses): the user's mistake too, said in one line
        print(f"compass-sparse {args.cmd}: {str(exc).splitlines()[0]}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"\ncompass-sparse {args.cmd}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except MemoryError:
        print(f"compass-sparse {args.cmd}: not enough memory for a problem of this size "
              "(give smaller sizes)", file=sys.stderr)
        return 1
    ap.print_help()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
