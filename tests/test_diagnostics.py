"""Help for the common mistakes: check_jacobian finds a wrong Jacobian entry and names it;
a failed solve whose Jacobian disagrees with F says so and names check_jacobian; a foreign
option name gets a did-you-mean hint; the generators print no numpy warnings at the trial
points the solver rejects."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.diagnostics import directional_mismatch
from compass_sparse.exceptions import OptionError, ProblemError

N = 8
A = sp.diags([-np.ones(N - 1), 4.0 * np.ones(N), -np.ones(N - 1)], [-1, 0, 1]).tocsc()
B = np.linspace(1.0, 2.0, N)
NAMES = [f"price[{k}]" for k in range(N)]


def F(x):
    return A @ x + x**3 - B


def J(x):
    return (A + sp.diags(3.0 * x**2)).tocsc()


def J_flipped(x):
    # one entry of the wrong sign: d F_2 / d x_3 should be -1
    M = J(x).tolil()
    M[2, 3] = 1.0
    return M.tocsc()


def test_check_jacobian_accepts_a_correct_jacobian():
    rep = cs.check_jacobian(F, J, np.full(N, 0.5))
    assert rep.ok and rep.max_error < 1e-8 and rep.columns == N and not rep.skipped
    assert "agrees" in str(rep)


def test_check_jacobian_finds_a_flipped_sign_and_names_it():
    rep = cs.check_jacobian(F, J_flipped, np.full(N, 0.5), var_names=NAMES)
    assert not rep.ok
    row, col, jv, dv, err = rep.worst[0]
    assert (row, col) == ("F(price[2])", "price[3]")
    assert jv == 1.0 and dv == pytest.approx(-1.0, abs=1e-8) and err == pytest.approx(2.0)
    assert "DISAGREES" in str(rep) and "price[3]" in str(rep)
    # the other rows of the report are right: only the flipped entry is above tolerance
    assert all(e <= rep.tolerance for *_, e in rep.worst[1:])


def test_check_jacobian_of_an_mcp_uses_its_names_and_start():
    p = cs.MCP(F, J_flipped, 0.0, np.inf, np.full(N, 0.5), eqn_names=[f"mkt{k}" for k in
                                                                      range(N)])
    rep = cs.check_jacobian(p)
    assert rep.worst[0][:2] == ("mkt2", "x[3]")


def test_check_jacobian_samples_the_columns_of_a_large_problem():
    rep = cs.check_jacobian(F, J_flipped, np.full(N, 0.5), max_columns=3, seed=1)
    assert rep.columns == 3


def test_check_jacobian_skips_columns_where_f_fails():
    def F_log(x):
        return np.log(x) - 1.0

    def J_log(x):
        return sp.diags(1.0 / x).tocsc()

    x = np.array([1.0, 1e-12, 2.0])  # x_1 - h < 0: log is NaN there
    rep = cs.check_jacobian(F_log, J_log, x)
    assert rep.skipped == ["x[1]"] and rep.columns == 2 and rep.ok


def test_a_failed_solve_with_a_wrong_sign_jacobian_names_check_jacobian():
    def J_negated(x):
        return -J(x)

    res = cs.solve_mcp(F, J_negated, 0.0, np.inf, np.zeros(N))
    assert not res.success
    assert "check_jacobian" in res.message and "disagrees" in res.message


def test_a_failed_solve_with_a_correct_jacobian_does_not_blame_it():
    # F = x^2 + 1 has no zero on a free variable: the solve fails, J is right
    res = cs.solve_mcp(lambda x: x**2 + 1.0, lambda x: np.diag(2.0 * x), -np.inf, np.inf,
                       np.array([1.5]))
    assert not res.success and "check_jacobian" not in res.message


def test_the_jacobian_check_of_a_failed_solve_is_not_counted_as_its_work():
    p = cs.MCP(F, lambda x: -J(x), 0.0, np.inf, np.zeros(N))
    res = cs.solve_mcp(p)
    assert "check_jacobian" in res.message
    assert (p.counters.nfev, p.counters.njev) == (res.nfev, res.njev)


def test_directional_mismatch_is_zero_for_a_right_jacobian():
    p = cs.MCP(F, J, 0.0, np.inf, np.zeros(N))
    assert directional_mismatch(p, np.full(N, 0.7), p.x0) < 1e-6
    assert directional_mismatch(cs.MCP(F, J_flipped, 0.0, np.inf, np.zeros(N)),
                                np.full(N, 0.7), np.zeros(N)) > 1e-2


@pytest.mark.parametrize("name, meant", [("tol", "convergence_tolerance"),
                                         ("maxiter", "major_iteration_limit"),
                                         ("iterlim", "major_iteration_limit"),
                                         ("output", "verbosity"),
                                         ("preprocess", "presolve")])
def test_foreign_option_names_get_a_did_you_mean_hint(name, meant):
    with pytest.raises(OptionError, match=f"'{name}' \\(did you mean '{meant}'\\?\\)"):
        cs.Options(**{name: 1})
    with pytest.raises(ProblemError, match=f"did you mean the option '{meant}'\\? pass "
                       f"options=\\{{'{meant}'"):
        cs.solve_mcp(F, J, 0.0, np.inf, np.zeros(N), **{name: 1})


def test_cge_generator_prints_no_warning_where_the_solver_rejects_a_point():
    from compass_sparse.generators.cge import static_cge

    m = static_cge(seed=0)
    z = m.benchmark.copy()
    z[m.blocks["PA"]] = -1.0  # negative prices: outside the CES functions' domain
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = m.problem.F_uncounted(z)
        m.J(z)
    assert not np.all(np.isfinite(f))  # the point is one the solver rejects
