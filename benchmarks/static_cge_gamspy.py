"""The static multi-region CGE model of ``compass_sparse.generators.cge.static`` in GAMSPy.

Written once from the generator's calibrated data (its evaluator's arrays), so that PATH
solves exactly the MCP our solver gets: the same variables in the same order, the same
rows (the module docstring of the generator gives them), the same bounds, numeraire and
start point.  Every index set of the generator (sectors of all regions, factors,
households, trade links, input-output entries, the elements of each CES nest) becomes a
GAMS set of labels ``<tag><k>`` with k the generator's flat index, and every index map a
two-dimensional set, so each row is a sum over the map it uses.

Only general CES nests are written (every elasticity different from 0 and 1: the
generator's defaults 0.8, 2.0 and 0.5); a model with Cobb-Douglas or Leontief nests
raises ``NotImplementedError`` rather than being solved as a different model.

``solve_static_with_path(model)`` returns the point (in the generator's order), PATH's
"Total Time", its counters and exit message; where GAMS cannot run it raises the package's
``GamsLicenseError`` (or ImportError without GAMSPy) before building anything.  bench_small.py
calls it only for a live PATH run (elsewhere PATH's figures come from
``benchmarks/reference/small.csv``).  tests/test_static_cge_gamspy.py checks that
the two formulations agree: PATH's solution of this one zeroes the generator's F and is
the point our solver finds.
"""
from __future__ import annotations

import io
import logging
import time

import numpy as np

__all__ = ["static_container", "solve_static_with_path"]


def _evaluator(model):
    fn = getattr(model._jac_fn, "__wrapped__", model._jac_fn)  # (quiet()'s wrapper)
    ev = getattr(fn, "__self__", None)
    if ev is None or not hasattr(ev, "cva"):
        raise TypeError("not a static CGE model of compass_sparse.generators.cge")
    return ev


def _general_ces(*groups):
    for g in groups:
        if not g.gen_e.all():
            raise NotImplementedError("only general CES nests (elasticity not 0 or 1) are "
                                      "written in GAMSPy")


def static_container(model):
    """(container, gamspy model, {block: variable}, labels per block) of a static CGE model."""
    import gamspy as gp
    import pandas as pd

    ev = _evaluator(model)
    _general_ces(ev.cva, ev.cA, ev.e)
    pol = ev.policy
    R, N, F, H = ev.R, ev.N, ev.F, ev.H
    RN, RF, RH = R * N, R * F, R * H
    m = gp.Container()

    def labels(tag, k):
        return [f"{tag}{i}" for i in range(k)]

    def make_set(name, tag, k):
        return gp.Set(m, name, records=labels(tag, k)), labels(tag, k)

    y, ly = make_set("sec", "y", RN)  # (region, sector) / (region, commodity)
    w, lw = make_set("fac", "w", RF)  # (region, factor)
    h, lh = make_set("hh", "h", RH)  # (region, household)
    r, lr = make_set("reg", "r", R)
    L = ev.l_src.size
    lk, llk = make_set("lk", "l", L)  # trade links
    io_, lio = make_set("io", "z", ev.Z.size)  # input-output entries
    va, lva = make_set("va", "v", ev.va_g.size)  # value-added elements
    ce, lce = make_set("ce", "c", ev.c_g.size)  # household demand elements
    ic, lic = make_set("ic", "i", ev.inc_g.size)  # factor income elements
    # aliases for the sums inside the CES functions, which appear inside sums over y, w, va
    j = gp.Alias(m, "sec1", y)
    y2 = gp.Alias(m, "sec2", y)
    w2 = gp.Alias(m, "fac2", w)
    va2 = gp.Alias(m, "va2", va)

    def pairs(name, dom1, lab1, idx1, dom2, lab2, idx2):
        recs = [(lab1[a], lab2[b]) for a, b in zip(idx1, idx2)]
        return gp.Set(m, name, domain=[dom1, dom2], records=recs)

    def param(name, dom, lab, vals):
        vals = np.broadcast_to(np.asarray(vals, float), (len(lab),))
        return gp.Parameter(m, name, domain=dom,
                            records=pd.DataFrame({"d": lab, "value": vals}))

    ZYI = pairs("ZYI", io_, lio, range(ev.Z.size), y, ly, ev.z_yi)
    ZPA = pairs("ZPA", io_, lio, range(ev.Z.size), y, ly, ev.z_pa)
    VAG = pairs("VAG", va, lva, range(ev.va_g.size), y, ly, ev.va_g)
    VAW = pairs("VAW", va, lva, range(ev.va_g.size), w, lw, ev.va_w)
    LSRC = pairs("LSRC", lk, llk, range(L), y, ly, ev.l_src)
    LDST = pairs("LDST", lk, llk, range(L), y, ly, ev.l_dst)
    LREG = pairs("LREG", lk, llk, range(L), r, lr, ev.l_r)
    CG = pairs("CG", ce, lce, range(ev.c_g.size), h, lh, ev.c_g)
    CPA = pairs("CPA", ce, lce, range(ev.c_g.size), y, ly, ev.c_pa)
    ICG = pairs("ICG", ic, lic, range(ev.inc_g.size), h, lh, ev.inc_g)
    ICW = pairs("ICW", ic, lic, range(ev.inc_g.size), w, lw, ev.inc_w)
    HREG = pairs("HREG", h, lh, range(RH), r, lr, ev.hreg)
    SREG = pairs("SREG", y, ly, range(RN), r, lr, ev.sreg)

    Zv = param("Zv", io_, lio, ev.Z)
    VA = param("VAbar", y, ly, ev.VA)
    Ub = param("Ubar", y, ly, ev.U)  # Armington benchmark value (data, not the variable U)
    Mb = param("Mbar", h, lh, ev.Mbar)
    phX = param("phX", y, ly, pol.phi * ev.X)
    tax = param("tout", y, ly, pol.t)
    tm = param("tm", lk, llk, pol.tm)
    T = param("Tlink", lk, llk, ev.l_T)
    th_va = param("th_va", va, lva, ev.cva.theta)
    th_a = param("th_a", lk, llk, ev.cA.theta)
    th_c = param("th_c", ce, lce, ev.e.theta)
    FV = param("FV", va, lva, ev.va_FV)
    cD = param("cD", ce, lce, ev.c_D)
    s_va = param("s_va", y, ly, ev.s_va)
    s_a = param("s_a", y, ly, ev.s_a)
    s_c = param("s_c", h, lh, ev.s_c)
    endow = param("endow", w, lw, pol.eps * ev.E)
    om = param("om", ic, lic, ev.inc_om)
    tau = param("tau", h, lh, ev.tau)
    bval = param("bval", h, lh, ev.bval * pol.bscale[ev.hreg] if ev.open else np.zeros(RH))

    pos = "positive"
    Y = gp.Variable(m, "Y", domain=y, type=pos)
    A = gp.Variable(m, "A", domain=y, type=pos)
    U = gp.Variable(m, "U", domain=h, type=pos)
    P = gp.Variable(m, "P", domain=y, type=pos)
    PA = gp.Variable(m, "PA", domain=y, type=pos)
    W = gp.Variable(m, "W", domain=w, type=pos)
    PU = gp.Variable(m, "PU", domain=h, type=pos)
    TR = gp.Variable(m, "TR", domain=r, type="free")
    M = gp.Variable(m, "M", domain=h, type="free")
    var = {"Y": Y, "A": A, "U": U, "P": P, "PA": PA, "W": W, "PU": PU, "TR": TR, "M": M}
    lab = {"Y": ly, "A": ly, "U": lh, "P": ly, "PA": ly, "W": lw, "PU": lh, "TR": lr, "M": lh}

    # the CES unit functions, as expressions of the variables (one map per nest)
    def cva(jj):  # value-added cost per unit, sector jj
        return gp.Sum(va2.where[VAG[va2, jj]],
                      th_va[va2] * gp.Sum(w2.where[VAW[va2, w2]], W[w2]) ** (1 - s_va[jj])
                      ) ** (1 / (1 - s_va[jj]))

    def q(ll):  # tariff-inclusive price of the good shipped on link ll
        return gp.Sum(y2.where[LSRC[ll, y2]], P[y2]) * (1 + tm[ll])

    def cA(jj):  # Armington unit cost
        return gp.Sum(lk.where[LDST[lk, jj]], th_a[lk] * q(lk) ** (1 - s_a[jj])
                      ) ** (1 / (1 - s_a[jj]))

    def e(hh):  # unit expenditure of household hh
        return gp.Sum(ce.where[CG[ce, hh]],
                      th_c[ce] * gp.Sum(y2.where[CPA[ce, y2]], PA[y2]) ** (1 - s_c[hh])
                      ) ** (1 / (1 - s_c[hh]))

    def dem(ll):  # Armington demand for the good on link ll
        return gp.Sum(j.where[LDST[ll, j]], A[j] * T[ll] * (PA[j] / q(ll)) ** s_a[j])

    zero = gp.Number(0)
    prf_Y = gp.Equation(m, "prf_Y", domain=y)
    prf_Y[y] = (gp.Sum(io_.where[ZYI[io_, y]], Zv[io_] * gp.Sum(j.where[ZPA[io_, j]], PA[j]))
                + VA[y] * cva(y) - (1 - tax[y]) * phX[y] * P[y]) >= zero
    prf_A = gp.Equation(m, "prf_A", domain=y)
    prf_A[y] = Ub[y] * (cA(y) - PA[y]) >= zero
    prf_U = gp.Equation(m, "prf_U", domain=h)
    prf_U[h] = Mb[h] * (e(h) - PU[h]) >= zero
    mkt_P = gp.Equation(m, "mkt_P", domain=y)
    mkt_P[y] = phX[y] * Y[y] - gp.Sum(lk.where[LSRC[lk, y]], dem(lk)) >= zero
    mkt_PA = gp.Equation(m, "mkt_PA", domain=y)
    mkt_PA[y] = (Ub[y] * A[y]
                 - gp.Sum(io_.where[ZPA[io_, y]], Zv[io_] * gp.Sum(j.where[ZYI[io_, j]], Y[j]))
                 - gp.Sum(ce.where[CPA[ce, y]],
                          cD[ce] * gp.Sum(h.where[CG[ce, h]],
                                          U[h] * (PU[h] / PA[y]) ** s_c[h]))) >= zero
    mkt_W = gp.Equation(m, "mkt_W", domain=w)
    mkt_W[w] = (endow[w] - gp.Sum(va.where[VAW[va, w]],
                                  FV[va] * gp.Sum(j.where[VAG[va, j]],
                                                  Y[j] * (cva(j) / W[w]) ** s_va[j]))) >= zero
    mkt_PU = gp.Equation(m, "mkt_PU", domain=h)
    mkt_PU[h] = Mb[h] * U[h] - M[h] / PU[h] >= zero
    bal_TR = gp.Equation(m, "bal_TR", domain=r)
    foreign = np.zeros(L, bool)
    foreign[ev.foreign] = True
    FOR = gp.Set(m, "forlink", domain=lk, records=[llk[k] for k in np.flatnonzero(foreign)])
    bal_TR[r] = (TR[r] - gp.Sum(y.where[SREG[y, r]], tax[y] * phX[y] * P[y] * Y[y])
                 - gp.Sum(lk.where[FOR[lk] & LREG[lk, r]],
                          tm[lk] * gp.Sum(j.where[LSRC[lk, j]], P[j]) * dem(lk))) == zero
    num = gp.Parameter(m, "num", domain=y,
                       records=pd.DataFrame({"d": [ly[ev.num_good]], "value": [1.0]}))
    inc_M = gp.Equation(m, "inc_M", domain=h)
    inc_M[h] = (M[h] - gp.Sum(ic.where[ICG[ic, h]],
                              om[ic] * gp.Sum(w.where[ICW[ic, w]], endow[w] * W[w]))
                - tau[h] * gp.Sum(r.where[HREG[h, r]], TR[r])
                - bval[h] * gp.Sum(y, num[y] * P[y])) == zero

    # bounds and start point, block by block in the generator's order
    prob = model.problem
    for b, v in var.items():
        sl = ev.blocks[b]
        lo, up, x0 = prob.lb[sl], prob.ub[sl], prob.x0[sl]
        d = lab[b]
        if np.any(np.isfinite(lo)) and np.any(lo != 0):
            _set_attr(m, v, "lo", d, lo, f"lo_{b}")
        if np.any(np.isfinite(up)):
            _set_attr(m, v, "up", d, up, f"up_{b}")
        _set_attr(m, v, "l", d, x0, f"x0_{b}")
    gm = gp.Model(m, "static_cge", problem="MCP", matches={
        prf_Y: Y, prf_A: A, prf_U: U, mkt_P: P, mkt_PA: PA, mkt_W: W, mkt_PU: PU,
        bal_TR: TR, inc_M: M})
    return m, gm, var, lab


def _set_attr(m, v, attr, labels, vals, pname):
    """v.attr[d] = vals over the labels (infinite values as GAMS' +-inf)."""
    import gamspy as gp
    import pandas as pd

    vals = np.where(np.isposinf(vals), gp.SpecialValues.POSINF,
                    np.where(np.isneginf(vals), gp.SpecialValues.NEGINF, vals))
    dom = v.domain[0]
    p = gp.Parameter(m, pname, domain=dom, records=pd.DataFrame({"d": labels, "value": vals}))
    getattr(v, attr)[dom] = p[dom]


def solve_static_with_path(model, tol=1e-6, options=None):
    """Solve a static CGE model with PATH through GAMSPy from the model's start point.
    Returns dict(x, time (PATH's Total Time), wall, status, major, minor, log)."""
    from compass_sparse.interfaces.gams_state import gams_refusals, require_gams
    from compass_sparse.interfaces.path_gamspy import parse_path_log

    ev = _evaluator(model)
    _general_ces(ev.cva, ev.cA, ev.e)  # (a model this cannot write: said before GAMS' state)
    require_gams("solve the static CGE model with PATH")
    with gams_refusals("solve the static CGE model with PATH"):
        m, gm, var, lab = static_container(model)
    buf = io.StringIO()
    lg = logging.getLogger("MODEL")
    old = lg.level
    lg.setLevel(logging.ERROR)
    opts = {"convergence_tolerance": tol}
    opts.update(options or {})
    t0 = time.perf_counter()
    try:
        with gams_refusals("solve the static CGE model with PATH", log=buf.getvalue):
            gm.solve(solver="PATH", solver_options=opts, output=buf)
    finally:
        lg.setLevel(old)
    wall = time.perf_counter() - t0
    log = buf.getvalue()
    info = parse_path_log(log)
    x = np.zeros(model.n)
    for b, v in var.items():
        sl = ev.blocks[b]
        rec = v.records
        if rec is None:
            continue
        idx = rec.iloc[:, 0].astype(str).str[1:].astype(int).to_numpy()
        x[sl.start + idx] = rec["level"].to_numpy(float)
    return dict(x=x, time=info.get("path_time"), wall=wall,
                status=str(info.get("exit_message") or gm.solve_status),
                major=info.get("major_iterations"), minor=info.get("minor_iterations"),
                size=info.get("path_size"), log=log)
