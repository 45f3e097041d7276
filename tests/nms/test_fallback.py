"""The fallback steps of the stabilized Newton method (compass_sparse.nms.fallback):
Levenberg-Marquardt with CHOLMOD or SuperLU, the projected gradient, and their search."""

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.nms.fallback import cholmod_available, gradient_steps, lm_step, spd_solve
from compass_sparse.merit import fb_phi, fb_psi
from compass_sparse.generators import structured_quadratic


def _spd(n, seed):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=5 / n, random_state=seed, format="csc")
    return (B.T @ B + sp.identity(n) * rng.uniform(0.5, 1.0)).tocsc()


def test_spd_solve_uses_cholmod_and_agrees_with_dense(monkeypatch):
    assert cholmod_available()           # kvxopt is a required dependency
    from kvxopt import cholmod

    calls = []
    real = cholmod.linsolve
    monkeypatch.setattr(cholmod, "linsolve", lambda *a, **k: calls.append(1) or real(*a, **k))
    A = _spd(300, 1)
    b = np.random.default_rng(2).normal(size=300)
    x = spd_solve(A, b)
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)
    assert np.allclose(x, np.linalg.solve(A.toarray(), b), rtol=1e-9, atol=1e-12)
    assert calls == [1]


def test_spd_solve_falls_back_to_superlu_when_cholmod_finds_the_matrix_indefinite():
    A = _spd(100, 4) - 50.0 * sp.identity(100)   # symmetric, regular, indefinite
    A = sp.csc_matrix(A)
    b = np.ones(100)
    x = spd_solve(A, b)
    assert np.linalg.norm(A @ x - b) <= 1e-9 * np.linalg.norm(b)


def test_spd_solve_without_cholmod_matches(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_kvxopt(name, *a, **k):
        if name.startswith("kvxopt"):
            raise ImportError("hidden for this test")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_kvxopt)
    A = _spd(200, 3)
    b = np.ones(200)
    x = spd_solve(A, b)
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lm_and_gradient_steps_decrease_psi(seed):
    g = structured_quadratic(400, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    z = np.clip(g.solution + rng.normal(scale=0.5, size=p.n), p.lb, p.ub)
    ev = p.evaluator
    f = ev.f(z)
    psi0 = fb_psi(fb_phi(z, f, p.lb, p.ub))
    opt = cs.Options()
    out = lm_step(ev, z, f, None, p.lb, p.ub, opt)
    assert out is not None
    zt, ft, phit, psit, mu = out
    assert np.all(zt >= p.lb) and np.all(zt <= p.ub)
    assert psit < psi0 and np.isclose(psit, fb_psi(fb_phi(zt, p.F(zt), p.lb, p.ub)))
    g_out = gradient_steps(ev, z, f, None, p.lb, p.ub, opt)
    assert g_out is not None and g_out[3] < psi0


class _CountingEvaluator:
    """The two calls the fallback steps make of an evaluator, counted."""

    def __init__(self, F, J):
        self.F, self.J, self.f_calls = F, J, 0

    def f(self, z):
        self.f_calls += 1
        return self.F(z)

    def jac(self, z, f=None):
        return sp.csc_matrix(self.J(z))


def test_fallback_search_stops_when_the_trial_point_rounds_to_the_start():
    """billups from x0 = 0 stalls at x = 0, a stationary point of Psi on the box where
    -grad Psi points out of it: every trial of every search is z itself.  The LM step
    (4 values of mu) and the gradient step evaluated z there ~100 times per fallback (memo
    hits, each with an acceptance test); now each search ends at its first trial."""
    F = lambda x: np.array([(x[0] - 1.0) ** 2 - 1.01])  # noqa: E731
    J = lambda x: np.array([[2.0 * (x[0] - 1.0)]])  # noqa: E731
    lb, ub, z = np.zeros(1), np.full(1, np.inf), np.zeros(1)
    ev = _CountingEvaluator(F, J)
    opt = cs.Options()
    seen = []
    on_point = lambda *a: seen.append(a[0].copy())  # noqa: E731
    assert lm_step(ev, z, F(z), None, lb, ub, opt, on_point=on_point) is None
    assert gradient_steps(ev, z, F(z), None, lb, ub, opt, on_point=on_point) is None
    assert ev.f_calls == 0 and seen == []
    # A search whose trials move still evaluates them: from x = 0.5 Psi decreases
    # towards x = 0, and both steps find that descent.
    z = np.array([0.5])
    psi0 = fb_psi(fb_phi(z, F(z), lb, ub))
    out = lm_step(ev, z, F(z), None, lb, ub, opt)
    assert out is not None and out[3] < psi0 and ev.f_calls >= 1
    g = gradient_steps(ev, z, F(z), None, lb, ub, opt)
    assert g is not None and g[3] < psi0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dense_lm_step_agrees_with_the_sparse_route(monkeypatch, seed):
    import compass_sparse.nms.fallback as fb

    g = structured_quadratic(60, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    z = np.clip(g.solution + rng.normal(scale=0.5, size=p.n), p.lb, p.ub)
    opt = cs.Options()
    f = p.evaluator.f(z)
    dense = lm_step(p.evaluator, z, f, None, p.lb, p.ub, opt)
    monkeypatch.setattr(fb, "DENSE_SOLVE_MAX_N", 0)
    sparse = lm_step(p.evaluator, z, f, None, p.lb, p.ub, opt)
    assert dense is not None and sparse is not None
    assert dense[0] == pytest.approx(sparse[0], rel=1e-9, abs=1e-12)
    assert dense[3] == pytest.approx(sparse[3], rel=1e-8)
    assert dense[4] == pytest.approx(sparse[4], rel=1e-12)  # the same search outcome
