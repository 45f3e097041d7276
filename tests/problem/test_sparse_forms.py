"""Every scipy.sparse form of a Jacobian, of a pattern and of an LCP's M is converted (the
README accepts any scipy.sparse matrix): dok, lil, coo, csr, bsr, dia and csc, as the
``*_matrix`` classes and as the ``*_array`` (sparray) ones.

Each solve is checked on its returned point (the residual recomputed from F by the test,
and the distance to the planted solution), not on its status alone."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.exceptions import EvaluationError

FORMATS = ("dok", "lil", "coo", "csr", "bsr", "dia", "csc")
KINDS = ("matrix", "array")


def _as_form(A, fmt, kind):
    """A (any sparse matrix) in format ``fmt``, as a spmatrix or an sparray."""
    B = sp.csr_matrix(A) if kind == "matrix" else sp.csr_array(A)
    out = B.asformat(fmt)
    assert out.format == fmt and (sp.isspmatrix(out) == (kind == "matrix"))
    return out


def _planted_ncp(n=12):
    """An NCP F(x) = A x + b with a planted solution x* (every third component 0 with a
    positive F there, the others positive with F = 0); A tridiagonal and diagonally
    dominant, so x* is the only solution."""
    A = sp.diags([np.full(n - 1, -1.0), np.full(n, 4.0), np.full(n - 1, -1.0)], [-1, 0, 1],
                 format="csc")
    x_star = np.linspace(1.0, 2.0, n)
    x_star[::3] = 0.0
    w = np.zeros(n)
    w[::3] = 0.5
    b = w - A @ x_star
    return A, b, x_star


def _check_point(res, F, x_star):
    rep = res.check(F, 0.0, np.inf)
    assert res.status == cs.Status.SOLVED
    assert rep.natural <= 1e-8
    np.testing.assert_allclose(res.x, x_star, atol=1e-8)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("fmt", FORMATS)
def test_a_dok_jacobian_is_converted_not_rejected_as_the_users_fault(fmt, kind):
    """Every sparse form of J from a jac callable and from F returning (f, J).  The old
    code read ``J.data`` to test for complex entries, which a dok matrix or array lacks:
    the start check raised EvaluationError(AttributeError(... no attribute 'data'))."""
    A, b, x_star = _planted_ncp()

    def F(x):
        return A @ x + b

    res = cs.solve_mcp(F, lambda x: _as_form(A, fmt, kind), x0=np.zeros(A.shape[0]))
    _check_point(res, F, x_star)
    res = cs.solve_mcp(lambda x: (A @ x + b, _as_form(A, fmt, kind)), True,
                       x0=np.zeros(A.shape[0]))
    _check_point(res, F, x_star)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("fmt", FORMATS)
def test_every_sparse_form_of_a_pattern_and_of_constant_jac_is_converted(fmt, kind):
    """``jac_sparsity`` (finite differences on it) and ``constant_jac`` (the preprocessor's
    linear entries) in every sparse form."""
    A, b, x_star = _planted_ncp()

    def F(x):
        return A @ x + b

    res = cs.solve_mcp(F, None, x0=np.zeros(A.shape[0]), jac_sparsity=_as_form(A, fmt, kind))
    rep = res.check(F, 0.0, np.inf)
    assert res.status == cs.Status.SOLVED and rep.natural <= 1e-6
    np.testing.assert_allclose(res.x, x_star, atol=1e-6)  # (differences: ~1e-8 accurate)
    res = cs.solve_mcp(F, lambda x: A, x0=np.zeros(A.shape[0]),
                       constant_jac=_as_form(A, fmt, kind))
    _check_point(res, F, x_star)
    assert res.passes["presolve"].ran  # the declared linear rows reached the preprocessor


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("fmt", FORMATS)
def test_solve_lcp_takes_every_sparse_form_of_m(fmt, kind):
    """The old code tested ``M.data`` for complex entries: a dok M raised AttributeError."""
    A, b, x_star = _planted_ncp()
    res = cs.solve_lcp(_as_form(A, fmt, kind), b)
    _check_point(res, lambda x: A @ x + b, x_star)


@pytest.mark.parametrize("kind", KINDS)
def test_a_complex_dok_jacobian_is_refused_in_the_users_terms(kind):
    """Converted, not accepted blindly: complex entries still raise the package's error."""
    A, b, _ = _planted_ncp()
    Jc = _as_form(A.astype(complex) * (1 + 1j), "dok", kind)
    with pytest.raises(EvaluationError, match="complex"):
        cs.solve_mcp(lambda x: A @ x + b, lambda x: Jc, x0=np.zeros(A.shape[0]))
    with pytest.raises(cs.ProblemError, match="complex"):
        cs.solve_lcp(Jc, b)


def test_check_jacobian_takes_a_dok_jacobian():
    """check_jacobian compares a dok J with differences of F like any other form: a
    correct J passes, one wrong entry is named."""
    A, b, _ = _planted_ncp()
    x = np.linspace(0.5, 1.5, A.shape[0])
    good = cs.check_jacobian(lambda x: A @ x + b, lambda x: _as_form(A, "dok", "matrix"), x)
    assert good.ok
    W = _as_form(A, "dok", "array")
    W[2, 3] = 7.0
    bad = cs.check_jacobian(lambda x: A @ x + b, lambda x: W, x)
    assert not bad.ok and bad.worst[0][:2] == ("F[2]", "x[3]")
