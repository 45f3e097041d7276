"""MPSGE.jl's two-by-two models with non-unit reference prices (in inputs, outputs and
final demand) and with auxiliary variables (in an endowment, in tax rates of inputs and
of outputs), matched to the GAMS/MPSGE values of its tests (relative tolerance sqrt(eps);
an absolute tolerance only where the peer's test states one)."""
from compass_sparse.mge import Model

from ._peer import getters, sheet, solve_and_match


def _xyu(m, x_out, x_in, u_q, endow_l, x_out_price=1.0, x_in_price=1.0, demand=None):
    """X and Y from labour and capital, U from X and Y, one consumer RA; X's output and
    labour input are taxed (rates itax, otax) with the given reference prices."""
    p = {n: m.parameter(n, v) for n, v in demand["params"].items()} if demand else {}
    endow = m.parameter("endow", 1.0)
    otax = m.parameter("otax", demand["otax"] if demand else x_out[1])
    itax = m.parameter("itax", demand["itax"] if demand else x_in[1])
    X, Y, U = m.sector("X"), m.sector("Y"), m.sector("U")
    PX, PY, PU, PL, PK = (m.commodity(n) for n in ("PX", "PY", "PU", "PL", "PK"))
    RA = m.consumer("RA")
    m.production(X, s=1).output(PX, x_out[0], price=x_out_price, taxes=[(RA, otax)]) \
        .input(PL, x_in[0], price=x_in_price, taxes=[(RA, itax)]).input(PK, 50)
    m.production(Y, s=1).output(PY, 54).input(PL, 24).input(PK, 30)
    m.production(U, s=1).output(PU, u_q[0]).input(PX, x_out[0]).input(PY, u_q[1])
    if demand:
        d = m.demand(RA, s=p["esub_ra"])
        d.final(PU, u_q[0], price=p["pr_Ud"]).final(PY, 10)
    else:
        d = m.demand(RA).final(PU, u_q[0])
    d.endowment(PL, endow * endow_l).endowment(PK, 80)
    g = getters({"X": X, "Y": Y, "U": U, "PX": PX, "PY": PY, "PU": PU, "PL": PL, "PK": PK, "RA": RA},
                inputs={"DXL": (X, PL), "DXK": (X, PK), "DYL": (Y, PL), "DYK": (Y, PK), "DUX": (U, PX),
                            "DUY": (U, PY)},
                outputs={"SX": (X, PX), "SY": (Y, PY), "SU": (U, PU)},
                finals=dict(DU=(RA, PU), **({"DY": (RA, PY)} if demand else {})))
    return dict(endow=endow, otax=otax, itax=itax, PU=PU, PX=PX, PL=PL, g=g, **p)


def _price_sequence(m, v, ref, otax_atol=None):
    g = v["g"]
    m.fix(v["PU"], 1.0)
    assert m.benchmark().ok(1e-10)
    solve_and_match(m, ref, "benchmark", g)
    v["endow"].set(1.1)
    solve_and_match(m, ref, "RA=157", g)
    m.unfix(v["PU"])
    m.fix(v["PX"], 1.0)
    solve_and_match(m, ref, "PX=1", g)
    m.unfix(v["PX"])
    m.fix(v["PL"], 1.0)
    solve_and_match(m, ref, "PL=1", g)
    v["itax"].set(0.1)
    solve_and_match(m, ref, "Itax=0.1", g)
    v["otax"].set(0.1)
    solve_and_match(m, ref, "Otax=0.1", g, atol=otax_atol)


def test_reference_price_in_input_mirrors_mpsgejl_test_twobytwo_price_inputs():
    """Labour bought by X at a reference price of 1.2, tax included (itax = 0.2)."""
    m = Model()
    v = _xyu(m, (110, 0.0), (50, 0.2), (164, 54), 74, x_in_price=1.2)
    _price_sequence(m, v, sheet("two_by_two_PriceinIntput"))


def test_reference_price_in_output_mirrors_mpsgejl_test_twobytwo_price_outputs():
    """X sold at a reference price of 1.2 before an output tax of 0.2."""
    m = Model()
    v = _xyu(m, (100, 0.2), (30, 0.0), (154, 54), 54, x_out_price=1.2)
    _price_sequence(m, v, sheet("two_by_two_PriceinOutput"), otax_atol={"PK": 1e-7})


def test_reference_price_in_demand_mirrors_mpsgejl_test_twobytwo_price_demand():
    """Final demand for U at a reference price pr_Ud, and for Y; CES elasticity esub_ra."""
    ref = sheet("two_by_two_PriceinDem")
    m = Model()
    v = _xyu(m, (80, 0.0), (30, 0.0), (124, 44), 54,
             demand={"params": {"esub_ra": 1.0, "pr_Ud": 1.0}, "otax": 0.0, "itax": 0.0})
    g = v["g"]
    m.fix(v["PU"], 1.0)
    solve_and_match(m, ref, "benchmark", g)
    v["endow"].set(1.1)
    solve_and_match(m, ref, "RA=157", g)
    steps = [({"esub_ra": 0.6}, "eRA=.6"), ({"pr_Ud": 3.0}, "pr_Ud=3"),
             ({"esub_ra": 0.5, "pr_Ud": 2.0}, "prU2,eRA.5"),
             ({"pr_Ud": 0.5, "esub_ra": 0.6}, "prUd.5,e.6"), ({"esub_ra": 0.0}, "prUd.5,e.0"),
             ({"esub_ra": 0.6, "itax": 0.1}, "Itax=0.1"), ({"otax": 0.1}, "Otax=0.1")]
    for changes, col in steps:
        for k, val in changes.items():
            v[k].set(val)
        solve_and_match(m, ref, col, g)


def test_auxiliary_in_endowment_mirrors_mpsgejl_test_twobytwo_aux_in_demand():
    """Unemployment U: the labour endowment is 120 - 80 U / (1 - 0.2), and U adjusts so
    that the real wage PL / PW stays at 1 (U >= 0 as MPSGE's auxiliaries default to)."""
    ref = sheet("TwoxTwowAuxDem")
    m = Model()
    tx, ty, tkx = m.parameter("tx", 0.1), m.parameter("ty", 0.0), m.parameter("tkx", 0.0)
    uo = 0.2
    X, Y, W = m.sector("X"), m.sector("Y"), m.sector("W")
    PX, PY, PW, PL, PK = (m.commodity(n) for n in ("PX", "PY", "PW", "PL", "PK"))
    CONS = m.consumer("CONS")
    U = m.auxiliary("U", start=0.2)
    m.production(X, s=1).output(PX, 100, taxes=[(CONS, tx)]) \
        .input(PK, 50, taxes=[(CONS, tkx)]).input(PL, 40)
    m.production(Y, s=1).output(PY, 100, taxes=[(CONS, ty)]).input(PL, 60).input(PK, 40)
    m.production(W, s=1).output(PW, 200).input(PX, 100).input(PY, 100)
    m.demand(CONS).final(PW, 200).endowment(PL, 120 - 80 / (1 - uo) * U).endowment(PK, 90)
    m.constraint(U, PL - PW)
    g = getters({"X": X, "Y": Y, "W": W, "PX": PX, "PY": PY, "PW": PW, "PL": PL, "PK": PK, "U": U, "CONS": CONS},
                inputs={"DKX": (X, PK), "DLX": (X, PL), "DLY": (Y, PL), "DKY": (Y, PK), "DXW": (W, PX),
                            "DYW": (W, PY)},
                outputs={"SXX": (X, PX), "SYY": (Y, PY), "SWW": (W, PW)},
                finals={"CWCONS": (CONS, PW)})
    assert m.benchmark().ok(1e-10)
    solve_and_match(m, ref, "benchmark", g)
    m.set_start(U, 0.1)
    m.fix(CONS, 210.0)
    solve_and_match(m, ref, "UnEmp=.1", g)
    tkx.set(0.25)
    tx.set(0.0)
    m.unfix(CONS)
    m.fix(PX, 1.0)
    solve_and_match(m, ref, "TKX=0.25", g)
    ty.set(0.5)
    solve_and_match(m, ref, "&TY=.5", g)
    tkx.set(0.0)
    solve_and_match(m, ref, "TY=0.5", g)


def test_endogenous_input_tax_mirrors_mpsgejl_test_twobytwo_aux_in_inputs():
    """Factor taxes txl TAU and txk TAU, with TAU set so that the value of W's output pays
    for the factors and a fixed government purchase (an equal-yield closure)."""
    ref = sheet("two_by_two_AuxinInput")
    m = Model()
    txl, txk = m.parameter("txl", 0.2), m.parameter("txk", 0.2)
    X, Y, W, TL, TK = (m.sector(n) for n in ("X", "Y", "W", "TL", "TK"))
    PX, PY, PW, PL, PK, PKS, PLS = (m.commodity(n) for n in
                                     ("PX", "PY", "PW", "PL", "PK", "PKS", "PLS"))
    CONS = m.consumer("CONS")
    TAU = m.auxiliary("TAU", start=1.0)
    m.production(X, s=1).output(PX, 120).input(PLS, 48).input(PKS, 72)
    m.production(Y, s=1).output(PY, 120).input(PLS, 72).input(PKS, 48)
    m.production(W, s=0.7, nests={"AW": ("s", 1.0)}).output(PW, 340).input(PL, 100) \
        .input(PX, 120, nest="AW").input(PY, 120, nest="AW")
    m.production(TL, s=1).output(PLS, 120).input(PL, 100, taxes=[(CONS, txl * TAU)])
    m.production(TK, s=1).output(PKS, 120).input(PK, 100, taxes=[(CONS, txk * TAU)])
    m.demand(CONS).final(PW, 340).endowment(PL, 200).endowment(PK, 100)
    m.constraint(TAU, W * PW * 340 - PL * 200 - PK * 100 - 40 * (PX + PY) / 2)
    g = getters({"X": X, "Y": Y, "W": W, "TL": TL, "TK": TK, "PX": PX, "PY": PY, "PW": PW, "PL": PL, "PK": PK,
                     "PKS": PKS, "PLS": PLS, "TAU": TAU, "CONS": CONS},
                inputs={"DLSX": (X, PLS), "DKSX": (X, PKS), "DLSY": (Y, PLS), "DKSY": (Y, PKS),
                            "DXW": (W, PX), "DYW": (W, PY), "DLW": (W, PL), "DLTL": (TL, PL),
                            "DKTK": (TK, PK)},
                outputs={"SXX": (X, PX), "SYY": (Y, PY), "SWW": (W, PW), "SLSTL": (TL, PLS),
                             "SKSTK": (TK, PKS)},
                finals={"CWCONS": (CONS, PW)})
    m.fix(CONS, 340.0)
    assert m.benchmark().ok(1e-10)
    solve_and_match(m, ref, "benchmark", g)
    steps = [(None, 0.15, 0.25, "L.15,K.25"), (339.5832292, 0.1, 0.3, "L.1,K.3"),
             (338.7151989, 0.05, 0.35, "L.05,K.35"), (337.2894147, 0.0, 0.4, "L.0,K.4"),
             (335.0362347, -0.05, 0.45, "L-.05,K.45")]
    for cons, l, k, col in steps:
        if cons is not None:
            m.fix(CONS, cons)
        txl.set(l)
        txk.set(k)
        solve_and_match(m, ref, col, g, atol={"TAU": 1e-6} if col == "L.0,K.4" else None)


def test_endogenous_markup_mirrors_mpsgejl_test_twobytwo_aux_in_outputs():
    """A markup on X's output (a tax to the consumer) set by X's value share through two
    auxiliary constraints, one of them rational; MARKUP[b]'s constraint is identically 0."""
    ref = sheet("two_by_two_AuxinOutput")
    m = Model()
    sigma = m.parameter("sigma", 9.0)
    X, Y, W = m.sector("X"), m.sector("Y"), m.sector("W")
    PX, PY, PW, PL, PK = (m.commodity(n) for n in ("PX", "PY", "PW", "PL", "PK"))
    CONS = m.consumer("CONS")
    SHAREX = m.auxiliary("SHAREX", start=0.5)
    MARKUP = m.auxiliaries("MARKUP", ["a", "b"], start=0.2)
    m.production(X, s=1).output(PX, 80, taxes=[(CONS, MARKUP["a"])]).input(PL, 14) \
        .input(PK, 50)
    m.production(Y, s=1).output(PY, 100).input(PL, 60).input(PK, 40)
    m.production(W, s=9).output(PW, 180).input(PX, 80).input(PY, 100)
    m.demand(CONS).final(PW, 180).endowment(PL, 74).endowment(PK, 90)
    m.constraint(SHAREX, SHAREX - 100 * PX * X / (100 * PX * X + 100 * PY * Y))
    m.constraint(MARKUP["a"], MARKUP["a"] - 1 / (sigma - (sigma - 1) * SHAREX))
    m.constraint(MARKUP["b"], MARKUP["b"] - MARKUP["b"])
    # MARKUP[b] appears nowhere else and its constraint is identically zero, so any value
    # is part of a solution; it is held at its start (free, it leaves the Jacobian with a
    # zero row and column, on which the last scenario's solve stalls at |F| ~ 3e-8).
    m.fix(MARKUP["b"], 0.2)
    g = getters({"X": X, "Y": Y, "W": W, "PX": PX, "PY": PY, "PW": PW, "PL": PL, "PK": PK, "SHAREX": SHAREX,
                     "CONS": CONS},
                inputs={"DLX": (X, PL), "DKX": (X, PK), "DLY": (Y, PL), "DKY": (Y, PK), "DXW": (W, PX),
                            "DYW": (W, PY)},
                outputs={"SXX": (X, PX), "SYY": (Y, PY), "SWW": (W, PW)},
                finals={"CWCONS": (CONS, PW)})
    g["MARKUP"] = lambda s: s.value(MARKUP["a"])
    m.fix(CONS, 180.0)
    assert m.benchmark().ok(1e-10)
    solve_and_match(m, ref, "benchmark", g)
    m.fix(CONS, 164.0)
    m.fix(MARKUP["a"], 0.0)
    solve_and_match(m, ref, "S.5,M.FX=0", {k: v for k, v in g.items() if k != "MARKUP"},
                    atol={"SHAREX": 1e-7})
    m.fix(CONS, 214.5077935)
    m.fix(SHAREX, 0.2)
    m.unfix(MARKUP["a"])
    m.set_start(MARKUP["a"], 0.5)
    solve_and_match(m, ref, "S.FX.2,M.5", g)


def _indexed_demand_prices(nested):
    """U makes two utility goods PU[l], PU[k] bought by C at reference prices pricepu
    (in a nest of their own when ``nested``: the same economy)."""
    m = Model()
    goods, factors = ["x", "y"], ["l", "k"]
    endow = m.parameter("endow", [70.0, 80.0], index=factors)
    pricepu = m.parameter("pricepu", [1.0, 1.0], index=factors)
    Y, U = m.sectors("Y", goods), m.sector("U")
    PC, PU, PF = (m.commodities(n, idx) for n, idx in (("PC", goods), ("PU", factors),
                                                       ("PF", factors)))
    C = m.consumers("C", ["ra"])
    m.production(Y, s=1).output(PC, [100.0, 50.0]) \
        .input(PF, [[50.0, 50.0], [20.0, 30.0]])
    m.production(U, s=1).output(PU, [[75.0, 75.0]]).input(PC, [[100.0, 50.0]])
    d = m.demand(C, s=1.0, nests={"CU": ("s", 1.0)} if nested else None)
    d.final(PU, [[75.0, 75.0]], price=pricepu, nest="CU" if nested else None)
    d.endowment(PF, endow)
    rows = {"y.x": Y["x"], "y.y": Y["y"], "U._": U, "RA._": C, "PC.x": PC["x"],
            "PC.y": PC["y"], "PF.L": PF["l"], "PF.K": PF["k"], "PU.L": PU["l"], "PU.K": PU["k"]}
    g = getters(rows, inputs={"x.L": (Y["x"], PF["l"]), "x.K": (Y["x"], PF["k"]),
                              "y.L": (Y["y"], PF["l"]), "y.K": (Y["y"], PF["k"]),
                              "DU.x": (U, PC["x"]), "DU.y": (U, PC["y"])},
                outputs={"SU.L": (U, PU["l"]), "SU.K": (U, PU["k"]), "SY.x": (Y["x"], PC["x"]),
                         "SY.y": (Y["y"], PC["y"])},
                finals={"FDRA.L": (C, PU["l"]), "FDRA.K": (C, PU["k"])})
    return m, {"endow": endow, "pricepu": pricepu, "C": C, "PU": PU, "PF": PF}, g


def test_indexed_demand_reference_prices_mirror_mpsgejl_test_twobytwo_indexed_demand():
    for nested in (False, True):
        ref = sheet("TwoxTwo_DemandIndPrice_Nest", keys=2)
        m, h, g = _indexed_demand_prices(nested)
        solve_and_match(m, ref, "benchmark", g)
        h["endow"].set(77.0, at="l")
        m.fix(h["C"], 157.0)
        solve_and_match(m, ref, "RA=157", g)
        m.unfix(h["C"])
        m.fix(h["PU"]["k"], 1.0)
        solve_and_match(m, ref, "PC.x=1", g)
        h["pricepu"].set(1.5, at="l")
        solve_and_match(m, ref, "Pr.l=1.5", g, atol={"PU.L": 1e-7})
        m.fix(h["PF"]["l"], 1.0)    # with PU[k] still fixed, as the peer
        solve_and_match(m, ref, "PF.l=1", g)
