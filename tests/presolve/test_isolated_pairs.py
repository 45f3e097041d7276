"""Isolated pairs (compass_sparse.problem.isolated, the preprocessor's isolated_pairs
pass): a variable and its row that nothing else touches in the declared pattern, solved
at the start value, are kept there -- above all a free variable whose F is identically 0,
with a zero row and column in every Jacobian, which made every Newton system singular.

Numpy only: the problems are a small CGE model of the generators (numpy F and J) with
variables appended by hand."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.generators.cge import static_cge
from compass_sparse.problem.isolated import isolated_pairs, solved_exactly

TOL = {"convergence_tolerance": 1e-10}


def _appended(p, extra_F, extra_J, lb, ub, x0, declare=True, coupled_to=None):
    """``p`` with k variables appended: F_extra(x_extra, x) and its diagonal derivative;
    ``coupled_to`` (index of p, or None): the extra rows also read that variable of p
    (an entry of the declared pattern, derivative 0)."""
    n, k = p.n, len(x0)
    D = sp.identity(k, format="csc")
    C = None
    if coupled_to is not None:
        C = sp.csc_matrix((np.ones(k), (np.arange(k), np.full(k, coupled_to))), shape=(k, n))
    pattern = sp.bmat([[p.pattern, None], [C, D]], format="csc")

    def F(x):
        return np.concatenate([p.F(x[:n]), extra_F(x[n:], x[:n])])

    def J(x):
        return sp.bmat([[p.J(x[:n]), None], [None, sp.diags(extra_J(x[n:], x[:n]))]],
                       format="csc")

    kw = {"jac_sparsity": pattern} if declare else {}
    return cs.MCP(F, J, np.append(p.lb, lb), np.append(p.ub, ub), np.append(p.x0, x0), **kw)


def _zero(xe, x):
    return np.zeros(xe.size)


CASES = {"1 region, 4 sectors, output tax 0.5": (1, 4, {"output_tax": 0.5}),
         "2 regions, 2 sectors, productivity 1.3": (2, 2, {"productivity": 1.3})}


@pytest.mark.parametrize("case", CASES)
def test_a_free_variable_with_a_zero_row_and_column_keeps_its_start_value_and_costs_nothing(
        case):
    """The old solver took the singular Newton systems to many more major iterations
    (4 -> 23 and 3 -> 22 on these models; the modelling layer's example with such a
    variable: 4 -> 33, NO_PROGRESS after 158 in an earlier version).  Now the pair
    leaves the problem: the same major iterations and point as without the variable, and
    the variable keeps its start value."""
    regions, sectors, shock = CASES[case]
    p = static_cge(regions=regions, sectors=sectors).with_shock(**shock).problem
    plain = cs.solve_mcp(p, options=TOL)
    q = _appended(p, _zero, _zero, -np.inf, np.inf, [0.7])
    res = cs.solve_mcp(q, options=TOL)
    assert plain.success and res.success
    assert res.nit == plain.nit
    assert res.x[-1] == 0.7  # (the old solver moved it to 0: not wrong, but not PATH's)
    assert res.check(q).natural <= 1e-10  # (recomputed on the problem with the variable)
    np.testing.assert_allclose(res.x[:-1], plain.x, rtol=0, atol=1e-9)
    assert res.passes["presolve"].ran and "removed" in res.passes["presolve"].reason


def test_pairs_isolated_once_fixed_variables_leave_are_kept_at_a_bound_or_inside():
    """Rows that also read a fixed variable of the model (the numeraire, l = u) are
    isolated once it leaves: a free pair with F = 0 and a pair at its lower bound with
    F > 0 (J_ii = 1 there: no singularity, but nothing to solve either) both stay put."""
    p = static_cge(regions=1, sectors=4).with_shock(output_tax=0.5).problem
    fixed = int(np.flatnonzero(p.lb == p.ub)[0])

    def F(xe, x):
        return np.array([0.0, np.exp(xe[1])])

    def J(xe, x):
        return np.array([0.0, np.exp(xe[1])])

    q = _appended(p, F, J, [-np.inf, 0.0], [np.inf, np.inf], [-3.0, 0.0], coupled_to=fixed)
    res = cs.solve_mcp(q, options=TOL)
    assert res.success and res.check(q).natural <= 1e-10
    assert res.x[-2] == -3.0 and res.x[-1] == 0.0
    assert res.nit == cs.solve_mcp(p, options=TOL).nit


def test_an_isolated_pair_not_solved_at_its_start_is_left_to_the_solver():
    """F = x^3 - 8 from x0 = 0, and F = x - c from one ulp away from c: not solved
    exactly at the start (the test has no tolerance), so not fixed; the solver finds
    x = 2 and x = c."""
    p = static_cge(regions=1, sectors=3).problem
    c = 1.0 / 3.0

    def F(xe, x):
        return np.array([xe[0] ** 3 - 8.0, xe[1] - c])

    def J(xe, x):
        return np.array([3 * xe[0] ** 2, 1.0])

    x0 = [0.0, np.nextafter(c, 1.0)]
    q = _appended(p, F, J, [-np.inf, -np.inf], [np.inf, np.inf], x0)
    assert not solved_exactly(x0, F(np.array(x0), None), -np.inf, np.inf).any()
    res = cs.solve_mcp(q, options=TOL)
    assert res.success and res.check(q).natural <= 1e-10
    np.testing.assert_allclose(res.x[-2:], [2.0, c], rtol=0, atol=1e-10)


def test_an_undeclared_pattern_is_never_read_as_isolated():
    """Without jac_sparsity the pattern is what J has returned so far, which may grow: the
    pair is not removed (the solve still ends at a solution)."""
    p = static_cge(regions=1, sectors=3).with_shock(output_tax=0.5).problem
    q = _appended(p, _zero, _zero, -np.inf, np.inf, [0.7], declare=False)
    res = cs.solve_mcp(q, options={**TOL, "verbosity": 0})
    assert res.check(q).natural <= 1e-10
    assert res.passes["presolve"].reason.startswith("Preprocessor removed 0 rows")


def test_isolated_pairs_reads_the_pattern_without_the_removed_indices():
    # 0: only (0, 0); 1, 2: coupled; 3: (3, 3) and (3, 4), alone once 4 is removed
    P = sp.csc_matrix(np.array([[1, 0, 0, 0, 0],
                                [0, 1, 1, 0, 0],
                                [0, 1, 1, 0, 0],
                                [0, 0, 0, 1, 1],
                                [0, 0, 0, 0, 1]], dtype=float))
    assert isolated_pairs(P.indptr, P.indices, 5).tolist() == [0]  # (4: row 3 reads it)
    removed = np.array([False, False, False, False, True])
    assert isolated_pairs(P.indptr, P.indices, 5, removed).tolist() == [0, 3]
    z = np.array([0.0, 0.0, 1.0, 2.0, np.nan])
    f = np.array([1.0, -1e-300, 0.0, -1.0, 0.0])
    lb = np.array([0.0, 0.0, 0.0, -np.inf, 0.0])
    ub = np.array([np.inf, np.inf, np.inf, 2.0, 1.0])
    assert solved_exactly(z, f, lb, ub).tolist() == [True, False, True, True, True]
