"""The economics report of a CGE counterfactual and the `cge` command that prints it."""
import csv
import io

import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse.cli import main
from compass_sparse.generators.cge import economics_report, static_cge


@pytest.fixture(scope="module")
def solved():
    model = static_cge(regions=2, sectors=4, households=2, seed=1)
    shocked = model.with_shock(output_tax=0.0)
    res = cs.solve_mcp(shocked.problem, options={"convergence_tolerance": 1e-10})
    assert res.success
    return shocked, res


def test_report_classifies_prices_quantities_and_incomes_by_block(solved):
    shocked, res = solved
    rep = economics_report(shocked, shocked.benchmark, res.x)
    kinds = {c.block: c.kind for c in rep.changes}
    assert kinds == {"Y": "quantity", "A": "quantity", "U": "quantity", "P": "price",
                     "PA": "price", "W": "price", "PU": "price", "TR": "income",
                     "M": "income"}
    assert len(rep.changes) == shocked.n
    assert [c.after for c in rep.changes] == list(res.x)


def test_equivalent_variation_equals_the_real_income_change_at_an_equilibrium(solved):
    # EV = M0 (U1/U0 - 1) uses the utility index; the income-based measure uses M/PU.
    # At an equilibrium M = Mbar PU U, so the two agree to the solve tolerance.
    shocked, res = solved
    rep = economics_report(shocked, shocked.benchmark, res.x)
    assert len(rep.welfare) == 4
    for w in rep.welfare:
        assert w.ev_percent == pytest.approx(w.real_income_percent, abs=1e-6)
        assert w.ev == pytest.approx(w.income_before * w.ev_percent / 100, rel=1e-12)


def test_report_of_an_unchanged_point_shows_no_change(solved):
    shocked, _ = solved
    rep = economics_report(shocked, shocked.benchmark, shocked.benchmark)
    assert all(c.change == 0.0 for c in rep.changes)
    assert all(w.ev == 0.0 and w.ev_percent == 0.0 for w in rep.welfare)


def test_uniform_productivity_gain_raises_every_households_welfare():
    model = static_cge(regions=1, sectors=5, households=3, seed=2)
    shocked = model.with_shock(productivity=1.1)
    res = cs.solve_mcp(shocked.problem)
    assert res.success
    rep = economics_report(shocked, shocked.benchmark, res.x)
    assert rep.welfare and all(w.ev > 0 for w in rep.welfare)


def test_report_csv_holds_every_variable_and_household(solved, tmp_path):
    shocked, res = solved
    rep = economics_report(shocked, shocked.benchmark, res.x)
    rows = list(csv.reader(io.StringIO(rep.to_csv())))
    assert rows[0] == ["kind", "block", "name", "before", "after", "change", "percent"]
    assert len(rows) == 1 + shocked.n + len(rep.welfare)
    byname = {r[2]: r for r in rows[1:] if r[0] != "welfare_ev"}
    i = shocked.index("W[r1,f1]")
    assert float(byname["W[r1,f1]"][4]) == res.x[i]


def test_report_rejects_points_of_the_wrong_size(solved):
    shocked, _ = solved
    with pytest.raises(ValueError, match="entries"):
        economics_report(shocked, shocked.benchmark, np.zeros(3))


def test_cge_command_prints_the_welfare_table_and_writes_csv(tmp_path, capsys):
    out_csv = tmp_path / "econ.csv"
    assert main(["cge", "--sectors", "4", "--households", "2", "--csv", str(out_csv)]) == 0
    out = capsys.readouterr().out
    assert "welfare by household" in out and "largest price changes" in out
    rows = list(csv.reader(out_csv.open()))
    assert len(rows) > 20 and rows[0][0] == "kind"


def test_report_of_a_dynamic_model_classifies_blocks_and_has_no_household_welfare():
    from compass_sparse.generators.cge import ramsey_cge

    model = ramsey_cge(periods=10)
    shocked = model.with_shock(capital_tax=0.25)
    res = cs.solve_mcp(shocked.problem)
    assert res.success
    rep = economics_report(shocked, shocked.benchmark, res.x)
    kinds = {c.block: c.kind for c in rep.changes}
    assert kinds["K"] == "quantity" and kinds["RK"] == "price" and kinds["HA"] == "income"
    assert rep.welfare == []
    # A capital tax lowers the capital stock after the first period.
    k = [c for c in rep.changes if c.block == "K"]
    assert all(c.after < c.before for c in k[1:])
    assert "welfare by household" not in rep.table()
