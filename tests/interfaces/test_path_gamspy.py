"""Tests of the PATH (via GAMSPy) reference adapter."""

import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.interfaces.path_gamspy import (
    PathLicenseError,
    PathSession,
    parse_path_log,
    solve_lcp_with_path,
    solve_quadratic_mcp_with_path,
)

gams = pytest.mark.gams  # these tests run PATH: GAMS must run here (tests/conftest.py)

TOL = 1e-6


def nat_res(x, f, lb, ub):
    """Independent natural residual ||z - clip(z - F(z), lb, ub)||_inf."""
    return np.max(np.abs(x - np.clip(x - f, lb, ub)))


def check_run(run, F, lb, ub):
    assert run.success, run.log[-3000:]
    assert run.exit_message == "solution found"
    f = F(run.x)
    np.testing.assert_allclose(run.f, f, rtol=0, atol=1e-12)
    assert nat_res(run.x, f, lb, ub) <= TOL
    assert run.residual is not None and run.residual <= TOL
    assert isinstance(run.path_time, float) and run.path_time >= 0
    assert run.wall_time >= run.path_time
    for k in ("major_iterations", "minor_iterations", "crash_iterations", "restarts",
              "fevals", "jevals"):
        assert isinstance(getattr(run, k), int), k
    assert run.solver_status_code == 1 and run.model_status_code in (1, 2)


# --------------------------------------------------------------------------- #
@gams
def test_readme_lcp():
    M = np.array([[0, 0, -1, -1], [0, 0, 1, -2], [1, -1, 2, -2], [1, 2, -2, 4]], float)
    q = np.array([2, 2, -2, -6], float)
    lb, ub = np.zeros(4), np.full(4, np.inf)
    run = solve_lcp_with_path(M, q, lb, ub)
    check_run(run, lambda z: M @ z + q, lb, ub)
    np.testing.assert_allclose(run.x, [2.8, 0.0, 0.8, 1.2], atol=1e-8)
    # first crash-log residual is ||Phi_FB(0)||_2 = sqrt(160)
    assert run.crash_residuals[0] == pytest.approx(np.sqrt(160), rel=1e-4)
    assert "Path 5." in run.log
    np.testing.assert_allclose(run.f_reported, run.f, atol=1e-9)


def _manufactured_box_lcp(seed=3):
    """Box-LCP with all bound types and known solution z*.

    q = w* - v* - M z*, so F(z*) = w* - v* with w* > 0 only where z* = lb and
    v* > 0 only where z* = ub.
    """
    rng = np.random.default_rng(seed)
    inf = np.inf
    # (lb, ub, z*, F(z*)) per variable
    spec = [
        (-inf, inf, 0.7, 0.0),    # free
        (-inf, inf, -1.3, 0.0),   # free
        (0.0, inf, 0.0, 1.5),     # lower-bounded, at bound
        (0.0, inf, 2.0, 0.0),     # lower-bounded, interior
        (-inf, 1.0, 1.0, -0.8),   # upper-bounded, at bound
        (-inf, 1.0, -0.5, 0.0),   # upper-bounded, interior
        (-1.0, 2.0, -1.0, 0.4),   # boxed, at lower
        (-1.0, 2.0, 2.0, -2.2),   # boxed, at upper
        (-1.0, 2.0, 0.3, 0.0),    # boxed, interior
        (0.5, 0.5, 0.5, 3.0),     # fixed (F arbitrary)
        (-2.0, -2.0, -2.0, -1.0),  # fixed
        (0.0, 0.0, 0.0, 0.0),     # fixed at 0, F = 0
    ]
    lb = np.array([s[0] for s in spec])
    ub = np.array([s[1] for s in spec])
    zs = np.array([s[2] for s in spec])
    fs = np.array([s[3] for s in spec])
    n = len(spec)
    # sparse, strictly monotone (positive definite symmetric part) => unique solution
    B = sp.random(n, n, density=0.25, random_state=rng, data_rvs=lambda k: rng.uniform(-1, 1, k))
    S = sp.random(n, n, density=0.2, random_state=rng, data_rvs=lambda k: rng.uniform(-1, 1, k))
    M = (B @ B.T + 0.5 * sp.eye(n) + (S - S.T)).tocsr()
    q = fs - M @ zs
    return M, q, lb, ub, zs


@gams
@pytest.mark.parametrize("dense", [False, True])
def test_box_lcp_all_bound_types(dense):
    M, q, lb, ub, zs = _manufactured_box_lcp()
    Mi = M.toarray() if dense else M
    x0 = np.clip(np.linspace(-3, 3, len(q)), lb, ub)
    run = solve_lcp_with_path(Mi, q, lb, ub, x0, convergence_tolerance=1e-10)
    check_run(run, lambda z: M @ z + q, lb, ub)
    np.testing.assert_allclose(run.x, zs, atol=1e-7)


@gams
def test_empty_rows_and_missing_diagonal():
    # rows without any nonzero: GAMS needs a structural entry (sent as EPS)
    n = 6
    M = sp.csr_matrix(np.diag([1.0, 2.0, 0.0, 0.0, 3.0, 0.0]))
    q = np.array([-1.0, 1.0, -1.0, -1.0, 0.0, 0.0])
    lb = np.array([0.0, 0.0, -np.inf, -1.0, 2.0, -np.inf])
    ub = np.array([np.inf, 1.0, 5.0, 1.0, 2.0, np.inf])
    run = solve_lcp_with_path(M, q, lb, ub)
    check_run(run, lambda z: M @ z + q, lb, ub)
    np.testing.assert_allclose(run.x[:5], [1.0, 0.0, 5.0, 1.0, 2.0], atol=1e-9)


def _quadratic_family(n, seed=0):
    rng = np.random.default_rng(seed)
    D = rng.uniform(-1, 1, n)
    A = rng.uniform(-1, 1, (n, n))
    b = rng.uniform(-1, 1, n)
    lo = rng.uniform(-1, 1, n)
    up = lo + rng.uniform(0, 1, n)
    x0 = rng.uniform(-1, 2, n)
    return D, A, b, lo, up, x0


@gams
@pytest.mark.parametrize("sparse_A", [False, True])
def test_quadratic_family_n10(sparse_A):
    D, A, b, lo, up, x0 = _quadratic_family(10)
    Ai = sp.csc_matrix(A) if sparse_A else A
    run = solve_quadratic_mcp_with_path(D, Ai, b, lo, up, x0)
    check_run(run, lambda z: D * z**2 + A @ z + b, lo, up)
    assert run.path_size == (10, 100)


@gams
def test_session_reuse_with_changing_data():
    n = 4
    s = PathSession(n)
    M1 = np.array([[0, 0, -1, -1], [0, 0, 1, -2], [1, -1, 2, -2], [1, 2, -2, 4]], float)
    q1 = np.array([2, 2, -2, -6], float)
    r1 = solve_lcp_with_path(M1, q1, 0.0, np.inf, session=s)
    np.testing.assert_allclose(r1.x, [2.8, 0.0, 0.8, 1.2], atol=1e-8)
    # different sparsity pattern and bounds in the same container
    M2 = sp.diags([1.0, 2.0, 4.0, 8.0]).tocsr()
    q2 = np.array([-1.0, 4.0, -8.0, 8.0])
    lb2 = np.array([0.0, 0.0, -np.inf, -0.5])
    ub2 = np.array([np.inf, 1.0, 1.0, np.inf])
    r2 = solve_lcp_with_path(M2, q2, lb2, ub2, session=s)
    check_run(r2, lambda z: M2 @ z + q2, lb2, ub2)
    np.testing.assert_allclose(r2.x, [1.0, 0.0, 1.0, -0.5], atol=1e-9)
    with pytest.raises(ValueError):
        solve_quadratic_mcp_with_path(np.ones(n), M1, q1, 0.0, np.inf, session=s)


@gams
def test_failure_is_reported():
    # MCPLIB "billups": 0 <= x  _|_  (x-1)^2 - 1.01 ; PATH fails from x0 = 0 ...
    run = solve_quadratic_mcp_with_path([1.0], [[-2.0]], [-0.01], [0.0], [np.inf], [0.0])
    assert not run.success
    assert run.model_status_code not in (1, 2)
    # ... and solves it from x0 = 3
    run = solve_quadratic_mcp_with_path([1.0], [[-2.0]], [-0.01], [0.0], [np.inf], [3.0])
    assert run.success and run.x[0] == pytest.approx(1 + np.sqrt(1.01), abs=1e-6)


@gams
def test_options_pass_through():
    D, A, b, lo, up, x0 = _quadratic_family(50)
    run = solve_quadratic_mcp_with_path(D, A, b, lo, up, x0,
                                        options={"major_iteration_limit": 2})
    assert not run.success
    assert run.major_iterations == 2
    assert run.exit_message == "iteration limit"
    assert "major_iteration_limit 2" in run.log


@gams
def test_input_validation():
    M = np.eye(2)
    with pytest.raises(ValueError):
        solve_lcp_with_path(M, [1.0, 1.0], [1.0, 0.0], [0.0, 1.0])  # lb > ub
    with pytest.raises(ValueError):
        solve_lcp_with_path(np.eye(3), [1.0, 1.0], 0.0, np.inf)  # shape mismatch


@gams
def test_license_limit_is_a_clear_error():
    n = 1001
    M = sp.identity(n, format="csr")
    with pytest.raises(PathLicenseError):
        solve_lcp_with_path(M, -np.ones(n), 0.0, np.inf)


def test_parse_log_snippet():
    log = """Path 5.2.01 (Sat Oct 24 11:54:36 2026)
Crash Log
major  func  diff  size  residual    step       prox   (label)
    0     0             1.2649e+01             0.0e+00 (f(3))
    1     2     4     2 1.0535e+01  8.0e-01    0.0e+00 (f(0))
pn_search terminated: no basis change.

Major Iteration Log
major minor  func  grad  residual    step  type prox    inorm  (label)
    0     0     5     4 4.4409e-16           I 0.0e+00 4.4e-16 (f(2))

 ** EXIT - solution found.

Major Iterations. . . . 0
Minor Iterations. . . . 7
Restarts. . . . . . . . 1
Crash Iterations. . . . 3
Gradient Steps. . . . . 0
Function Evaluations. . 5
Gradient Evaluations. . 4
Basis Time. . . . . . . 0.000013
Total Time. . . . . . . 0.000096
Residual. . . . . . . . 4.440892e-16
"""
    info = parse_path_log(log)
    assert info["minor_iterations"] == 7 and info["restarts"] == 1
    assert info["crash_iterations"] == 3 and info["fevals"] == 5 and info["jevals"] == 4
    assert info["path_time"] == pytest.approx(9.6e-5)
    assert info["residual"] == pytest.approx(4.440892e-16)
    assert info["exit_message"] == "solution found"
    assert info["crash_residuals"] == [12.649, 10.535]
    assert info["major_residuals"] == [4.4409e-16]


def test_module_imports_without_gamspy():
    code = (
        "import sys; sys.modules['gamspy'] = None\n"
        "from compass_sparse.interfaces import path_gamspy as p\n"
        "assert p.path_available() is False\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
