"""The path tracker (compass_sparse.homotopy.tracker): predictor and corrector, the
statuses that end a path (divergence, step limit), the end game, non-finite
corrections, and its compiled steps against the array formulas."""

import numpy as np
import pytest

import known_problems as kp

import compass_sparse.homotopy.smoothing as smoothing
import compass_sparse.homotopy.tracker as hom
from compass_sparse import MCP, Options, solve_mcp
from compass_sparse.generators import thesis_family
from compass_sparse.homotopy import HomotopyStatus, track_paths
from compass_sparse.merit import natural_residual
from compass_sparse.status import Status


def test_path_divergence_is_reported_with_its_status():
    F, J, lb, ub, x0 = kp.diverging_free()
    ev = MCP(F, J, lb, ub, x0).evaluator
    seen = []
    out = track_paths(ev, lb, ub, x0, Options(homotopy_path_limit=2),
                      on_point=lambda z, f, phi, psi: seen.append(psi),
                      rng=np.random.default_rng(0))
    assert out.status is HomotopyStatus.DIVERGED
    assert out.path_status == [HomotopyStatus.DIVERGED] * 2
    assert out.lam == pytest.approx(0.5, abs=1e-3)  # where (1 - 2 lam) vanishes
    # the best point is kept: the lowest merit seen on the paths
    assert out.z is not None and 0.5 * np.sum(F(out.z) ** 2) == pytest.approx(min(seen))


def test_tight_path_tracking_reaches_the_same_solution(monkeypatch):
    # CORRECTOR_TOLERANCE only decides how closely the path is followed; a 1e4 times
    # tighter value must follow the same curve to the same end point (the stationary
    # problem's unique solution, and the same solution of a thesis instance).
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    g = thesis_family(25, 2, seed=4)
    loose = [solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"}),
             solve_mcp(g.problem, options={"homotopy": "only"})]
    monkeypatch.setattr(hom, "CORRECTOR_TOLERANCE", hom.CORRECTOR_TOLERANCE * 1e-4)
    tight = [solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"}),
             solve_mcp(thesis_family(25, 2, seed=4).problem, options={"homotopy": "only"})]
    for a, b in zip(loose, tight):
        assert a.success and b.success
        assert a.x == pytest.approx(b.x, abs=1e-6)
        assert b.passes["homotopy"].iterations >= a.passes["homotopy"].iterations


def test_corrector_accepts_tiny_steps_from_a_base_point_on_the_curve_to_tracking_accuracy():
    # The accepted points are on the curve only to CORRECTOR_TOLERANCE; a first correction
    # of that size must not reject a tiny step (it once rejected every step down to 1e-9
    # and ended paths of family 2 at n = 500 as "step too small").
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    ev = MCP(F, J, lb, ub, x0).evaluator
    tr = hom.Tracker(ev, lb, ub, Options(), deadline=None, on_point=None, tol=1e-12, log=None)
    a = x0.copy()
    y = np.append(a, 0.3)
    for _ in range(30):  # Newton in x at fixed lam: onto the curve ...
        H, Hx, Hlam = tr.residual(y, a, True)
        y[:-1] += np.linalg.solve(Hx, -H)
    assert np.linalg.norm(tr.residual(y, a, False)[0]) <= 1e-12
    y[:-1] += 0.5 * hom.CORRECTOR_TOLERANCE  # ... then off it by half the tolerance
    H, Hx, Hlam = tr.residual(y, a, True)
    v = np.array([0.0, 1.0])
    Bf = tr.factor(Hx, Hlam, v)
    tau = Bf.solve(np.array([0.0, 1.0]))
    tau /= np.linalg.norm(tau)
    tr._y = y
    out, ok = tr._correct(y + 1e-9 * tau, a, Bf, v)
    assert ok
    yc = out[0]
    assert np.linalg.norm(tr.residual(yc, a, False)[0]) <= 1e-6


def test_step_limit_ends_every_path_with_its_status():
    g = thesis_family(20, 2, seed=1)
    res = solve_mcp(g.problem, options={"homotopy": "only", "homotopy_step_limit": 2,
                                        "homotopy_path_limit": 2})
    assert not res.success and res.status is Status.NO_PROGRESS
    h = res.passes["homotopy"]
    assert h.reason.startswith("step limit") and "(2 paths, 4 steps" in h.reason


def test_a_smaller_divergence_bound_stops_the_path_earlier():
    F, J, lb, ub, x0 = kp.diverging_free()
    ev = MCP(F, J, lb, ub, x0).evaluator
    lams = []
    for bound in (1e2, 1e4):
        out = track_paths(ev, lb, ub, x0, Options(homotopy_path_limit=1,
                                                  homotopy_divergence_bound=bound),
                          rng=np.random.default_rng(0))
        assert out.status is HomotopyStatus.DIVERGED
        lams.append(out.lam)
    # x = (1 - lam) a / (1 - 2 lam) passes 1e2 (1 + |a|) before 1e4 (1 + |a|)
    assert lams[0] < lams[1] < 0.5


def test_end_game_from_the_end_of_the_path_only_still_solves():
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only", "homotopy_end_lambda": 1.0})
    assert res.success


@pytest.mark.parametrize("route", ["compiled", "arrays"])
def test_a_non_finite_correction_shortens_the_step_instead_of_failing_the_solve(
        monkeypatch, route):
    # _Bordered.solve raises on a non-finite solution; in the corrector that once escaped
    # the pass.  Every third corrector solve fails here (the tangent's right-hand side is
    # e_{n+1}): the pass must carry on with shorter steps.  A dense problem's corrector
    # solves in the compiled chord step (-1 for a non-finite correction), the array route
    # through _Bordered.solve.
    calls = {"n": 0}
    # (the Python route's dense corrector, engine = "reference": the compiled tracker
    # calls chord_step inside compiled code, tests/routes/test_homotopy_routes.py)
    if route == "compiled":
        chord = hom.chord_step

        def flaky(*args):
            calls["n"] += 1
            return -1.0 if calls["n"] % 3 == 0 else chord(*args)

        monkeypatch.setattr(hom, "chord_step", flaky)
    else:
        solve = hom.Bordered.solve

        def flaky(self, b):
            if b[-1] == 1.0 and not np.any(b[:-1]):
                return solve(self, b)
            calls["n"] += 1
            if calls["n"] % 3 == 0:
                raise np.linalg.LinAlgError("non-finite solution of the bordered system")
            return solve(self, b)

        monkeypatch.setattr(hom, "float_vectors", lambda *args: False)
        monkeypatch.setattr(smoothing, "float_vectors", lambda *args: False)
        monkeypatch.setattr(hom.Bordered, "solve", flaky)
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    res = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only", "engine": "reference"})
    assert calls["n"] >= 3
    assert res.x.shape == (1,) and res.passes["homotopy"].ran
    assert res.success or res.status is Status.NO_PROGRESS


@pytest.mark.parametrize("n,family,seed", [(1, 1, 0), (7, 2, 1), (30, 1, 2)])
def test_compiled_homotopy_values_and_bordered_matrix_give_the_array_expressions_bits(
        monkeypatch, n, family, seed):
    """_Tracker.residual's dense route (the map's values and the bordered matrix in one
    compiled pass each) against its array expressions, at points along lam in [0, 1]:
    H, H_x and H_lam bit for bit, and the factors of the bordered matrix too."""
    g = thesis_family(n, family, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    a = np.clip(rng.normal(size=n), p.lb, p.ub)

    def pieces(arrays):
        with monkeypatch.context() as m:
            if arrays:
                m.setattr(hom, "float_vectors", lambda *args: False)
                m.setattr(smoothing, "float_vectors", lambda *args: False)
            tr = hom.Tracker(p.evaluator, p.lb, p.ub, Options(), deadline=None,
                              on_point=None, tol=1e-12, log=None)
            out = []
            for lam in (0.0, 0.3, 0.999, 1.0):
                y = np.append(a + rng.normal(scale=0.1, size=n), lam)
                H, Hx, Hlam = tr.residual(y, a, True)
                v = rng.normal(size=n + 1)
                out.append((H.copy(), np.array(Hx), np.array(Hlam)))
                out.append(tr.factor(Hx, Hlam, v).lu)
            return out

    state = rng.bit_generator.state
    compiled = pieces(False)
    rng.bit_generator.state = state
    reference = pieces(True)
    for got, ref in zip(compiled, reference):
        for u, w in zip(got, ref):
            assert np.array_equal(u, w)


@pytest.mark.parametrize("n,family,seed", [(1, 1, 0), (7, 2, 1), (30, 1, 2)])
def test_compiled_tangent_and_chord_steps_agree_with_the_array_route(monkeypatch, n, family,
                                                                     seed):
    """The dense route's tangent (unit_tangent) and corrector (chord_correction around F)
    against the array route (_Bordered.solve, residual): the same tangent, turning flag,
    corrected point and step factor to rounding, at points along lam in (0, 1)."""
    g = thesis_family(n, family, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    a = np.clip(rng.normal(size=n), p.lb, p.ub)
    tr = hom.Tracker(p.evaluator, p.lb, p.ub, Options(), deadline=None, on_point=None,
                      tol=1e-12, log=None)
    compared = 0
    for lam in (0.05, 0.2, 0.4, 0.6):
        y = np.append(a + rng.normal(scale=0.1, size=n), lam)
        for _ in range(30):  # Newton in x at fixed lam: onto the curve
            H, Hx, Hlam = tr.residual(y, a, True)
            y[:-1] += np.linalg.solve(Hx, -H)
        v = rng.normal(size=n + 1)
        v /= np.linalg.norm(v)
        H, Hx, Hlam = tr.residual(y, a, True)
        Bf = tr.factor(Hx, Hlam, v)
        tau, turned = tr._tangent(Bf, v)
        e = np.zeros(n + 1)
        e[-1] = 1.0
        w = Bf.solve(e)
        ref = w / np.linalg.norm(w) * (1.0 if w @ v >= 0 else -1.0)
        np.testing.assert_allclose(tau, ref, rtol=1e-10, atol=1e-12)
        assert turned == int(ref[-1] * v[-1] < 0)
        tr._y = y
        yp = y + 1e-3 * tau
        fast = tr._correct(yp, a, Bf, v)
        with monkeypatch.context() as mp:
            mp.setattr(hom, "float_vectors", lambda *args: False)
            mp.setattr(smoothing, "float_vectors", lambda *args: False)
            slow = tr._correct(yp, a, Bf, v)
        assert fast[1] == slow[1]
        if fast[1]:
            compared += 1
            np.testing.assert_allclose(fast[0][0], slow[0][0], rtol=1e-10, atol=1e-12)
            assert abs(fast[0][1] - slow[0][1]) <= 1e-8 * abs(slow[0][1])
    assert compared >= 2


@pytest.mark.parametrize("n,lam", [(1, 0.3), (7, 0.999), (30, 1.0), (12, 1.2)])
def test_chord_step_is_the_correction_then_the_next_smoothed_projection_bit_for_bit(n, lam):
    """chord_step (one call per chord iteration of the dense corrector) gives what
    chord_correction followed by smoothed_projection at the corrected point, with the
    tracker's mu(lam) (0 past lam = 1), gives: the same y, d, p, dp/dx, dp/dmu and ||d||
    bits; a non-finite correction (-1.0) leaves p alone."""
    from compass_sparse.homotopy._kernels import chord_correction, chord_step, smoothed_projection

    g = thesis_family(n, 2, seed=n)
    p = g.problem
    rng = np.random.default_rng(n)
    a = np.clip(rng.normal(size=n), p.lb, p.ub)
    tr = hom.Tracker(p.evaluator, p.lb, p.ub, Options(), deadline=None, on_point=None,
                      tol=1e-12, log=None)
    y = np.append(a + rng.normal(scale=0.1, size=n), lam)
    v = rng.normal(size=n + 1)
    H, Hx, Hlam = tr.residual(y, a, True)
    lu, piv = tr.factor(Hx, Hlam, v).lu
    yp = y + 1e-3 * rng.normal(size=n + 1)
    pt = np.empty(n)
    smoothed_projection(yp[:n], tr._mu(float(yp[n])), tr.lb, tr.ub, pt, np.empty(n),
                        np.empty(n))
    f = p.F(pt)
    y1, p1, d1, dx1, dm1 = yp.copy(), pt.copy(), np.empty(n + 1), np.empty(n), np.empty(n)
    dn1 = chord_step(f, y1, yp, p1, a, v, lu, piv, d1, tr.mu0, tr.lb, tr.ub, dx1, dm1)
    y2, p2, d2, dx2, dm2 = yp.copy(), pt.copy(), np.empty(n + 1), np.empty(n), np.empty(n)
    dn2 = chord_correction(f, y2, yp, p2, a, v, lu, piv, d2)
    smoothed_projection(y2[:n], tr._mu(float(y2[n])), tr.lb, tr.ub, p2, dx2, dm2)
    assert dn1 == dn2 >= 0.0
    for u, w in ((y1, y2), (d1, d2), (p1, p2), (dx1, dx2), (dm1, dm2)):
        assert u.tobytes() == w.tobytes()
    bad = lu.copy()
    bad[-1, -1] = 0.0  # a zero pivot: the correction is not finite
    p3 = pt.copy()
    assert chord_step(f, yp.copy(), yp, p3, a, v, bad, piv, np.empty(n + 1), tr.mu0, tr.lb,
                      tr.ub, np.empty(n), np.empty(n)) == -1.0
    assert p3.tobytes() == pt.tobytes()


@pytest.mark.parametrize("family,seed", [(1, 10), (2, 1), (2, 5), (2, 27)])
def test_compiled_dense_path_steps_reach_the_array_routes_solution(monkeypatch, family, seed):
    """homotopy = 'only' on thesis instances at n = 10 with the dense route's compiled steps
    and with the array route: both solve, at the same solution."""
    prob = thesis_family(10, family, seed).problem
    got = solve_mcp(prob, options={"homotopy": "only"})
    with monkeypatch.context() as mp:
        mp.setattr(hom, "float_vectors", lambda *args: False)
        mp.setattr(smoothing, "float_vectors", lambda *args: False)
        ref = solve_mcp(thesis_family(10, family, seed).problem, options={"homotopy": "only"})
    for r in (got, ref):
        assert r.success and natural_residual(r.x, prob.F(r.x), prob.lb, prob.ub) <= 1e-6
    np.testing.assert_allclose(got.x, ref.x, atol=1e-5)


@pytest.mark.parametrize("family,n,seed", [(2, 10, 1), (1, 20, 12), (2, 50, 22)])
def test_corrector_points_are_within_the_tolerance_of_the_curve(monkeypatch, family, n,
                                                                 seed):
    """The corrector stops on an estimate of its point's distance to the curve
    (CORRECTOR_ESTIMATE): every accepted point is checked against the curve's point on the
    same hyperplane, found by running the chord iterations to 1e-13 from the same
    predictor.  The estimate assumes the contraction of the last two corrections holds:
    the distances stay within twice CORRECTOR_TOLERANCE (1 + ||y||) (measured: at most
    0.96 times it on these instances), most within it."""
    assert hom.CORRECTOR_ESTIMATE
    # the Python route's corrector (engine = "reference"), instrumented (the compiled
    # tracker's points are its bits: tests/routes/test_homotopy_routes.py)
    orig = hom.Tracker._correct
    seen = []

    def checked(self, yp, a, Bf, v):
        out, ok = orig(self, yp, a, Bf, v)
        if ok:
            with monkeypatch.context() as m:
                m.setattr(hom, "CORRECTOR_TOLERANCE", 1e-13)
                m.setattr(hom, "CORRECTOR_ESTIMATE", False)
                m.setattr(hom, "CORRECTOR_ITERATIONS", 60)
                ref, ok_ref = orig(self, yp, a, Bf, v)
            if ok_ref:
                tol = hom.CORRECTOR_TOLERANCE * (1.0 + np.linalg.norm(yp))
                seen.append(np.linalg.norm(out[0] - ref[0]) / tol)
        return out, ok

    monkeypatch.setattr(hom.Tracker, "_correct", checked)
    r = solve_mcp(thesis_family(n, family, seed).problem, options={"engine": "reference"})
    assert r.success and r.passes["homotopy"].ran
    assert len(seen) >= 5
    assert max(seen) <= 2.0, max(seen)
    assert np.median(seen) <= 1.0


def test_accepted_point_reuses_the_correctors_projection_bit_for_bit(monkeypatch):
    """An accepted point's smoothed projection is the one the corrector's last chord step
    made (no second projection): p, dp/dx and dp/dmu are the bits a fresh projection at
    that point gives, on every accepted point of a homotopy-only solve."""
    g = thesis_family(10, 2, 1)
    inner = hom.Tracker.residual
    reused = []

    def checked(self, y, a, want_jac):
        if want_jac and self._corrected is not None and self._corrected[0] is y:
            n = self.n
            p, dx, dmu = self.smooth.project(y[:n], self._mu(y[n]))
            assert np.array_equal(self._corrected[1], p)
            assert np.array_equal(self._dx, dx) and np.array_equal(self._dmu, dmu)
            reused.append(True)
        return inner(self, y, a, want_jac)

    monkeypatch.setattr(hom.Tracker, "residual", checked)
    # (the Python route's residual)
    r = solve_mcp(g.problem, options={"homotopy": "only", "engine": "reference"})
    assert r.success
    assert len(reused) >= 5  # the dense route accepted several points with it
