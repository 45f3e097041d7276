"""The Pyomo link: SolverFactory('compass_sparse') on pyomo.mpec models."""
import numpy as np
import pytest

pytest.importorskip("pyomo.environ", reason="pyomo is not installed (optional extra: "
                    "pip install compass-sparse[pyomo])")
pytest.importorskip("casadi", reason="casadi is not installed (optional extra: "
                    "pip install compass-sparse[pyomo])")

import pyomo.environ as pe
from pyomo.mpec import Complementarity, complements
from pyomo.opt import TerminationCondition

import compass_sparse.interfaces.pyomo as cpy
from compass_sparse.examples import cournot, spatial
from compass_sparse.exceptions import ModelError, OptionError


def natural_residual(x, f, lb, ub):
    return float(np.max(np.abs(x - np.clip(x - f, lb, ub))))


def test_solver_factory_solves_the_classic_cournot_market_and_loads_the_solution():
    m = cournot.pyomo_model(cournot.data(1))
    opt = pe.SolverFactory("compass_sparse")
    res = opt.solve(m)
    pe.assert_optimal_termination(res)
    q = cournot.pyomo_solution(m)
    np.testing.assert_allclose(q, cournot.CLASSIC_SOLUTION, atol=1e-3)
    # the loaded point solves the hand-written model, independently of the link
    kw = cournot.callables(cournot.data(1))
    assert natural_residual(q, kw["F"](q), kw["lb"], kw["ub"]) < 1e-6
    assert res.problem.number_of_variables == 5


def forms_model():
    """One complementarity of every form complements() accepts, with known solutions."""
    m = pe.ConcreteModel(name="forms")
    m.p = pe.Param(mutable=True, initialize=2.0)
    m.x = pe.Var(within=pe.NonNegativeReals, initialize=0.5)
    m.y = pe.Var(initialize=0.0)
    m.z = pe.Var(initialize=0.0)
    m.w = pe.Var(initialize=0.5)
    m.u = pe.Var(initialize=0.0)
    m.v = pe.Var(initialize=0.0)
    m.v2 = pe.Var(initialize=0.0)
    m.s = pe.Var(initialize=1.0)
    m.h = pe.Var(initialize=0.0)
    m.mu = pe.Var(initialize=0.0)
    m.fx = pe.Var(initialize=3.0)
    m.fx.fix(3.0)
    m.a = Complementarity(expr=complements(m.x >= 0, m.x - m.p >= 0))  # x = p
    m.b = Complementarity(expr=complements(m.y + 3 >= 0, m.y >= -1))  # swapped: y = -1
    m.c = Complementarity(expr=complements(m.z <= 4, 10 - m.z >= 0))  # upper bound: z = 4
    m.d = Complementarity(expr=complements(pe.inequality(0, m.w, 1), m.w - 3))  # ranged: w = 1
    m.e = Complementarity(expr=complements(pe.inequality(-1, m.u, 1), m.u ** 3 - 0.125))  # u = 0.5
    m.f = Complementarity(expr=complements(2 * m.v + 1 >= 3, m.v - 5 >= 0))  # affine: v = 5
    m.g = Complementarity(expr=complements(-m.v2 >= -2, 5 - m.v2 >= 0))  # v2 <= 2: v2 = 2
    m.k = Complementarity(expr=complements(m.s ** 3 - 8 == 0, m.s))  # equality, free: s = 2
    m.l = Complementarity(expr=complements(pe.inequality(1, m.h - m.mu, 3), m.mu))  # mu = 4
    m.hdef = pe.Constraint(expr=m.h - 5 == 0)  # square equation paired with h
    m.fixed = Complementarity(expr=complements(m.fx >= 0, m.fx - 7 >= 0))  # dropped
    return m


EXPECTED = {"x": 2.0, "y": -1.0, "z": 4.0, "w": 1.0, "u": 0.5, "v": 5.0, "v2": 2.0, "s": 2.0,
            "h": 5.0, "mu": 4.0, "fx": 3.0}


def test_every_complements_form_is_read_with_its_bounds_and_sign():
    m = forms_model()
    res = pe.SolverFactory("compass_sparse").solve(m, options={"convergence_tolerance": 1e-12})
    pe.assert_optimal_termination(res)
    for name, want in EXPECTED.items():
        assert pe.value(getattr(m, name)) == pytest.approx(want, abs=1e-8), name
    pm = cpy.compiled(m)
    assert pm.n == 11  # 10 unfixed variables + the auxiliary of the ranged multiplier form
    assert "fx" not in pm.var_names


def test_mutable_param_changes_without_recompiling():
    m = forms_model()
    opt = pe.SolverFactory("compass_sparse")
    opt.solve(m)
    first = cpy.compiled(m)
    m.p = 3.5
    opt.solve(m)
    assert cpy.compiled(m) is first
    assert pe.value(m.x) == pytest.approx(3.5, abs=1e-8)


def test_fixing_a_variable_recompiles_and_keeps_auxiliary_rows_aligned():
    """Fixing z (declared before the ranged multiplier form) once shifted the auxiliary
    variable's index and broke its start value."""
    m = forms_model()
    opt = pe.SolverFactory("compass_sparse")
    opt.solve(m)
    first = cpy.compiled(m)
    m.z.fix(1.0)
    opt.solve(m)
    second = cpy.compiled(m)
    assert second is not first and second.n == first.n - 1
    assert pe.value(m.z) == 1.0 and pe.value(m.x) == pytest.approx(2.0, abs=1e-8)


def test_scenario_loop_matches_the_hand_written_model_at_each_demand():
    d = cournot.data(3, seed=1)
    m = cournot.pyomo_model(d)
    opt = pe.SolverFactory("compass_sparse")
    for scale in (1.0, 0.7, 1.3):
        for i in m.M:
            m.D[i] = float(d["D"][i] * scale)
        res = opt.solve(m, options={"convergence_tolerance": 1e-10})
        pe.assert_optimal_termination(res)
        d2 = dict(d, D=d["D"] * scale)
        kw = cournot.callables(d2)
        q = cournot.pyomo_solution(m)
        assert natural_residual(q, kw["F"](q), kw["lb"], kw["ub"]) < 1e-8


@pytest.mark.parametrize("module,args", [(cournot, (4,)), (spatial, (15,))])
def test_compiled_F_and_J_equal_the_hand_written_ones(module, args):
    d = module.data(*args)
    kw = module.callables(d)
    pm = cpy.PyomoMCP(module.pyomo_model(d))
    # the same variables in the same order, named after the Pyomo components
    assert pm.var_names == module.names(d)
    rng = np.random.default_rng(0)
    x = kw["x0"] + rng.random(kw["x0"].size)
    pm._fj.set_parameters(pm.parameter_values())
    fe = pm.evaluator
    np.testing.assert_allclose(fe.F(x), kw["F"](x), rtol=1e-12, atol=1e-12)
    Jc, Jh = fe.J(x), kw["jac"](x)
    assert abs(Jc - Jh).max() <= 1e-11 * max(1.0, abs(Jh).max())
    # the pattern is the same at every point (structural, not value-based)
    Jz = fe.J(np.zeros_like(x) + 1.0)
    assert np.array_equal(Jz.indices, Jc.indices) and np.array_equal(Jz.indptr, Jc.indptr)


def test_names_reach_the_result_diagnostics():
    m = cournot.pyomo_model(cournot.data(2))
    res = pe.SolverFactory("compass_sparse").solve(m, options={"major_iteration_limit": 1})
    assert res.solver.termination_condition == TerminationCondition.maxIterations
    worst = res.compass_result.worst_rows
    assert worst and worst[0][0].startswith("profit[")


def test_unknown_option_is_an_option_error():
    m = cournot.pyomo_model(cournot.data(1))
    with pytest.raises(OptionError):
        pe.SolverFactory("compass_sparse").solve(m, options={"no_such_option": 1})


def test_linear_rows_are_declared_constant_for_the_preprocessor():
    d = spatial.data(8)
    pm = cpy.PyomoMCP(spatial.pyomo_model(d))
    kw = spatial.callables(d)
    C = pm.evaluator.constant.toarray() != 0
    hand = kw["constant_jac"].toarray() != 0
    assert np.all(C[hand])  # every entry the hand-written model knows to be constant
    A = d["src"].size
    # the price rows are nonlinear in their own price (the demand term)
    assert not np.any(np.diag(C)[A:])
    # and the shipment rows are linear in the shipment (unit cost k + r x)
    assert np.all(np.diag(C)[:A])


# --------------------------------------------------------------------------- #
# bad models
# --------------------------------------------------------------------------- #
def test_complementarity_with_no_variable_on_either_side_is_a_model_error():
    m = pe.ConcreteModel()
    m.x = pe.Var()
    m.y = pe.Var()
    m.both = Complementarity(expr=complements(m.x + m.y >= 0, m.x - m.y >= 0))
    m.other = pe.Constraint(expr=m.x + 2 * m.y == 1)
    with pytest.raises(ModelError, match="both"):
        pe.SolverFactory("compass_sparse").solve(m)


def test_unmatched_equations_are_a_model_error_naming_them():
    m = pe.ConcreteModel()
    m.x = pe.Var()
    m.e1 = pe.Constraint(expr=m.x == 1)
    m.e2 = pe.Constraint(expr=2 * m.x == 2)
    with pytest.raises(ModelError, match="unmatched equations.*e2"):
        pe.SolverFactory("compass_sparse").solve(m)


def test_missing_bound_is_a_model_error_naming_the_complementarity():
    m = pe.ConcreteModel()
    m.x = pe.Var()
    m.loose = Complementarity(expr=complements(m.x >= 0, m.x - 1))
    with pytest.raises(ModelError, match="loose.*bound is missing"):
        pe.SolverFactory("compass_sparse").solve(m)


def test_inequality_constraint_outside_a_complementarity_is_a_model_error():
    m = pe.ConcreteModel()
    m.x = pe.Var()
    m.ineq = pe.Constraint(expr=m.x >= 1)
    with pytest.raises(ModelError, match="ineq"):
        pe.SolverFactory("compass_sparse").solve(m)


def test_structurally_singular_equations_are_a_model_error():
    m = pe.ConcreteModel()
    m.x = pe.Var()
    m.y = pe.Var()
    m.z = pe.Var()
    m.e1 = pe.Constraint(expr=m.x == 1)
    m.e2 = pe.Constraint(expr=m.x ** 2 == 1)  # e1 and e2 contain x only
    m.e3 = pe.Constraint(expr=m.x + m.y + m.z == 3)
    with pytest.raises(ModelError, match="structurally singular.*e[12]"):
        pe.SolverFactory("compass_sparse").solve(m)


def test_tee_prints_the_iteration_log_and_removes_its_handler(capsys):
    import logging

    m = cournot.pyomo_model(cournot.data(1))
    before = list(logging.getLogger("compass_sparse").handlers)
    pe.SolverFactory("compass_sparse").solve(m, tee=True)
    out = capsys.readouterr().out
    assert "major" in out.lower()
    assert "(profit[0," in out  # the iteration log labels rows by their Pyomo names
    assert logging.getLogger("compass_sparse").handlers == before


def test_sub_blocks_are_read_and_deactivated_components_ignored():
    m = pe.ConcreteModel()
    m.b = pe.Block()
    m.b.x = pe.Var(within=pe.NonNegativeReals)
    m.b.c = Complementarity(expr=complements(m.b.x >= 0, m.b.x - 3 >= 0))
    m.y = pe.Var()
    m.e = pe.Constraint(expr=m.y - 2 * m.b.x == 0)
    m.off = Complementarity(expr=complements(m.y >= 0, m.y + 100 >= 0))
    m.off.deactivate()
    opt = pe.SolverFactory("compass_sparse")
    assert opt.available() and opt.license_is_valid() and len(opt.version()) == 3
    pe.assert_optimal_termination(opt.solve(m))
    assert pe.value(m.b.x) == pytest.approx(3.0) and pe.value(m.y) == pytest.approx(6.0)
    assert cpy.compiled(m).var_names == ["b.x", "y"]


def test_every_status_has_a_pyomo_termination_condition():
    # Pinned gap: statuses added after the link was written (FLAT_RESIDUAL,
    # STATIONARY_POINT, MEMORY_LIMIT) came back as unknown/unknown.
    from pyomo.opt import SolverStatus

    from compass_sparse import Status
    from compass_sparse.interfaces.pyomo import _termination

    for st in Status:
        solver_status, tc = _termination(st)
        assert solver_status is not SolverStatus.unknown and tc.name != "unknown", st
