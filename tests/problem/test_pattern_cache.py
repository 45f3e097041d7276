"""Objects made once per Jacobian pattern (compass_sparse.problem.pattern_cache) and shared
by the solves of one problem; rebuilt when an undeclared pattern grows; a problem that
needs the full work still gets it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from compass_sparse import MCP, solve_mcp


def _cournot():
    def F(q):
        return np.array([1.0, 2.0]) - (10.0 - q.sum()) + q

    return MCP(F, lambda q: np.array([[2.0, 1.0], [1.0, 2.0]]), 0.0, np.inf, np.zeros(2))


def test_linearizer_made_once_per_pattern_and_shared_by_the_solves_of_a_problem():
    # (no crash: it ends these solves, and then no linearizer is needed or made)
    opt = {"crash_method": "none"}
    prob = _cournot()
    first = solve_mcp(prob.with_start(np.zeros(2)), options=opt)
    lin = prob.evaluator.pattern_cache.linearizer
    assert lin is not None
    again = solve_mcp(prob.with_start(np.zeros(2)), options=opt)
    assert prob.evaluator.pattern_cache.linearizer is lin
    # another problem object, nothing shared: the same answer and counts
    fresh = solve_mcp(_cournot().with_start(np.zeros(2)), options=opt)
    for r in (first, again):
        assert r.success and r.nit > 0
        np.testing.assert_array_equal(r.x, fresh.x)
        assert (r.nit, r.minor_iterations, r.nfev, r.njev) == (
            fresh.nit, fresh.minor_iterations, fresh.nfev, fresh.njev)


def test_pattern_store_rebuilds_when_an_undeclared_pattern_grows():
    # J is diagonal at the start and gains an off-diagonal entry away from it: the stored
    # pattern grows, so everything derived from the old pattern must be made again.
    def F(x):
        return np.array([x[0] - 1.0 + 0.5 * x[1] ** 2, x[1] - 2.0])

    def J(x):
        return sp.csc_matrix(np.array([[1.0, x[1]], [0.0, 1.0]]))

    prob = MCP(F, J, -np.inf, np.inf, np.zeros(2))
    ev = prob.evaluator
    ev.fj(np.zeros(2))
    first = ev.pattern_cache
    first.linear_rows = 7
    assert ev.pattern_cache is first and ev.pattern_cache.linear_rows == 7
    ev.fj(np.ones(2))  # J now has the (0, 1) entry: the pattern grows
    assert ev.pattern_growths == 1
    assert ev.pattern_cache is not first and ev.pattern_cache.linear_rows is None
    assert ev.pattern_cache.pattern is ev.pattern_ref
    res = solve_mcp(prob.with_start(np.zeros(2)))
    assert res.success
    np.testing.assert_allclose(res.x, [-1.0, 2.0], atol=1e-8)


def test_tiny_problem_with_a_declared_linear_row_still_presolved_in_every_solve():
    # The count of linear rows is kept per pattern; a problem that has one must still
    # reach the preprocessor on the second solve (and one without must not).
    M = np.array([[2.0, 1.0], [0.0, 1.0]])

    def F(x):
        return np.array([2.0 * x[0] + x[1] + 0.1 * x[0] ** 3 - 4.0, x[1] - 1.0])

    def J(x):
        return np.array([[2.0 + 0.3 * x[0] ** 2, 1.0], [0.0, 1.0]])

    # row 2 entirely constant (its stored zero at (1, 0) included)
    const = sp.csc_matrix((np.ones(3), ([0, 1, 1], [1, 0, 1])), shape=(2, 2))
    prob = MCP(F, J, 0.0, np.inf, np.zeros(2), constant_jac=const)
    plain = MCP(F, J, 0.0, np.inf, np.zeros(2))
    for _ in range(2):
        r = solve_mcp(prob.with_start(np.zeros(2)))
        assert r.success and r.passes["presolve"].ran
        p = solve_mcp(plain.with_start(np.zeros(2)))
        assert p.success and not p.passes["presolve"].ran
        np.testing.assert_allclose(r.x, p.x, atol=1e-9)
    del M
