"""Dynamic Ramsey CGE model in complementarity form (Lau, Pahlke & Rutherford 2002).

Periods t = 0 .. T-1 (``periods = T``; tl = T - 1 is the last one), sectors s, goods i
(one good per sector).  Steady-state calibration with growth gamma, interest rbar and
depreciation delta:  qref_t = (1+gamma)^t, pref_t = (1+rbar)^-t, K0_s = I0_s/(gamma+delta),
RK0_s = (rbar+delta) K0_s, L0_s = VA_s - RK0_s.

Variables (block, bounds, benchmark)::

    Y[s,t]   output activity            >= 0    qref_t
    I[s,t]   investment in sector s     >= 0    I0_s qref_t
    K[s,t]   capital stock of sector s  >= 0    K0_s qref_t
    C[t]     consumption                >= 0    C0 qref_t
    P[s,t]   price of good s            >= plb  pref_t
    RK[s,t]  capital rental price       >= plb  (rbar+delta) pref_t
    PL[t]    wage                       >= plb  pref_t
    PK[s,t]  price of capital           >= plb  (1+rbar) pref_t
    PU[t]    price of consumption       >= plb  pref_t
    PKT[s]   price of terminal capital  >= plb  pref_tl
    TK[s]    terminal capital stock     free    K0_s qref_T
    HA       income of the agent        free    sum_t pref_t C0 qref_t

Rows (c_st = PL_t^thL_s (RK_st (1+tauK)/(rbar+delta))^thK_s, Cobb-Douglas value added;
PK_{s,T} means PKT_s)::

    prf_Y   sum_i Z_is P_it + VA_s c_st - X_s P_st                       >= 0  _|_ Y
    prf_I   sum_i iota_is P_it - PK_{s,t+1}                              >= 0  _|_ I
    prf_K   PK_st - RK_st - (1-delta) PK_{s,t+1}                         >= 0  _|_ K
    prf_C   cC(P_t) - PU_t                                               >= 0  _|_ C
    mkt_P   X_i Y_it - sum_s Z_is Y_st - sum_s iota_is I_st - beta_i C_t (PU_t/P_it)^sc >= 0
    mkt_RK  K_st - Y_st K0_s c_st / (RK_st (1+tauK)/(rbar+delta))        >= 0  _|_ RK
    mkt_PL  L0 qref_t - sum_s Y_st L0_s c_st / PL_t                      >= 0  _|_ PL
    mkt_PK  K0_s - K_s0 (t = 0);  (1-delta) K_s,t-1 + I_s,t-1 - K_st     >= 0  _|_ PK
    mkt_PKT (1-delta) K_s,tl + I_s,tl - TK_s                             >= 0  _|_ PKT
    mkt_PU  C_t - theta_t HA / PU_t                                      >= 0  _|_ PU
    inc_HA  HA - [sum_t PL_t L0 qref_t + sum_s PK_s0 K0_s - sum_s PKT_s TK_s
                  + sum_st tauK RK_st kd_st] = 0                               _|_ HA
    term    I_s,tl / I_s,tl-1 - Y_s,tl / Y_s,tl-1 = 0                          _|_ TK (free)

theta_t = pref_t qref_t / sum_u pref_u qref_u (Cobb-Douglas over time, as in the LPR listing).
With ``sectors=1`` and the default data (Y0 = 10, C0 = 7.5, I0 = 2.5, gamma = .02,
rbar = .04, delta = .08) this is exactly the one-sector LPR model (9 T + 3 variables).
With more sectors the input-output flows Z, investment composition iota (sparse columns
summing to 1) and consumption shares beta come from a random balanced SAM.

Structure: bandwidth-one coupling in time (through PK, K, I), one dense row (inc_HA) and
one dense column (HA in every mkt_PU row): an arrowhead.
"""
from __future__ import annotations

import numpy as np


from ._assembly import CESGroups, PatternAssembler
from .model import CGEModel, assemble_model, fix_numeraire

__all__ = ["ramsey_cge", "ramsey_size", "ramsey_size_for"]

BLOCKS = ("Y", "I", "K", "C", "TK", "P", "RK", "PL", "PK", "PU", "PKT", "HA")
ROWS = {"Y": "prf_Y", "I": "prf_I", "K": "prf_K", "C": "prf_C", "TK": "term",
        "P": "mkt_P", "RK": "mkt_RK", "PL": "mkt_PL", "PK": "mkt_PK", "PU": "mkt_PU",
        "PKT": "mkt_PKT", "HA": "inc_HA"}
QUANTITY_BLOCKS = ("Y", "I", "K", "C", "TK")
PRICE_BLOCKS = ("P", "RK", "PL", "PK", "PU", "PKT")
DEGREE = {"Y": 1, "I": 1, "K": 1, "C": 1, "TK": 0, "P": 0, "RK": 0, "PL": 0, "PK": 0,
          "PU": 0, "PKT": 0, "HA": 1}


def ramsey_size(periods: int, sectors: int = 1) -> int:
    """n = T (6 N + 3) + 2 N + 1 (9 T + 3 for one sector)."""
    return periods * (6 * sectors + 3) + 2 * sectors + 1


def ramsey_size_for(n_target: int, periods: int | None = None) -> dict:
    """Keyword arguments of :func:`ramsey_cge` giving n close to ``n_target``
    (periods 40 by default, up to 100 for large targets)."""
    n_target = int(n_target)
    if periods is None:
        periods = 40 if n_target < 20000 else 100
    sectors = max(1, int(round((n_target / periods - 3) / 6)))
    return {"periods": int(periods), "sectors": sectors}


def ramsey_cge(
    periods: int = 41,
    sectors: int = 1,
    *,
    gamma: float = 0.02,
    rbar: float = 0.04,
    delta: float = 0.08,
    Y0: float = 10.0,
    C0: float = 7.5,
    I0: float = 2.5,
    io_density: int = 3,
    inv_density: int = 2,
    sigma_consumer: float = 0.0,
    numeraire="auto",
    price_lb: float = 0.0,
    income_free: bool = True,
    seed: int = 0,
) -> CGEModel:
    """The LPR Ramsey model, calibrated to a steady state (the benchmark growth path).

    ``periods`` = T >= 2 periods t = 0..T-1.  With ``sectors=1`` the data are Y0, C0, I0
    (defaults of the LPR example: K0 = 25, RK0 = 3, L0 = 7); with ``sectors > 1`` a random
    balanced SAM (seeded) with ``io_density`` input-output and ``inv_density`` investment-
    composition nonzeros per column is scaled to GDP = C0 + I0.  ``sigma_consumer`` is the
    within-period elasticity of the consumption bundle (0: Leontief).  The benchmark has no
    capital tax; the LPR counterfactual (a 10% capital subsidy) is
    ``model.with_shock(capital_tax=-0.1)``; ``with_shock(labour=1.05)`` scales the labour
    endowment path.
    ``numeraire``: 'auto' fixes HA (the only consumer, as MPSGE does); ('price', name),
    ('income', 'HA') or None as in :func:`static_cge`.
    """
    T, N = int(periods), int(sectors)
    if T < 2:
        raise ValueError("periods must be >= 2 (the terminal constraint links T-1 and T-2)")
    if N < 1:
        raise ValueError("sectors must be >= 1")
    if not rbar > gamma:
        raise ValueError("need rbar > gamma for a finite present value")
    data = _calibrate(N, gamma, rbar, delta, Y0, C0, I0, io_density, inv_density, seed)
    data.update(T=T, N=N, gamma=gamma, rbar=rbar, delta=delta, sigma_c=float(sigma_consumer),
                seed=int(seed))
    ev = _RamseyEvaluator(data, {"tauK": 0.0, "lscale": 1.0})
    return ev.make_model(numeraire=numeraire, price_lb=price_lb, income_free=income_free,
                         start=None, numeraire_value=None, shock_text=None)


def _calibrate(N, gamma, rbar, delta, Y0, C0, I0, k, kinv, seed):
    if N == 1:
        K0 = I0 / (gamma + delta)
        RK0 = K0 * (rbar + delta)
        L0 = Y0 - RK0
        if L0 <= 0 or abs(Y0 - C0 - I0) > 1e-12 * Y0:
            raise ValueError("inconsistent one-sector data: need Y0 = C0 + I0 and L0 > 0")
        return dict(X=np.array([Y0]), io_i=np.zeros(0, np.int64), io_s=np.zeros(0, np.int64),
                    Z=np.zeros(0), VA=np.array([Y0]), thK=np.array([RK0 / Y0]),
                    K0=np.array([K0]), I0=np.array([I0]), L0s=np.array([L0]),
                    iv_i=np.zeros(1, np.int64), iv_s=np.zeros(1, np.int64), iota=np.ones(1),
                    Cg=np.array([C0]))
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 11]))
    k = max(0, min(int(k), N))
    kinv = max(1, min(int(kinv), N))
    # input-output coefficients, about k per column, column sums in [0.2, 0.5]
    if k:
        io_s = np.repeat(np.arange(N), k)
        io_i = rng.integers(0, N, size=N * k)
        key = np.unique(io_s * N + io_i)
        io_s, io_i = key // N, key % N
        w = rng.random(io_s.size) + 0.1
        a = w * (rng.uniform(0.2, 0.5, N) / np.bincount(io_s, w, minlength=N))[io_s]
    else:
        io_s = io_i = np.zeros(0, np.int64)
        a = np.zeros(0)
    # investment composition: kinv goods per investing sector, column sums 1
    iv_s = np.repeat(np.arange(N), kinv)
    iv_i = rng.integers(0, N, size=N * kinv)
    key = np.unique(iv_s * N + iv_i)
    iv_s, iv_i = key // N, key % N
    w = rng.random(iv_s.size) + 0.2
    iota = w / np.bincount(iv_s, w, minlength=N)[iv_s]
    kappa = rng.uniform(0.2, 0.5, N)  # capital share of value added
    vshare = 1.0 - np.bincount(io_s, a, minlength=N)  # VA per unit output
    winv = (gamma + delta) / (rbar + delta) * kappa * vshare  # investment per unit output
    Ctarget = rng.uniform(0.5, 1.5, N)
    # X = A X + iota W X + C  (contraction: column sums < 1)
    X = Ctarget.copy()
    for _ in range(2000):
        Xn = (np.bincount(io_i, a * X[io_s], minlength=N)
              + np.bincount(iv_i, iota * (winv * X)[iv_s], minlength=N) + Ctarget)
        if np.max(np.abs(Xn - X)) <= 1e-15 * np.max(Xn):
            X = Xn
            break
        X = Xn
    # scale to GDP = C0 + I0 of the one-sector example
    Z = a * X[io_s]
    VA = X - np.bincount(io_s, Z, minlength=N)
    scale = (C0 + I0) / VA.sum()
    X, Z, VA = X * scale, Z * scale, VA * scale
    RK0 = kappa * VA
    K0 = RK0 / (rbar + delta)
    I0s = (gamma + delta) * K0
    L0s = VA - RK0
    Cg = X - np.bincount(io_i, Z, minlength=N) - np.bincount(iv_i, iota * I0s[iv_s], minlength=N)
    if np.any(Cg <= 0):
        raise ValueError("calibration produced nonpositive consumption; change the seed")
    return dict(X=X, io_i=io_i, io_s=io_s, Z=Z, VA=VA, thK=RK0 / VA, K0=K0, I0=I0s, L0s=L0s,
                iv_i=iv_i, iv_s=iv_s, iota=iota, Cg=Cg)


class _RamseyEvaluator:
    def __init__(self, data: dict, policy: dict):
        self.d = data
        self.policy = dict(policy)
        T, N = data["T"], data["N"]
        self.T, self.N = T, N
        TN = T * N
        sizes = {"Y": TN, "I": TN, "K": TN, "C": T, "TK": N, "P": TN, "RK": TN, "PL": T,
                 "PK": TN, "PU": T, "PKT": N, "HA": 1}
        off = 0
        self.blocks = {}
        for b in BLOCKS:
            self.blocks[b] = slice(off, off + sizes[b])
            off += sizes[b]
        self.n = off
        self.shapes = {b: (T, N) for b in ("Y", "I", "K", "P", "RK", "PK")}
        self.shapes.update({"C": (T,), "PL": (T,), "PU": (T,), "TK": (N,), "PKT": (N,),
                            "HA": (1,)})
        g, r, dl = data["gamma"], data["rbar"], data["delta"]
        t = np.arange(T)
        self.qref = (1.0 + g) ** t
        self.pref = (1.0 + r) ** (-t.astype(float))
        self.qT = (1.0 + g) ** T
        w = self.pref * self.qref
        self.theta_t = w / w.sum()
        self.C0 = float(data["Cg"].sum())
        self.beta = data["Cg"] / self.C0
        self.L0 = float(data["L0s"].sum())
        self.HA0 = float(np.sum(self.pref * self.C0 * self.qref))
        self.thK = data["thK"]
        self.thL = 1.0 - self.thK
        self.rd = r + dl
        self.one_m_delta = 1.0 - dl
        self.sig_c = data["sigma_c"]
        # grids
        st = np.arange(TN)
        self.s_of, self.t_of = st % N, st // N
        # IO triplets over time: Z_is -> (i,t) row index t*N+i, sector (s,t)
        io_i, io_s, Z = data["io_i"], data["io_s"], data["Z"]
        tt = np.repeat(t, io_i.size)
        self.zi = tt * N + np.tile(io_i, T)
        self.zs = tt * N + np.tile(io_s, T)
        self.zv = np.tile(Z, T)
        iv_i, iv_s, iota = data["iv_i"], data["iv_s"], data["iota"]
        tt = np.repeat(t, iv_i.size)
        self.vi = tt * N + np.tile(iv_i, T)
        self.vs = tt * N + np.tile(iv_s, T)
        self.vv = np.tile(iota, T)
        # consumption bundle: groups t, elements goods (t, i)
        self.cC = CESGroups(self.t_of, np.tile(self.beta, T), self.sig_c, T)
        self._build_pattern()

    # ------------------------------------------------------------------------------------
    def _build_pattern(self):
        T, N = self.T, self.N
        o = {b: self.blocks[b].start for b in BLOCKS}
        self.o = o
        TN = T * N
        st = np.arange(TN)
        tl = T - 1
        nxt = st[self.t_of < tl]  # (s,t) with t < tl
        last = st[self.t_of == tl]
        prev = st[self.t_of == tl - 1]
        sN = np.arange(N)
        pa = PatternAssembler(self.n)
        add = pa.add
        # prf_Y
        add("Y_P_io", o["Y"] + self.zs, o["P"] + self.zi, const=True)
        add("Y_PL", o["Y"] + st, o["PL"] + self.t_of)
        add("Y_RK", o["Y"] + st, o["RK"] + st)
        add("Y_P", o["Y"] + st, o["P"] + st, const=True)
        # prf_I
        add("I_P", o["I"] + self.vs, o["P"] + self.vi, const=True)
        add("I_PK", o["I"] + nxt, o["PK"] + nxt + N, const=True)
        add("I_PKT", o["I"] + last, o["PKT"] + sN, const=True)
        # prf_K
        add("K_PK", o["K"] + st, o["PK"] + st, const=True)
        add("K_RK", o["K"] + st, o["RK"] + st, const=True)
        add("K_PKn", o["K"] + nxt, o["PK"] + nxt + N, const=True)
        add("K_PKT", o["K"] + last, o["PKT"] + sN, const=True)
        # prf_C
        add("C_P", o["C"] + self.t_of, o["P"] + st, const=self.sig_c == 0)
        add("C_PU", o["C"] + np.arange(T), o["PU"] + np.arange(T), const=True)
        # term
        add("TK_I", o["TK"] + np.concatenate([sN, sN]), o["I"] + np.concatenate([last, prev]))
        add("TK_Y", o["TK"] + np.concatenate([sN, sN]), o["Y"] + np.concatenate([last, prev]))
        # mkt_P
        add("P_Y", o["P"] + st, o["Y"] + st, const=True)
        add("P_Yio", o["P"] + self.zi, o["Y"] + self.zs, const=True)
        add("P_I", o["P"] + self.vi, o["I"] + self.vs, const=True)
        add("P_C", o["P"] + st, o["C"] + self.t_of, const=self.sig_c == 0)
        if self.sig_c != 0:
            add("P_PU", o["P"] + st, o["PU"] + self.t_of)
            add("P_P", o["P"] + st, o["P"] + st)
        # mkt_RK
        add("RK_K", o["RK"] + st, o["K"] + st, const=True)
        add("RK_Y", o["RK"] + st, o["Y"] + st)
        add("RK_PL", o["RK"] + st, o["PL"] + self.t_of)
        add("RK_RK", o["RK"] + st, o["RK"] + st)
        # mkt_PL
        add("PL_Y", o["PL"] + self.t_of, o["Y"] + st)
        add("PL_PL", o["PL"] + self.t_of, o["PL"] + self.t_of)
        add("PL_RK", o["PL"] + self.t_of, o["RK"] + st)
        # mkt_PK
        first = st[self.t_of == 0]
        later = st[self.t_of > 0]
        add("PK_K0", o["PK"] + first, o["K"] + first, const=True)
        add("PK_Kp", o["PK"] + later, o["K"] + later - N, const=True)
        add("PK_Ip", o["PK"] + later, o["I"] + later - N, const=True)
        add("PK_K", o["PK"] + later, o["K"] + later, const=True)
        # mkt_PKT
        add("PKT_K", o["PKT"] + sN, o["K"] + last, const=True)
        add("PKT_I", o["PKT"] + sN, o["I"] + last, const=True)
        add("PKT_TK", o["PKT"] + sN, o["TK"] + sN, const=True)
        # mkt_PU
        tT = np.arange(T)
        add("PU_C", o["PU"] + tT, o["C"] + tT, const=True)
        add("PU_HA", o["PU"] + tT, np.full(T, o["HA"]))
        add("PU_PU", o["PU"] + tT, o["PU"] + tT)
        # inc_HA
        h = o["HA"]
        add("HA_HA", [h], [h], const=True)
        add("HA_PL", np.full(T, h), o["PL"] + tT)
        add("HA_PK0", np.full(N, h), o["PK"] + sN, const=True)
        add("HA_PKT", np.full(N, h), o["PKT"] + sN)
        add("HA_TK", np.full(N, h), o["TK"] + sN)
        add("HA_Ytax", np.full(TN, h), o["Y"] + st)
        add("HA_PLtax", np.full(TN, h), o["PL"] + self.t_of)
        add("HA_RKtax", np.full(TN, h), o["RK"] + st)
        self.pat = pa.finalize()

    def _unpack(self, z):
        b = self.blocks
        return {k: z[b[k]] for k in BLOCKS}

    def _va(self, v):
        """c_st, kd_st (capital demand), ld_st (labour demand) and helpers."""
        tauK = self.policy["tauK"]
        s, t = self.s_of, self.t_of
        PL = v["PL"][t]
        RK = v["RK"]
        g = RK * (1.0 + tauK) / self.rd
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            c = np.power(PL, self.thL[s]) * np.power(g, self.thK[s])
            kd = v["Y"] * self.d["K0"][s] * c / g
            ld = v["Y"] * self.d["L0s"][s] * c / PL
        return PL, RK, g, c, kd, ld

    def eval_F(self, z):
        z = np.asarray(z, dtype=float)
        v = self._unpack(z)
        T, N = self.T, self.N
        TN = T * N
        d = self.d
        tl = T - 1
        s, t = self.s_of, self.t_of
        out = np.empty(self.n)
        b = self.blocks
        PL, RK, g, c, kd, ld = self._va(v)
        P, PK, PKT = v["P"], v["PK"], v["PKT"]
        PKnext = np.concatenate([PK[N:], PKT])  # PK_{s,t+1}, PKT at tl
        out[b["Y"]] = (np.bincount(self.zs, self.zv * P[self.zi], minlength=TN)
                       + d["VA"][s] * c - d["X"][s] * P)
        out[b["I"]] = np.bincount(self.vs, self.vv * P[self.vi], minlength=TN) - PKnext
        out[b["K"]] = PK - RK - self.one_m_delta * PKnext
        cC = self.cC.value(P)
        out[b["C"]] = cC - v["PU"]
        Y, I, K, C = v["Y"], v["I"], v["K"], v["C"]
        out[b["TK"]] = I[tl * N:] / I[(tl - 1) * N:tl * N] - Y[tl * N:] / Y[(tl - 1) * N:tl * N]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rho = np.power(v["PU"][t] / P, self.sig_c) if self.sig_c != 0 else 1.0
        cons = np.tile(self.beta, T) * C[t] * rho
        out[b["P"]] = (d["X"][s] * Y - np.bincount(self.zi, self.zv * Y[self.zs], minlength=TN)
                       - np.bincount(self.vi, self.vv * I[self.vs], minlength=TN) - cons)
        out[b["RK"]] = K - kd
        lscale = self.policy["lscale"]
        out[b["PL"]] = lscale * self.L0 * self.qref - np.bincount(t, ld, minlength=T)
        K0 = d["K0"]
        pk = np.empty(TN)
        pk[:N] = K0 - K[:N]
        pk[N:] = self.one_m_delta * K[:-N] + I[:-N] - K[N:]
        out[b["PK"]] = pk
        out[b["PKT"]] = self.one_m_delta * K[tl * N:] + I[tl * N:] - v["TK"]
        HA = v["HA"][0]
        with np.errstate(divide="ignore", invalid="ignore"):
            out[b["PU"]] = C - self.theta_t * HA / v["PU"]
        tauK = self.policy["tauK"]
        inc = (lscale * self.L0 * np.dot(v["PL"], self.qref) + np.dot(PK[:N], K0)
               - np.dot(PKT, v["TK"]) + tauK * np.sum(RK * kd))
        out[b["HA"]] = HA - inc
        return out

    def eval_J(self, z):
        z = np.asarray(z, dtype=float)
        v = self._unpack(z)
        T, N = self.T, self.N
        d = self.d
        tl = T - 1
        s, t = self.s_of, self.t_of
        PL, RK, g, c, kd, ld = self._va(v)
        thL, thK = self.thL[s], self.thK[s]
        P = v["P"]
        Y, I, C = v["Y"], v["I"], v["C"]
        vals = []
        ap = vals.append
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            # prf_Y
            ap(self.zv)
            ap(d["VA"][s] * thL * c / PL)
            ap(d["VA"][s] * thK * c / RK)
            ap(-d["X"][s])
            # prf_I
            ap(self.vv); ap(-1.0); ap(-1.0)
            # prf_K
            ap(1.0); ap(-1.0); ap(-self.one_m_delta); ap(-self.one_m_delta)
            # prf_C
            cC = self.cC.value(P)
            ap(self.cC.grad(cC, P)); ap(-1.0)
            # term: d/dI_tl, d/dI_prev ; d/dY_tl, d/dY_prev
            Il, Ip = I[tl * N:], I[(tl - 1) * N:tl * N]
            Yl, Yp = Y[tl * N:], Y[(tl - 1) * N:tl * N]
            ap(np.concatenate([1.0 / Ip, -Il / (Ip * Ip)]))
            ap(np.concatenate([-1.0 / Yp, Yl / (Yp * Yp)]))
            # mkt_P
            ap(d["X"][s]); ap(-self.zv); ap(-self.vv)
            bt = np.tile(self.beta, T)
            if self.sig_c != 0:
                PU = v["PU"][t]
                rho = np.power(PU / P, self.sig_c)
                cons = bt * C[t] * rho
                ap(-bt * rho)
                ap(-self.sig_c * cons / PU)
                ap(self.sig_c * cons / P)
            else:
                ap(-bt)
            # mkt_RK: K - kd, kd ~ Y PL^thL RK^(thK-1)
            ap(1.0)
            ap(-d["K0"][s] * c / g)
            ap(-kd * thL / PL)
            ap((1.0 - thK) * kd / RK)
            # mkt_PL: - sum ld, ld ~ Y PL^(thL-1) RK^thK
            ap(-d["L0s"][s] * c / PL)
            ap((1.0 - thL) * ld / PL)
            ap(-thK * ld / RK)
            # mkt_PK
            ap(-1.0); ap(self.one_m_delta); ap(1.0); ap(-1.0)
            # mkt_PKT
            ap(self.one_m_delta); ap(1.0); ap(-1.0)
            # mkt_PU
            HA = v["HA"][0]
            PUt = v["PU"]
            ap(1.0); ap(-self.theta_t / PUt); ap(self.theta_t * HA / (PUt * PUt))
            # inc_HA
            tauK = self.policy["tauK"]
            lscale = self.policy["lscale"]
            ap(1.0)
            ap(-lscale * self.L0 * self.qref)
            ap(-d["K0"])
            ap(v["TK"])
            ap(v["PKT"])
            # tax revenue tauK RK kd = tauK (rbar+delta)/(1+tauK) K0 Y c
            base = tauK * self.rd / (1.0 + tauK) * d["K0"][s]
            ap(-base * c)
            ap(-base * Y * thL * c / PL)
            ap(-base * Y * thK * c / RK)
        return self.pat.assemble(vals)

    # ------------------------------------------------------------------------------------
    def benchmark(self):
        T, N = self.T, self.N
        d = self.d
        z = np.empty(self.n)
        b = self.blocks
        q = np.repeat(self.qref, N)
        p = np.repeat(self.pref, N)
        z[b["Y"]] = q
        z[b["I"]] = np.tile(d["I0"], T) * q
        z[b["K"]] = np.tile(d["K0"], T) * q
        z[b["C"]] = self.C0 * self.qref
        z[b["TK"]] = d["K0"] * self.qT
        z[b["P"]] = p
        z[b["RK"]] = self.rd * p
        z[b["PL"]] = self.pref
        z[b["PK"]] = (1.0 + self.d["rbar"]) * p
        z[b["PU"]] = self.pref
        z[b["PKT"]] = self.pref[-1]
        z[b["HA"]] = self.HA0
        return z

    def names(self):
        T, N = self.T, self.N
        if N == 1:
            st = [f"t{t}" for t in range(T)]
            sec = ["s1"]
        else:
            st = [f"s{s + 1},t{t}" for t in range(T) for s in range(N)]
            sec = [f"s{s + 1}" for s in range(N)]
        tt = [f"t{t}" for t in range(T)]
        lab = {"Y": st, "I": st, "K": st, "P": st, "RK": st, "PK": st, "C": tt, "PL": tt,
               "PU": tt, "TK": sec if N > 1 else None, "PKT": sec if N > 1 else None,
               "HA": None}
        var, row = [], []
        for b in BLOCKS:
            if lab[b] is None:
                var.append(b)
                row.append(ROWS[b])
            else:
                var += [f"{b}[{x}]" for x in lab[b]]
                row += [f"{ROWS[b]}[{x}]" for x in lab[b]]
        return var, row

    def make_model(self, *, numeraire, price_lb, income_free, start, numeraire_value,
                   shock_text):
        n = self.n
        zbar = self.benchmark()
        names, row_names = self.names()
        lb = np.zeros(n)
        ub = np.full(n, np.inf)
        for b in PRICE_BLOCKS:
            lb[self.blocks[b]] = price_lb
        lb[self.blocks["TK"]] = -np.inf
        if income_free:
            lb[self.blocks["HA"]] = -np.inf
        ray = np.zeros(n, dtype=bool)
        for b in PRICE_BLOCKS + ("HA",):
            ray[self.blocks[b]] = True
        degree = np.empty(n)
        for b in BLOCKS:
            degree[self.blocks[b]] = DEGREE[b]
        x0 = zbar if start is None else np.asarray(start, dtype=float).copy()
        num_idx = None
        num_text = ("none: the model is homogeneous of degree 0 in prices and income, so its "
                    "Jacobian is singular along the price ray at every solution")
        if numeraire is not None:
            if numeraire == "auto":
                num_idx, how = self.blocks["HA"].start, "income of the representative agent"
            else:
                kind, name = numeraire
                num_idx = names.index(name)
                if not ray[num_idx]:
                    raise ValueError(f"{name} is not a price or income")
                how = kind
            x0, num_text = fix_numeraire(lb, ub, x0, num_idx, how, numeraire_value, names,
                                         row_names)
        d = self.d
        info = {
            "family": "ramsey_cge", "periods": self.T, "sectors": self.N,
            "n": n, "nnz": self.pat.nnz, "numeraire": num_text, "numeraire_index": num_idx,
            "gamma": d["gamma"], "rbar": d["rbar"], "delta": d["delta"],
            "K0": d["K0"].copy(), "I0": d["I0"].copy(), "L0": d["L0s"].copy(),
            "X": d["X"].copy(), "C0": self.C0, "HA0": self.HA0, "qref": self.qref.copy(),
            "pref": self.pref.copy(), "policy": dict(self.policy), "seed": d["seed"],
            "price_lb": price_lb, "income_free": income_free,
            "benchmark_is_solution": shock_text is None,
            "shock": shock_text,
        }
        return assemble_model(
            self, lb=lb, ub=ub, x0=x0, names=names, row_names=row_names, degree=degree,
            ray=ray, num_idx=num_idx, info=info, shock_text=shock_text,
            spec=dict(numeraire=numeraire, price_lb=price_lb, income_free=income_free))

    def after_shock(self, shock):
        """(evaluator under the shocked policy, description); shock None: same policy."""
        pol = dict(self.policy)
        if not shock:
            return _RamseyEvaluator(self.d, pol), None
        unknown = set(shock) - {"capital_tax", "labour"}
        if unknown:
            raise ValueError(f"unknown shock(s) {sorted(unknown)}: use capital_tax= or labour=")
        if "capital_tax" in shock:
            pol["tauK"] = float(shock["capital_tax"])
        if "labour" in shock:
            pol["lscale"] = pol["lscale"] * float(shock["labour"])
        return _RamseyEvaluator(self.d, pol), "shock: " + ", ".join(sorted(shock))
