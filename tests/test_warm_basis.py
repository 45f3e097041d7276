"""Warm starts from the basis of another problem, and Result.sensitivity's arguments: a
basis of another size is refused at every entry point with a ShapeError naming both sizes
(its indices would pair with other variables), a batch scenario whose parent has another
size starts cold, and a sensitivity without its problem raises the package's error."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.batch import solve_batch
from compass_sparse.exceptions import ProblemError, ShapeError

NO_CRASH = {"crash_method": "none"}  # (the path starts at once: its pivots are counted)


def _lcp(n, seed=0):
    """A tridiagonal, diagonally dominant LCP (one solution) of order n: (M, q)."""
    M = sp.diags([np.full(n - 1, -1.0), np.full(n, 4.0), np.full(n - 1, -1.0)], [-1, 0, 1],
                 format="csc")
    return M, np.random.default_rng(seed).normal(size=n)


def _mcp(n, seed=0):
    M, q = _lcp(n, seed)
    return cs.MCP(lambda x: M @ x + q, lambda x: M, x0=np.zeros(n))


@pytest.fixture(scope="module")
def basis_of_5():
    res = cs.solve_lcp(*_lcp(5), options=NO_CRASH)
    assert res.success and res.basis is not None and res.basis.basic.shape == (5,)
    return res.basis


def _refused(call):
    with pytest.raises(ShapeError) as info:
        call()
    msg = str(info.value)
    assert "warm-start basis" in msg and "5 variables" in msg and "has 7" in msg
    return msg


def test_solve_lcp_refuses_a_warm_basis_of_another_size(basis_of_5):
    """The old solve_lcp had no basis argument: the Result.basis it returns could not be
    given back (a builtin TypeError, unexpected keyword)."""
    _refused(lambda: cs.solve_lcp(*_lcp(7), basis=basis_of_5))
    _refused(lambda: cs.solve_lcp(*_lcp(7), basis=basis_of_5.basic))


def test_solve_mcp_and_the_solver_object_refuse_a_warm_basis_of_another_size(basis_of_5):
    _refused(lambda: cs.solve_mcp(_mcp(7), basis=basis_of_5))
    _refused(lambda: cs.solve_mcp(_mcp(7), basis=basis_of_5.basic.tolist()))
    solver = cs.MCPSolver(_mcp(7))
    first = solver.solve()
    assert first.success
    solver.last.basis = basis_of_5  # (a basis left from another problem)
    _refused(solver.solve)


def test_a_warm_basis_is_refused_before_any_evaluation(basis_of_5):
    """Bad input raises before the user's F is called (the old check ran after the start
    point's evaluation)."""
    M, q = _lcp(7)
    calls = []

    def F(x):
        calls.append(1)
        return M @ x + q

    problem = cs.MCP(F, lambda x: M, x0=np.zeros(7), check=False)
    _refused(lambda: cs.solve_mcp(problem, basis=basis_of_5))
    assert calls == []


def test_a_warm_basis_that_is_not_a_vector_of_codes_is_refused():
    with pytest.raises(ShapeError, match="warm-start basis is an array of shape"):
        cs.solve_mcp(_mcp(7), basis=np.zeros((7, 2), dtype=np.int8))
    with pytest.raises(ShapeError, match="dtype"):
        cs.solve_lcp(*_lcp(7), basis=np.full(7, 0.5))


def test_solve_lcp_warm_started_from_its_own_basis_needs_no_pivots():
    """The warm start solve_lcp now takes: a nearby q re-solved from the last basis (the
    same active set) makes no pivot where the cold path makes some, and both reach the
    same point."""
    M, q = _lcp(200)
    first = cs.solve_lcp(M, q, options=NO_CRASH)
    q2 = q + 1e-3 * np.random.default_rng(1).normal(size=q.size)
    cold = cs.solve_lcp(M, q2, options=NO_CRASH)
    warm = cs.solve_lcp(M, q2, options=NO_CRASH, basis=first.basis)
    assert cold.success and warm.success
    assert cold.minor_iterations > 0 and warm.minor_iterations == 0
    assert warm.check(lambda z: M @ z + q2, 0.0, np.inf).natural <= 1e-10
    np.testing.assert_allclose(warm.x, cold.x, atol=1e-12)


def _sized_model(k):
    """A model whose size is a parameter (k variables)."""
    return _mcp(int(k))


def test_batch_scenarios_whose_parent_has_another_size_start_cold_instead_of_failing():
    """The old worker handed the parent's point and basis to a problem of another size:
    solve_mcp raised ShapeError and the scenario, solvable, became an ERROR row."""
    scen = [{"k": 3.0}, {"k": 3.1}, {"k": 4.0}, {"k": 5.0}]
    res = solve_batch(_sized_model, scen, workers=0, progress=None, options=NO_CRASH)
    rows = sorted(res.rows, key=lambda r: r["index"])
    assert [r["status"] for r in rows] == ["SOLVED"] * 4
    assert [r["start"] for r in rows] == ["cold", "warm", "cold", "cold"]
    for r, s in zip(rows, scen):
        M, q = _lcp(int(s["k"]))
        x = np.asarray(r["x"])
        assert x.shape == (int(s["k"]),)
        assert np.linalg.norm(np.minimum(x, M @ x + q)) <= 1e-8


def test_result_sensitivity_without_its_problem_raises_the_packages_error():
    """The old code raised a builtin TypeError for problem=None; dF_dp=None gave a
    ShapeError about a shape ()."""
    problem = _mcp(7)
    res = cs.solve_mcp(problem)
    assert res.success
    with pytest.raises(ProblemError, match="needs the problem the point solves.*NoneType"):
        res.sensitivity(None, np.ones(7))
    with pytest.raises(ProblemError, match="dF_dp is None"):
        res.sensitivity(problem, None)
    with pytest.raises(ProblemError, match="dF_dp must be an array"):
        res.sensitivity(problem, ["a"] * 7)
    with pytest.raises(ShapeError, match="the point has shape \\(7,\\) but the problem has 5"):
        res.sensitivity(_mcp(5), np.ones(5))
    d = res.sensitivity(problem, np.ones(7))  # (and with its problem, a derivative)
    assert d.dx.shape == (7, 1) and np.all(np.isfinite(d.dx))
