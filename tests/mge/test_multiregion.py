"""A multi-region model of ~1e4 variables built from the same blocks: its synthetic
benchmark replicates, and removing every tariff is solved to a point that solves the
model; welfare moves as the economics says (EV of the world's households > 0 and the
governments, whose only income is tariff revenue, end with none)."""
import numpy as np
import pytest

from compass_sparse.mge.multiregion import multiregion_model


def test_multiregion_benchmark_and_tariff_removal_at_1e4_variables():
    m, h, d = multiregion_model(R=50, S=20, H=2)
    st, eq = m.compile()
    assert 9_000 <= eq.n <= 12_000
    check = m.benchmark()
    assert check.max <= 1e-9, check
    base = m.solve()
    assert base.success and base.result.nit == 0
    h["tm"].set(0.0)
    sol = m.solve()
    assert sol.success, sol.result.message
    assert sol.residual() <= 1e-8
    gov = sol.value(h["GOV"])
    assert np.all(np.abs(gov) <= 1e-8)
    ev = sol.equivalent_variation(base)
    hh = np.isin(st.demand_root[0], h["HH"].cols)
    assert ev[hh].sum() > 0
    # Households' incomes are the value of the factors they own.
    factor_income = sol.value(h["PL"]) @ d["labour"] + sol.value(h["PK"]) @ d["capital"]
    assert sol.value(h["HH"]).sum() == pytest.approx(factor_income, rel=1e-12)
