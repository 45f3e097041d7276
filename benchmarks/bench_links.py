"""Modelling-language links: build, evaluation and solve times of the Pyomo and GAMSPy routes.

Parts (``--parts``):

* ``evaluator`` — the choice of the Pyomo evaluator at n ~ 1e4: F and J of the same Pyomo
  model compiled by (a) CasADi (the link's evaluator), (b) Pyomo's own reverse-mode
  symbolic differentiation printed to Python source and compiled (one statement per entry),
  against (c) hand-written vectorized numpy F and J.
* ``pyomo`` — for the Cournot and spatial-price models at n ~ 1e2, 1e3, 1e4: Pyomo model
  build time, compilation time, F and J evaluation times and their ratio to hand-written
  numpy, and solve times of the Pyomo route and of the numpy callables (same solver).
* ``gamspy`` — the same for the GAMSPy route (GMO evaluation) within the free licence
  (n <= 1000), with PATH on the identical GAMSPy model side by side.  Where GAMS cannot
  run (or with ``--path recorded``) PATH's column is the recorded one of
  ``benchmarks/reference/links.csv``, marked as such (the first lines of the output say
  which source is used); our GAMSPy route needs GAMS as well, so without GAMS its columns
  are "–".

Times are medians over ``--repeats`` runs (evaluations: over 30 calls).  Only the public
API is used.  Usage::

    python benchmarks/bench_links.py                     # every part
    python benchmarks/bench_links.py --parts evaluator --repeats 3
    python benchmarks/bench_links.py --parts gamspy --path recorded
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from compass_sparse import solve_mcp
from compass_sparse.examples import cournot, spatial

from _common import RECORDED_NOTE, add_path_argument, choose_path_source  # noqa: E402

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

SIZES = {  # n -> model data arguments (n = 5 * markets; n ~ nodes + 2.5 nodes)
    "cournot": {100: (20,), 1000: (200,), 10000: (2000,)},
    "spatial": {100: (29,), 1000: (286,), 10000: (2858,)},
}
GAMS_SIZES = {"cournot": {100: (20,), 1000: (199,)}, "spatial": {100: (29,), 1000: (285,)}}
MODULES = {"cournot": cournot, "spatial": spatial}
TOL = 1e-8


def med(fn, k):
    ts = []
    for _ in range(k):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def case(mod, args):
    """Model data, the hand-written callables and an evaluation point off the start."""
    d = mod.data(*args)
    kw = mod.callables(d)
    return d, kw, kw["x0"] + np.random.default_rng(0).random(kw["x0"].size)


def natural(x, f, lb, ub):
    return float(np.max(np.abs(x - np.clip(x - f, lb, ub))))


def revision():
    try:
        return subprocess.check_output(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                                       text=True).strip()
    except Exception:
        return "unknown"


# --------------------------------------------------------------------------- #
# (b) Pyomo symbolic differentiation compiled to Python source
# --------------------------------------------------------------------------- #
class PyomoSymbolicEvaluator:
    """F and J from pyomo.core.expr.calculus (reverse symbolic mode), printed as one Python
    statement per F row and per J entry and compiled once; mutable parameters are read
    from an array p.  A measurement baseline, not a product."""

    def __init__(self, pm):
        import math as _m

        from pyomo.core.expr.calculus.derivatives import Modes, differentiate
        from pyomo.core.expr.symbol_map import SymbolMap
        from pyomo.core.expr.visitor import identify_variables

        smap = SymbolMap()
        for j, p in enumerate(pm.pairs):
            smap.addSymbol(p.var, f"x[{j}]")
        for k, d in enumerate(pm._data):
            smap.addSymbol(d, f"p[{k}]")
        n = pm.n
        col = {id(p.var): j for j, p in enumerate(pm.pairs)}
        flines, jlines, rows, cols = [], [], [], []
        for i, p in enumerate(pm.pairs):
            e = p.row
            flines.append(f"    f[{i}] = {e.to_string(smap=smap)}")
            vs = [v for v in identify_variables(e, include_fixed=False)]
            ders = differentiate(e, wrt_list=vs, mode=Modes.reverse_symbolic)
            for v, de in zip(vs, ders):
                txt = de.to_string(smap=smap) if hasattr(de, "to_string") else repr(float(de))
                jlines.append(f"    v[{len(rows)}] = {txt}")
                rows.append(i)
                cols.append(col[id(v)])
        ns = {k: getattr(_m, k) for k in ("exp", "log", "sqrt", "sin", "cos", "tan")}
        src_f = "def F(x, p, f):\n" + "\n".join(flines) + "\n    return f\n"
        src_j = "def J(x, p, v):\n" + "\n".join(jlines) + "\n    return v\n"
        exec(compile(src_f, "<pyomo-F>", "exec"), ns)
        exec(compile(src_j, "<pyomo-J>", "exec"), ns)
        self._F, self._J = ns["F"], ns["J"]
        self.n = n
        self.p = pm.parameter_values()
        C = sp.csc_matrix((np.arange(1, len(rows) + 1, dtype=float), (rows, cols)), shape=(n, n))
        self._perm = C.data.astype(np.int64) - 1
        self._indices, self._indptr = C.indices, C.indptr
        self._nnz = len(rows)

    def F(self, x):
        return self._F(x.tolist(), self.p.tolist(), np.empty(self.n))

    def J(self, x):
        v = self._J(x.tolist(), self.p.tolist(), np.empty(self._nnz))
        return sp.csc_matrix((v[self._perm], self._indices, self._indptr), shape=(self.n, self.n))


# --------------------------------------------------------------------------- #
def part_evaluator(reps):
    import compass_sparse.interfaces.pyomo as cpy

    print("\n## Evaluator choice (n ~ 1e4): median seconds per call, ratio to numpy\n")
    print("| model | n | nnz(J) | evaluator | build [s] | F [ms] | J [ms] | F ratio | J ratio |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("cournot", "spatial"):
        mod = MODULES[name]
        d = mod.data(*SIZES[name][10000])
        kw = mod.callables(d)
        rng = np.random.default_rng(0)
        x = kw["x0"] + rng.random(kw["x0"].size)
        m = mod.pyomo_model(d)
        t = time.perf_counter()
        pm = cpy.PyomoMCP(m, cse=False)
        t_cas = time.perf_counter() - t
        pm.mcp()  # loads the parameter values
        t = time.perf_counter()
        pm_cse = cpy.PyomoMCP(m, cse=True)
        t_cse = time.perf_counter() - t
        pm_cse.mcp()
        t = time.perf_counter()
        sym = PyomoSymbolicEvaluator(pm)
        t_sym = time.perf_counter() - t
        fe = pm.evaluator
        assert np.allclose(sym.F(x), fe.F(x)) and abs(sym.J(x) - fe.J(x)).max() < 1e-8
        hf = med(lambda: kw["F"](x), 30)
        hj = med(lambda: kw["jac"](x), 30)
        nnz = fe.pattern.nnz
        print(f"| {name} | {pm.n} | {nnz} | numpy (hand-written) | - | {hf*1e3:.3f} | "
              f"{hj*1e3:.3f} | 1 | 1 |")
        for label, ev, tb in (("CasADi templates, no CSE", fe, t_cas),
                              ("CasADi templates + CSE", pm_cse.evaluator, t_cse),
                              ("Pyomo reverse_sd -> Python", sym, t_sym)):
            k = max(3, reps) if ev is sym else 30
            ef = med(lambda: ev.F(x), k)  # noqa: B023 - evaluated inside the iteration
            ej = med(lambda: ev.J(x), k)  # noqa: B023
            print(f"| {name} | {pm.n} | {nnz} | {label} | {tb:.2f} | {ef*1e3:.3f} | "
                  f"{ej*1e3:.3f} | {ef/hf:.1f} | {ej/hj:.1f} |")


def part_pyomo(reps):
    import pyomo.environ as pe

    import compass_sparse.interfaces.pyomo as cpy

    print("\n## Pyomo route: build, evaluation and solve times (medians)\n")
    print("| model | n | Pyomo build [s] | compile [s] | F [ms] (x numpy) | J [ms] (x numpy) | "
          "solve Pyomo route [s] | solve callables [s] | natural residual |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, sizes in SIZES.items():
        mod = MODULES[name]
        for n_target, args in sizes.items():
            d, kw, x = case(mod, args)
            k = reps if n_target < 10000 else max(1, reps // 2)
            tb = med(lambda: mod.pyomo_model(d), k)
            m = mod.pyomo_model(d)
            tc = med(lambda: cpy.compiled(m, recompile=True), k)  # noqa: B023
            pm = cpy.compiled(m)
            pm.mcp()
            fe = pm.evaluator
            ef, ej = med(lambda: fe.F(x), 30), med(lambda: fe.J(x), 30)
            hf, hj = med(lambda: kw["F"](x), 30), med(lambda: kw["jac"](x), 30)
            opt = pe.SolverFactory("compass_sparse")

            start = [(v, v.value) for v in m.component_data_objects(pe.Var)]

            def run_pyomo():  # from the model's initial point every time (no warm start)
                for v, val in start:  # noqa: B023
                    v.set_value(val)
                return opt.solve(m, options={"convergence_tolerance": TOL})  # noqa: B023

            ts = med(run_pyomo, k)
            xs = mod.pyomo_solution(m)
            nat = natural(xs, kw["F"](xs), kw["lb"], kw["ub"])
            th = med(lambda: solve_mcp(**kw, options={"convergence_tolerance": TOL}), k)
            print(f"| {name} | {pm.n} | {tb:.2f} | {tc:.2f} | {ef*1e3:.3f} ({ef/hf:.1f}) | "
                  f"{ej*1e3:.3f} ({ej/hj:.1f}) | {ts:.3f} | {th:.3f} | {nat:.1e} |")


def part_gamspy(reps, source):
    from compass_sparse.interfaces.gams_state import gams_state

    recorded = source.recorded
    gams_runs = gams_state().runs  # our GAMSPy route needs GAMS too
    if gams_runs:
        from compass_sparse.interfaces.gamspy import GamsMCP, solve_gamspy
    mark = " (recorded)" if recorded else ""
    print("\n## GAMSPy route (free licence: n <= 1000), PATH on the same model\n")
    if not gams_runs:
        print(f"Our GAMSPy route is not run: GAMS cannot run ({gams_state().reason}); "
              "its columns are '–'.\n")
    print("| model | n | GAMSPy build [s] | GMO generation [s] | F [ms] (x numpy) | "
          f"J [ms] (x numpy) | solve ours [s] (in solve_mcp) | solve PATH [s]{mark} | "
          "max level diff |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, sizes in GAMS_SIZES.items():
        mod = MODULES[name]
        for n_target, args in sizes.items():
            ref = None
            if recorded:
                ref = source.lookup(model=name, n_target=n_target)
                if ref is not None and ref["size_arg"] != args[0]:
                    ref = None  # recorded at another size: not this model
            if not gams_runs:
                path = f"{ref['solve_wall']:.2f}" if ref else "– (not in the reference)"
                n = ref["n"] if ref else f"~{n_target}"
                print(f"| {name} | {n} | – | – | – | – | – | {path} | – |")
                continue
            d, kw, x = case(mod, args)
            tb = med(lambda: mod.gamspy_model(d), reps)
            ct, model, sym = mod.gamspy_model(d)
            t = time.perf_counter()
            gm = GamsMCP(ct, model)
            tg = time.perf_counter() - t
            # evaluation in GAMS' column order (a permutation of the same point)
            xo = gm.x0 + np.random.default_rng(0).random(gm.n)
            ef, ej = med(lambda: gm.F(xo), 30), med(lambda: gm.J(xo), 30)
            gm.close()
            hf, hj = med(lambda: kw["F"](x), 30), med(lambda: kw["jac"](x), 30)
            ours, inner, path = [], [], []
            diff = None
            for _ in range(reps):
                ct, model, sym = mod.gamspy_model(d)
                t = time.perf_counter()
                res = solve_gamspy(ct, model, {"convergence_tolerance": TOL})
                ours.append(time.perf_counter() - t)
                inner.append(res.time)
                if recorded:
                    continue
                xa = mod.gamspy_solution(sym, d)
                ct2, model2, sym2 = mod.gamspy_model(d)
                t = time.perf_counter()
                model2.solve(solver="path", solver_options={"convergence_tolerance": TOL})
                path.append(time.perf_counter() - t)
                xb = mod.gamspy_solution(sym2, d)
                diff = float(np.max(np.abs(xa - xb)))
            if recorded:
                path_text = f"{ref['solve_wall']:.2f}" if ref else "– (not in the reference)"
            else:
                path_text = f"{statistics.median(path):.2f}"
            print(f"| {name} | {gm.n} | {tb:.2f} | {tg:.2f} | {ef*1e3:.2f} ({ef/hf:.0f}) | "
                  f"{ej*1e3:.2f} ({ej/hj:.0f}) | {statistics.median(ours):.2f} "
                  f"({statistics.median(inner):.2f}) | {path_text} | "
                  f"{'–' if diff is None else f'{diff:.1e}'} |")
    if recorded:
        print("\n" + RECORDED_NOTE + " Here PATH's time is the wall time of GAMSPy's "
              "model.solve (GAMS process included), as recorded (0.01 s).")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", nargs="+", default=["evaluator", "pyomo", "gamspy"],
                    choices=["evaluator", "pyomo", "gamspy"])
    ap.add_argument("--repeats", type=int, default=3)
    add_path_argument(ap)
    a = ap.parse_args(argv)
    import platform

    print(f"# bench_links: revision {revision()}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"python {platform.python_version()}, numpy {np.__version__}")
    source = None
    if "gamspy" in a.parts:
        source = choose_path_source("links", a.path_mode)
        print(source.line(), flush=True)
    for part in a.parts:
        if part == "gamspy":
            part_gamspy(a.repeats, source)
        else:
            {"evaluator": part_evaluator, "pyomo": part_pyomo}[part](a.repeats)


if __name__ == "__main__":
    main()
