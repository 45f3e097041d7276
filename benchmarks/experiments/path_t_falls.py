"""How far t falls along the pivotal paths that still reach t = 1 (an experiment; not part of
the suite).  Each solve runs with the minor log (verbosity 3); per path: t after each pivot.
Printed per problem: the deepest fall, t / (largest t so far), among the paths that end at
t = 1, counted where the largest t so far is at least 0.5 (falls below 0.9 listed); and the
paths that end below half their largest t (pivots, largest t, its pivot, last t).

    python benchmarks/experiments/path_t_falls.py pivots   # bench_pivots.py's problems
    python benchmarks/experiments/path_t_falls.py thesis   # thesis families, n = 10 ... 200
    python benchmarks/experiments/path_t_falls.py known    # the suite's known problems
"""
import io, logging, re, sys, json
from pathlib import Path
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / 'benchmarks')); sys.path.insert(0, str(ROOT / 'tests'))
import numpy as np
from compass_sparse import solve_mcp, Options

LINE = re.compile(r"^minor\s+(\d+) t (\S+)")

def paths_of(problem, opts):
    buf = io.StringIO()
    h = logging.StreamHandler(buf); h.setLevel(logging.DEBUG)
    lg = logging.getLogger("compass_sparse"); lg.addHandler(h); old = lg.level; lg.setLevel(logging.DEBUG)
    try:
        r = solve_mcp(problem, options=Options(verbosity=3, **opts))
    finally:
        lg.removeHandler(h); lg.setLevel(old)
    paths = []; cur = None
    for line in buf.getvalue().splitlines():
        m = LINE.match(line)
        if not m: continue
        k, t = int(m.group(1)), float(m.group(2))
        if k == 1 or cur is None:
            cur = []; paths.append(cur)
        cur.append(t)
    return r, paths

def stats(paths, lo=0.5):
    out = []
    for ts in paths:
        ts = np.array(ts)
        run = np.maximum.accumulate(ts)
        imax = int(np.argmax(ts)); tmax = float(ts[imax])
        ok = run >= lo
        fall = float(np.min(ts[ok] / run[ok])) if ok.any() else 1.0
        out.append(dict(piv=len(ts), tmax=tmax, imax=imax + 1, last=float(ts[-1]),
                        reached=bool(ts[-1] >= 1 - 1e-12), fall=fall))
    return out

def cases(which):
    import bench_pivots as bp
    if which == "pivots":
        for name in ["traffic8", "traffic24", "thesis1_n600", "thesis2_n600", "cge_outtax",
                     "cge_productivity", "cge_endowment", "cge_outtax_engine",
                     "cge_productivity_engine", "cge_endowment_engine", "grid4900", "obstacle60"]:
            p, o = bp.CASES[name]()
            yield name, p, o
    elif which == "thesis":
        from compass_sparse.generators import thesis_family
        for fam in (1, 2):
            for n in (10, 20, 50, 100, 200):
                for seed in range(20 if n <= 50 else 8):
                    yield f"thesis{fam}_n{n}_s{seed}", thesis_family(n, fam, seed=seed).problem, {}
    elif which == "known":
        import known_problems as kp
        from compass_sparse import MCP
        makers = dict(kp.ALL_SOLVABLE)
        makers.update(double_root=kp.degenerate_root, billups=kp.billups,
                      log_ncp=lambda: kp.log_ncp(raise_errors=False), sqrt_ncp=kp.sqrt_ncp)
        for name, make in makers.items():
            p = make()
            yield name, MCP(p.F, p.J, p.lb, p.ub, p.x0), {}

if __name__ == "__main__":
    for name, p, o in cases(sys.argv[1]):
        r, paths = paths_of(p, o)
        st = stats(paths)
        recovered = [s for s in st if s["reached"]]
        worst = min([s["fall"] for s in recovered], default=1.0)
        lost = [s for s in st if not s["reached"] and s["tmax"] >= 0.5 and s["last"] < 0.5 * s["tmax"]]
        print(json.dumps(dict(name=name, status=str(r.status), paths=len(st), pivots=sum(s["piv"] for s in st),
                              worst_fall_of_reached=round(worst, 4),
                              reached_falls=[round(s["fall"], 4) for s in recovered if s["fall"] < 0.9],
                              lost=[(s["piv"], round(s["tmax"], 4), s["imax"], round(s["last"], 4)) for s in lost])), flush=True)
