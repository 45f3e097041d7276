"""The compiled crash (compass_sparse.crash.compiled and the one-call dense step) against
the Python projected-Newton loop (compass_sparse.crash.projected_newton): the same
attempts, steps and points bit for bit, at the time limit too."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.crash import crash
from compass_sparse.crash.outcome import RAISED


def _python_perturbed_attempts(Jii, rhs, eps, eps0, limit, attempts=8):
    """The crash's attempts written in Python on scipy's LU (lu_factor + lu_solve, an
    exactly zero pivot meaning singular): the reference of the compiled loop."""
    import warnings

    import scipy.linalg as sla

    nf = 0
    for _ in range(attempts):
        A = Jii if eps == 0.0 else Jii + eps * sp.identity(Jii.shape[0], format="csc")
        nf += 1
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)
            lu = sla.lu_factor(A.toarray())
        if np.all(np.diag(lu[0]) != 0.0):
            d = sla.lu_solve(lu, rhs)
            if np.all(np.isfinite(d)) and not (eps > 0.0 and np.max(np.abs(d)) > limit):
                return d, eps, nf
        eps = eps0 if eps == 0.0 else eps * 10.0
    return None, eps, nf


def test_compiled_perturbed_attempts_give_the_python_routes_steps_bit_for_bit():
    """All attempts of a dense crash step in one compiled call (numba's LAPACK gesv):
    the same d, bit for bit, the same final eps and the same number of factorizations as
    getrf + getrs called per attempt, on regular blocks of orders 1 ... 200, exactly
    singular ones (a zero column: shifted), and blocks whose shifted steps run away until
    eps is large (the step limit)."""
    from compass_sparse.linalg.blas import single_threaded_blas
    from compass_sparse.crash._kernels import dense_perturbed_solve
    from compass_sparse.linalg._csc_kernels import csc_to_dense

    rng = np.random.default_rng(11)
    cases = []
    for n in (1, 2, 3, 4, 7, 10, 31, 64, 101, 200):
        A = sp.random(n, n, density=min(1.0, 6.0 / n), random_state=rng, format="csc")
        A = sp.csc_matrix(A + sp.identity(n) * rng.uniform(0.5, 2.0))
        cases.append((A, 0.0, np.inf))                        # regular: eps = 0 works
        B = A.tolil()
        B[:, n // 2] = 0.0
        B = sp.csc_matrix(B)
        cases.append((B, 1e-8, np.inf))                       # singular: the first shift
        cases.append((B, 1e-8, 10.0))                         # ... refused until eps grows
        C = B.copy()
        C.data[:] = 0.0
        cases.append((C, 1e-8, 1e-30))                        # every attempt refused
    with single_threaded_blas():
        for A, eps_start, limit in cases:
            n = A.shape[0]
            rhs = rng.normal(size=n)
            ref, eps_r, nf_r = _python_perturbed_attempts(A, rhs, eps_start, 1e-8, limit)
            dense = np.empty((n, n), order="F")
            csc_to_dense(A.indptr, A.indices, A.data, dense)
            d, eps, nf, found = dense_perturbed_solve(dense, rhs, eps_start, 1e-8, True, 8,
                                                      limit)
            assert found == (ref is not None) and nf == nf_r and eps == eps_r, (n, limit)
            if found:
                assert d.tobytes() == ref.tobytes(), n
    # not perturbed: one attempt, and a singular block fails at once
    S = np.zeros((3, 3), order="F")
    d, eps, nf, found = dense_perturbed_solve(S, np.ones(3), 0.0, 1e-8, False, 8, np.inf)
    assert not found and nf == 1 and eps == 0.0


def _crash_problems(trials):
    """The known small problems and ``trials`` random ones: singular and structurally
    singular reduced blocks, points at bounds, box constraints, a runaway-step limit."""

    import known_problems as kp

    problems = [cs.MCP(q.F, q.J, q.lb, q.ub, q.x0) for q in (
        kp.kojima_shindo(), kp.josephy(), kp.mathiesen(), kp.nash_cournot_mss(),
        kp.separable_box_vi())]
    rng = np.random.default_rng(7)
    for trial in range(trials):
        n = int(rng.integers(1, 60))
        A = sp.random(n, n, density=rng.choice([0.1, 0.4]), random_state=rng, format="csc")
        if trial % 3:
            A = A + sp.eye(n) * rng.choice([0.0, 1.0, 3.0])
        A = sp.csc_matrix(A)
        A.sum_duplicates()
        b = rng.normal(size=n)
        lb = rng.choice([-np.inf, 0.0, -1.0], n)
        ub = np.where((rng.random(n) < 0.3) & np.isfinite(lb), lb + 2.0, np.inf)
        x0 = np.clip(rng.normal(size=n), lb, ub)
        problems.append(cs.MCP(lambda x, A=A, b=b: A @ x + b + 0.1 * x ** 3,
                               lambda x, A=A: sp.csc_matrix(A + sp.diags(0.3 * x ** 2)),
                               lb, ub, x0))
    return problems


def _crash_both_ways(p, opt, monkeypatch):
    """The crash with its one-call dense step, and with the general route (the same
    kernels called one by one from Python)."""
    import compass_sparse.crash.projected_newton as C

    real = C.dense_crash_step
    used = []
    with monkeypatch.context() as m:
        m.setattr(C, "dense_crash_step", lambda *a: used.append(1) or real(*a))
        fast = crash(p.evaluator, p.x0, p.lb, p.ub, opt)
    fast.one_call_steps = len(used)
    with monkeypatch.context() as m:
        calls = []
        m.setattr(C, "dense_crash_step", lambda *a: calls.append(1) or 1 / 0)
        m.setattr(C, "solver_vectors", lambda *a: False)  # the general route
        p.evaluator.forget()
        slow = crash(p.evaluator, p.x0, p.lb, p.ub, opt)
        assert not calls
    return fast, slow


def test_one_call_dense_crash_step_gives_the_general_routes_steps_bit_for_bit(monkeypatch):
    """The crash step of a problem of order <= 200 runs in one compiled call; on random
    problems -- singular and structurally singular reduced blocks, points at bounds,
    box constraints, a runaway-step limit -- it gives the steps, points, factorizations
    and stop reasons of the route that calls its kernels one by one."""
    steps = factored = 0
    for p in _crash_problems(40):
        for opt in (cs.Options(), cs.Options(crash_nbchange_limit=3, crash_perturb=False)):
            fast, slow = _crash_both_ways(p, opt, monkeypatch)
            steps += fast.one_call_steps
            factored += fast.factorizations > fast.iterations  # perturbed attempts
            assert fast.z.tobytes() == slow.z.tobytes()
            assert fast.f.tobytes() == slow.f.tobytes()
            assert (fast.iterations, fast.factorizations, fast.stop_reason, fast.log) == \
                (slow.iterations, slow.factorizations, slow.stop_reason, slow.log)
    assert steps > 50 and factored > 3


def _domain_problems():
    """Problems whose F or J fail away from the start: trial points rejected, and a J that
    cannot be evaluated at the crash's next point."""
    A = sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]]))
    b = np.array([-8.0, 1.0, -2.0])

    def F(x):
        if x[0] > 2.5:  # (the full Newton step overshoots into this region)
            raise ValueError("outside the domain")
        return A @ x + b + 0.1 * x ** 3

    def J(x):
        return sp.csc_matrix(A + sp.diags(0.3 * x ** 2))

    def J_fails(x):
        if np.any(x != 0.0):
            return sp.csc_matrix(np.full((3, 3), np.nan))
        return J(x)

    x0 = np.zeros(3)
    # (the second's cubic term is small enough that the first step goes below the start:
    # a crash whose step raises ||Phi|| stops before it asks for J there; crash.RAISED)
    return [cs.MCP(F, J, -np.inf, np.inf, x0),
            cs.MCP(lambda x: A @ x + b + 0.01 * x ** 3, J_fails, -np.inf, np.inf, x0)]


def test_compiled_crash_gives_the_python_routes_points_bit_for_bit(monkeypatch):
    """The compiled crash (reverse communication: one compiled call between two
    evaluations) against the Python route it replaces, on the known and random problems
    and on F and J that fail at some points, with every crash option that changes its
    path: the same points (z, F, x), iterations, norms, stop reasons, factorizations,
    log rows and lines, counts, evaluations and trial points offered, bit for bit."""
    import compass_sparse.crash._kernels as ck
    from compass_sparse.status import PassStats

    used = []
    real = ck.crash_dense
    monkeypatch.setattr(ck, "crash_dense", lambda *a: used.append(1) or real(*a))
    options = (cs.Options(), cs.Options(crash_nbchange_limit=3, crash_perturb=False),
               cs.Options(crash_searchtype="line"), cs.Options(crash_iteration_limit=1),
               cs.Options(crash_stepsize_minimum=0.3), cs.Options(crash_iteration_limit=0))
    reasons = set()
    for p in _crash_problems(12) + _domain_problems():
        f0, J0 = p.evaluator.fj(p.x0)
        for opt in options:
            for J_start in (J0, None):
                out = {}
                for compiled in (False, True):
                    p.evaluator.forget()
                    p.evaluator.counters.reset()
                    st, lines, offered = PassStats(), [], []
                    cr = crash(p.evaluator, p.x0, p.lb, p.ub, opt, f0=f0, J0=J_start,
                               stats=st, log=lines.append, compiled=compiled,
                               on_point=lambda z, f: offered.append(z.tobytes() + f.tobytes()))
                    c = p.evaluator.counters
                    out[compiled] = (cr.z.tobytes(), cr.f.tobytes(), cr.x.tobytes(),
                                     cr.iterations, cr.fb_norm, cr.stop_reason,
                                     cr.factorizations, cr.log, st.iterations,
                                     st.factorizations, lines, offered, c.nfev, c.njev,
                                     c.domain_errors)
                assert out[False] == out[True]
                reasons.add(cr.stop_reason)
    assert len(used) > 500
    assert {"converged", "no basis change", "no progress", "iteration limit",
            "domain error in J", RAISED} <= reasons


def test_compiled_crash_stops_at_the_time_limit_as_the_python_route():
    """A deadline already past: no step, the reason "time limit", the start handed on."""
    import time

    p = _crash_problems(0)[0]
    f0, J0 = p.evaluator.fj(p.x0)
    cr = crash(p.evaluator, p.x0, p.lb, p.ub, cs.Options(), f0=f0, J0=J0,
               deadline=time.perf_counter() - 1.0)
    assert (cr.iterations, cr.stop_reason) == (0, "time limit")
    assert cr.z.tobytes() == p.x0.tobytes() and cr.f.tobytes() == f0.tobytes()
