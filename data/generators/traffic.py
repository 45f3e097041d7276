"""Wardrop traffic equilibrium on the Sioux Falls network as an MCP: the multicommodity
formulation of Ferris, Meeraus and Rutherford, "Computing Wardropian equilibria in a
complementarity framework", Optim. Methods Softw. 10 (1999) 669-685 (the GAMS model
library's ``traffic``).

Data (``data/siouxfalls_arcs.csv``, ``data/siouxfalls_trips.csv``; their headers give
source and units): 24 nodes, 38 streets = 76 directed arcs a = (i, j), each with the
travel time of the BPR type

    c_a(x_a) = A_a + B_a (x_a / K_a)^4        (free-flow time A, B = 0.15 A, capacity K),

and a symmetric trip table, scaled by 0.11 as the model library does.  Flows are grouped
by destination k (a commodity per destination).  Variables, in this order:

* y[a, k] >= 0, flow towards k on arc a = (i, j), for every arc not leaving k
  (a flow out of its own destination is zero; the model library fixes it, here it is no
  variable at all);
* t[i, k] free, the time from node i to k, for i != k (t[k, k] = 0 is no variable);
* v[a] >= A_a, the time on arc a;
* x[a] free, the aggregate flow on arc a.

Equations paired with them (F_i paired with variable i):

* y[a, k]  _|_  v[a] + t[j, k] - t[i, k] >= 0   (no route to k is faster than the one used:
  flow only on arcs of shortest paths);
* t[i, k]  _|_  sum_{a out of i} y[a, k] - sum_{a into i} y[a, k] - trips(i, k) = 0;
* v[a]     _|_  v[a] - c_a(x[a]) (>= 0 at the bound A_a: there c_a = A_a, so x_a = 0);
* x[a]     _|_  x[a] - sum_k y[a, k] = 0.

Sizes: with all 24 destinations n = 76*24 - 76 + 24*23 + 2*76 = 2452, the model
library's size; with the 8 destinations of the largest inbound demand (nodes 10, 16, 17,
15, 20, 22, 11, 8; their arcs out are 32) n = 76*8 - 32 + 23*8 + 152 = 912.

F is affine except for the BPR term, so J = L + (the entries dv/dx), L constant: the
Jacobian is L's CSC arrays with 76 data entries replaced, exact, and built without a
Python loop over arcs or destinations.  At an equilibrium the primal (Beckmann) and dual
objectives of the model library's NLP formulations agree with the MCP's point; see
:meth:`TrafficNetwork.beckmann` and :meth:`TrafficNetwork.dual_objective`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp

from compass_sparse.problem import MCP

__all__ = ["traffic_equilibrium", "TrafficNetwork", "sioux_falls_data", "TRIP_SCALE"]

TRIP_SCALE = 0.11
"""Factor from the tabulated trips to the demand of the cost data (the model library's)."""

_DATA = Path(__file__).resolve().parent / "data"
N_NODES = 24


def _read_csv(path):
    rows = [ln.strip() for ln in path.read_text().splitlines()
            if ln.strip() and not ln.startswith("#")]
    return rows


def sioux_falls_data():
    """(tail, head, A, B, K, trips): 76 directed arcs (0-based nodes, each street in both
    directions, the street's data on both) and the 24 x 24 symmetric trip table as
    tabulated (not yet scaled by ``TRIP_SCALE``)."""
    rows = _read_csv(_DATA / "siouxfalls_arcs.csv")
    assert rows[0] == "i,j,a,b,k"
    streets = np.array([[float(v) for v in r.split(",")] for r in rows[1:]])
    i = streets[:, 0].astype(np.int64) - 1
    j = streets[:, 1].astype(np.int64) - 1
    tail = np.concatenate([i, j])
    head = np.concatenate([j, i])
    A, B, K = (np.concatenate([streets[:, c], streets[:, c]]) for c in (2, 3, 4))
    trips = np.zeros((N_NODES, N_NODES))
    for r, line in enumerate(_read_csv(_DATA / "siouxfalls_trips.csv")):
        vals = [float(v) for v in line.split(",")]
        trips[r, r + 1:r + 1 + len(vals)] = vals
    trips = trips + trips.T
    return tail, head, A, B, K, trips


class TrafficNetwork:
    """The MCP's data and index maps; F and J (picklable, vectorized)."""

    def __init__(self, destinations=8, trip_scale=TRIP_SCALE):
        tail, head, A, B, K, trips = sioux_falls_data()
        self.tail, self.head, self.A, self.B, self.K = tail, head, A, B, K
        self.trips = trips * trip_scale
        m = tail.size
        self.m = m
        inbound = self.trips.sum(axis=0)
        if isinstance(destinations, (int, np.integer)):
            if not 1 <= destinations <= N_NODES:
                raise ValueError(f"destinations must be 1 ... {N_NODES}")
            # the largest inbound demand first; ties by node number (stable sort)
            dest = np.argsort(-inbound, kind="stable")[:int(destinations)]
        else:
            dest = np.asarray(destinations, dtype=np.int64) - 1
            if dest.size == 0 or np.any((dest < 0) | (dest >= N_NODES)) or \
                    np.unique(dest).size != dest.size:
                raise ValueError("destinations: distinct node numbers 1 ... 24")
        self.dest = np.asarray(dest, dtype=np.int64)
        D = self.dest.size
        # y[a, d] exists where arc a does not leave destination d
        ymask = tail[None, :] != self.dest[:, None]  # (D, m)
        yd, ya = np.nonzero(ymask)  # row-major: grouped by destination, arcs in order
        ny = yd.size
        # t[i, d] exists for i != destination d
        tmask = np.arange(N_NODES)[None, :] != self.dest[:, None]  # (D, 24)
        td, ti = np.nonzero(tmask)
        nt = td.size
        self.ny, self.nt = ny, nt
        self.yd, self.ya, self.td, self.ti = yd, ya, td, ti
        self.ymask, self.tmask = ymask, tmask
        self.off_t = ny
        self.off_v = ny + nt
        self.off_x = ny + nt + m
        self.n = ny + nt + 2 * m
        # position of t[i, d] in z, -1 for the destination itself (t = 0 there)
        tpos = -np.ones((D, N_NODES), dtype=np.int64)
        tpos[td, ti] = self.off_t + np.arange(nt)
        self.tpos = tpos
        ypos = -np.ones((D, m), dtype=np.int64)
        ypos[yd, ya] = np.arange(ny)
        self.ypos = ypos

        # --- the constant part L (rows = equations, paired with the variables' order)
        rows, cols, vals = [], [], []
        yrow = np.arange(ny)
        # rational: v[a] + t[head, d] - t[tail, d]
        rows += [yrow]
        cols += [self.off_v + ya]
        vals += [np.ones(ny)]
        th = tpos[yd, head[ya]]
        keep = th >= 0
        rows += [yrow[keep]]
        cols += [th[keep]]
        vals += [np.ones(int(keep.sum()))]
        tt = tpos[yd, tail[ya]]  # never the destination (y exists only there)
        rows += [yrow]
        cols += [tt]
        vals += [-np.ones(ny)]
        # balance of node i for d: + y on arcs out of i, - y on arcs into i
        rows += [tt]
        cols += [yrow]
        vals += [np.ones(ny)]
        rows += [th[keep]]
        cols += [yrow[keep]]
        vals += [-np.ones(int(keep.sum()))]
        # vdef: v[a] - B (x/K)^4 - A ; the x entry is nonlinear (its value set per J)
        arow = np.arange(m)
        rows += [self.off_v + arow, self.off_v + arow]
        cols += [self.off_v + arow, self.off_x + arow]
        vals += [np.ones(m), np.zeros(m)]
        # xdef: x[a] - sum_d y[a, d]
        rows += [self.off_x + arow, self.off_x + ya]
        cols += [self.off_x + arow, yrow]
        vals += [np.ones(m), -np.ones(ny)]
        r = np.concatenate(rows)
        c = np.concatenate(cols)
        L = sp.csc_matrix((np.concatenate(vals), (r, c)), shape=(self.n, self.n))
        L.sum_duplicates()  # (no duplicates: every (row, col) above is distinct)
        L.sort_indices()
        self.L = L
        # where J's nonlinear entries (row v[a], column x[a]) sit in L.data
        col_of = np.repeat(np.arange(self.n), np.diff(L.indptr))
        pos = np.flatnonzero((col_of >= self.off_x) & (L.indices == col_of - self.m))
        assert pos.size == m  # one per arc, column order = arc order
        self.dvdx_pos = pos
        # the constant vector
        self.c = np.zeros(self.n)
        self.c[self.off_t:self.off_v] = -self.trips[ti, self.dest[td]]
        self.c[self.off_v:self.off_x] = -A
        # the bounds
        self.lb = np.full(self.n, -np.inf)
        self.ub = np.full(self.n, np.inf)
        self.lb[:ny] = 0.0
        self.lb[self.off_v:self.off_x] = A

    # -------------------------------------------------------------- the MCP
    def F(self, z):
        f = self.L @ z + self.c
        x = z[self.off_x:]
        f[self.off_v:self.off_x] -= self.B * (x / self.K) ** 4
        return f

    def jac(self, z):
        x = z[self.off_x:]
        data = self.L.data.copy()
        data[self.dvdx_pos] = -4.0 * self.B / self.K * (x / self.K) ** 3
        return sp.csc_matrix((data, self.L.indices, self.L.indptr), shape=(self.n, self.n))

    def constant_pattern(self) -> sp.csc_matrix:
        """The entries of J that do not depend on z: all but the 76 dv/dx ones."""
        mask = np.ones(self.L.nnz, dtype=bool)
        mask[self.dvdx_pos] = False
        col = np.repeat(np.arange(self.n), np.diff(self.L.indptr))
        return sp.csc_matrix((np.ones(int(mask.sum())), (self.L.indices[mask], col[mask])),
                             shape=(self.n, self.n))

    # -------------------------------------------------------------- reading a point
    def split(self, z):
        """(y, t, v, x): y (D, 76) flows per destination (0 where no variable), t (D, 24)
        times to each destination (0 at the destination), v and x (76,)."""
        z = np.asarray(z, dtype=float)
        D = self.dest.size
        y = np.zeros((D, self.m))
        y[self.yd, self.ya] = z[:self.ny]
        t = np.zeros((D, N_NODES))
        t[self.td, self.ti] = z[self.off_t:self.off_v]
        return y, t, z[self.off_v:self.off_x].copy(), z[self.off_x:].copy()

    def arc_times(self, x):
        return self.A + self.B * (np.asarray(x) / self.K) ** 4

    def total_travel_time(self, z):
        """sum_a x_a c_a(x_a), the vehicle-hours of the assignment at z."""
        x = self.split(z)[3]
        return float(np.dot(x, self.arc_times(x)))

    def beckmann(self, x):
        """The primal NLP's objective sum_a int_0^{x_a} c_a = A x + B K (x/K)^5 / 5, which
        the equilibrium minimizes over the feasible flows."""
        x = np.asarray(x, dtype=float)
        return float(np.sum(self.A * x + self.B * self.K * (x / self.K) ** 5 / 5.0))

    def dual_objective(self, z):
        """The dual NLP's objective sum_{i,k} trips(i,k) t(i,k) - sum_a (4/5) K B^(-1/4)
        (v - A)^(5/4), maximized at the equilibrium with the same value as the primal."""
        _, t, v, _ = self.split(z)
        demand = np.sum(self.trips[:, self.dest].T * t)
        excess = np.maximum(v - self.A, 0.0)
        return float(demand - np.sum(0.8 * self.K / self.B ** 0.25 * excess ** 1.25))

    def var_names(self):
        nodes = np.arange(1, N_NODES + 1)
        k1 = self.dest + 1
        names = [f"y[{self.tail[a] + 1}-{self.head[a] + 1},{k1[d]}]"
                 for d, a in zip(self.yd, self.ya)]
        names += [f"t[{nodes[i]},{k1[d]}]" for d, i in zip(self.td, self.ti)]
        names += [f"v[{self.tail[a] + 1}-{self.head[a] + 1}]" for a in range(self.m)]
        names += [f"x[{self.tail[a] + 1}-{self.head[a] + 1}]" for a in range(self.m)]
        return names


def traffic_equilibrium(destinations=8, *, trip_scale=TRIP_SCALE):
    """The Sioux Falls traffic equilibrium MCP (see the module).

    destinations : int or sequence of node numbers (1 ... 24)
        An int k takes the k nodes of the largest inbound demand (ties by node number):
        8 gives n = 912, 24 (all) n = 2452 as the GAMS model library's ``traffic``.  Only
        the trips to the chosen destinations are loaded.
    trip_scale : float
        Factor on the tabulated trips (0.11: the model library's demand).

    The start point is the model library's: every level 0, projected (v = A, the
    free-flow times).  ``info['network']`` is the :class:`TrafficNetwork` (its ``split``,
    ``total_travel_time``, ``beckmann`` and ``dual_objective`` read a point);
    ``solution`` is None (the equilibrium is not known in closed form).
    """
    from . import GeneratedProblem

    net = TrafficNetwork(destinations, trip_scale)
    problem = MCP(net.F, net.jac, net.lb, net.ub, np.zeros(net.n),
                  constant_jac=net.constant_pattern(), var_names=net.var_names())
    k = net.dest.size
    info = dict(network=net, destinations=(net.dest + 1).tolist(), trip_scale=trip_scale,
                arcs=net.m, nodes=N_NODES)
    return GeneratedProblem(name=f"traffic(sioux falls, {k} destinations, n={net.n})",
                            problem=problem, solution=None, info=info)
