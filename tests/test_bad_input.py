"""Bad input gets an exception of compass_sparse.exceptions naming the culprit in the user's
terms; a failed solve gets a Status with the best point (never a raw exception).

The table of bad inputs (docs/bad_inputs.md, shown on docs/trust.rst) is checked here row
by row (``BAD_INPUTS``; the faults during a solve in test_faults.py).
"""
from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.path.linear_mcp as linear_mcp_module
from compass_sparse import MCP, MCPSolver, Options, Status, solve_lcp, solve_mcp
from compass_sparse.exceptions import (CompassError, EvaluationError, OptionError,
                                       ProblemError, ShapeError)
from compass_sparse.presolve import PresolveOptions

A3 = np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 1.0], [0.0, 1.0, 2.0]])


def F3(x):
    return A3 @ x - 1.0


def J3(x):
    return sp.csc_matrix(A3)


M2 = np.array([[2.0, 1.0], [1.0, 2.0]])
q2 = np.array([-1.0, -1.0])

# (label, call, exception class, message pattern): the rows of docs/bad_inputs.md
BAD_INPUTS = [
    ("complex x0", lambda: solve_mcp(F3, J3, 0.0, np.inf, np.zeros(3) + 1j),
     ProblemError, r"x0 is complex"),
    ("complex bounds", lambda: solve_mcp(F3, J3, np.zeros(3) + 0j, np.inf, np.zeros(3)),
     ProblemError, r"lb is complex"),
    ("complex q", lambda: solve_lcp(M2, q2 + 0j), ProblemError, r"q is complex"),
    ("complex M", lambda: solve_lcp(M2 + 0j, q2), ProblemError, r"M is complex"),
    ("F returns complex", lambda: solve_mcp(lambda x: F3(x) + 0j, J3, 0.0, np.inf, np.zeros(3)),
     EvaluationError, r"F\(x\) returned complex"),
    ("x0 of the wrong length, scalar bounds",
     lambda: solve_mcp(F3, J3, 0.0, np.inf, np.zeros(2)),
     EvaluationError, r"n = 2 was taken from x0"),
    ("q of shape (n, 2)", lambda: solve_lcp(M2, np.ones((2, 2))), ShapeError, r"q has shape"),
    ("M not n x n", lambda: solve_lcp(np.ones((2, 3)), q2), ShapeError, r"M has shape"),
    ("NaN in M", lambda: solve_lcp(np.array([[np.nan, 1.0], [1.0, 2.0]]), q2), ProblemError,
     r"M\[0, 0\] is nan"),
    ("Inf in q", lambda: solve_lcp(M2, np.array([np.inf, 1.0])), ProblemError,
     r"q\[0\] is inf"),
    ("unknown keyword to solve_mcp", lambda: solve_mcp(F3, J3, 0.0, np.inf, np.zeros(3), tol=1),
     ProblemError, r"unknown keyword.*'tol'"),
    ("an option given as a keyword",
     lambda: solve_mcp(F3, J3, 0.0, np.inf, np.zeros(3), time_limit=1),
     ProblemError, r"options=\{'time_limit'"),
    ("unknown option", lambda: Options(foo=1), OptionError, r"unknown option.*'foo'"),
    ("unknown presolve option", lambda: PresolveOptions(bar=1), OptionError, r"'bar'"),
    ("non-integral integer option", lambda: Options(nms_memory_size=3.5), OptionError,
     r"nms_memory_size=3.5: expected an integer"),
    ("infinite tolerance", lambda: Options(convergence_tolerance=np.inf), OptionError,
     r"convergence_tolerance=inf: must be finite"),
    ("MCPSolver without an MCP", lambda: MCPSolver(F3), ProblemError, r"MCPSolver takes an MCP"),
    ("Result.check with a wrong-size F",
     lambda: solve_mcp(F3, J3, 0.0, np.inf, np.zeros(3)).check(lambda x: np.ones(4)),
     ShapeError, r"F\(x\) returned 4 values"),
    ("J entry outside the declared jac_sparsity",
     lambda: solve_mcp(F3, lambda x: sp.csc_matrix(A3 + np.eye(3, k=2)), 0.0, np.inf,
                       np.zeros(3), jac_sparsity=A3 != 0),
     EvaluationError, r"outside the declared pattern"),
]


@pytest.mark.parametrize("label, call, exc, pattern", BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_raises_our_error_naming_the_culprit(label, call, exc, pattern):
    with pytest.raises(exc, match=pattern) as ei:
        call()
    assert isinstance(ei.value, CompassError)


# ------------------------------------------------------------------ numbered failures
def test_complex_input_is_rejected_not_truncated_to_its_real_part():
    with pytest.raises(ProblemError, match="complex"):
        solve_mcp(F3, J3, 0.0, np.inf, np.array([1.0 + 2j, 0, 0]))
    with pytest.raises(ProblemError, match="complex"):
        solve_lcp(M2, q2 + 1j)


def test_wrong_length_x0_with_scalar_bounds_says_n_came_from_x0():
    with pytest.raises(EvaluationError, match=r"taken from x0"):
        solve_mcp(F3, J3, 0.0, np.inf, np.zeros(2))


def test_x0_of_shape_n_by_1_is_accepted_like_the_bounds():
    r = solve_mcp(F3, J3, np.zeros((3, 1)), np.inf, np.zeros((3, 1)))
    assert r.success and r.x.shape == (3,)


def test_solve_lcp_accepts_a_column_q_and_speaks_of_M_and_q():
    r = solve_lcp(M2, q2[:, None])
    assert r.success and r.x == pytest.approx([1 / 3, 1 / 3])
    with pytest.raises(ProblemError, match=r"M\[1, 0\] is nan"):
        solve_lcp(np.array([[2.0, 1.0], [np.nan, 2.0]]), q2)


def test_solve_lcp_leaves_the_users_unsorted_csc_matrix_alone():
    M = sp.csc_matrix((np.array([1.0, 2.0, 3.0]), np.array([1, 0, 1]), np.array([0, 2, 3])),
                      shape=(2, 2))
    assert not M.has_sorted_indices
    before = (M.indices.copy(), M.data.copy())
    solve_lcp(M, q2)
    assert np.array_equal(M.indices, before[0]) and np.array_equal(M.data, before[1])


@pytest.mark.parametrize("kw", [dict(nms_memory_size=3.0), dict(seed=1.0),
                                dict(crash_iteration_limit=5.0),
                                dict(major_iteration_limit=np.int64(10)),
                                dict(presolve=np.bool_(True)),
                                dict(convergence_tolerance=np.float64(1e-8))])
def test_integral_floats_and_numpy_scalars_are_valid_options_and_solve(kw):
    o = Options(**kw)
    for k, v in kw.items():
        assert getattr(o, k) == v and type(getattr(o, k)) in (int, float, bool)
    rng = np.random.default_rng(0)
    n = 12
    B = rng.normal(size=(n, n))
    M = sp.csc_matrix(B @ B.T + np.eye(n))
    q = rng.normal(size=n)
    r = solve_mcp(lambda x: M @ x + q, lambda x: M, 0.0, np.inf, np.zeros(n), options=o)
    assert r.success


def test_ctrl_c_during_solve_lcps_first_path_returns_a_result(monkeypatch):
    def interrupted(*a, **k):  # Ctrl-C while the first pivotal path runs
        raise KeyboardInterrupt

    # (solve_lcp's path: solve_handing_over, which calls solve_linear_mcp)
    monkeypatch.setattr(linear_mcp_module, "solve_linear_mcp", interrupted)
    # (no crash: it would solve this 2 x 2 LCP before the path starts)
    r = solve_lcp(M2, q2, options={"crash_method": "none"})
    assert r.status is Status.USER_INTERRUPT and r.x.shape == (2,)


def _neumann_laplacian(n):
    e = np.ones(n)
    L = sp.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1]).tolil()
    L[0, 0] = L[n - 1, n - 1] = 1.0
    return L.tocsc()


def test_inconsistent_singular_free_lcp_is_reported_infeasible_not_searched_for():
    n = 1000
    r = solve_lcp(_neumann_laplacian(n), -np.ones(n), -np.inf, np.inf)
    assert r.status is Status.INFEASIBLE
    assert "linear system" in r.message and "not in its range" in r.message
    # consistent right-hand side (orthogonal to the null vector): solved
    q = np.linspace(-1, 1, n)
    q -= q.mean()
    r = solve_lcp(_neumann_laplacian(n), q, -np.inf, np.inf)
    assert r.success
    assert np.max(np.abs(_neumann_laplacian(n) @ r.x + q)) <= 1e-6


def test_cli_demo_cge_checks_the_shocked_solution_on_the_shocked_model(capsys):
    from compass_sparse.cli import main

    assert main(["demo", "--problem", "cge"]) == 0
    out = capsys.readouterr().out
    m = re.search(r"recomputed\s+natural residual ([0-9.e+-]+)", out)
    assert m and float(m.group(1)) <= 1e-6, out


def test_largest_factorization_update_limit_does_not_exhaust_memory(monkeypatch):
    # factorization_update_limit accepts any integer >= 1, but both bases preallocate room
    # for their updates: 1e9 asked the dense engine for a 298 GiB eta file (MemoryError)
    # and the sparse manager for two 8 GB index arrays.  The limit is capped at max(n, 50).
    from compass_sparse import generators as gen
    from compass_sparse.basis import BasisManager

    g = gen.thesis_family(40, 2, 1)
    opt = Options(factorization_update_limit=10 ** 9)
    r = solve_mcp(g.problem, options=opt)
    assert r.status is Status.SOLVED
    assert r.residual.natural <= opt.convergence_tolerance
    # the sparse manager gets the same cap (asked of the factory, no 8 GB allocation here)
    from compass_sparse.routes import basis_factory

    bm = basis_factory("sparse basis", Options(factorization_update_limit=10 ** 6))(
        sp.identity(70, format="csc"))
    assert isinstance(bm, BasisManager) and bm.options.update_limit == 70
