"""Spatial price equilibrium on a transport network (Samuelson–Takayama–Judge).

Nodes i have a price pi_i >= 0, a linear supply S_i(pi) = s_i pi and a demand
D_i(pi) = d_i exp(-e_i pi); arcs a = (i -> j) carry shipments x_a >= 0 at the unit cost
k_a + r_a x_a.  The equilibrium is the NCP

    x_a  >= 0   _|_   pi_i + k_a + r_a x_a - pi_j >= 0                    (no profitable trade)
    pi_i >= 0   _|_   S_i(pi_i) + sum_{a into i} x_a - D_i(pi_i) - sum_{a out of i} x_a >= 0
                                                                          (market clearing)

The network is a ring (both directions) plus random chords, so every node has at least two
neighbours and the Jacobian has about 7 entries per row.  n = nodes + arcs; ``nodes`` for a
target n is about n / 4.  The model is written three times: Pyomo, GAMSPy and numpy
callables with a hand-written sparse Jacobian.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..interfaces.gams_state import require_gams


def data(nodes: int = 10, seed: int = 0, chords: float = 0.5) -> dict:
    rng = np.random.default_rng(seed)
    ring = np.arange(nodes)
    src = [ring, (ring + 1) % nodes]
    dst = [(ring + 1) % nodes, ring]
    nch = int(chords * nodes)
    if nch and nodes > 3:
        a = rng.integers(0, nodes, nch)
        b = (a + rng.integers(2, nodes - 1, nch)) % nodes
        src.append(a)
        dst.append(b)
    src, dst = np.concatenate(src), np.concatenate(dst)
    keep = np.unique(src * nodes + dst, return_index=True)[1]
    src, dst = src[np.sort(keep)], dst[np.sort(keep)]
    return {
        "nodes": nodes, "src": src, "dst": dst,
        "s": 1.0 + rng.random(nodes), "d": 5.0 + 10.0 * rng.random(nodes),
        "e": 0.2 + 0.3 * rng.random(nodes),
        "k": 0.1 + rng.random(src.size), "r": 0.05 + 0.1 * rng.random(src.size),
    }


def size(d) -> int:
    return d["nodes"] + d["src"].size


def names(d) -> list[str]:
    return ([f"x[{i},{j}]" for i, j in zip(d["src"], d["dst"])]
            + [f"pi[{i}]" for i in range(d["nodes"])])


# --------------------------------------------------------------------------- #
def callables(d) -> dict:
    """Variables ordered (x_a for every arc, then pi_i for every node)."""
    N, A = d["nodes"], d["src"].size
    src, dst = d["src"], d["dst"]
    n = A + N
    arcs = np.arange(A)
    # incidence: B[i, a] = +1 if a enters i, -1 if a leaves i
    B = sp.csc_matrix((np.r_[np.ones(A), -np.ones(A)], (np.r_[dst, src], np.r_[arcs, arcs])),
                      shape=(N, A))
    # constant part of J:  rows of x: d/dpi_src = +1, d/dpi_dst = -1; rows of pi: B
    Jc = sp.bmat([[None, -B.T], [B, None]], format="csc")
    diag = sp.csc_matrix((np.ones(n), (np.arange(n), np.arange(n))), shape=(n, n))
    pattern = (abs(Jc) + diag).tocsc()
    pattern.sort_indices()
    # positions of the diagonal and values of the constant part in the fixed pattern
    Pc = pattern.tocoo()
    key = Pc.col.astype(np.int64) * n + Pc.row
    order = np.argsort(key)  # pattern's CSC order is column-major already
    base = np.zeros(pattern.nnz)
    Jcc = Jc.tocoo()
    base[np.searchsorted(key[order], Jcc.col.astype(np.int64) * n + Jcc.row)] = Jcc.data
    dpos = np.searchsorted(key[order], np.arange(n, dtype=np.int64) * n + np.arange(n))
    s, dd, e, k, r = d["s"], d["d"], d["e"], d["k"], d["r"]

    def F(z):
        x, p = z[:A], z[A:]
        fx = p[src] + k + r * x - p[dst]
        fp = s * p + B @ x - dd * np.exp(-e * p)
        return np.concatenate([fx, fp])

    def J(z):
        p = z[A:]
        vals = base.copy()
        vals[dpos[:A]] += r
        vals[dpos[A:]] += s + dd * e * np.exp(-e * p)
        return sp.csc_matrix((vals, pattern.indices, pattern.indptr), shape=(n, n))

    return {"F": F, "jac": J, "lb": np.zeros(n), "ub": np.full(n, np.inf),
            "x0": np.r_[np.zeros(A), np.ones(N)], "var_names": names(d),
            "constant_jac": Jc}


# --------------------------------------------------------------------------- #
def pyomo_model(d):
    # (Pyomo: an optional extra)
    import pyomo.environ as pe
    from pyomo.mpec import Complementarity, complements

    N = d["nodes"]
    arcs = list(zip(d["src"].tolist(), d["dst"].tolist()))
    m = pe.ConcreteModel(name="spatial")
    m.N = pe.RangeSet(0, N - 1)
    m.A = pe.Set(initialize=arcs, dimen=2, ordered=True)
    m.s = pe.Param(m.N, initialize=lambda m, i: float(d["s"][i]))
    m.d = pe.Param(m.N, mutable=True, initialize=lambda m, i: float(d["d"][i]))
    m.e = pe.Param(m.N, initialize=lambda m, i: float(d["e"][i]))
    kk = dict(zip(arcs, d["k"].tolist()))
    rr = dict(zip(arcs, d["r"].tolist()))
    m.k = pe.Param(m.A, initialize=kk)
    m.r = pe.Param(m.A, initialize=rr)
    m.x = pe.Var(m.A, within=pe.NonNegativeReals, initialize=0.0)
    m.pi = pe.Var(m.N, within=pe.NonNegativeReals, initialize=1.0)
    into = {i: [] for i in range(N)}
    out = {i: [] for i in range(N)}
    for a in arcs:
        out[a[0]].append(a)
        into[a[1]].append(a)
    m.trade = Complementarity(m.A, rule=lambda m, i, j: complements(
        m.x[i, j] >= 0, m.pi[i] + m.k[i, j] + m.r[i, j] * m.x[i, j] - m.pi[j] >= 0))
    m.balance = Complementarity(m.N, rule=lambda m, i: complements(
        m.pi[i] >= 0,
        m.s[i] * m.pi[i] + sum(m.x[a] for a in into[i]) - m.d[i] * pe.exp(-m.e[i] * m.pi[i])
        - sum(m.x[a] for a in out[i]) >= 0))
    return m


def pyomo_solution(m) -> np.ndarray:
    # (Pyomo: an optional extra)
    import pyomo.environ as pe

    return np.array([pe.value(m.x[a]) for a in m.A] + [pe.value(m.pi[i]) for i in m.N])


# --------------------------------------------------------------------------- #
def gamspy_model(d):
    require_gams("build the GAMSPy model")
    # (GAMSPy: an optional extra)
    import gamspy as gp

    N = d["nodes"]
    ct = gp.Container()
    i = gp.Set(ct, "i", records=[str(t) for t in range(N)])
    j = gp.Alias(ct, "j", i)
    arc = gp.Set(ct, "arc", domain=[i, j],
                 records=[(str(a), str(b)) for a, b in zip(d["src"], d["dst"])])

    def par(name, arr):
        return gp.Parameter(ct, name, domain=i,
                            records=[(str(t), float(v)) for t, v in enumerate(arr)])

    def apar(name, arr):
        return gp.Parameter(ct, name, domain=[i, j],
                            records=[(str(a), str(b), float(v))
                                     for a, b, v in zip(d["src"], d["dst"], arr)])

    s, dd, e = par("s", d["s"]), par("dem", d["d"]), par("e", d["e"])
    k, r = apar("k", d["k"]), apar("r", d["r"])
    x = gp.Variable(ct, "x", domain=[i, j], type="positive")
    pi = gp.Variable(ct, "pi", domain=i, type="positive")
    pi.l[i] = 1.0
    trade = gp.Equation(ct, "trade", domain=[i, j])
    clear = gp.Equation(ct, "clear", domain=i)
    trade[arc[i, j]] = pi[i] + k[i, j] + r[i, j] * x[i, j] - pi[j] >= gp.Number(0)
    clear[i] = (s[i] * pi[i] + gp.Sum(arc[j, i], x[j, i]) - dd[i] * gp.math.exp(-e[i] * pi[i])
                - gp.Sum(arc[i, j], x[i, j])) >= gp.Number(0)
    model = gp.Model(ct, "spatial", problem="MCP", matches={trade: x, clear: pi})
    return ct, model, {"x": x, "pi": pi, "trade": trade, "clear": clear}


def gamspy_solution(sym, d) -> np.ndarray:
    xr, pr = sym["x"].records, sym["pi"].records
    xs = {(int(a), int(b)): v for a, b, v in zip(xr.iloc[:, 0], xr.iloc[:, 1], xr["level"])}
    ps = {int(a): v for a, v in zip(pr.iloc[:, 0], pr["level"])}
    return np.array([xs.get((a, b), 0.0) for a, b in zip(d["src"], d["dst"])]
                    + [ps.get(t, 0.0) for t in range(d["nodes"])])
