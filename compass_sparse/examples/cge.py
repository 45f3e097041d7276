"""A small calibrated CGE model in MPSGE-like algebraic form (Mathiesen's formulation).

A closed economy with S sectors, two primary factors (labour L, capital K) and one
representative household.  Sector s produces with Cobb–Douglas technology and pays an ad
valorem output tax t_s; the household's utility (welfare W) is Cobb–Douglas in the S goods.
Calibration: benchmark factor payments L0_s, K0_s (a social accounting matrix without
taxes) with every price and activity level 1, so Y0_s = L0_s + K0_s, the value shares
alpha_s = L0_s / Y0_s, theta_s = Y0_s / W0 and W0 = sum_s Y0_s.  The counterfactual
raises the labour endowment by ``lscale`` and taxes sector 0's output at ``tax``.

Unit cost c_s = PL^alpha_s PK^(1 - alpha_s), unit expenditure e = prod_s P_s^theta_s.
MPSGE's three classes of conditions, each with its complementary variable:

    zero profit      Y_s  >= 0  _|_  c_s - (1 - t_s) P_s                        >= 0
                     W    >= 0  _|_  e - PW                                     >= 0
    market clearing  P_s  >= 0  _|_  Y0_s Y_s - W0 W theta_s e / P_s              >= 0
                     PW   >= 0  _|_  W0 W - CONS / PW                           >= 0
                     PL   >= 0  _|_  lscale L_tot - sum_s Y0_s Y_s alpha_s c_s / PL     >= 0
                     PK   >= 0  _|_  K_tot - sum_s Y0_s Y_s (1 - alpha_s) c_s / PK     >= 0
    income balance   CONS free  :    CONS - PL lscale L_tot - PK K_tot - sum_s t_s P_s Y0_s Y_s = 0

PW = 1 is the numeraire (a fixed variable: its market-clearing row is dropped, as
Walras' law makes it redundant).  n = 2 S + 5 (with PW).  Variables are ordered
Y, W, P, PW, PL, PK, CONS in every route.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..interfaces.gams_state import require_gams


def data(sectors: int = 3, seed: int = 0, lscale: float = 1.1, tax: float = 0.2) -> dict:
    rng = np.random.default_rng(seed)
    L0 = 1.0 + 2.0 * rng.random(sectors)
    K0 = 1.0 + 2.0 * rng.random(sectors)
    t = np.zeros(sectors)
    t[0] = tax
    return {"S": sectors, "L0": L0, "K0": K0, "lscale": lscale, "t": t}


def _calibrate(d):
    Y0 = d["L0"] + d["K0"]
    W0 = Y0.sum()
    return Y0, W0, d["L0"] / Y0, Y0 / W0, d["L0"].sum(), d["K0"].sum()


def names(d) -> list[str]:
    S = d["S"]
    return ([f"Y[{s}]" for s in range(S)] + ["W"] + [f"P[{s}]" for s in range(S)]
            + ["PW", "PL", "PK", "CONS"])


# --------------------------------------------------------------------------- #
def callables(d) -> dict:
    """F in numpy; J by sparse forward differences on the (dense, small) pattern."""
    S = d["S"]
    Y0, W0, al, th, Lt, Kt = _calibrate(d)
    t, ls = d["t"], d["lscale"]
    n = 2 * S + 5

    def F(z):
        Y, W, P = z[:S], z[S], z[S + 1:2 * S + 1]
        PW, PL, PK, CONS = z[2 * S + 1:]
        c = PL ** al * PK ** (1 - al)
        e = np.prod(P ** th)
        return np.concatenate([
            c - (1 - t) * P,
            [e - PW],
            Y0 * Y - W0 * W * th * e / P,
            [W0 * W - CONS / PW,
             ls * Lt - np.sum(Y0 * Y * al * c) / PL,
             Kt - np.sum(Y0 * Y * (1 - al) * c) / PK,
             CONS - PL * ls * Lt - PK * Kt - np.sum(t * P * Y0 * Y)],
        ])

    lb = np.zeros(n)
    ub = np.full(n, np.inf)
    lb[2 * S + 1] = ub[2 * S + 1] = 1.0  # numeraire PW
    lb[-1] = -np.inf  # CONS free
    x0 = np.ones(n)
    x0[-1] = W0
    return {"F": F, "jac": None, "jac_sparsity": sp.csc_matrix(np.ones((n, n))),
            "lb": lb, "ub": ub, "x0": x0, "var_names": names(d)}


# --------------------------------------------------------------------------- #
def pyomo_model(d):
    # (Pyomo: an optional extra)
    import pyomo.environ as pe
    from pyomo.mpec import Complementarity, complements

    S = d["S"]
    Y0, W0, al, th, Lt, Kt = _calibrate(d)
    m = pe.ConcreteModel(name="cge")
    m.S = pe.RangeSet(0, S - 1)
    m.Y0 = pe.Param(m.S, initialize=lambda m, s: float(Y0[s]))
    m.alpha = pe.Param(m.S, initialize=lambda m, s: float(al[s]))
    m.theta = pe.Param(m.S, initialize=lambda m, s: float(th[s]))
    m.tax = pe.Param(m.S, mutable=True, initialize=lambda m, s: float(d["t"][s]))
    m.lscale = pe.Param(mutable=True, initialize=d["lscale"])
    m.Y = pe.Var(m.S, within=pe.NonNegativeReals, initialize=1.0)
    m.W = pe.Var(within=pe.NonNegativeReals, initialize=1.0)
    m.P = pe.Var(m.S, within=pe.NonNegativeReals, initialize=1.0)
    m.PW = pe.Var(within=pe.NonNegativeReals, initialize=1.0)
    m.PL = pe.Var(within=pe.NonNegativeReals, initialize=1.0)
    m.PK = pe.Var(within=pe.NonNegativeReals, initialize=1.0)
    m.CONS = pe.Var(initialize=W0)
    m.PW.fix(1.0)  # numeraire
    m.c = pe.Expression(m.S, rule=lambda m, s: m.PL ** m.alpha[s] * m.PK ** (1 - m.alpha[s]))
    m.e = pe.Expression(expr=pe.prod(m.P[s] ** m.theta[s] for s in m.S))
    m.prf_Y = Complementarity(m.S, rule=lambda m, s: complements(
        m.Y[s] >= 0, m.c[s] - (1 - m.tax[s]) * m.P[s] >= 0))
    m.prf_W = Complementarity(expr=complements(m.W >= 0, m.e - m.PW >= 0))
    m.mkt_P = Complementarity(m.S, rule=lambda m, s: complements(
        m.P[s] >= 0, m.Y0[s] * m.Y[s] - W0 * m.W * m.theta[s] * m.e / m.P[s] >= 0))
    m.mkt_PW = Complementarity(expr=complements(m.PW >= 0, W0 * m.W - m.CONS / m.PW >= 0))
    m.mkt_PL = Complementarity(expr=complements(
        m.PL >= 0,
        m.lscale * Lt - sum(m.Y0[s] * m.Y[s] * m.alpha[s] * m.c[s] for s in m.S) / m.PL >= 0))
    m.mkt_PK = Complementarity(expr=complements(
        m.PK >= 0,
        Kt - sum(m.Y0[s] * m.Y[s] * (1 - m.alpha[s]) * m.c[s] for s in m.S) / m.PK >= 0))
    m.income = pe.Constraint(expr=m.CONS == m.PL * m.lscale * Lt + m.PK * Kt
                             + sum(m.tax[s] * m.P[s] * m.Y0[s] * m.Y[s] for s in m.S))
    return m


def pyomo_solution(m) -> np.ndarray:
    # (Pyomo: an optional extra)
    import pyomo.environ as pe

    vals = ([m.Y[s] for s in m.S] + [m.W] + [m.P[s] for s in m.S]
            + [m.PW, m.PL, m.PK, m.CONS])
    return np.array([pe.value(v) for v in vals])


# --------------------------------------------------------------------------- #
def gamspy_model(d):
    require_gams("build the GAMSPy model")
    # (GAMSPy: an optional extra)
    import gamspy as gp

    S = d["S"]
    Y0v, W0v, al, th, Lt, Kt = _calibrate(d)
    ct = gp.Container()
    s = gp.Set(ct, "s", records=[str(k) for k in range(S)])

    def par(name, arr):
        return gp.Parameter(ct, name, domain=s,
                            records=[(str(k), float(v)) for k, v in enumerate(arr)])

    Y0, alpha, theta, tax = par("Y0", Y0v), par("alpha", al), par("theta", th), par("tax", d["t"])
    W0 = gp.Parameter(ct, "W0", records=W0v)
    Ltot = gp.Parameter(ct, "Ltot", records=Lt * d["lscale"])
    Ktot = gp.Parameter(ct, "Ktot", records=Kt)
    Y = gp.Variable(ct, "Y", domain=s, type="positive")
    P = gp.Variable(ct, "P", domain=s, type="positive")
    W = gp.Variable(ct, "W", type="positive")
    PW = gp.Variable(ct, "PW", type="positive")
    PL = gp.Variable(ct, "PL", type="positive")
    PK = gp.Variable(ct, "PK", type="positive")
    CONS = gp.Variable(ct, "CONS", type="free")
    Y.l[s] = 1.0
    P.l[s] = 1.0
    for v in (W, PL, PK):
        v.l[...] = 1.0
    PW.fx[...] = 1.0  # numeraire
    CONS.l[...] = W0v
    sa = gp.Alias(ct, "sa", s)
    c = PL ** alpha[s] * PK ** (1 - alpha[s])
    e = gp.Product(sa, P[sa] ** theta[sa])
    prf_Y = gp.Equation(ct, "prf_Y", domain=s)
    prf_W = gp.Equation(ct, "prf_W")
    mkt_P = gp.Equation(ct, "mkt_P", domain=s)
    mkt_PW = gp.Equation(ct, "mkt_PW")
    mkt_PL = gp.Equation(ct, "mkt_PL")
    mkt_PK = gp.Equation(ct, "mkt_PK")
    income = gp.Equation(ct, "income")
    prf_Y[s] = c - (1 - tax[s]) * P[s] >= gp.Number(0)
    prf_W[...] = e - PW >= gp.Number(0)
    mkt_P[s] = Y0[s] * Y[s] - W0 * W * theta[s] * e / P[s] >= gp.Number(0)
    mkt_PW[...] = W0 * W - CONS / PW >= gp.Number(0)
    mkt_PL[...] = Ltot - gp.Sum(s, Y0[s] * Y[s] * alpha[s] * c) / PL >= gp.Number(0)
    mkt_PK[...] = Ktot - gp.Sum(s, Y0[s] * Y[s] * (1 - alpha[s]) * c) / PK >= gp.Number(0)
    income[...] = (CONS - PL * Ltot - PK * Ktot - gp.Sum(s, tax[s] * P[s] * Y0[s] * Y[s])
                   == gp.Number(0))
    model = gp.Model(ct, "cge", problem="MCP",
                     matches={prf_Y: Y, prf_W: W, mkt_P: P, mkt_PW: PW, mkt_PL: PL,
                              mkt_PK: PK, income: CONS})
    return ct, model, {"Y": Y, "W": W, "P": P, "PW": PW, "PL": PL, "PK": PK, "CONS": CONS,
                       "prf_Y": prf_Y, "mkt_P": mkt_P, "income": income}


def gamspy_solution(sym, d) -> np.ndarray:
    def lev(name):
        return sym[name].records["level"].to_numpy(dtype=float)

    return np.concatenate([lev("Y"), lev("W"), lev("P"), lev("PW"), lev("PL"), lev("PK"),
                           lev("CONS")])
