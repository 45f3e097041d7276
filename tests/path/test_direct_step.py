"""The direct Newton step (compass_sparse.path.direct_step): a path that makes no pivot ends
where one sparse solve of M_FF says; otherwise the path runs as before.

Checked against the pivotal path itself (both bases), against the linear MCP's own
conditions recomputed here, and on its two tolerances from both sides."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.path.direct_step as ds
import compass_sparse.linalg.direct as ld
import compass_sparse.generators as gen
from compass_sparse import Options, solve_mcp
from compass_sparse.path._kernels import VAR_V, VAR_W, VAR_Z
from compass_sparse.basis import BasisManager
from compass_sparse.path.dense_engine import DensePathEngine
from compass_sparse.path.outcome import LinearCode
from compass_sparse.path.pivotal import PivotalPath


def _agreement(cases, scales, seed, manager, factors, atol):
    """Paths from points near the normal-map point of the solution of P-matrix LCPs, with
    and without the direct step: where the path makes no pivot the direct step returns its
    end point (one factorization, the same basis); where it pivots the direct step
    declines and the path's result is unchanged.  Returns the branches exercised."""
    kinds = set()
    for n, structure, bounds in cases:
        g = gen.p_matrix_lcp(n, structure, seed, bounds)
        M, q, lb, ub = g.lcp
        M = sp.csc_matrix(M)
        rng = np.random.default_rng(seed)
        xs = g.solution - (M @ g.solution + q)  # the normal-map point of the solution
        for scale in scales:
            x = xs + scale * rng.standard_normal(n)
            plain = PivotalPath(M, q, lb, ub, manager(M), Options()).run(x)
            direct = PivotalPath(M, q, lb, ub, manager(M), Options(),
                                 direct=factors()).run(x)
            assert plain.code is LinearCode.SOLVED and direct.code is LinearCode.SOLVED
            if plain.pivots == 0:
                kinds.add("direct")
                assert direct.factorizations == 1 and direct.pivots == 0
                assert direct.direct_lu_nnz > 0 or not (direct.basis.basic == VAR_Z).any()
                np.testing.assert_allclose(direct.z, plain.z, rtol=0, atol=atol)
                np.testing.assert_allclose(direct.w - direct.v, plain.w - plain.v,
                                           rtol=0, atol=atol)
                np.testing.assert_array_equal(direct.basis.basic, plain.basis.basic)
            else:
                kinds.add("path")
                assert direct.pivots == plain.pivots
                np.testing.assert_array_equal(direct.z, plain.z)
            f = M @ direct.z + q
            assert np.max(np.abs(direct.z - np.clip(direct.z - f, lb, ub))) <= 1e-9
    return kinds


@pytest.mark.parametrize("manager", [BasisManager, DensePathEngine])
@pytest.mark.parametrize("seed", range(4))
def test_direct_step_agrees_with_the_path(manager, seed):
    """Sparse direct step (n = 120): both branches, on both bases."""
    kinds = _agreement([(120, "banded", "box"), (120, "grid", "mixed")], (1e-4, 1e-2, 1.0),
                       seed, manager, ld.DirectFactors, 1e-9)
    assert kinds == {"direct", "path"}  # both branches were exercised


def _one_dim(target, lb=0.0):
    """z = target solves M z + q = 0 with M = I (2 x 2), both z basic."""
    M = sp.csc_matrix(np.eye(2))
    q = -np.array([target, 0.5])
    n = 2
    return M, q, np.full(n, lb), np.full(n, 1.0), np.full(n, 0.5), np.full(n, VAR_Z, np.int8)


def test_feasibility_tolerance_from_both_sides():
    """A basic value outside its bound by at most FEASIBILITY_TOLERANCE (relative to
    max(1, |bound|)) is rounding: it is put on the bound; beyond it the path must pivot."""
    tol = ds.FEASIBILITY_TOLERANCE
    end, _ = ds.direct_step(*_one_dim(-0.5 * tol))
    assert end is not None and end[0][0] == 0.0
    end, nnz = ds.direct_step(*_one_dim(-2.0 * tol))
    assert end is None and nnz > 0
    # relative to the bound's magnitude
    end, _ = ds.direct_step(*_one_dim(-100.0 - 50.0 * tol, lb=-100.0))
    assert end is not None and end[0][0] == -100.0
    end, _ = ds.direct_step(*_one_dim(-100.0 - 200.0 * tol, lb=-100.0))
    assert end is None


def test_slack_signs_decide():
    """A slack basic at a lower bound must end >= 0, at an upper bound <= 0."""
    M = sp.csc_matrix(np.array([[2.0, 0.0], [1.0, 1.0]]))
    lb, ub = np.zeros(2), np.ones(2)
    basic = np.array([VAR_W, VAR_Z], dtype=np.int8)  # z_0 at its lower bound
    z = np.array([0.0, 0.5])
    end, _ = ds.direct_step(M, np.array([1.0, -0.5]), lb, ub, z, basic)
    assert end is not None
    np.testing.assert_allclose(end[1], [1.0, 0.0])  # w_0 = F_0 = 1 >= 0
    end, _ = ds.direct_step(M, np.array([-1.0, -0.5]), lb, ub, z, basic)
    assert end is None  # F_0 = -1 < 0 at the lower bound: z_0 must enter
    basic = np.array([VAR_V, VAR_Z], dtype=np.int8)  # z_0 at its upper bound
    z = np.array([1.0, 0.2])
    end, _ = ds.direct_step(M, np.array([-3.0, -1.0]), lb, ub, z, basic)
    assert end is not None and end[2][0] == pytest.approx(1.0)


@pytest.mark.parametrize("rel,accepted", [(1e-13, True), (1e-7, False)])
def test_residual_tolerance_from_both_sides(monkeypatch, rel, accepted):
    """An end point is returned only when it satisfies M z + q - w + v = 0 to
    RESIDUAL_TOLERANCE relative to 1 + max|M z| + max|q|: an inaccurate solve (simulated by
    perturbing the factor's solution) beyond it is declined."""
    real = ld.superlu_colamd

    class Inaccurate:
        def __init__(self, lu):
            self.lu, self.nnz = lu, lu.nnz

        def solve(self, b):
            x = self.lu.solve(b)
            return x * (1.0 + rel)

    monkeypatch.setattr(ld, "superlu_colamd", lambda K: Inaccurate(real(K)))
    rng = np.random.default_rng(0)
    n = 60
    M = sp.random(n, n, density=0.05, random_state=1, format="csc") + 4.0 * sp.identity(n)
    M = sp.csc_matrix(M)
    q = rng.uniform(-1.0, 1.0, n)
    lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
    end, _ = ds.direct_step(M, q, lb, ub, np.zeros(n), np.full(n, VAR_Z, np.int8),
                            ld.DirectFactors(klu=False))  # (the SuperLU route: simulated)
    assert (end is not None) is accepted
    if end is not None:
        z = end[0]
        scale = 1.0 + np.max(np.abs(M @ z)) + np.max(np.abs(q))
        assert np.max(np.abs(M @ z + q)) <= ds.RESIDUAL_TOLERANCE * scale


def test_singular_block_is_left_to_the_path():
    """An exactly singular M_FF: no end point (the path's rank repair decides)."""
    M = sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    end, nnz = ds.direct_step(M, np.array([-1.0, -1.0]), np.full(2, -np.inf),
                              np.full(2, np.inf), np.zeros(2), np.full(2, VAR_Z, np.int8))
    assert end is None and nnz == 0


def test_direct_step_applies_only_to_sparse_moderate_orders(monkeypatch):
    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    o = Options()
    n = ds.DIRECT_MIN_N + 50
    sparse = sp.csc_matrix(sp.identity(n) + sp.eye(n, k=1))
    assert ds.direct_step_applies(sparse, o)
    assert not ds.direct_step_applies(sp.csc_matrix(np.ones((n, n))), o)  # dense
    small = ds.DIRECT_MIN_N - 1  # the compiled engine's dense step instead
    assert not ds.direct_step_applies(sp.csc_matrix(sp.identity(small) + sp.eye(small, k=1)),
                                      o)
    assert not ds.direct_step_applies(sparse, Options(lu_backend="superlu"))
    assert not ds.direct_step_applies(sparse, Options(lu_ordering="amd"))
    monkeypatch.setenv("COMPASS_SPARSE_LU", "umfpack")
    assert not ds.direct_step_applies(sparse, o)


def _ramsey(T):
    from compass_sparse.generators.cge import ramsey_cge

    return ramsey_cge(periods=T, sectors=1).with_shock(capital_tax=0.25).problem


def test_newton_steps_without_pivots_take_no_dense_factorization(monkeypatch):
    """The Ramsey CGE model (n = 363, 0 pivots in every major iteration) was factored
    densely (O(n^3)) by the compiled engine in every major iteration; its Newton steps now
    end by the direct step, and the engine never even makes its dense copy of M.  The
    answer is the path's: same status and iterations, the same point to 1e-9."""
    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    engines = []
    real_init = DensePathEngine.__init__

    def spy(self, *a, **kw):
        engines.append(self)
        real_init(self, *a, **kw)

    monkeypatch.setattr(DensePathEngine, "__init__", spy)
    p = _ramsey(40)
    r = solve_mcp(p)
    assert r.success and r.minor_iterations == 0
    assert engines and all(e._dense is None and e.L is None for e in engines)
    assert r.passes["path"].factorizations == r.passes["path"].iterations
    assert r.lu["backend"] == "klu"  # the Ramsey model's blocks barely fill
    monkeypatch.setattr("compass_sparse.nms.newton.direct_step_applies", lambda M, o: False)
    ref = solve_mcp(p)
    assert ref.status is r.status and ref.nit == r.nit
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-9, atol=1e-9)


def _direct_steps_and_paths(monkeypatch, problem):
    """The solve's sequence of direct step attempts ("D", whether it ended the path) and
    paths ("P", pivots), and its Result."""
    import compass_sparse.nms.newton as newton
    import compass_sparse.path.pivotal as pivotal

    events = []
    step, done = pivotal.direct_step, newton.NewtonStep.path_done

    def spy_step(*a, **kw):
        out = step(*a, **kw)
        events.append(("D", out[0] is not None))
        return out

    def spy_done(self, res, t0, opt):
        events.append(("P", res.pivots))
        return done(self, res, t0, opt)

    monkeypatch.setattr(pivotal, "direct_step", spy_step)
    monkeypatch.setattr(newton.NewtonStep, "path_done", spy_done)
    return events, solve_mcp(problem)


def test_no_direct_step_after_a_path_that_pivoted_on_the_sparse_engine(monkeypatch):
    """Regression: on the sparse engine every Newton path first tried the direct step,
    and where the active set still changes from one major iteration to the next the step
    failed and the path pivoted from the same start: traffic n = 912 factored M_FF (KLU
    or SuperLU) in vain before 8 of its 9 paths, 7 ms of an 81 ms solve.  Now a path that
    follows one that pivoted goes to the engine at once; the same pivots, the same
    answer.  A model whose Newton steps need no pivot (Ramsey, n = 993, on the engine)
    still ends every one by the direct step."""
    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    events, r = _direct_steps_and_paths(monkeypatch, gen.traffic_equilibrium(8).problem)
    assert r.routes["path"] == "sparse engine" and r.success
    assert r.minor_iterations == 586
    last = None
    for kind, value in events:
        if kind == "D":
            assert not last, events  # the first path, or one after a path without pivots
        else:
            last = value
    assert sum(1 for k, v in events if k == "P" and v) >= 5
    events, r = _direct_steps_and_paths(monkeypatch, _ramsey(110))
    assert r.routes["path"] == "sparse engine" and r.success and r.minor_iterations == 0
    paths = [v for k, v in events if k == "P"]
    steps = [v for k, v in events if k == "D"]
    assert len(paths) >= 2 and steps == [True] * len(paths)


def test_direct_step_leaves_large_factors_to_reuse():
    """The static CGE model at n = 759 fills its LU to ~1.3e5 entries: on the basis
    manager (the Python loop's route: the factor reuse is the manager's), the crash's
    factors are reused by GMRES in every Newton step (no factorization in the paths), and
    the direct step does not take that over."""
    from compass_sparse.generators.cge import size_for, static_cge

    p = static_cge(**size_for(830)).with_shock(tariff=0.25).problem
    r = solve_mcp(p, options={"path_basis": "sparse"})
    assert r.success
    assert r.passes["path"].iterations >= 1 and r.passes["path"].factorizations == 0


def test_non_finite_data_give_no_end_point():
    """A NaN in a column outside F (its slack would be NaN) or in q: no end point."""
    M = sp.csc_matrix(np.array([[2.0, np.nan], [1.0, 1.0]]))
    lb, ub = np.zeros(2), np.ones(2)
    basic = np.array([VAR_Z, VAR_W], dtype=np.int8)
    end, _ = ds.direct_step(M, np.array([-1.0, 0.5]), lb, ub, np.array([0.3, 0.0]), basic)
    assert end is None
    M = sp.csc_matrix(np.eye(2))
    end, _ = ds.direct_step(M, np.array([np.nan, -0.5]), lb, ub, np.full(2, 0.5),
                            np.full(2, VAR_Z, np.int8))
    assert end is None


# ----------------------------------------------------------------- the dense direct step
@pytest.mark.parametrize("seed", range(6))
def test_dense_direct_step_agrees_with_the_path_on_small_problems(seed):
    """Small problems (n < DIRECT_MIN_N) on the compiled engine: the dense direct step
    (one compiled pass) agrees with the path in both branches."""
    kinds = _agreement([(2, "banded", "box"), (7, "grid", "mixed"), (30, "banded", "mixed")],
                       (1e-6, 1e-2, 1.0), seed, DensePathEngine,
                       lambda: ld.DirectFactors(dense=True), 1e-10)
    assert kinds == {"direct", "path"}


def test_dense_direct_step_tolerances_and_singular_block():
    """The dense kernel applies the same feasibility tolerance as the sparse step and the
    compiled engine's rank tolerance (each from both sides); an exactly singular M_FF is
    left to the path."""
    tol = ds.FEASIBILITY_TOLERANCE
    dense = ld.DirectFactors(dense=True)
    end, nnz = ds.direct_step(*_one_dim(-0.5 * tol), factors=dense)
    assert end is not None and end[0][0] == 0.0 and nnz == 4
    end, _ = ds.direct_step(*_one_dim(-2.0 * tol), factors=dense)
    assert end is None
    M = sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    end, _ = ds.direct_step(M, np.array([-1.0, -1.0]), np.full(2, -np.inf),
                            np.full(2, np.inf), np.zeros(2), np.full(2, VAR_Z, np.int8),
                            factors=dense)
    assert end is None
    # the compiled engine's rank test, from both sides: a pivot at most
    # rank_tolerance * max(1, ||M[:, j]||_inf) makes the block singular (left to the path)
    rank_tol = dense.rank_tolerance
    for d, accepted in ((2.0 * rank_tol, True), (0.5 * rank_tol, False)):
        M = sp.csc_matrix(np.array([[1.0, 0.0], [0.0, d]]))
        end, _ = ds.direct_step(M, np.array([-1.0, -d]), np.full(2, -np.inf),
                                np.full(2, np.inf), np.zeros(2),
                                np.full(2, VAR_Z, np.int8), factors=dense)
        assert (end is not None) is accepted
        if accepted:
            np.testing.assert_allclose(end[0], [1.0, 1.0], rtol=1e-12)


def test_small_solves_take_the_dense_direct_step():
    """A 2-variable LCP solved as an MCP: its Newton step makes no pivot and ends by the
    dense direct step (no dense factorization of the engine), at the known solution."""
    a, b, c = 10.0, 1.0, np.array([1.0, 2.0])
    M = np.array([[2 * b, b], [b, 2 * b]])

    def F(x):
        return M @ x - (a - c)

    r = solve_mcp(F, lambda x: sp.csc_matrix(M), 0.0, np.inf, np.zeros(2))
    assert r.success and r.minor_iterations == 0
    assert r.passes["path"].factorizations == r.passes["path"].iterations
    np.testing.assert_allclose(r.x, np.linalg.solve(M, a - c), atol=1e-9)


def test_dense_direct_step_does_not_run_off_a_flat_tail_of_mathiesen():
    """Regression: the first dense direct step solved nearly singular blocks that the
    compiled engine repairs (pivot test of exact zeros only); on Mathiesen's problem from
    (2, 1, 0.5, 0.5) its Newton steps ran off to |x| ~ 6e6 along a flat direction and the
    solve reported success there, far from the solution set {(s, 0, 0, 0): 0 <= s <= 3}.
    With the engine's rank test the solve reaches the solution set."""

    import known_problems as kp

    p = kp.ALL_SOLVABLE["mathiesen"](np.array([2.0, 1.0, 0.5, 0.5]))
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"convergence_tolerance": 1e-6})
    assert r.success
    assert p.distance_to_solutions(r.x) <= 1e-4


def _covering(M, q, lb, ub, x):
    """r = M z + q - w + v at the components (z, w, v) of x."""
    z = np.clip(x, lb, ub)
    return M @ z + q - np.maximum(z - x, 0.0) + np.maximum(x - z, 0.0)


@pytest.mark.parametrize("seed", range(6))
def test_failed_one_call_step_hands_the_path_the_start_it_would_compute(seed):
    """When the one-call dense direct step fails, the path runs from the start that call
    computed: the components of x, the start basis with the inward guess and, when the
    guess changed the basis, the basis before it -- what PivotalPath._run computes
    itself (path.components and path.start_basis_with_guess)."""
    from compass_sparse.path.direct_step import dense_direct_path
    from compass_sparse.path.outcome import WarmBasis
    from compass_sparse.path.warm import components, default_basis, start_basis_with_guess

    rng = np.random.default_rng(seed)
    got = set()
    for trial in range(40):
        n = int(rng.integers(1, 9))
        M = sp.csc_matrix(rng.standard_normal((n, n)) * (rng.random((n, n)) < 0.6))
        q = rng.standard_normal(n)
        lb = np.where(rng.random(n) < 0.7, 0.0, -np.inf)
        ub = np.where(rng.random(n) < 0.3, 1.0, np.inf)
        x = rng.standard_normal(n) * 2.0
        x[rng.random(n) < 0.4] = 0.0  # components at the lower bound, no slack value
        r = _covering(M, q, lb, ub, x)
        warm = None if trial % 3 else WarmBasis(default_basis(np.clip(x, lb, ub), lb, ub))
        out = dense_direct_path(M, q, lb, ub, x, r, warm, ld.DirectFactors(dense=True))
        if out is None or out[0] != "path":
            continue
        z, w, v, basic, slack = out[1]
        z0, w0, v0 = components(x, lb, ub)
        b0, want_slack = start_basis_with_guess(z0, w0, v0, r, lb, ub, warm)
        for a, b in ((z, z0), (w, w0), (v, v0), (basic, b0)):
            assert np.array_equal(a, b)
        assert (slack is None) == (want_slack is None)
        if slack is not None:
            assert np.array_equal(slack, want_slack)
        got.add(("warm" if warm is not None else "cold", slack is not None))
    assert got == {("cold", False), ("cold", True), ("warm", False)}
