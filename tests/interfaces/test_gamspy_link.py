"""The GAMSPy link: F and J from GAMS' GMO evaluator; levels and marginals against PATH."""
import numpy as np
import pytest

from compass_sparse.examples import cge, cournot, spatial
from compass_sparse.exceptions import GamsLicenseError, ModelError
from compass_sparse.interfaces.gamspy import GamsMCP, solve_gamspy

# every test here has GAMS generate a model: GAMS must run (tests/conftest.py)
pytestmark = pytest.mark.gams

TOL = 1e-10


@pytest.mark.parametrize("module,args", [(cournot, (2,)), (spatial, (12,)), (cge, (3,))])
def test_levels_and_marginals_equal_path_on_the_same_model(module, args):
    d = module.data(*args)
    ct, model, ours = module.gamspy_model(d)
    res = solve_gamspy(ct, model, {"convergence_tolerance": TOL})
    assert res.success, res.message
    ct2, model2, theirs = module.gamspy_model(d)
    model2.solve(solver="path", solver_options={"convergence_tolerance": TOL})
    assert model2.status.value in (1, 2)
    for name in ours:
        a, b = ours[name].records, theirs[name].records
        assert len(a) == len(b), name
        key = list(a.columns[:ours[name].dimension])
        if key:
            a, b = a.copy(), b.copy()
            for frame in (a, b):
                frame[key] = frame[key].astype(str)
            a = a.sort_values(key).reset_index(drop=True)
            b = b.sort_values(key).reset_index(drop=True)
        for col in ("level", "marginal"):
            np.testing.assert_allclose(a[col].to_numpy(float), b[col].to_numpy(float),
                                       atol=1e-7, rtol=1e-7, err_msg=f"{name}.{col}")
        if name in ("prf_Y", "mkt_P", "income", "trade", "balance", "profit"):
            for col in ("lower", "upper"):
                np.testing.assert_array_equal(a[col].to_numpy(float), b[col].to_numpy(float))


@pytest.mark.parametrize("module,args", [(cournot, (3,)), (spatial, (10,))])
def test_gmo_F_and_J_equal_the_hand_written_ones(module, args):
    d = module.data(*args)
    kw = module.callables(d)
    ct, model, _ = module.gamspy_model(d)
    gm = GamsMCP(ct, model)
    try:
        # map GAMS' column order to the hand-written order through the names
        order = _order(gm.var_names, module, d)
        rng = np.random.default_rng(3)
        x = kw["x0"] + rng.random(kw["x0"].size)
        f = gm.F(x[order])
        np.testing.assert_allclose(f, kw["F"](x)[order], rtol=1e-12, atol=1e-12)
        J = gm.J(x[order]).toarray()
        Jh = kw["jac"](x).toarray()[np.ix_(order, order)]
        np.testing.assert_allclose(J, Jh, rtol=1e-12, atol=1e-12)
    finally:
        gm.close()


def _order(gams_names, module, d):
    """Index into the hand-written variable order of every GAMS column."""
    want = {}
    for k, nm in enumerate(module.names(d)):
        sym, idx = nm.rstrip("]").split("[")
        want[(sym, tuple(idx.split(",")))] = k
    out = []
    for nm in gams_names:
        sym, rest = nm.split("(")
        labels = tuple(t.strip("'\"") for t in rest.rstrip(")").split(","))
        out.append(want[(sym, labels)])
    return np.array(out)


def test_model_above_the_free_licence_size_raises_a_licence_error():
    # 1 + 5 * 201 = 1005 rows/columns: above the free GAMSPy licence's 1000
    ct, model, _ = cournot.gamspy_model(cournot.data(201))
    with pytest.raises(GamsLicenseError, match="1000"):
        solve_gamspy(ct, model)


def _bad_models():
    import gamspy as gp

    m = gp.Container()
    x = gp.Variable(m, "x", type="positive")
    y = gp.Variable(m, "y", type="free")
    e = gp.Equation(m, "e")
    e[...] = x + y >= gp.Number(1)
    h = gp.Equation(m, "h")
    h[...] = x - y == gp.Number(0)
    return m, gp.Model(m, "bad_eq", problem="MCP", matches={e: x}, equations=[e, h]), \
        gp.Model(m, "bad_var", problem="MCP", matches={e: x})


def test_unmatched_equation_is_a_model_error_naming_it():
    m, bad_eq, _ = _bad_models()
    with pytest.raises(ModelError, match="unmatched equations in model bad_eq: h"):
        solve_gamspy(m, bad_eq)


def test_unmatched_free_variable_is_a_model_error_naming_it():
    m, _, bad_var = _bad_models()
    with pytest.raises(ModelError, match="bad_var.*Unmatched free variables = 1 y"):
        solve_gamspy(m, bad_var)


def test_labels_with_spaces_and_commas_are_written_back_to_their_records():
    import gamspy as gp

    m = gp.Container()
    i = gp.Set(m, "i", records=["a b", "c,d", "e"])
    p = gp.Parameter(m, "p", domain=i, records=[("a b", 1.0), ("c,d", -2.0), ("e", 3.0)])
    x = gp.Variable(m, "x", domain=i, type="positive")
    e = gp.Equation(m, "e", domain=i)
    e[i] = x[i] * x[i] * x[i] - p[i] >= gp.Number(0)
    res = solve_gamspy(m, gp.Model(m, "labels", problem="MCP", matches={e: x}),
                       {"convergence_tolerance": TOL})
    assert res.success
    lev = dict(zip(x.records.iloc[:, 0].astype(str), x.records["level"]))
    marg = dict(zip(x.records.iloc[:, 0].astype(str), x.records["marginal"]))
    assert lev["a b"] == pytest.approx(1.0) and lev["e"] == pytest.approx(3.0 ** (1 / 3))
    assert lev["c,d"] == 0.0 and marg["c,d"] == pytest.approx(2.0)  # F = 0 - (-2) at the bound
