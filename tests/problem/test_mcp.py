"""The MCP definition: validation messages, Jacobian forms, finite differences, counters."""
import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.exceptions import (
    BoundsError,
    CompassError,
    EvaluationError,
    JacobianPatternError,
    ProblemError,
    ShapeError,
    StartPointError,
)
from compass_sparse.problem import INFINITY, MCP

NAMES = ["price", "wage", "rent", "output", "demand"]
N = len(NAMES)


def lin_F(z):
    return np.arange(1.0, N + 1) * z - 1.0


def lin_J(z):
    return sp.diags(np.arange(1.0, N + 1)).tocsc()


def tridiag(n):
    """A nonlinear tridiagonal F with its analytic Jacobian (fixed pattern)."""
    i = np.arange(n)

    def F(z):
        zl = np.concatenate([[0.0], z[:-1]])
        zr = np.concatenate([z[1:], [0.0]])
        return z**3 + 2 * z - 0.5 * zl + np.sin(zr) - 1.0

    def J(z):
        rows = np.concatenate([i, i[1:], i[:-1]])
        cols = np.concatenate([i, i[:-1], i[1:]])
        data = np.concatenate([3 * z**2 + 2, -0.5 * np.ones(n - 1), np.cos(z[1:])])
        return sp.csc_matrix((data, (rows, cols)), shape=(n, n))

    return F, J


# ----------------------------------------------------------------------- validation
def test_shape_mismatch_x0_vs_bounds():
    with pytest.raises(ShapeError, match="x0.*lb|lb.*x0"):
        MCP(lin_F, lin_J, np.zeros(4), np.ones(4) * 9, np.zeros(N))
    with pytest.raises(ShapeError, match="ub"):
        MCP(lin_F, lin_J, np.zeros(N), np.ones(3), np.zeros(N))
    with pytest.raises(ShapeError, match="var_names"):
        MCP(lin_F, lin_J, 0.0, np.inf, np.zeros(N), var_names=NAMES[:3])


@pytest.mark.parametrize("i", [0, 3])
def test_lb_greater_than_ub_names_variable(i):
    lb, ub = np.zeros(N), np.ones(N)
    lb[i] = 2.0
    with pytest.raises(BoundsError, match=f"lb > ub.*{NAMES[i]}"):
        MCP(lin_F, lin_J, lb, ub, np.zeros(N), var_names=NAMES)


def test_nan_in_bounds_names_variable():
    lb = np.zeros(N)
    lb[2] = np.nan
    with pytest.raises(BoundsError, match="NaN.*rent"):
        MCP(lin_F, lin_J, lb, np.inf, np.zeros(N), var_names=NAMES)
    ub = np.full(N, np.inf)
    ub[4] = np.nan
    with pytest.raises(BoundsError, match="ub is NaN.*demand"):
        MCP(lin_F, lin_J, 0.0, ub, np.zeros(N), var_names=NAMES)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_x0_names_variable(bad):
    x0 = np.zeros(N)
    x0[1] = bad
    with pytest.raises(StartPointError, match="wage"):
        MCP(lin_F, lin_J, 0.0, np.inf, x0, var_names=NAMES)


def test_infinite_bounds_on_the_wrong_side():
    lb = np.zeros(N)
    lb[3] = np.inf
    with pytest.raises(BoundsError, match=r"lb = \+inf.*output"):
        MCP(lin_F, lin_J, lb, np.inf, np.zeros(N), var_names=NAMES)
    ub = np.full(N, np.inf)
    ub[0] = -np.inf
    with pytest.raises(BoundsError, match="ub = -inf.*price"):
        MCP(lin_F, lin_J, -np.inf, ub, np.zeros(N), var_names=NAMES)
    # the 1e20 convention applies on both sides
    lb = np.zeros(N)
    lb[2] = 1e20
    with pytest.raises(BoundsError, match="rent"):
        MCP(lin_F, lin_J, lb, np.inf, np.zeros(N), var_names=NAMES)


def test_bounds_beyond_1e20_are_infinite():
    lb = np.array([-1e20, -1e25, 0.0, -5.0, -1e19])
    ub = np.array([1e20, 3e21, 1e30, 5.0, 1e19])
    p = MCP(lin_F, lin_J, lb, ub, np.zeros(N))
    assert np.all(np.isneginf(p.lb[:2])) and np.all(np.isposinf(p.ub[:3]))
    assert p.lb[4] == -1e19 and p.ub[4] == 1e19
    assert INFINITY == 1e20
    assert "free=2" in repr(p)


def test_one_pass_bounds_check_gives_the_array_routes_bounds_and_errors():
    """as_bounds checks valid bounds in one compiled pass (clean_bounds) and falls back to
    the array operations, which name the offender, otherwise.  On random pairs drawn from
    values at, beyond and below 1e20, infinities and NaN: valid pairs give the mapped
    bounds, every invalid one a BoundsError; arrays given by the user are not changed."""
    from compass_sparse.problem import as_bounds

    rng = np.random.default_rng(7)
    values = np.array([-np.inf, -1e25, -1e20, -9.9e19, -1.0, 0.0, 2.5, 9.9e19, 1e20, 1e25,
                       np.inf, np.nan])
    valid = invalid = 0
    for _ in range(400):
        lb, ub = rng.choice(values, 2), rng.choice(values, 2)
        lb0, ub0 = lb.copy(), ub.copy()
        lo = np.where(lb <= -INFINITY, -np.inf, np.where(lb >= INFINITY, np.inf, lb))
        hi = np.where(ub >= INFINITY, np.inf, np.where(ub <= -INFINITY, -np.inf, ub))
        ok = not (np.isnan(lb).any() or np.isnan(ub).any()) and bool(
            np.all((lo < np.inf) & (hi > -np.inf) & (lo <= hi)))
        if ok:
            valid += 1
            got = as_bounds(lb, ub, 2)
            np.testing.assert_array_equal(got[0], lo)
            np.testing.assert_array_equal(got[1], hi)
        else:
            invalid += 1
            with pytest.raises(BoundsError):
                as_bounds(lb, ub, 2)
        np.testing.assert_array_equal(lb, lb0)  # (NaN compare equal here)
        np.testing.assert_array_equal(ub, ub0)
    assert valid > 40 and invalid > 40, (valid, invalid)
    # scalars of Python and numpy types take the same values
    for lo_s, hi_s in ((0, 1e30), (0.0, np.inf), (np.float32(-2.0), 3)):
        lo, hi = as_bounds(lo_s, hi_s, 2)
        assert lo.dtype == hi.dtype == np.float64 and lo.shape == hi.shape == (2,)
        assert lo[0] == float(lo_s) and (hi[0] == np.inf if hi_s >= INFINITY else hi[0] == hi_s)


def test_F_wrong_shape():
    with pytest.raises(ShapeError, match=r"F\(x\) returned shape"):
        MCP(lambda z: np.zeros(N + 1), lin_J, 0.0, np.inf, np.zeros(N))


def test_J_wrong_shape():
    with pytest.raises(ShapeError, match="Jacobian has shape"):
        MCP(lin_F, lambda z: sp.identity(N + 1, format="csc"), 0.0, np.inf, np.zeros(N))
    with pytest.raises(ShapeError, match="Jacobian has shape"):
        MCP(lin_F, lambda z: np.eye(N, N - 1), 0.0, np.inf, np.zeros(N))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nonfinite_F_at_start_names_row(bad):
    def F(z):
        f = lin_F(z)
        f[3] = bad
        return f

    with pytest.raises(EvaluationError, match=r"F\(output\)"):
        MCP(F, lin_J, 0.0, np.inf, np.zeros(N), var_names=NAMES)
    with pytest.raises(EvaluationError, match="market_out"):
        MCP(F, lin_J, 0.0, np.inf, np.zeros(N), var_names=NAMES,
            eqn_names=["a", "b", "c", "market_out", "e"])


def test_nonfinite_J_at_start_names_entry():
    def J(z):
        rows = np.array([0, 1, 2, 3, 4, 4])
        cols = np.array([0, 1, 2, 3, 4, 1])
        data = np.array([1.0, 2, 3, 4, 5, np.nan])
        return sp.csc_matrix((data, (rows, cols)), shape=(N, N))

    with pytest.raises(EvaluationError, match=r"row F\(demand\), column wage"):
        MCP(lin_F, J, 0.0, np.inf, np.zeros(N), var_names=NAMES)


def test_F_raising_at_start_is_an_evaluation_error():
    def F(z):
        raise ZeroDivisionError("boom")

    with pytest.raises(EvaluationError, match="boom"):
        MCP(F, lin_J, 0.0, np.inf, np.zeros(N))


def test_jacobian_entry_that_becomes_zero_mid_solve_is_a_zero_not_a_pattern_error():
    A = np.array([[2.0, 1, 0, 0, 0], [1, 2, 1, 0, 0], [0, 1, 2, 1, 0], [0, 0, 1, 2, 1],
                  [0, 0, 0, 1, 2]])

    def J(z):
        M = A.copy()
        M[2, 1] = z[0]  # becomes 0 at z = 0: built from a dense array, the entry drops
        return sp.csc_matrix(M)

    p = MCP(lambda z: A @ z, J, -np.inf, np.inf, np.ones(N), var_names=NAMES)
    nnz = p.pattern.nnz
    Jz = p.J(np.zeros(N))
    assert Jz.nnz == nnz and Jz[2, 1] == 0.0 and abs(Jz - sp.csc_matrix(J(np.zeros(N)))).max() == 0


def test_undeclared_pattern_grows_when_a_later_jacobian_adds_entries():
    A = np.array([[2.0, 1, 0, 0, 0], [1, 2, 1, 0, 0], [0, 1, 2, 1, 0], [0, 0, 1, 2, 1],
                  [0, 0, 0, 1, 2]])
    q = MCP(lambda z: A @ z, lambda z: sp.csc_matrix(A + (z[0] > 1) * np.eye(N, k=4)),
            -np.inf, np.inf, np.zeros(N), var_names=NAMES)
    nnz = q.pattern.nnz
    J2 = q.J(np.full(N, 2.0))
    assert J2.nnz == nnz + 1 and J2[0, 4] == 1.0 and q.evaluator.pattern_growths == 1
    assert q.J(np.zeros(N)).nnz == nnz + 1  # the grown pattern stays


def test_jac_sparsity_with_callable_jac_is_the_declared_pattern():
    A = np.array([[2.0, 1, 0, 0, 0], [1, 2, 1, 0, 0], [0, 1, 2, 1, 0], [0, 0, 1, 2, 1],
                  [0, 0, 0, 1, 2]])
    pat = sp.csc_matrix(A != 0)
    q = MCP(lambda z: A @ z, lambda z: sp.csc_matrix(A * (z[0] > 1)), -np.inf, np.inf,
            np.zeros(N), var_names=NAMES, jac_sparsity=pat)
    assert q.J(np.zeros(N)).nnz == pat.nnz  # J = 0 there: all zeros, pattern kept
    bad = MCP(lambda z: A @ z, lambda z: sp.csc_matrix(A + (z[0] > 1) * np.eye(N, k=4)),
              -np.inf, np.inf, np.zeros(N), var_names=NAMES, jac_sparsity=pat)
    with pytest.raises(JacobianPatternError, match=r"F\(price\).*demand.*outside the declared"):
        bad.J(np.full(N, 2.0))


def test_non_square_jac_sparsity():
    with pytest.raises(ShapeError, match="jac_sparsity"):
        MCP(lin_F, None, 0.0, np.inf, np.zeros(N), jac_sparsity=sp.csc_matrix((N, N + 1)))
    with pytest.raises(ShapeError, match="jac_sparsity"):
        MCP(lin_F, None, 0.0, np.inf, np.zeros(N), jac_sparsity=np.ones((N, 2)))


def test_missing_jacobian_and_bad_arguments():
    with pytest.raises(ProblemError, match="no Jacobian"):
        MCP(lin_F, None, 0.0, np.inf, np.zeros(N))
    with pytest.raises(ProblemError, match="F must be callable"):
        MCP(3.0, lin_J, 0.0, np.inf, np.zeros(N))
    with pytest.raises(ProblemError, match="jac must be"):
        MCP(lin_F, "yes", 0.0, np.inf, np.zeros(N))
    assert issubclass(ProblemError, ValueError) and issubclass(EvaluationError, CompassError)


# ------------------------------------------------------------------ Jacobian forms
def test_jac_true_form():
    F, J = tridiag(8)
    p = MCP(lambda z: (F(z), J(z)), True, -np.inf, np.inf, np.zeros(8))
    z = np.linspace(-1, 1, 8)
    f, Jz = p.FJ(z)
    np.testing.assert_allclose(f, F(z))
    assert abs(Jz - J(z)).max() == 0
    np.testing.assert_allclose(p.F(z), F(z))
    assert abs(p.J(z) - J(z)).max() == 0
    with pytest.raises(ShapeError, match=r"\(f, J\)"):
        MCP(F, True, -np.inf, np.inf, np.zeros(8))


def test_dense_jacobian_keeps_full_pattern():
    A = np.array([[1.0, 0.0], [0.0, 1.0]])
    p = MCP(lambda z: A @ z, lambda z: A * (1 + z[0]), -np.inf, np.inf, np.zeros(2))
    assert p.J(np.array([-1.0, 0.0])).nnz == 4  # all entries zero but stored


def test_finite_difference_jacobian_with_grouping():
    n = 40
    F, J = tridiag(n)
    P = J(np.zeros(n))
    p = MCP(F, None, -np.inf, np.inf, np.zeros(n), jac_sparsity=P)
    z = np.random.default_rng(0).uniform(-1, 1, n)
    before_fd = p.counters.nfev_fd
    Jfd = p.J(z)
    used = p.counters.nfev_fd - before_fd
    assert used <= 3 < n  # tridiagonal: three colours
    np.testing.assert_allclose(Jfd.toarray(), J(z).toarray(), rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(Jfd.indices, P.indices)
    # upper bounds close by: the steps go inward, still accurate
    q = MCP(F, None, -np.inf, z + 1e-12, z, jac_sparsity=P)
    np.testing.assert_allclose(q.J(z).toarray(), J(z).toarray(), rtol=1e-6, atol=1e-6)
    # dense boolean pattern works too
    r = MCP(F, None, -np.inf, np.inf, np.zeros(n), jac_sparsity=P.toarray() != 0)
    np.testing.assert_allclose(r.J(z).toarray(), J(z).toarray(), rtol=1e-6, atol=1e-6)


def test_callbacks_receive_copies():
    seen = []

    def F(z):
        seen.append(z)
        out = 2 * z - 1
        z[:] = 123.0  # vandalise the argument
        return out

    def J(z):
        z[:] = -7.0
        return sp.identity(N, format="csc") * 2

    x0 = np.full(N, 0.25)
    p = MCP(F, J, 0.0, np.inf, x0)
    assert np.all(x0 == 0.25) and np.all(p.x0 == 0.25)
    x = np.full(N, 0.5)
    p.F(x)
    p.J(x)
    p.FJ(x)
    assert np.all(x == 0.5)
    assert all(s is not x for s in seen)


def test_evaluation_counters():
    F, J = tridiag(6)
    p = MCP(F, J, -np.inf, np.inf, np.zeros(6), check=False)
    c = p.counters
    assert (c.nfev, c.njev) == (0, 0)
    x = np.ones(6)
    p.F(x)
    p.F(x)  # the last point is memoized: F and J are asked once per point
    p.J(x)
    p.FJ(x)
    assert (c.nfev, c.njev, c.nfev_fd) == (1, 1, 0)
    y = np.full(6, 2.0)
    p.F(y)
    p.FJ(x)  # the memo holds one point per function: x was displaced for F, not for J
    assert (c.nfev, c.njev, c.nfev_fd) == (3, 1, 0)
    p.F_uncounted(x)
    assert c.nfev == 3
    q = MCP(F, J, -np.inf, np.inf, np.zeros(6))  # the start check costs one of each
    assert (q.counters.nfev, q.counters.njev) == (1, 1)
    r = MCP(F, None, -np.inf, np.inf, np.zeros(6), jac_sparsity=J(x), check=False)
    r.J(x)
    assert r.counters.njev == 1 and r.counters.nfev == 1 + r.counters.nfev_fd
    assert r.counters.nfev_fd == 3
    s = p.with_start(np.full(6, 0.5))
    assert s.counters.nfev == 0 and np.all(s.x0 == 0.5)


def test_constant_jac_mask():
    n = 6
    F, J = tridiag(n)
    # off-diagonal entries below the diagonal are constant (-0.5)
    C = sp.diags([np.ones(n - 1)], [-1], shape=(n, n)).tocsc()
    p = MCP(F, J, -np.inf, np.inf, np.zeros(n), constant_jac=C)
    P = p.pattern.tocoo()
    expected = P.row == P.col + 1
    np.testing.assert_array_equal(p.constant_mask, expected)
    # the same with finite differences (pattern known from jac_sparsity)
    q = MCP(F, None, -np.inf, np.inf, np.zeros(n), jac_sparsity=J(np.zeros(n)), constant_jac=C)
    np.testing.assert_array_equal(q.constant_mask, expected)
    # an entry outside the pattern is refused, naming it
    bad = sp.csc_matrix(([1.0], ([0], [n - 1])), shape=(n, n))
    names = [f"v{i}" for i in range(n)]
    with pytest.raises(ProblemError, match=r"row F\(v0\), column v5"):
        MCP(F, J, -np.inf, np.inf, np.zeros(n), constant_jac=bad, var_names=names)
    with pytest.raises(ShapeError, match="constant_jac"):
        MCP(F, J, -np.inf, np.inf, np.zeros(n), constant_jac=sp.identity(n + 1))


def test_x0_is_projected_and_defaults():
    p = MCP(lin_F, lin_J, np.zeros(N), np.ones(N), np.array([-1.0, 0.5, 2.0, 1.0, 0.0]))
    np.testing.assert_array_equal(p.x0, [0.0, 0.5, 1.0, 1.0, 0.0])
    q = MCP(lin_F, lin_J, n=N)  # NCP bounds, x0 = 0
    assert np.all(q.lb == 0) and np.all(np.isposinf(q.ub)) and np.all(q.x0 == 0)
    with pytest.raises(ShapeError, match="cannot infer"):
        MCP(lin_F, lin_J)
    assert q.row_label(2) == "F[2]" and q.var_label(2) == "x[2]"
