"""Static multi-region, multi-household CGE models in calibrated share form (MCP).

Model (per region r; sectors i, j; factors f; households h; trade links l = (i, s -> r)):

Variables (block, bounds, benchmark)::

    Y[r,j]   activity level of sector j           >= 0     1
    A[r,i]   Armington aggregation activity        >= 0     1
    U[r,h]   utility (welfare) activity of h       >= 0     1
    P[r,i]   producer (output) price                >= plb   1
    PA[r,i]  Armington composite price              >= plb   1
    W[r,f]   factor price                           >= plb   1
    PU[r,h]  unit-expenditure (utility) price      >= plb   1
    TR[r]    tax revenue (output taxes + tariffs)   free     benchmark revenue
    M[r,h]   household income                       free (or >= 0)   M-bar

Rows, in value units at benchmark prices (row k is complementary to variable k)::

    prf_Y  sum_i Z_ij PA_i + VA_j cva_j(W) - (1 - t_j) phi_j X_j P_j              >= 0
    prf_A  U_i [cA_i(P_s (1 + tm_l), l into (r,i)) - PA_i]                         >= 0
    prf_U  M-bar_h [e_h(PA) - PU_h]                                               >= 0
    mkt_P  phi_i X_i Y_i - sum_{l from (s,i)} A_ri T_l (PA_ri / (P_si (1+tm_l)))^sA  >= 0
    mkt_PA U_i A_i - sum_j Z_ij Y_j - sum_h D_hi U_h (PU_h / PA_i)^sC_h              >= 0
    mkt_W  eps_f E_f - sum_j Y_j FV_jf (cva_j / W_f)^sVA_j                           >= 0
    mkt_PU M-bar_h U_h - M_h / PU_h                                               >= 0
    bal_TR TR - sum_j t_j phi_j X_j P_j Y_j - sum_l tm_l P_s A_r T_l (PA/(P(1+tm)))^sA = 0
    inc_M  M_h - sum_f omega_hf eps_f E_f W_f - tau_h TR - b_h P_num                  = 0

cva, cA, e are calibrated CES unit functions (Cobb-Douglas at sigma = 1, Leontief at 0) with
benchmark value 1.  Armington and household demands use the price-index variables PA and PU
(the "implicit-variable" form), which keeps every row sparse: at an equilibrium PA = cA and
PU = e, so it is the same equilibrium as the compact form.  Output taxes and tariffs go to
TR; each region's imbalance B_r (sum_r B_r = 0) is paid to its households as an endowment of
the numeraire good P[r1,s1] (GTAP convention).  Benchmark: every activity and price 1,
TR = benchmark revenue, M = M-bar: an exact solution by construction.

Numeraire (as in MPSGE): by default the income of the largest household is fixed at its
benchmark value (lb = ub); its row is then implied by Walras' law.  ``numeraire=None`` keeps
the homogeneous (singular) model.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


from ._assembly import CESGroups, PatternAssembler, group_pairs
from .model import CGEModel, assemble_model, fix_numeraire
from .sam import SAM, random_sam

__all__ = ["static_cge", "static_from_sam", "size_for", "static_size"]

BLOCKS = ("Y", "A", "U", "P", "PA", "W", "PU", "TR", "M")
ROWS = {"Y": "prf_Y", "A": "prf_A", "U": "prf_U", "P": "mkt_P", "PA": "mkt_PA", "W": "mkt_W",
        "PU": "mkt_PU", "TR": "bal_TR", "M": "inc_M"}
QUANTITY_BLOCKS = ("Y", "A", "U")
DEGREE = {"Y": 1, "A": 1, "U": 1, "P": 0, "PA": 0, "W": 0, "PU": 0, "TR": 1, "M": 1}


@dataclass(frozen=True)
class Policy:
    """Parameters a shock may change (the calibration data stay fixed)."""

    t: np.ndarray  # (R*N,) output tax rates
    tm: np.ndarray  # (links,) ad-valorem tariffs (0 on home links)
    phi: np.ndarray  # (R*N,) productivity (output per unit of activity, relative)
    eps: np.ndarray  # (R*F,) factor endowment scale
    bscale: np.ndarray  # (R,) scale of the imbalance endowment B_r


def static_size(regions: int, sectors: int, factors: int = 2, households: int = 1) -> int:
    """Number of variables n = R (4N + F + 3H + 1)."""
    return regions * (4 * sectors + factors + 3 * households + 1)


def size_for(n_target: int, *, factors: int = 3, households: int | None = None,
             regions: int | None = None, sectors: int | None = None) -> dict:
    """Keyword arguments of :func:`static_cge` giving n close to ``n_target``.

    Models grow the way real ones do: by regions (states, countries) with a sparse trade
    graph, not by sectors.  Sectors stay at a GTAP/WiNDC-like count (about 60; fewer for
    small models), because a random input-output block of many hundreds of sectors fills
    in catastrophically under sparse LU (measured: R=4, N=620, n=1e4 gave 1.8e7 nonzeros
    in L+U from 1.3e5 in J).  Households 1-5.  Trade partners: min(R-1, 3) up to 4
    regions, then 1 — a random trade graph of degree 4 over 40 regions is an expander whose
    LU fills globally (measured: 3.5e7 nonzeros in L+U at n=1e4 against 2.4e6 with one
    partner; n=1e5 with one partner: 2.3e7 nonzeros, 1.5 s per factorization).
    Examples: size_for(1e3) -> R=4, N=60; size_for(1e4) -> R=40, N=60;
    size_for(1e5) -> R=400, N=60.
    """
    n_target = int(n_target)
    if households is None:
        households = 1 if n_target <= 300 else 3 if n_target <= 3000 else 5
    if sectors is None:
        sectors = int(min(60, max(2, round((n_target - factors - 3 * households - 1) / 4))))
    per_region = 4 * sectors + factors + 3 * households + 1
    if regions is None:
        regions = max(1, int(round(n_target / per_region)))
    return {"regions": int(regions), "sectors": int(sectors), "factors": int(factors),
            "households": int(households),
            "trade_partners": min(regions - 1, 3) if regions <= 4 else 1}


def _elasticity(val, shape, rng, name):
    """Scalar, array, or 'mixed' (random draw from {0, 0.5, 1, 2}) -> array of shape."""
    if isinstance(val, str):
        if val != "mixed":
            raise ValueError(f"{name} must be a number, an array or 'mixed'")
        return rng.choice(np.array([0.0, 0.5, 1.0, 2.0]), size=shape)
    arr = np.broadcast_to(np.asarray(val, dtype=float), shape).copy()
    if np.any(arr < 0):
        raise ValueError(f"{name} must be >= 0")
    return arr


def static_cge(
    regions: int = 1,
    sectors: int = 10,
    factors: int = 2,
    households: int = 1,
    *,
    trade_partners: int | None = None,
    io_density: int | float = 4,
    sigma_va=0.8,
    sigma_armington=2.0,
    sigma_consumer=0.5,
    taxes: bool = True,
    numeraire="auto",
    price_lb: float = 0.0,
    income_free: bool = True,
    seed: int = 0,
) -> CGEModel:
    """A calibrated static CGE model with known benchmark equilibrium.

    Parameters
    ----------
    regions, sectors, factors, households : R, N, F, H (households per region).
    trade_partners : m, regions each region imports from (default min(R - 1, 4)).
    io_density : nonzeros per column of the input-output matrix (int) or fraction of N.
    sigma_va : value-added elasticity: scalar, array (R, N), or 'mixed'.  0 = Leontief,
        1 = Cobb-Douglas, otherwise CES.
    sigma_armington : Armington elasticity: scalar, array (R, N) or 'mixed'.
    sigma_consumer : household demand elasticity: scalar, array (R, H) or 'mixed'.
    taxes : draw benchmark output taxes (revenue to households).
    numeraire : 'auto' (fix the income of the largest household, as MPSGE does),
        ('price', name) or ('income', name) to fix that variable at its benchmark value, or
        None for the homogeneous (singular) model.
    price_lb : lower bound of every price (0 is standard; a tiny positive value guards
        p^(-sigma) terms).
    income_free : incomes M free (default) or M >= 0.
    seed : all random draws (SAM, elasticity mixes) follow from it.
    """
    sam = random_sam(regions, sectors, factors, households, trade_partners=trade_partners,
                     io_density=io_density, taxes=taxes, seed=seed)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7]))
    R, N, H = sam.R, sam.N, sam.H
    s_va = _elasticity(sigma_va, (R, N), rng, "sigma_va").ravel()
    s_a = _elasticity(sigma_armington, (R, N), rng, "sigma_armington").ravel()
    s_c = _elasticity(sigma_consumer, (R, H), rng, "sigma_consumer").ravel()
    return static_from_sam(sam, sigma_va=s_va, sigma_armington=s_a, sigma_consumer=s_c,
                           numeraire=numeraire, price_lb=price_lb, income_free=income_free)


def static_from_sam(sam: SAM, *, sigma_va, sigma_armington, sigma_consumer, numeraire="auto",
                    price_lb: float = 0.0, income_free: bool = True, policy: Policy | None = None,
                    start=None, numeraire_value=None, shock_text=None) -> CGEModel:
    """Build the MCP from a SAM (see the module docstring for the equations)."""
    ev = _StaticEvaluator(sam, sigma_va, sigma_armington, sigma_consumer, policy)
    return ev.make_model(numeraire=numeraire, price_lb=price_lb, income_free=income_free,
                         start=start, numeraire_value=numeraire_value, shock_text=shock_text)


class _StaticEvaluator:
    def __init__(self, sam: SAM, s_va, s_a, s_c, policy: Policy | None):
        R, N, F, H = sam.R, sam.N, sam.F, sam.H
        RN, RF, RH = R * N, R * F, R * H
        self.sam = sam
        self.R, self.N, self.F, self.H = R, N, F, H
        self.s_va = np.broadcast_to(np.asarray(s_va, float), (RN,)).copy()
        self.s_a = np.broadcast_to(np.asarray(s_a, float), (RN,)).copy()
        self.s_c = np.broadcast_to(np.asarray(s_c, float), (RH,)).copy()
        L = sam.l_i.size
        if policy is None:
            policy = Policy(t=sam.t.copy(), tm=np.zeros(L), phi=np.ones(RN), eps=np.ones(RF),
                            bscale=np.ones(R))
        self.policy = policy

        sizes = {"Y": RN, "A": RN, "U": RH, "P": RN, "PA": RN, "W": RF, "PU": RH, "TR": R,
                 "M": RH}
        off = 0
        self.blocks = {}
        for b in BLOCKS:
            self.blocks[b] = slice(off, off + sizes[b])
            off += sizes[b]
        self.n = off
        self.shapes = {"Y": (R, N), "A": (R, N), "U": (R, H), "P": (R, N), "PA": (R, N),
                       "W": (R, F), "PU": (R, H), "TR": (R,), "M": (R, H)}
        o = {b: self.blocks[b].start for b in BLOCKS}
        self.o = o

        # --- data -------------------------------------------------------------------------
        self.X, self.VA, self.U = sam.X, sam.VA, sam.U
        self.z_yi = sam.io_r * N + sam.io_j  # sector using the input (Y index)
        self.z_pa = sam.io_r * N + sam.io_i  # commodity used (PA index)
        self.Z = sam.io_Z
        # value-added nest: group = sector (r, j), elements = factors
        self.va_g = np.repeat(np.arange(RN), F)
        self.va_w = (np.arange(RN) // N).repeat(F) * F + np.tile(np.arange(F), RN)
        self.va_FV = sam.FV.ravel()
        va_theta = self.va_FV / self.VA[self.va_g]
        self.cva = CESGroups(self.va_g, va_theta, self.s_va, RN)
        self.va_e1, self.va_e2 = group_pairs(self.va_g, RN)
        # Armington: group = (r, i) absorbing, elements = links
        self.l_src = sam.l_s * N + sam.l_i
        self.l_dst = sam.l_r * N + sam.l_i
        self.l_r = sam.l_r
        self.l_T = sam.l_T
        self.foreign = np.flatnonzero(sam.l_s != sam.l_r)
        self.cA = CESGroups(self.l_dst, self.l_T / self.U[self.l_dst], self.s_a, RN)
        self.sig_l = self.s_a[self.l_dst]
        # households: group = (r, h), elements = goods of region r
        self.c_g = np.repeat(np.arange(RH), N)
        self.c_pa = (np.arange(RH) // H).repeat(N) * N + np.tile(np.arange(N), RH)
        self.c_D = sam.D.ravel()
        self.Mbar = sam.M
        self.e = CESGroups(self.c_g, self.c_D / self.Mbar[self.c_g], self.s_c, RH)
        self.sig_ce = self.s_c[self.c_g]
        # incomes
        self.E = sam.E
        self.inc_g = np.repeat(np.arange(RH), F)
        self.inc_w = (np.arange(RH) // H).repeat(F) * F + np.tile(np.arange(F), RH)
        self.inc_om = sam.omega.ravel()
        self.hreg = np.arange(RH) // H
        self.sreg = np.arange(RN) // N
        self.tau = sam.tau
        self.bval = sam.bshare * sam.B[self.hreg]
        self.num_good = 0  # P[r1,s1] index within the P block
        self.open = R > 1
        self._build_pattern()

    # --- pattern ----------------------------------------------------------------------------
    def _build_pattern(self):
        o = self.o
        R, N, F, H = self.R, self.N, self.F, self.H
        RN, RH = R * N, R * H
        ar_RN, ar_RH, ar_R = np.arange(RN), np.arange(RH), np.arange(R)
        pa = PatternAssembler(self.n)
        add = pa.add
        # prf_Y
        add("Y_PA", o["Y"] + self.z_yi, o["PA"] + self.z_pa, const=True)
        add("Y_W", o["Y"] + self.va_g, o["W"] + self.va_w)
        add("Y_P", o["Y"] + ar_RN, o["P"] + ar_RN, const=True)
        # prf_A
        add("A_P", o["A"] + self.l_dst, o["P"] + self.l_src)
        add("A_PA", o["A"] + ar_RN, o["PA"] + ar_RN, const=True)
        # prf_U
        add("U_PA", o["U"] + self.c_g, o["PA"] + self.c_pa)
        add("U_PU", o["U"] + ar_RH, o["PU"] + ar_RH, const=True)
        # mkt_P
        add("P_Y", o["P"] + ar_RN, o["Y"] + ar_RN, const=True)
        add("P_A", o["P"] + self.l_src, o["A"] + self.l_dst)
        add("P_PA", o["P"] + self.l_src, o["PA"] + self.l_dst)
        add("P_P", o["P"] + self.l_src, o["P"] + self.l_src)
        # mkt_PA
        add("PA_A", o["PA"] + ar_RN, o["A"] + ar_RN, const=True)
        add("PA_Y", o["PA"] + self.z_pa, o["Y"] + self.z_yi, const=True)
        add("PA_U", o["PA"] + self.c_pa, o["U"] + self.c_g)
        add("PA_PU", o["PA"] + self.c_pa, o["PU"] + self.c_g)
        add("PA_PA", o["PA"] + self.c_pa, o["PA"] + self.c_pa)
        # mkt_W
        add("W_Y", o["W"] + self.va_w, o["Y"] + self.va_g)
        add("W_W", o["W"] + self.va_w[self.va_e1], o["W"] + self.va_w[self.va_e2])
        # mkt_PU
        add("PU_U", o["PU"] + ar_RH, o["U"] + ar_RH, const=True)
        add("PU_M", o["PU"] + ar_RH, o["M"] + ar_RH)
        add("PU_PU", o["PU"] + ar_RH, o["PU"] + ar_RH)
        # bal_TR
        add("TR_TR", o["TR"] + ar_R, o["TR"] + ar_R, const=True)
        add("TR_P", o["TR"] + self.sreg, o["P"] + ar_RN)
        add("TR_Y", o["TR"] + self.sreg, o["Y"] + ar_RN)
        fl = self.foreign
        if fl.size:
            add("TR_tA", o["TR"] + self.l_r[fl], o["A"] + self.l_dst[fl])
            add("TR_tPA", o["TR"] + self.l_r[fl], o["PA"] + self.l_dst[fl])
            add("TR_tP", o["TR"] + self.l_r[fl], o["P"] + self.l_src[fl])
        # inc_M
        add("M_M", o["M"] + ar_RH, o["M"] + ar_RH, const=True)
        add("M_W", o["M"] + self.inc_g, o["W"] + self.inc_w, const=True)
        add("M_TR", o["M"] + ar_RH, o["TR"] + self.hreg, const=True)
        if self.open:
            add("M_Pnum", o["M"] + ar_RH, np.full(RH, o["P"] + self.num_good), const=True)
        self.pat = pa.finalize()

    # --- evaluation ---------------------------------------------------------------------
    def _unpack(self, z):
        b = self.blocks
        return (z[b["Y"]], z[b["A"]], z[b["U"]], z[b["P"]], z[b["PA"]], z[b["W"]], z[b["PU"]],
                z[b["TR"]], z[b["M"]])

    def _common(self, z):
        Y, A, Uu, P, PA, W, PU, TR, M = self._unpack(z)
        pol = self.policy
        xw = W[self.va_w]
        cva = self.cva.value(xw)
        q = P[self.l_src] * (1.0 + pol.tm)
        cA = self.cA.value(q)
        xpa = PA[self.c_pa]
        e = self.e.value(xpa)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rho = np.power(PA[self.l_dst] / q, self.sig_l)  # Armington demand factor
            rhoc = np.power(PU[self.c_g] / xpa, self.sig_ce)  # household demand factor
        return (Y, A, Uu, P, PA, W, PU, TR, M, xw, cva, q, cA, xpa, e, rho, rhoc)

    def eval_F(self, z):
        z = np.asarray(z, dtype=float)
        (Y, A, Uu, P, PA, W, PU, TR, M, xw, cva, q, cA, xpa, e, rho, rhoc) = self._common(z)
        pol = self.policy
        RN, RH, RF, R = self.R * self.N, self.R * self.H, self.R * self.F, self.R
        out = np.empty(self.n)
        b = self.blocks
        phX = pol.phi * self.X
        out[b["Y"]] = (np.bincount(self.z_yi, self.Z * PA[self.z_pa], minlength=RN)
                       + self.VA * cva - (1.0 - pol.t) * phX * P)
        out[b["A"]] = self.U * (cA - PA)
        out[b["U"]] = self.Mbar * (e - PU)
        dem = A[self.l_dst] * self.l_T * rho
        out[b["P"]] = phX * Y - np.bincount(self.l_src, dem, minlength=RN)
        dc = self.c_D * Uu[self.c_g] * rhoc
        out[b["PA"]] = (self.U * A - np.bincount(self.z_pa, self.Z * Y[self.z_yi], minlength=RN)
                        - np.bincount(self.c_pa, dc, minlength=RN))
        fd = self.va_FV * self.cva.ratio_pow(cva, xw)
        out[b["W"]] = pol.eps * self.E - np.bincount(self.va_w, Y[self.va_g] * fd, minlength=RF)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[b["PU"]] = self.Mbar * Uu - M / PU
        rev = np.bincount(self.sreg, pol.t * phX * P * Y, minlength=R)
        fl = self.foreign
        if fl.size:
            rev += np.bincount(self.l_r[fl], pol.tm[fl] * P[self.l_src[fl]] * dem[fl], minlength=R)
        out[b["TR"]] = TR - rev
        inc = np.bincount(self.inc_g, self.inc_om * (pol.eps * self.E * W)[self.inc_w],
                          minlength=RH) + self.tau * TR[self.hreg]
        if self.open:
            inc = inc + self.bval * pol.bscale[self.hreg] * P[self.num_good]
        out[b["M"]] = M - inc
        return out

    def eval_J(self, z):
        z = np.asarray(z, dtype=float)
        (Y, A, Uu, P, PA, W, PU, TR, M, xw, cva, q, cA, xpa, e, rho, rhoc) = self._common(z)
        pol = self.policy
        phX = pol.phi * self.X
        vals = []
        ap = vals.append
        # prf_Y
        ap(self.Z)
        dcva = self.cva.grad(cva, xw)
        ap(self.VA[self.va_g] * dcva)
        ap(-(1.0 - pol.t) * phX)
        # prf_A
        dcA = self.cA.grad(cA, q)
        ap(self.U[self.l_dst] * dcA * (1.0 + pol.tm))
        ap(-self.U)
        # prf_U
        ap(self.Mbar[self.c_g] * self.e.grad(e, xpa))
        ap(-self.Mbar)
        # mkt_P
        ap(phX)
        dem = A[self.l_dst] * self.l_T * rho
        sig = self.sig_l
        with np.errstate(divide="ignore", invalid="ignore"):
            sdem_pa = np.where(sig > 0, sig * dem / PA[self.l_dst], 0.0)
            sdem_p = np.where(sig > 0, sig * dem / P[self.l_src], 0.0)
        ap(-self.l_T * rho)
        ap(-sdem_pa)
        ap(sdem_p)
        # mkt_PA
        ap(self.U)
        ap(-self.Z)
        dc = self.c_D * Uu[self.c_g] * rhoc
        sc = self.sig_ce
        with np.errstate(divide="ignore", invalid="ignore"):
            ap(-self.c_D * rhoc)
            ap(-np.where(sc > 0, sc * dc / PU[self.c_g], 0.0))
            ap(np.where(sc > 0, sc * dc / xpa, 0.0))
        # mkt_W: demand d_e = Y_g FV_e c_g^s W_e^-s
        rp = self.cva.ratio_pow(cva, xw)
        fd = self.va_FV * rp
        ap(-fd)
        Yg = Y[self.va_g]
        s_e = self.cva.sig_e
        e1, e2 = self.va_e1, self.va_e2
        with np.errstate(divide="ignore", invalid="ignore"):
            # d d_e1 / d W_e2 = Y s d_e1/c * dc/dW_e2 - delta Y s d_e1 / W_e1
            cross = np.where(s_e[e1] > 0, Yg[e1] * s_e[e1] * fd[e1] / cva[self.va_g[e1]]
                             * dcva[e2], 0.0)
            diag = np.where(s_e > 0, Yg * s_e * fd / xw, 0.0)
        ww = -cross
        ww = ww + np.where(e1 == e2, diag[e1], 0.0)
        ap(ww)
        # mkt_PU
        ap(self.Mbar)
        with np.errstate(divide="ignore", invalid="ignore"):
            ap(-1.0 / PU)
            ap(M / (PU * PU))
        # bal_TR
        ap(1.0)
        ap(-pol.t * phX * Y)
        ap(-pol.t * phX * P)
        fl = self.foreign
        if fl.size:
            tmf = pol.tm[fl]
            Ps = P[self.l_src[fl]]
            ap(-tmf * Ps * self.l_T[fl] * rho[fl])
            ap(-tmf * Ps * sdem_pa[fl])
            ap(-tmf * dem[fl] * (1.0 - sig[fl]))
        # inc_M
        ap(1.0)
        ap(-self.inc_om * (pol.eps * self.E)[self.inc_w])
        ap(-self.tau)
        if self.open:
            ap(-self.bval * pol.bscale[self.hreg])
        return self.pat.assemble(vals)

    # --- model ----------------------------------------------------------------------------
    def benchmark(self):
        z = np.ones(self.n)
        z[self.blocks["TR"]] = self.sam.TR
        z[self.blocks["M"]] = self.Mbar
        return z

    def names(self):
        R, N, F, H = self.R, self.N, self.F, self.H
        rs = [f"r{r + 1}" for r in range(R)]
        lab = {
            "Y": [f"{r},s{i + 1}" for r in rs for i in range(N)],
            "U": [f"{r},h{h + 1}" for r in rs for h in range(H)],
            "W": [f"{r},f{f + 1}" for r in rs for f in range(F)],
            "TR": rs,
        }
        lab["A"] = lab["P"] = lab["PA"] = lab["Y"]
        lab["PU"] = lab["M"] = lab["U"]
        var, row = [], []
        for b in BLOCKS:
            var += [f"{b}[{s}]" for s in lab[b]]
            row += [f"{ROWS[b]}[{s}]" for s in lab[b]]
        return var, row

    def make_model(self, *, numeraire, price_lb, income_free, start, numeraire_value,
                   shock_text):
        n = self.n
        zbar = self.benchmark()
        names, row_names = self.names()
        lb = np.zeros(n)
        ub = np.full(n, np.inf)
        for b in ("P", "PA", "W", "PU"):
            lb[self.blocks[b]] = price_lb
        lb[self.blocks["TR"]] = -np.inf
        if income_free:
            lb[self.blocks["M"]] = -np.inf
        ray = np.ones(n, dtype=bool)
        for b in QUANTITY_BLOCKS:
            ray[self.blocks[b]] = False
        degree = np.empty(n)
        for b in BLOCKS:
            degree[self.blocks[b]] = DEGREE[b]
        x0 = zbar if start is None else np.asarray(start, dtype=float)

        num_idx, num_text = None, "none: the model is homogeneous of degree 0 in prices and " \
            "incomes, so its Jacobian is singular along the price ray at every solution"
        if numeraire is not None:
            if numeraire == "auto":
                h = int(np.argmax(self.Mbar))
                num_idx = self.blocks["M"].start + h
                how = "income of the largest household"
            else:
                kind, name = numeraire
                if kind not in ("price", "income"):
                    raise ValueError("numeraire must be 'auto', None, ('price', name) or "
                                     "('income', name)")
                num_idx = names.index(name)
                blk = next(b for b in BLOCKS
                           if self.blocks[b].start <= num_idx < self.blocks[b].stop)
                if kind == "price" and blk not in ("P", "PA", "W", "PU"):
                    raise ValueError(f"{name} is not a price")
                if kind == "income" and blk != "M":
                    raise ValueError(f"{name} is not an income")
                how = kind
            x0, num_text = fix_numeraire(lb, ub, x0, num_idx, how, numeraire_value, names,
                                         row_names)

        R, N, F, H = self.R, self.N, self.F, self.H
        info = {
            "family": "static_cge",
            "regions": R, "sectors": N, "factors": F, "households": H,
            "trade_partners": self.sam.info["m"], "io_density": self.sam.info["k"],
            "n": n, "nnz": self.pat.nnz, "nnz_coo_terms": self.pat.ncoo,
            "numeraire": num_text, "numeraire_index": num_idx,
            "numeraire_good": names[self.blocks["P"].start + self.num_good] if self.open else None,
            "sigma_va": self.s_va, "sigma_armington": self.s_a, "sigma_consumer": self.s_c,
            "seed": self.sam.seed, "sam": self.sam, "policy": self.policy,
            "price_lb": price_lb, "income_free": income_free,
            "benchmark_is_solution": shock_text is None,
            "shock": shock_text,
            "imbalance": self.sam.B.copy(),
        }
        return assemble_model(
            self, lb=lb, ub=ub, x0=x0, names=names, row_names=row_names, degree=degree,
            ray=ray, num_idx=num_idx, info=info, shock_text=shock_text,
            spec=dict(numeraire=numeraire, price_lb=price_lb, income_free=income_free))

    def after_shock(self, shock):
        """(evaluator under the shocked policy, description); shock None: same policy."""
        pol, desc = self.policy, None
        if shock:
            pol, desc = self._apply_shock(pol, **shock)
        return _StaticEvaluator(self.sam, self.s_va, self.s_a, self.s_c, pol), desc

    # --- shocks -----------------------------------------------------------------------------
    def _apply_shock(self, pol: Policy, *, output_tax=None, tariff=None, endowment=None,
                     balance=None, productivity=None):
        R, N, F = self.R, self.N, self.F
        desc = []
        new = {}
        if output_tax is not None:
            t = np.broadcast_to(np.asarray(output_tax, float), (R, N)).ravel().copy()
            if np.any(t >= 1):
                raise ValueError("output tax rates must be < 1")
            new["t"] = t
            desc.append("output_tax")
        if tariff is not None:
            if isinstance(tariff, tuple) and len(tariff) == 2 and np.ndim(tariff[1]) == 0:
                reg, rate = tariff
                reg = self._region(reg)
                tm = pol.tm.copy()
                sel = (self.sam.l_r == reg) & (self.sam.l_s != reg)
                tm[sel] = float(rate)
                desc.append(f"tariff {rate:g} on imports of r{reg + 1}")
            else:
                tm = np.broadcast_to(np.asarray(tariff, float), pol.tm.shape).copy()
                tm[self.sam.l_s == self.sam.l_r] = 0.0
                desc.append("tariffs")
            if np.any(tm <= -1):
                raise ValueError("tariffs must be > -1")
            new["tm"] = tm
        if endowment is not None:
            new["eps"] = pol.eps * np.broadcast_to(np.asarray(endowment, float), (R, F)).ravel()
            desc.append("endowment")
        if balance is not None:
            new["bscale"] = pol.bscale * np.broadcast_to(np.asarray(balance, float), (R,))
            desc.append("balance")
        if productivity is not None:
            new["phi"] = pol.phi * np.broadcast_to(np.asarray(productivity, float), (R, N)).ravel()
            desc.append("productivity")
        if not desc:
            raise ValueError("no shock given: use output_tax=, tariff=(region, rate), "
                             "endowment=, balance= or productivity=")
        return replace(pol, **new), "shock: " + ", ".join(desc)

    def _region(self, reg):
        if isinstance(reg, str):
            return int(reg.lstrip("r")) - 1
        return int(reg)
