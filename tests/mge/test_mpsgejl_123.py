"""The 1-2-3 model (one country, two activities, three goods: domestic, exports,
imports) of MPSGE.jl's test_123.jl, with its three closure auxiliaries — a lump-sum
replacement tax, a labour-tax replacement and unemployment under a fixed real wage —
matched to the GAMS/MPSGE values of the tariff reform under each closure."""
import numpy as np

from compass_sparse.mge import Model

from ._peer import getters, sheet, solve_and_match


def _data():
    """The micro-consistent matrix of the peer's test (rows: accounts, columns S, D,
    GOVT, HH, INVEST), and the benchmark values derived from it."""
    S, D, GOVT, _HH, INVEST = range(5)
    mcm = {"PFX": [106.386, -144.701, 38.315, 0, 0], "PD": [218.308, -218.308, 0, 0, 0],
               "TA": [0, -32.027, 32.027, 0, 0], "TM": [0, -18.617, 18.617, 0, 0],
               "TX": [-1.136, 0, 1.136, 0, 0], "TK": [-12.837, 0, 12.837, 0, 0],
               "TL": [-3.539, 0, 3.539, 0, 0], "RK": [-143.862, 0, 0, 143.862, 0],
               "PL": [-163.320, 0, 0, 163.320, 0], "PA": [0, 413.653, -35.583, -291.694, -86.376]}
    d = {"d0": mcm["PD"][S], "x0": mcm["PFX"][S], "kd0": -mcm["RK"][S], "ly0": -mcm["PL"][S]}
    d.update(tk=mcm["TK"][S] / mcm["RK"][S], tl=mcm["TL"][S] / mcm["PL"][S],
             ta=-mcm["TA"][D] / mcm["PA"][D], tx=-mcm["TX"][S] / mcm["PFX"][S],
             a0=mcm["PA"][D], g0=-mcm["PA"][GOVT], m0=-mcm["PFX"][D],
             i0=-mcm["PA"][INVEST], tm=mcm["TM"][D] / mcm["PFX"][D],
             bopdef=mcm["PFX"][GOVT])
    d.update(l0=0.75 * d["ly0"], c0=d["a0"] - d["i0"] - d["g0"], pm0=1 + d["tm"],
             px0=1 - d["tx"], rr0=1 + d["tk"], pl0=1 + d["tl"])
    d["dtax"] = (d["g0"] - d["bopdef"] - d["tm"] * d["m0"] - d["ta"] * d["a0"]
                 - d["tl"] * d["ly0"] - d["tk"] * d["kd0"] - d["tx"] * d["x0"])
    return d


def test_one_two_three_model_mirrors_mpsgejl_test_123():
    ref = sheet("The123")
    d = _data()
    m = Model()
    TM = m.parameter("TM", d["tm"])
    Y, A, M, X = (m.sector(n) for n in ("Y", "A", "M", "X"))
    PD, PX, PM, PA, PL, RK, PFX = (m.commodity(n) for n in
                                    ("PD", "PX", "PM", "PA", "PL", "RK", "PFX"))
    HH, GOVT = m.consumer("HH"), m.consumer("GOVT")
    TAU_LS, TAU_TL, UR = (m.auxiliary(n) for n in ("TAU_LS", "TAU_TL", "UR"))
    y = m.production(Y, s=1.0, t=4.0)
    y.output(PD, d["d0"]).output(PX, d["x0"], price=d["px0"], taxes=[(GOVT, d["tx"])])
    y.input(RK, d["kd0"], price=d["rr0"], taxes=[(GOVT, d["tk"])])
    y.input(PL, d["ly0"], price=d["pl0"], taxes=[(GOVT, d["tl"] + TAU_TL)])
    a = m.production(A, s=4.0).output(PA, d["a0"], taxes=[(GOVT, d["ta"])])
    a.input(PD, d["d0"]).input(PM, d["m0"], price=d["pm0"], taxes=[(GOVT, TM)])
    m.production(M, s=1.0).output(PM, d["m0"]).input(PFX, d["m0"])
    m.production(X, s=1.0).output(PFX, d["x0"]).input(PX, d["x0"])
    m.constraint(UR, PL - PA)                       # a fixed real wage (when UR is free)
    m.constraint(TAU_LS, GOVT - PA * d["g0"])       # real government income fixed
    m.constraint(TAU_TL, GOVT - PA * d["g0"])
    m.demand(GOVT, s=0.0).final(PA, 35.583) \
        .endowment(PA, d["g0"] * TAU_LS + d["dtax"]).endowment(PFX, d["bopdef"])
    hh = m.demand(HH, s=0.4).final(PA, d["c0"]).final(PL, d["l0"])
    hh.endowment(PA, -d["g0"] * TAU_LS - d["dtax"] - d["i0"]).endowment(RK, d["kd0"])
    hh.endowment(PL, (d["ly0"] + d["l0"]) * (1 - UR))
    g = getters({"PFX": PFX, "PD": PD, "RK": RK, "PL": PL, "PA": PA, "GOVT": GOVT, "HH": HH, "PX": PX, "Y": Y, "A": A,
                     "M": M, "X": X, "PM": PM},
                inputs={"KD": (Y, RK), "LY": (Y, PL), "DA": (A, PD), "MA": (A, PM), "PFXM": (M, PFX),
                            "PXX": (X, PX)},
                outputs={"YD": (Y, PD), "YX": (Y, PX), "PAA": (A, PA), "PMM": (M, PM), "PFXX": (X, PFX)},
                finals={"CAHH": (HH, PA), "CAG": (GOVT, PA), "LD": (HH, PL)})
    m.fix(HH, 414.184)
    assert m.benchmark().ok(1e-9)
    base = solve_and_match(m, ref, "Benchmark", g)
    assert np.allclose([base.value(v) for v in (TAU_LS, TAU_TL, UR)], 0.0)
    TM.set(0.0)                                     # tariff reform
    m.fix(UR, 0.0)
    m.fix(TAU_TL, 0.0)                              # lump-sum replacement
    solve_and_match(m, ref, "Lump Sum F", {**g, "TAU_LS": lambda s: s.value(TAU_LS)})
    m.fix(HH, 427.4988518)
    solve_and_match(m, ref, "Lump Sum R", {**g, "TAU_LS": lambda s: s.value(TAU_LS)})
    m.unfix(TAU_TL)                                 # labour-tax replacement
    m.fix(TAU_LS, 0.0)
    solve_and_match(m, ref, "Wage Tax F", {**g, "TAU_TL": lambda s: s.value(TAU_TL)})
    m.unfix(UR)                                     # and a fixed real wage
    m.fix(HH, 441.2417391)
    solve_and_match(m, ref, "Wage Tax R", {**g, "TAU_TL": lambda s: s.value(TAU_TL),
                                           "UR": lambda s: s.value(UR)}, atol={"UR": 1e-8})
