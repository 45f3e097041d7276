"""A multi-region model of any size from a synthetic balanced accounting matrix.

Regions r, sectors s (one good each), households h per region, two factors per region:

* Y[r.s]: Leontief in ``n_inputs`` Armington goods PA[r.i] and a Cobb–Douglas value-added
  nest of labour PL[r] and capital PK[r]; output PY[r.s];
* A[r.s]: Armington supply of PA[r.s], CES (σ = 2) between the domestic good PY[r.s] and
  a nest (σ = 4) of imports PY[r'.s] from ``n_partners`` partner regions, each paying the
  ad-valorem tariff ``tm`` to the importing region's government;
* HH[r.h]: households endowed with labour and capital, nested CES final demand (σ = 1 at
  the top over a goods nest of σ = 0.5); GOV[r]: spends the tariff revenue (Cobb–Douglas).

The benchmark data are drawn at random and balanced by construction: every region's
trade is balanced at world prices (flows symmetric between partners), intermediate use
stays below domestic supply, and households' demands are made to add up to both the
region's final demand and each household's income by biproportional (RAS) scaling.  The
reference point (all prices and activities 1) therefore solves the model to rounding.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .model import Model


def _partners(R, k, rng):
    """A symmetric partner graph: region r trades with r ± 1, ..., r ± k/2 (mod R)."""
    half = max(1, min(k // 2, (R - 1) // 2)) if R > 1 else 0
    src, dst = [], []
    for d in range(1, half + 1):
        r = np.arange(R)
        src += [r, r]
        dst += [(r + d) % R, (r - d) % R]
    if not src:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pairs = np.unique(np.stack([np.concatenate(src), np.concatenate(dst)]), axis=1)
    return pairs[0], pairs[1]


def synthetic_data(R, S, H, n_inputs=5, n_partners=4, tariff=0.1, seed=0):
    """Balanced benchmark flows (see module doc) as a dict of arrays."""
    rng = np.random.default_rng(seed)
    RS = R * S
    y0 = rng.uniform(1.0, 1.5, (R, S))
    # Intermediate inputs: n_inputs goods per sector, 25% of output in total.
    k = min(n_inputs, S)
    cols = np.argsort(rng.random((RS, S)), axis=1)[:, :k]
    w = rng.uniform(0.5, 1.5, (RS, k))
    w *= 0.25 / w.sum(axis=1, keepdims=True)
    rows = np.repeat(np.arange(RS), k)
    reg = rows // S
    idq = sp.csr_matrix((w.ravel() * y0.ravel()[rows], (rows, reg * S + cols.ravel())),
                        shape=(RS, RS))
    va = 0.75 * y0.ravel()
    lab = rng.uniform(0.4, 0.7, RS)
    # Trade: symmetric flows between partners, at most 20% of output exported.
    src, dst = _partners(R, n_partners, rng)
    n_arcs = src.shape[0]
    key = np.minimum(src, dst) * R + np.maximum(src, dst)
    _, inv = np.unique(key, return_inverse=True)
    sym = rng.uniform(0.5, 1.0, (int(inv.max()) + 1 if n_arcs else 0, S))[inv]
    deg = np.bincount(src, minlength=R) if n_arcs else np.zeros(R)
    scale = 0.2 * y0.min() / max(1.0, float(deg.max()))
    trade = sym * scale                                  # (arc, s): src exports to dst
    exports = np.zeros((R, S))
    imports = np.zeros((R, S))
    np.add.at(exports, src, trade)
    np.add.at(imports, dst, trade)
    dom = y0 - exports
    tm0 = np.full((n_arcs, S), tariff)
    tariff_rev = np.zeros((R, S))
    np.add.at(tariff_rev, dst, trade * tm0)
    a0 = dom + imports + tariff_rev
    inter = np.asarray(idq.sum(axis=0)).reshape(R, S)     # use of PA[r.i] by sectors
    final = a0 - inter
    assert final.min() > 0, "intermediate use exceeds supply (raise output or lower use)"
    gov_income = tariff_rev.sum(axis=1)
    gov = final * (gov_income / final.sum(axis=1))[:, None]
    hh_total = final - gov                               # (R, S), sums to VA per region
    share = rng.uniform(0.5, 1.5, (R, H))
    share /= share.sum(axis=1, keepdims=True)
    va_r = va.reshape(R, S).sum(axis=1)
    c = _ras(rng.uniform(0.5, 1.5, (R, H, S)), hh_total, share * va_r[:, None])
    return {"R": R, "S": S, "H": H, "y0": y0, "idq": idq, "va": va, "lab": lab, "src": src, "dst": dst,
                "trade": trade, "tm0": tm0, "dom": dom, "a0": a0, "gov": gov, "c": c, "share": share,
                "labour": (va * lab).reshape(R, S).sum(axis=1),
                "capital": (va * (1 - lab)).reshape(R, S).sum(axis=1)}


def _ras(seed, col_totals, row_totals, iters=200):
    """Scale seed[r, h, s] so that Σ_h = col_totals[r, s] and Σ_s = row_totals[r, h]."""
    x = seed.copy()
    for _ in range(iters):
        x *= (col_totals / x.sum(axis=1))[:, None, :]
        x *= (row_totals / x.sum(axis=2))[:, :, None]
    x *= (col_totals / x.sum(axis=1))[:, None, :]  # exact on goods; households to ~1e-15
    return x


def multiregion_model(R, S, H, n_inputs=5, n_partners=4, tariff=0.1, seed=0):
    """(model, handles, data) for the synthetic multi-region economy; the parameter
    ``tm`` (one rate per trade arc and good) holds the tariffs."""
    d = synthetic_data(R, S, H, n_inputs, n_partners, tariff, seed)
    m = Model(f"multiregion_{R}x{S}x{H}")
    regions = [f"r{r}" for r in range(R)]
    rs = [f"r{r}.s{s}" for r in range(R) for s in range(S)]
    Y, A = m.sectors("Y", rs), m.sectors("A", rs)
    PY, PA = m.commodities("PY", rs), m.commodities("PA", rs)
    PL, PK = m.commodities("PL", regions), m.commodities("PK", regions)
    HH = m.consumers("HH", [f"r{r}.h{h}" for r in range(R) for h in range(H)])
    GOV = m.consumers("GOV", regions)
    n_arcs = d["src"].shape[0]
    tm = m.parameter("tm", d["tm0"].ravel())
    RS = R * S
    region_of = np.repeat(np.arange(R), S)
    y = m.production(Y, s=0.0, nests={"va": ("s", 1.0)})
    y.output(PY, d["y0"].ravel())
    y.input(PA, d["idq"])
    y.input(PL, sp.csr_matrix((d["va"] * d["lab"], (np.arange(RS), region_of)), (RS, R)),
            nest="va")
    y.input(PK, sp.csr_matrix((d["va"] * (1 - d["lab"]), (np.arange(RS), region_of)),
                              (RS, R)), nest="va")
    a = m.production(A, s=2.0, nests={"m": ("s", 4.0)})
    a.output(PA, d["a0"].ravel())
    a.input(PY, d["dom"].ravel())
    # Imports: A[dst.s] buys PY[src.s]; entries in row-major order of (A, PY).
    s_idx = np.tile(np.arange(S), n_arcs)
    rows = np.repeat(d["dst"], S) * S + s_idx
    cols = np.repeat(d["src"], S) * S + s_idx
    order = np.lexsort((cols, rows))
    imp = sp.csr_matrix((d["trade"].ravel()[order], (rows[order], cols[order])), (RS, RS))
    # Tariffs go to the importing region's government: one receiving consumer per owner.
    a.input(PY, imp, nest="m", price=1.0 + d["tm0"].ravel()[order],
            taxes=[(GOV[region_of], tm[order])])
    hh_region = np.repeat(np.arange(R), H)
    dem = m.demand(HH, s=1.0, nests={"g": ("s", 0.5)})
    cmat = d["c"].reshape(R * H, S)
    hrows = np.repeat(np.arange(R * H), S)
    hcols = hh_region[hrows] * S + np.tile(np.arange(S), R * H)
    dem.final(PA, sp.csr_matrix((cmat.ravel(), (hrows, hcols)), (R * H, RS)), nest="g")
    sh = d["share"].ravel()
    dem.endowment(PL, sp.csr_matrix((sh * d["labour"][hh_region],
                                     (np.arange(R * H), hh_region)), (R * H, R)))
    dem.endowment(PK, sp.csr_matrix((sh * d["capital"][hh_region],
                                     (np.arange(R * H), hh_region)), (R * H, R)))
    g = m.demand(GOV, s=1.0)
    grows = np.repeat(np.arange(R), S)
    g.final(PA, sp.csr_matrix((d["gov"].ravel(), (grows, np.arange(RS))), (R, RS)))
    handles = {"Y": Y, "A": A, "PY": PY, "PA": PA, "PL": PL, "PK": PK, "HH": HH, "GOV": GOV, "tm": tm}
    return m, handles, d
