"""Infeasible linear problems: the sign conditions of an LCP's rows decided by an LP
(compass_sparse.feasibility), INFEASIBLE with a Farkas certificate that is checked from
the data alone, each tolerance stressed on both sides, and random problems with planted
infeasibility and planted solutions (a solvable one is never called infeasible).

The certificates of the hand-made problems are checked here once more in exact rational
arithmetic (fractions), those of the random ones by this file's own float check."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.feasibility import (CERTIFICATE_MARGIN, CERTIFICATE_RTOL,
                                        FEASIBILITY_TOL, check_farkas, lcp_feasibility,
                                        polish_certificate, sign_rows)

INF = np.inf
PANG_M = np.array([[0.0, -1.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])


def pang(q1):
    """Siconos' lcp_Pang_isolated_sol (q1 = 0: the isolated solution z = (1, 0, 0)) and
    its perturbation lcp_Pang_isolated_sol_perturbed (q1 = -1e-4): w1 = -z2 - z3 + q1."""
    return PANG_M, np.array([q1, -1.0, 1.0])


def cycle(k, eps):
    """w_i = z_{i+1} - z_i + 1 (i < k), w_k = z_1 - z_k - (k - 1) - eps on z >= 0: the
    rows sum to -eps, so no z >= 0 has w >= 0 (y = 1 is a certificate), while each row
    alone can be met (no single-row argument of the preprocessor sees it)."""
    M = np.zeros((k, k))
    for i in range(k - 1):
        M[i, i], M[i, i + 1] = -1.0, 1.0
    M[k - 1, 0], M[k - 1, k - 1] = 1.0, -1.0
    q = np.ones(k)
    q[k - 1] = -(k - 1) - eps
    return M, q


def exact_box_max(M, q, lb, ub, y):
    """max over the box of y^T (M z + q) in exact rational arithmetic (+inf when a
    column's term is unbounded); every float is converted exactly."""
    M = np.asarray(sp.csr_matrix(M).toarray())
    n = q.size
    F = Fraction
    yf = [F(float(v)) for v in y]
    total = sum((yf[i] * F(float(q[i])) for i in range(n)), F(0))
    for j in range(n):
        c = sum((yf[i] * F(float(M[i, j])) for i in range(n)), F(0))
        if c > 0:
            if not math.isfinite(ub[j]):
                return math.inf
            total += c * F(float(ub[j]))
        elif c < 0:
            if not math.isfinite(lb[j]):
                return math.inf
            total += c * F(float(lb[j]))
    return total


def signs_ok(y, lb, ub):
    """y >= 0 on rows with only a finite lower bound, <= 0 with only a finite upper one,
    0 with both finite."""
    lo, hi = np.isfinite(lb), np.isfinite(ub)
    return bool(np.all(y[lo & ~hi] >= 0) and np.all(y[~lo & hi] <= 0)
                and np.all(y[lo & hi] == 0))


def float_certificate_floor(M, q, lb, ub, y):
    """This file's own float check of a certificate: the box maximum of y^T (M z + q),
    column by column, with the wrong-signed parts of M^T y on unbounded sides (at most
    1e-9 of ||M||_F ||y||_2) dropped; returns (box maximum, largest dropped part)."""
    M = sp.csc_matrix(M)
    c = M.T @ y
    total, dropped = float(y @ q), 0.0
    for j in range(q.size):
        if c[j] > 0:
            if math.isfinite(ub[j]):
                total += c[j] * ub[j]
            else:
                dropped = max(dropped, c[j])
        elif c[j] < 0:
            if math.isfinite(lb[j]):
                total += c[j] * lb[j]
            else:
                dropped = max(dropped, -c[j])
    return total, dropped / (np.linalg.norm(M.toarray()) * np.linalg.norm(y))


# ------------------------------------------------------------------- the reported problem
def test_an_lcp_with_an_empty_feasible_set_is_infeasible_with_a_farkas_certificate():
    """Siconos' lcp_Pang_isolated_sol_perturbed: w1 = -z2 - z3 - 1e-4 < 0 for every
    z >= 0.  The old solve_lcp ended in NO_PROGRESS after 146 major iterations (238 on
    this branch's base, 2.5 s)."""
    M, q = pang(-1e-4)
    lb, ub = np.zeros(3), np.full(3, INF)
    res = cs.solve_lcp(M, q)
    assert res.status == cs.Status.INFEASIBLE
    assert res.point_status == cs.PointStatus.CERTIFICATE and not res.success
    y = res.certificate
    assert y is not None and signs_ok(y, lb, ub)
    assert exact_box_max(M, q, lb, ub, y) < 0  # the proof, in exact arithmetic
    assert exact_box_max(M, q, lb, ub, y) == Fraction(-1e-4) * Fraction(float(y[0]))
    assert np.all(res.x >= 0)  # the LP's point of least violation, in the box
    assert res.passes["feasibility"].ran and res.nit <= 1
    assert "Farkas certificate" in res.message


def test_the_isolated_solution_of_the_unperturbed_problem_is_found_not_called_infeasible():
    """q1 = 0: the sign conditions are met at exactly one point, z = (1, 0, 0)."""
    M, q = pang(0.0)
    res = cs.solve_lcp(M, q)
    assert res.status == cs.Status.SOLVED
    np.testing.assert_allclose(res.x, [1.0, 0.0, 0.0], atol=1e-8)
    assert lcp_feasibility(M, q, np.zeros(3), np.full(3, INF), 0.0) is None


# ------------------------------------------------------------- the LP's tolerance, stressed
@pytest.mark.parametrize("factor, infeasible", [(3.0, True), (1 / 3, False)])
def test_the_lps_feasibility_tolerance_separates_barely_infeasible_from_within_it(
        factor, infeasible):
    """w1 misses by q1 = -factor * FEASIBILITY_TOL (row scale 1): three times the
    tolerance is infeasible, a third of it counts as met (the residual tolerance is set to
    0 so that only the LP's tolerance decides)."""
    M, q = pang(-factor * FEASIBILITY_TOL)
    out = lcp_feasibility(M, q, np.zeros(3), np.full(3, INF), 0.0)
    assert (out is not None) == infeasible
    if infeasible:
        assert out.check.valid and out.lp_violation == pytest.approx(3 * FEASIBILITY_TOL,
                                                                     rel=0.1)
        assert exact_box_max(M, q, np.zeros(3), np.full(3, INF), out.y) < 0


def test_a_barely_feasible_lcp_is_never_called_infeasible():
    """q1 = +1e-12: feasible by a hair (z2 = z3 = 0 gives w1 = 1e-12 >= 0)."""
    M, q = pang(1e-12)
    assert lcp_feasibility(M, q, np.zeros(3), np.full(3, INF), 0.0) is None
    res = cs.solve_lcp(M, q)
    assert res.status == cs.Status.SOLVED and res.check(lambda z: M @ z + q).natural <= 1e-6


@pytest.mark.parametrize("eps, infeasible", [(3e-6, True), (3e-7, False)])
def test_infeasible_is_claimed_only_when_no_point_passes_the_convergence_tolerance(
        eps, infeasible):
    """The cycle of 3 rows misses by eps in total: every z >= 0 has ||Phi||_2 >=
    eps / sqrt(3) (the certificate's floor).  Above the tolerance 1e-6 it is INFEASIBLE;
    below it points pass the acceptance test and the solver reports one (SOLVED)."""
    M, q = cycle(3, eps)
    res = cs.solve_lcp(M, q, options={"convergence_tolerance": 1e-6})
    if infeasible:
        assert res.status == cs.Status.INFEASIBLE
        assert exact_box_max(M, q, np.zeros(3), np.full(3, INF), res.certificate) < 0
        floor = -float(exact_box_max(M, q, np.zeros(3), np.full(3, INF), res.certificate))
        assert floor / np.linalg.norm(res.certificate) > 1e-6
        assert res.residual.fb_norm >= eps / np.sqrt(3) * (1 - 1e-9)
    else:
        assert res.status == cs.Status.SOLVED
        assert res.residual.fb_norm <= 1e-6 and res.residual.fb_norm >= eps / np.sqrt(3) / 2


# ---------------------------------------------------- the certificate's check, stressed
def test_check_farkas_backward_error_tolerance():
    """y = (1, d, 0) on Pang's problem: (M^T y)_1 = d > 0 on a variable without upper
    bound (wrong-signed).  Half the tolerance is accepted, twice it refused; wrong signs
    and a zero y are refused outright."""
    M, q = pang(-1e-4)
    lb, ub = np.zeros(3), np.full(3, INF)
    norm_m = np.linalg.norm(PANG_M)
    for factor, valid in ((0.5, True), (2.0, False)):
        d = factor * CERTIFICATE_RTOL * norm_m  # (||y||_2 = 1 to first order)
        chk = check_farkas(M, q, lb, ub, np.array([1.0, d, 0.0]))
        assert chk.valid == valid, chk
        assert chk.backward_error == pytest.approx(factor * CERTIFICATE_RTOL, rel=1e-6)
    assert not check_farkas(M, q, lb, ub, np.array([-1.0, 0.0, 0.0])).valid
    assert not check_farkas(M, q, lb, ub, np.zeros(3)).valid


def test_check_farkas_rounding_margin():
    """Row 0 (z0 >= 0): w0 = -z1 + q0 with z1 in [1e6, 2e6] (no sign condition on row 1):
    y = (1, 0) gives beta = q0 - 1e6 = -delta over terms of magnitude ~2e6.  delta = 1e-3
    is a proof; delta = 1e-5 is within the rounding margin (1e-10 x 2e6) and refused."""
    M = np.array([[0.0, -1.0], [0.0, 1.0]])
    lb, ub = np.array([0.0, 1e6]), np.array([INF, 2e6])
    for delta, valid in ((1e-3, True), (1e-5, False)):
        q = np.array([1e6 - delta, 0.0])
        chk = check_farkas(M, q, lb, ub, np.array([1.0, 0.0]))
        assert chk.valid == valid, chk
        assert chk.beta == pytest.approx(-delta, rel=1e-3)
        assert (chk.beta < -CERTIFICATE_MARGIN * 2e6) == valid


def test_no_certificate_passes_on_a_feasible_problem():
    """Planted solutions: every unit vector of the right sign, and the LP's own answer,
    fail the check (none can pass: the problem is feasible)."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        M, q, lb, ub, z = planted_solution(8, rng)
        kind = sign_rows(lb, ub)
        for i in np.flatnonzero(kind != 3):
            y = np.zeros(8)
            y[i] = -1.0 if kind[i] == 1 else 1.0
            assert not check_farkas(M, q, lb, ub, y).valid
        assert lcp_feasibility(M, q, lb, ub, 0.0) is None


def test_a_certificate_off_by_the_lps_tolerance_is_polished_into_a_valid_one():
    """HiGHS meets M^T y = 0 on free variables only to its tolerance (1e-10 scaled); such
    a y fails the 1e-9 backward-error test when it is 1e-7 off, and the least-squares
    polish on its support restores it."""
    M, q = cycle(4, 1e-2)
    lb, ub = np.full(4, -INF), np.full(4, INF)
    lb[:3] = 0.0  # rows 0-2: w >= 0; variable 3 free (row 3: w = 0)
    y = np.ones(4) + np.array([0.0, 0.0, 0.0, 1e-7])  # (M^T y)_3 = -1e-7 on a free column
    assert not check_farkas(M, q, lb, ub, y).valid
    p = polish_certificate(sp.csc_matrix(M), y, lb, ub, sign_rows(lb, ub))
    chk = check_farkas(M, q, lb, ub, p)
    assert chk.valid and chk.backward_error <= 1e-15 and np.abs(p - y).max() <= 1e-6


# ----------------------------------------------------------------- random planted problems
def bounds(n, rng, kinds):
    k = rng.choice(kinds, size=n)
    lb = np.where((k == 0) | (k == 3), rng.uniform(-1, 1, n), -INF)
    ub = np.where(k == 1, rng.uniform(-1, 1, n),
                  np.where(k == 3, lb + rng.uniform(0.1, 2, n), INF))
    return lb, ub


def planted_infeasible(n, rng, kinds=(0, 1, 2, 3), gap=1e-2):
    """A random sparse box LCP made infeasible: a y of the right signs on a tenth of the
    rows, one row changed so that M^T y has the signs of a certificate (0 on free
    columns, <= 0 / >= 0 on one-sided ones), q so that beta(y) = -gap."""
    lb, ub = bounds(n, rng, kinds)
    kind = sign_rows(lb, ub)
    M = sp.random(n, n, density=0.15, random_state=rng,
                  data_rvs=lambda m: rng.normal(size=m)).toarray()
    q = rng.normal(size=n)
    cand = np.flatnonzero(kind != 3)
    sup = rng.choice(cand, size=min(cand.size, max(1, n // 10)), replace=False)
    y = np.zeros(n)
    mag = rng.uniform(0.5, 2, sup.size)
    y[sup] = np.where(kind[sup] == 1, -mag, mag)
    k = sup[0]
    c = M.T @ y
    d = np.where(kind == 2, c, np.where(kind == 0, np.maximum(c, 0) + 0.1,
                                        np.where(kind == 1, np.minimum(c, 0) - 0.1, 0.0)))
    M[k] -= d / y[k]
    c = M.T @ y
    c = np.where(kind == 2, 0.0, np.where(kind == 0, np.minimum(c, 0),
                                          np.where(kind == 1, np.maximum(c, 0), c)))
    b = np.where(c > 0, ub, np.where(c < 0, lb, 0.0))
    q[k] -= (y @ q + np.sum(np.where(c != 0, c * b, 0.0)) + gap) / y[k]
    return sp.csc_matrix(M), q, lb, ub


def planted_solution(n, rng, kinds=(0, 1, 2, 3)):
    """A random sparse box LCP with a planted solution z (at a bound with w of the right
    sign, or inside with w = 0)."""
    lb, ub = bounds(n, rng, kinds)
    M = sp.random(n, n, density=0.15, random_state=rng,
                  data_rvs=lambda m: rng.normal(size=m)).tocsc()
    pos = rng.integers(0, 3, n)
    lo = np.where(np.isfinite(lb), lb, np.where(np.isfinite(ub), ub - 2, -1.0))
    hi = np.where(np.isfinite(ub), ub, lo + 2)
    z = lo + rng.uniform(0.2, 0.8, n) * (hi - lo)
    z = np.where(np.isfinite(lb) & (pos == 0), lb, np.where(np.isfinite(ub) & (pos == 1),
                                                           ub, z))
    w = np.where(z == lb, rng.uniform(0, 1, n), np.where(z == ub, -rng.uniform(0, 1, n),
                                                         0.0))
    return M, w - M @ z, lb, ub, z


KINDS = {"z >= 0": (0,), "mixed": (0, 1, 2, 3), "lower and free": (0, 2),
         "one-sided and boxed": (0, 1, 3)}


@pytest.mark.parametrize("kinds", KINDS)
def test_random_lcps_with_planted_infeasibility_are_infeasible_with_checked_certificates(
        kinds):
    """Planted infeasibility (n = 5 ... 40, four bound mixes): INFEASIBLE every time,
    with a certificate that passes this file's own check."""
    rng = np.random.default_rng(sorted(KINDS).index(kinds))
    for n in (5, 12, 40):
        M, q, lb, ub = planted_infeasible(n, rng, KINDS[kinds])
        res = cs.solve_lcp(M, q, lb, ub)
        assert res.status == cs.Status.INFEASIBLE, (n, res.message)
        y = res.certificate
        assert signs_ok(y, lb, ub)
        beta, dropped = float_certificate_floor(M, q, lb, ub, y)
        assert dropped <= 1e-9 and beta < -1e-6 * np.abs(y).sum()
        assert np.all(res.x >= lb) and np.all(res.x <= ub)


@pytest.mark.parametrize("kinds", KINDS)
def test_random_lcps_with_planted_solutions_are_never_called_infeasible(kinds):
    """Planted solutions (the solver may fail on these nonmonotone LCPs, which is not
    the point): never INFEASIBLE; the feasibility LP, run on each, finds them feasible."""
    rng = np.random.default_rng(10 + sorted(KINDS).index(kinds))
    for n in (5, 12, 40):
        M, q, lb, ub, z = planted_solution(n, rng, KINDS[kinds])
        assert lcp_feasibility(M, q, lb, ub, 0.0) is None
        res = cs.solve_lcp(M, q, lb, ub, options={"restart_limit": 2, "homotopy": "off"})
        assert res.status != cs.Status.INFEASIBLE
        if res.success:
            assert res.check(lambda x: M @ x + q, lb, ub).natural <= 1e-6


# ---------------------------------------------------------------- an MCP with affine F
def test_a_stalled_mcp_whose_f_is_declared_affine_is_infeasible_with_a_certificate():
    """solve_mcp on the cycle LCP with every Jacobian entry declared constant: the
    preprocessor's one-row arguments see nothing, the Newton method stalls, and the LP
    proves the sign conditions infeasible (the old solver: NO_PROGRESS).  Without the
    declaration nothing says F is affine: the stall is reported as it is."""
    M, q = cycle(3, 1e-2)
    Ms = sp.csc_matrix(M)
    fast = {"restart_limit": 2, "homotopy": "off"}
    res = cs.solve_mcp(lambda z: Ms @ z + q, lambda z: Ms, 0.0, INF, np.zeros(3),
                       constant_jac=Ms, options=fast)
    assert res.status == cs.Status.INFEASIBLE and "F is affine" in res.message
    assert exact_box_max(M, q, np.zeros(3), np.full(3, INF), res.certificate) < 0
    assert res.nit > 0 and res.passes["feasibility"].ran
    plain = cs.solve_mcp(lambda z: Ms @ z + q, lambda z: Ms, 0.0, INF, np.zeros(3),
                         options=fast)
    assert plain.status != cs.Status.INFEASIBLE and plain.certificate is None
