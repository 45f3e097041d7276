"""Each numerical threshold of the layer, stress-tested: the expansion about Cobb–Douglas
(RHO_CD), the elasticity standing for infinity (SIGMA_INF), the cap on quantities far
from consistent nest prices (LOGX_MAX) and the price floor inside logarithms."""
import mpmath
import numpy as np
import pytest

from compass_sparse.mge import RHO_CD, SIGMA_INF, Model
from compass_sparse.mge.equations import LOGX_MAX


def _one_nest(sigma, prices, values=(30.0, 50.0, 20.0)):
    """A sector whose inputs sit in one CES nest; returns (model, sector, commodities)."""
    m = Model()
    P = m.commodities("P", ["a", "b", "c", "out"], start=[*prices, 1.0])
    Y = m.sector("Y")
    H = m.consumer("H")
    m.production(Y, s=sigma).output(P["out"], sum(values)).input(P[["a", "b", "c"]],
                                                                  np.array(values))
    m.demand(H).final(P["out"], sum(values)).endowment(P[["a", "b", "c"]],
                                                       np.array([values]))
    return m


def _log_index(theta, prices, rho):
    """log of the CES price index in 60-digit arithmetic."""
    mpmath.mp.dps = 60
    if rho == 0:
        return float(mpmath.fsum(t * mpmath.log(p) for t, p in zip(theta, prices)))
    s = mpmath.fsum(t * mpmath.mpf(p) ** rho for t, p in zip(theta, prices))
    return float(mpmath.log(s) / rho)


@pytest.mark.parametrize("rho", [0.0, 1e-12, -1e-9, 3e-6, -2e-4, 0.999 * RHO_CD,
                                 -1.001 * RHO_CD, 5e-3, 0.3])
def test_price_index_near_cobb_douglas_is_accurate_on_both_sides_of_rho_cd(rho):
    """Within RHO_CD the cumulant expansion, outside it the log-sum-exp: both within
    1e-12 of the exact index for prices a factor 2 apart."""
    prices = (0.7, 1.4, 1.1)
    m = _one_nest(1.0 - rho, prices)
    st, eq = m.compile()
    x = m.start_point(eq)
    node = st.zp_in[1][0]
    theta = np.array([30.0, 50.0, 20.0]) / 100.0
    assert abs(np.log(x[st.node_col[node]]) - _log_index(theta, prices, rho)) < 1e-12


def test_perfect_substitutes_price_index_within_the_stated_tolerance():
    """σ = inf is SIGMA_INF: the index exceeds the min price by |log θ_min| / SIGMA_INF
    at most (relative), and the dearer inputs' demands vanish."""
    prices = (0.8, 1.0, 1.2)
    m = _one_nest(np.inf, prices)
    st, eq = m.compile()
    x = m.start_point(eq)
    pi = x[st.node_col[st.zp_in[1][0]]]
    assert 0.0 <= np.log(pi / 0.8) <= abs(np.log(0.3)) / (SIGMA_INF - 1) + 1e-15
    sol_x = x.copy()
    from compass_sparse.mge.report import Solution

    s = Solution(m, st, eq, sol_x, type("R", (), {"success": True})())
    Y, P = m.sets[1], m.sets[0]
    assert s.compensated_demand(Y, P["b"]) < 1e-100
    # A unit of activity needs 100 (reference) units of the cheapest input.
    assert s.compensated_demand(Y, P["a"]) == pytest.approx(100.0, rel=1e-3)


def test_perfect_substitutes_model_solves_to_the_cheapest_input():
    """Two perfect-substitute labour types, one taxed: all demand goes to the untaxed
    one and the equilibrium matches the closed form within SIGMA_INF's tolerance."""
    m = Model()
    L1, L2, PY = m.commodity("L1"), m.commodity("L2"), m.commodity("PY")
    Y, H = m.sector("Y"), m.consumer("H")
    tax = m.parameter("tax", 0.0)
    m.production(Y, s=np.inf).output(PY, 100).input(L1, 50).input(L2, 50, taxes=[(H, tax)])
    m.demand(H).final(PY, 100).endowment(L1, 50).endowment(L2, 50)
    m.fix(PY, 1.0)
    sol = m.solve()
    assert sol.success and sol.residual() <= 1e-8
    tax.set(0.5)
    sol = m.solve()
    assert sol.success and sol.residual() <= 1e-8
    # L2 is left unemployed (its price falls until the tax-inclusive prices tie): the
    # tie holds within the SIGMA_INF tolerance.
    pl1, pl2 = sol.value(L1), sol.value(L2)
    assert abs(np.log(pl1 / (pl2 * 1.5))) <= 2 * np.log(2) / SIGMA_INF


def test_quantities_stay_finite_far_from_consistent_nest_prices():
    """With σ = SIGMA_INF and a nest price 50% off its children, exp would overflow:
    F and J stay finite (quantities held at e^LOGX_MAX times the reference)."""
    m = _one_nest(np.inf, (1.0, 1.0, 1.0))
    st, eq = m.compile()
    x = m.start_point(eq)
    x[st.node_col] *= 1.5
    with np.errstate(all="raise"):
        F, J = eq.jacobian(x)
    assert np.all(np.isfinite(F)) and np.all(np.isfinite(J.data))
    assert np.abs(F).max() <= 100.0 * np.exp(LOGX_MAX)


def test_zero_price_gives_finite_residuals():
    """A price of exactly 0 (a free good) keeps F finite (PRICE_FLOOR inside logs)."""
    m = _one_nest(0.5, (1.0, 1.0, 1.0))
    _st, eq = m.compile()
    x = m.start_point(eq)
    x[m.sets[0].cols[0]] = 0.0
    F, _ = eq.evaluate(x, deriv=False)
    assert np.all(np.isfinite(F))
