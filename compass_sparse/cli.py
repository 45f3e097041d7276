"""The ``compass-sparse`` command.

    compass-sparse demo [--problem obstacle|structured|thesis|kojshin|cge] [--n N] [-v]
    compass-sparse cge  [--regions R --sectors N --households H --shock ...]
    compass-sparse options          list every solver option with its default
"""
from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np


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


def _print_result(name, n, res, problem=None, build_time=None):
    print(f"problem       {name} (n = {n})")
    if build_time is not None:
        print(f"built in      {build_time:.3f} s")
    print(res.summary())
    if problem is not None:
        rep = res.check(problem)
        print(f"recomputed    natural residual {rep.natural:.3e} on the original problem")


def _demo(args) -> int:
    from . import solve_lcp, solve_mcp
    from . import generators as gen

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
        from .generators.cge import static_cge

        model = static_cge(seed=args.seed)
        g = model
        build = time.perf_counter() - t0
        res = solve_mcp(model.with_shock(output_tax=0.0).problem, options=_opts(args))
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

        from .problem import MCP

        prob = MCP(F, J, 0.0, np.inf, np.zeros(4))
        build = time.perf_counter() - t0
        res = solve_mcp(prob, options=_opts(args))
        _print_result("kojshin", 4, res, prob, build)
        return 0 if res.success else 1
    prob = g.problem
    _print_result(f"{kind} (seed {args.seed})", prob.n, res, prob, build)
    if getattr(g, "solution", None) is not None:
        print(f"known solution max |x - x*| = {np.max(np.abs(res.x - g.solution)):.3e}")
    return 0 if res.success else 1


def _cge(args) -> int:
    from . import solve_mcp
    from .generators.cge import static_cge

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
    shock = {}
    if args.output_tax is not None:
        shock["output_tax"] = args.output_tax
    if args.tariff is not None:
        shock["tariff"] = (0, args.tariff)
    if args.productivity is not None:
        shock["productivity"] = args.productivity
    if args.endowment is not None:
        shock["endowment"] = args.endowment
    if not shock:
        shock = {"output_tax": 0.0}
    shocked = model.with_shock(**shock)
    print(f"shock: {shock}")
    res = solve_mcp(shocked.problem, options=_opts(args))
    _print_result("counterfactual", shocked.problem.n, res, shocked.problem)
    return 0 if res.success else 1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="compass-sparse",
        description="Sparse solver for mixed complementarity problems (PATH's method).")
    sub = ap.add_subparsers(dest="cmd")

    def common(p):
        p.add_argument("--seed", type=int, default=0, help="generator seed (default 0)")
        p.add_argument("--tol", type=float, default=1e-6,
                       help="convergence tolerance on ||Phi_FB||_2 (default 1e-6)")
        p.add_argument("--time-limit", type=float, default=None, help="seconds")
        p.add_argument("-v", "--verbose", action="count", default=0,
                       help="print the crash and major-iteration log (-vv: every pivot)")
        p.add_argument("--progress", action="store_true",
                       help="one-line progress display on a terminal for long solves")

    d = sub.add_parser("demo", help="solve a bundled default problem and print the summary")
    d.add_argument("--problem", default="structured",
                   choices=["obstacle", "structured", "thesis", "kojshin", "cge"],
                   help="default: 'structured', a nonlinear MCP on a 2-D grid with long-range "
                   "couplings and mixed bounds, n = 100000, with a known solution")
    d.add_argument("--n", type=int, default=None, help="problem size")
    common(d)
    c = sub.add_parser("cge", help="run a CGE scenario: benchmark replication, then a shock")
    c.add_argument("--regions", type=int, default=1)
    c.add_argument("--sectors", type=int, default=10)
    c.add_argument("--households", type=int, default=1)
    c.add_argument("--output-tax", type=float, default=None,
                   help="new uniform output tax rate (default shock: abolish output taxes)")
    c.add_argument("--tariff", type=float, default=None, help="import tariff of region 0")
    c.add_argument("--productivity", type=float, default=None, help="productivity factor")
    c.add_argument("--endowment", type=float, default=None, help="endowment factor")
    common(c)
    sub.add_parser("options", help="list every solver option with its default")
    args = ap.parse_args(argv)
    if args.cmd in ("demo", "cge"):
        _show_log(args)
    if args.cmd == "demo":
        return _demo(args)
    if args.cmd == "cge":
        return _cge(args)
    if args.cmd == "options":
        from .options import Options

        print(Options.describe())
        return 0
    ap.print_help()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
