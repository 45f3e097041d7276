"""WiNDC's national model of the U.S. economy (71 sectors), from WiNDC's 2017 accounts.

The model (as in WiNDC's national MPSGE model and MPSGE.jl's test of it):

* Y[j]: sectoral production, Leontief in intermediate inputs PA[i] and a Cobb–Douglas
  value-added nest of PVA (labour, capital); outputs PY[i] (make matrix), taxed at ty[j];
* A[i]: Armington supply, CET (τ = 2) between the domestic market PA[i] (taxed at ta[i],
  reference price 1 - ta0) and exports (PFX); inputs: margins PM[m] (Leontief) and a CES
  nest (σ = 2) of domestic PY[i] and imports (PFX, tariff tm[i], reference price 1 + tm0);
* MS[m]: margin supply (trade, transport) from PY[i], Leontief;
* RA: the representative agent, final demand (CES, elasticity ``d_elas_ra``) for PA[i]
  (personal consumption), endowed with value added, the balance-of-payments deficit
  (in PFX) and minus the other final demands (investment, government).

The data (``data/windc_national_2017``) are described in the README beside them.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .model import Model

DATA = Path(__file__).resolve().parent / "data" / "windc_national_2017"


def _set(name):
    with open(DATA / f"{name}.csv", newline="") as f:
        return [row[0] for row in list(csv.reader(f))[1:]]


def _table(name, *sets):
    """A parameter as a dense array over the given index lists."""
    where = [{k: i for i, k in enumerate(s)} for s in sets]
    out = np.zeros(tuple(len(s) for s in sets))
    with open(DATA / f"{name}.csv", newline="") as f:
        rows = list(csv.reader(f))[1:]
    for r in rows:
        try:
            idx = tuple(w[k] for w, k in zip(where, r[:-1]))
        except KeyError:
            continue  # an element outside the model's sets (use, oth)
        out[idx] = float(r[-1])
    return out


def load_national():
    """The 2017 national accounts as numpy arrays (billions of dollars) and their sets."""
    I = [i for i in _set("i") if i not in ("use", "oth")]
    VA = [v for v in _set("va") if v != "othtax"]
    FD = _set("fd")
    M = _set("m")
    d = {"I": I, "VA": VA, "FD": FD, "M": M}
    d.update(a0=_table("a_0", I), id0=_table("id_0", I, I), ys0=_table("ys_0", I, I),
             ms0=_table("ms_0", I, M), x0=_table("x_0", I), fs0=_table("fs_0", I),
             tm0=_table("tm_0", I), va0=_table("va_0", VA, I), md0=_table("md_0", M, I),
             fd0=_table("fd_0", I, FD), m0=_table("m_0", I), ty0=_table("ty_0", I),
             ta0=_table("ta_0", I), y0=_table("y_0", I))
    with open(DATA / "bopdef_0.csv", newline="") as f:
        d["bopdef0"] = float(list(csv.reader(f))[1][0])
    return d


def national_model(data=None):
    """(model, handles): WiNDC's national model; handles maps names (Y, A, MS, PA, PY,
    PVA, PM, PFX, RA, ta, ty, tm, d_elas_ra) to the model's variables and parameters."""
    d = load_national() if data is None else data
    I, VA, M = d["I"], d["VA"], d["M"]
    m = Model("windc_national", prune=True)
    ta = m.parameter("ta", d["ta0"], index=I)
    ty = m.parameter("ty", d["ty0"], index=I)
    tm = m.parameter("tm", d["tm0"], index=I)
    d_elas = m.parameter("d_elas_ra", 1.0)
    Y, A, MS = m.sectors("Y", I), m.sectors("A", I), m.sectors("MS", M)
    PA, PY = m.commodities("PA", I), m.commodities("PY", I)
    PVA, PM, PFX = m.commodities("PVA", VA), m.commodities("PM", M), m.commodity("PFX")
    RA = m.consumer("RA")
    y = m.production(Y, s=0.0, t=0.0, nests={"va": ("s", 1.0)})
    y.output(PY, d["ys0"], taxes=[(RA, ty)])
    y.input(PA, d["id0"].T)
    y.input(PVA, d["va0"].T, nest="va")
    ms = m.production(MS, s=0.0, t=0.0)
    ms.output(PM, d["ms0"].sum(axis=0)).input(PY, d["ms0"].T)
    a = m.production(A, s=0.0, t=2.0, nests={"dm": ("s", 2.0)})
    a.output(PA, d["a0"], price=1.0 - d["ta0"], taxes=[(RA, ta)])
    a.output(PFX, d["x0"][:, None])
    a.input(PM, d["md0"].T)
    a.input(PY, d["y0"], nest="dm")
    a.input(PFX, d["m0"][:, None], nest="dm", price=1.0 + d["tm0"], taxes=[(RA, tm)])
    other_fd = [k for k, f in enumerate(d["FD"]) if f != "pce"]
    dem = m.demand(RA, s=d_elas)
    dem.final(PA, d["fd0"][:, d["FD"].index("pce")][None, :])
    dem.endowment(PY, d["fs0"][None, :])
    dem.endowment(PFX, d["bopdef0"])
    dem.endowment(PA, -d["fd0"][:, other_fd].sum(axis=1)[None, :])
    dem.endowment(PVA, d["va0"].sum(axis=1)[None, :])
    handles = {"Y": Y, "A": A, "MS": MS, "PA": PA, "PY": PY, "PVA": PVA, "PM": PM, "PFX": PFX, "RA": RA, "ta": ta,
                   "ty": ty, "tm": tm, "d_elas_ra": d_elas}
    return m, handles
