"""Joint production with intermediate demand (GAMS' JPMGE example, in MPSGE.jl's
test_jpmge.jl): two sectors each making both goods (CET) from both goods and two factors
(Cobb–Douglas), one consumer with final-demand elasticity 1, 0 or 2; matched to the
GAMS/MPSGE values (outputs per unit in the plain columns, inputs in the 'D' columns)."""
import numpy as np
import pytest

from compass_sparse.mge import Model

from ._peer import sheet, solve_and_match

# The absolute tolerances the peer's test states (GAMS' values there carry ~1e-8 errors).
ATOL = {'P("g1")=1': {"PF.labor": 1e-7},
        'D_elas=0,P("g1")=1': {"X.s1": 1e-7, "PF.labor": 1e-7, "Y._": 1e-6, "labor.s1": 1e-7},
        'D_elas=2,P("g1")=1': {"PY.g1": 1e-7}}


@pytest.mark.parametrize("elasticity", [1.0, 0.0, 2.0])
def test_joint_production_mirrors_mpsgejl_test_jpmge(elasticity):
    ref = sheet("JPMGE", keys=2)
    goods, factors, secs = ["g1", "g2"], ["l", "k"], ["s1", "s2"]
    make0 = np.array([[6.0, 2.0], [2.0, 10.0]])    # (goods, sectors)
    use0 = np.array([[4.0, 2.0], [2.0, 6.0]])
    fd0 = np.array([[1.0, 3.0], [1.0, 1.0]])       # (factors, sectors)
    m = Model()
    endow = m.parameter("endow", fd0.sum(axis=1), index=factors)
    X = m.sectors("X", secs)
    P, PF = m.commodities("P", goods), m.commodities("PF", factors)
    Y = m.consumer("Y")
    m.production(X, s=1.0, t=1.0).output(P, make0.T).input(P, use0.T).input(PF, fd0.T)
    m.demand(Y, s=elasticity).final(P, [[2.0, 4.0]]).endowment(PF, endow)
    names = {"l": "labor", "k": "capital"}
    outs = {f"{g}.{s}": (lambda z, g=g, s=s: z.compensated_demand(X[s], P[g], output=True))
            for g in goods for s in secs}
    outs.update({f"{names[f]}.{s}": (lambda z, f=f, s=s: z.compensated_demand(X[s], PF[f]))
                 for f in factors for s in secs})
    outs.update({f"X.{s}": (lambda z, s=s: z.value(X[s])) for s in secs})
    outs.update({f"P.{g}": (lambda z, g=g: z.value(P[g])) for g in goods})
    outs.update({f"PF.{names[f]}": (lambda z, f=f: z.value(PF[f])) for f in factors})
    outs.update({f"PY.{g}": (lambda z, g=g: z.final_demand(Y, P[g])) for g in goods})
    outs["Y._"] = lambda z: z.value(Y)
    ins = {f"{g}.{s}": (lambda z, g=g, s=s: z.compensated_demand(X[s], P[g]))
           for g in goods for s in secs}
    tag = {1.0: "", 0.0: "D_elas=0,", 2.0: "D_elas=2,"}[elasticity]

    def both(column):
        sol = solve_and_match(m, ref, column, outs, atol=ATOL.get(column))
        solve_and_match(m, ref, "D " + column, ins)
        return sol

    both("benchmark")
    endow.set(4.4, at="l")
    m.fix(Y, 6.4)
    both(tag + "Y=6.4")
    m.unfix(Y)
    m.fix(P["g1"], 1.0)
    both(tag + 'P("g1")=1')
    m.unfix(P["g1"])
    m.fix(PF["l"], 1.0)
    both(tag + ('PF("labor")=1' if elasticity == 1.0 else 'PF("l")=1'))
