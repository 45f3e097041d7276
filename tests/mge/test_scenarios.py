"""Parameters that change between solves without rebuilding, warm starts, scenario loops
through solve_batch, names, and the report (changes and equivalent variation)."""
import numpy as np
import pytest

from compass_sparse.batch import grid, solve_batch
from compass_sparse.mge import Model


def _economy():
    """Two goods from labour and capital, a taxed good, one household, one government."""
    m = Model()
    G = ["agr", "man"]
    Y = m.sectors("Y", G)
    PY = m.commodities("PY", G)
    PL, PK = m.commodity("PL"), m.commodity("PK")
    HH, GOV = m.consumer("HH"), m.consumer("GOV")
    tax = m.parameter("tax", [0.1, 0.2], index=G)
    esub = m.parameter("esub", 1.0)
    p = m.production(Y, s=esub)
    p.output(PY, [100.0, 80.0], price=1.0 - np.array([0.1, 0.2]), taxes=[(GOV, tax)])
    p.input(PL, [50.0, 24.0]).input(PK, [40.0, 40.0])
    m.demand(HH, s=0.8).final(PY, np.array([[90.0, 64.0]])).endowment(PL, 74) \
        .endowment(PK, 80)
    m.demand(GOV).final(PY, np.array([[10.0, 16.0]]))
    m.fix(PL, 1.0)
    return m, {"Y": Y, "PY": PY, "PL": PL, "PK": PK, "HH": HH, "GOV": GOV, "tax": tax, "esub": esub}


def test_names_name_every_row_and_column():
    m, _h = _economy()
    problem, _st, _ = m.mcp()
    assert problem.var_names[:2] == ["Y[agr]", "Y[man]"]
    assert "PY[man]" in problem.var_names and "HH" in problem.var_names
    assert "market:PY[agr]" in problem.eqn_names and "income:GOV" in problem.eqn_names
    assert "zero_profit:Y[man]" in problem.eqn_names and "nest:Y[agr].s" in problem.eqn_names
    assert len(set(problem.var_names)) == problem.n


def test_parameter_changes_without_rebuilding_and_warm_starts():
    m, h = _economy()
    assert m.benchmark().ok(1e-10)
    base = m.solve()
    assert base.success and base.result.nit == 0
    h["tax"].set(0.0, at="man")
    cold = m.solve(x0=m.benchmark().x)
    assert cold.success and cold.residual() <= 1e-9
    again = m.solve()            # warm: from the last solution, the same data
    assert again.success and again.result.nit == 0
    np.testing.assert_allclose(again.x, cold.x, rtol=1e-12, atol=1e-12)
    h["tax"].set(0.01, at="man")  # a nearby scenario from the warm start
    near = m.solve()
    assert near.success and near.result.nit <= cold.result.nit


def test_report_and_equivalent_variation_agree_with_utility_from_quantities():
    """EV from the price index equals the money-metric change of utility computed from
    the household's final demands (CES with σ = 0.8, reference prices 1)."""
    m, h = _economy()
    base = m.solve()
    h["tax"].set([0.0, 0.0])
    sol = m.solve()
    HH, PY = h["HH"], h["PY"]
    d0 = np.array([base.final_demand(HH, PY[g]) for g in ("agr", "man")])
    d1 = np.array([sol.final_demand(HH, PY[g]) for g in ("agr", "man")])
    theta, rho = d0 / d0.sum(), (0.8 - 1.0) / 0.8
    u_ratio = (theta @ (d1 / d0) ** rho) ** (1.0 / rho)   # CES quantity index
    m0 = base.value(HH)
    ev = sol.equivalent_variation(base)[0]
    assert ev == pytest.approx(m0 * (u_ratio - 1.0), rel=1e-10)
    rows = {r[0]: r for r in sol.report(base)}
    assert rows["EV[HH]"][3] == pytest.approx(ev)
    assert rows["Y[man]"][4] == pytest.approx(100 * (sol.value(h["Y"]["man"]) - 1.0))


def test_scenario_loop_through_solve_batch_matches_single_solves():
    m, h = _economy()
    m.solve()
    scenarios = grid(esub=[0.5, 1.0, 2.0], tax=[0.0, 0.1])
    batch = solve_batch(m.scenario(), scenarios, workers=0, progress=None,
                        options={"convergence_tolerance": 1e-10})
    assert batch.failed == 0
    for s, x in zip(scenarios, batch.x):
        h["esub"].set(s["esub"])
        h["tax"].set(s["tax"])
        single = m.solve()
        np.testing.assert_allclose(x[:m.ncols], single.x[:m.ncols], rtol=1e-8, atol=1e-10)


def test_auxiliary_numeraire_and_bounds():
    """A price-index numeraire as an auxiliary constraint (PL + PK = 2 through an
    auxiliary scaling an endowment), and an upper bound that binds."""
    m = Model()
    Y = m.sector("Y")
    PY, PL, PK = m.commodity("PY"), m.commodity("PL"), m.commodity("PK")
    H = m.consumer("H")
    S = m.auxiliary("S", start=1.0, lower=0.0)
    m.production(Y, s=0.5).output(PY, 100).input(PL, 60).input(PK, 40)
    m.demand(H).final(PY, 100).endowment(PL, 60 * S).endowment(PK, 40)
    m.constraint(S, PL + PK - 2.0)
    m.fix(H, 100.0)
    sol = m.solve(numeraire=False)
    assert sol.success and sol.residual() <= 1e-10
    assert sol.value(PL) + sol.value(PK) == pytest.approx(2.0, abs=1e-12)
    m.set_bounds(Y, upper=0.9)
    sol = m.solve(numeraire=False)
    assert sol.success and sol.value(Y) == pytest.approx(0.9)
    F, _ = sol.eq.evaluate(sol.x, deriv=False)
    assert F[int(Y.cols[0])] <= 1e-10    # at its upper bound, F <= 0


def test_price_index_and_options_object():
    """The consumer's price index is 1 at the reference prices and moves with them; an
    Options object is accepted by solve."""
    import compass_sparse as cs

    m, h = _economy()
    base = m.solve(options=cs.Options(convergence_tolerance=1e-10))
    assert base.price_index(h["HH"]) == pytest.approx(1.0, abs=1e-12)
    h["tax"].set([0.3, 0.3])
    sol = m.solve()
    assert sol.price_index(h["HH"]) > 1.0    # dearer goods at a fixed wage
