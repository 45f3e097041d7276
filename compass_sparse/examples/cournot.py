"""Nash–Cournot oligopoly (Murphy, Sherali and Soyster's five-firm market, replicated).

In each of ``markets`` independent markets, five firms choose outputs q_f >= 0.  Firm f's
cost is  C_f(q) = c_f q + beta_f/(beta_f + 1) L_f^(-1/beta_f) q^((beta_f + 1)/beta_f),  and
the inverse demand is  p(Q) = D^(1/gamma) Q^(-1/gamma)  with Q the market's total output.
The Nash equilibrium is the NCP

    q_f >= 0   _|_   F_f(q) = C_f'(q_f) - p(Q) - q_f p'(Q)
                            = c_f + (q_f/L_f)^(1/beta_f) - p(Q) (1 - q_f/(gamma Q))  >= 0.

With D = 5000, gamma = 1.1 and the firms' data below, the classic equilibrium is
q = (36.93, 41.82, 43.71, 42.66, 39.18).  Markets m > 0 perturb c and D (``seed``); the
demand scale ``D`` is a mutable parameter in the Pyomo model (scenario loops).

n = 5 * markets.  The model is written three times: Pyomo (:func:`pyomo_model`), GAMSPy
(:func:`gamspy_model`) and numpy callables with a hand-written sparse Jacobian
(:func:`callables`).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..interfaces.gams_state import require_gams

C = np.array([10.0, 8.0, 6.0, 4.0, 2.0])
L = np.array([5.0, 5.0, 5.0, 5.0, 5.0])
BETA = np.array([1.2, 1.1, 1.0, 0.9, 0.8])
GAMMA = 1.1
DEMAND = 5000.0
FIRMS = 5
#: the five-firm equilibrium (Murphy, Sherali and Soyster 1982), to 4 digits
CLASSIC_SOLUTION = np.array([36.9318, 41.8175, 43.7060, 42.6588, 39.1786])


def data(markets: int = 1, seed: int = 0) -> dict:
    """Firm and market data; market 0 is the classic one."""
    rng = np.random.default_rng(seed)
    c = np.tile(C, (markets, 1))
    d = np.full(markets, DEMAND)
    if markets > 1:
        c[1:] *= 1.0 + 0.2 * rng.random((markets - 1, FIRMS))
        d[1:] *= 0.8 + 0.4 * rng.random(markets - 1)
    return {"markets": markets, "c": c, "L": np.tile(L, (markets, 1)),
            "beta": np.tile(BETA, (markets, 1)), "gamma": GAMMA, "D": d, "q0": 10.0}


def names(d) -> list[str]:
    return [f"q[{m},{f}]" for m in range(d["markets"]) for f in range(FIRMS)]


# --------------------------------------------------------------------------- #
def callables(d) -> dict:
    """F and its sparse Jacobian in numpy (vectorized over markets), for solve_mcp."""
    M = d["markets"]
    c, Lf, b, g, D = d["c"], d["L"], d["beta"], d["gamma"], d["D"][:, None]
    n = M * FIRMS
    # pattern: dense 5 x 5 block per market
    blk = np.arange(n).reshape(M, FIRMS)
    rows = np.repeat(blk, FIRMS, axis=1).ravel()
    cols = np.tile(blk, (1, FIRMS)).ravel()
    # CSC order of the entries: sort by (col, row)
    order = np.lexsort((rows, cols))
    pattern = sp.csc_matrix((np.ones(n * FIRMS), (rows, cols)), shape=(n, n))
    indices, indptr = pattern.indices, pattern.indptr

    def parts(x):
        q = x.reshape(M, FIRMS)
        Q = q.sum(axis=1, keepdims=True)
        p = D ** (1.0 / g) * Q ** (-1.0 / g)
        return q, Q, p

    def F(x):
        q, Q, p = parts(x)
        return (c + (q / Lf) ** (1.0 / b) - p * (1.0 - q / (g * Q))).ravel()

    def J(x):
        q, Q, p = parts(x)
        a = (1.0 / b) * (q / Lf) ** (1.0 / b - 1.0) / Lf + p / (g * Q)
        # off-diagonal part, the same for every column j of row i
        common = p / (g * Q) * (1.0 - q / (g * Q)) - p * q / (g * Q * Q)
        vals = np.repeat(common, FIRMS, axis=1).reshape(M, FIRMS, FIRMS)  # [m, i, j]
        idx = np.arange(FIRMS)
        vals[:, idx, idx] += a
        return sp.csc_matrix((vals.ravel()[order], indices, indptr), shape=(n, n))

    return {"F": F, "jac": J, "lb": np.zeros(n), "ub": np.full(n, np.inf),
            "x0": np.full(n, d["q0"]), "var_names": names(d)}


# --------------------------------------------------------------------------- #
def pyomo_model(d):
    """The Pyomo ConcreteModel with one Complementarity per firm."""
    # (Pyomo: an optional extra)
    import pyomo.environ as pe
    from pyomo.mpec import Complementarity, complements

    M = d["markets"]
    m = pe.ConcreteModel(name="cournot")
    m.M = pe.RangeSet(0, M - 1)
    m.F = pe.RangeSet(0, FIRMS - 1)
    m.c = pe.Param(m.M, m.F, initialize=lambda m, i, f: float(d["c"][i, f]))
    m.L = pe.Param(m.M, m.F, initialize=lambda m, i, f: float(d["L"][i, f]))
    m.beta = pe.Param(m.M, m.F, initialize=lambda m, i, f: float(d["beta"][i, f]))
    m.gamma = pe.Param(initialize=d["gamma"])
    m.D = pe.Param(m.M, mutable=True, initialize=lambda m, i: float(d["D"][i]))
    m.q = pe.Var(m.M, m.F, within=pe.NonNegativeReals, initialize=d["q0"])
    m.Q = pe.Expression(m.M, rule=lambda m, i: sum(m.q[i, f] for f in m.F))
    m.p = pe.Expression(m.M, rule=lambda m, i: m.D[i] ** (1.0 / m.gamma)
                        * m.Q[i] ** (-1.0 / m.gamma))

    def profit(m, i, f):
        mc = m.c[i, f] + (m.q[i, f] / m.L[i, f]) ** (1.0 / m.beta[i, f])
        return complements(m.q[i, f] >= 0,
                           mc - m.p[i] * (1 - m.q[i, f] / (m.gamma * m.Q[i])) >= 0)

    m.profit = Complementarity(m.M, m.F, rule=profit)
    return m


def pyomo_solution(m) -> np.ndarray:
    # (Pyomo: an optional extra)
    import pyomo.environ as pe

    return np.array([pe.value(m.q[i, f]) for i in m.M for f in m.F])


# --------------------------------------------------------------------------- #
def gamspy_model(d):
    """(container, model, symbols) of the same model in GAMSPy."""
    require_gams("build the GAMSPy model")
    # (GAMSPy: an optional extra)
    import gamspy as gp

    M = d["markets"]
    ct = gp.Container()
    mk = gp.Set(ct, "mk", records=[str(i) for i in range(M)])
    fi = gp.Set(ct, "fi", records=[str(f) for f in range(FIRMS)])
    recs = [(str(i), str(f)) for i in range(M) for f in range(FIRMS)]

    def par2(name, arr):
        return gp.Parameter(ct, name, domain=[mk, fi],
                            records=[(a, b, float(v)) for (a, b), v in zip(recs, arr.ravel())])

    c, Lp, beta = par2("c", d["c"]), par2("L", d["L"]), par2("beta", d["beta"])
    D = gp.Parameter(ct, "D", domain=mk,
                     records=[(str(i), float(v)) for i, v in enumerate(d["D"])])
    gam = gp.Parameter(ct, "gam", records=d["gamma"])
    q = gp.Variable(ct, "q", domain=[mk, fi], type="positive")
    q.l[mk, fi] = d["q0"]
    fa = gp.Alias(ct, "fa", fi)
    profit = gp.Equation(ct, "profit", domain=[mk, fi])
    Q = gp.Sum(fa, q[mk, fa])
    p = D[mk] ** (1 / gam) * Q ** (-1 / gam)
    profit[mk, fi] = (c[mk, fi] + (q[mk, fi] / Lp[mk, fi]) ** (1 / beta[mk, fi])
                      - p * (1 - q[mk, fi] / (gam * Q))) >= gp.Number(0)
    model = gp.Model(ct, "cournot", problem="MCP", matches={profit: q})
    return ct, model, {"q": q, "profit": profit}


def gamspy_solution(sym, d) -> np.ndarray:
    rec = sym["q"].records
    out = np.zeros((d["markets"], FIRMS))
    for a, b, lev in zip(rec.iloc[:, 0], rec.iloc[:, 1], rec["level"]):
        out[int(a), int(b)] = lev
    return out.ravel()
