"""Merit functions and residuals: Fischer–Burmeister Phi, Psi and its gradient, the natural
residual, the normal map and the residual report."""

from decimal import Decimal, getcontext

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

import compass_sparse.generators as gen
from compass_sparse import merit
from compass_sparse.box import max_abs, max_abs_diff, project
from compass_sparse.merit import (
    fb_directional,
    fb_gradient,
    fb_jacobian_diagonals,
    fb_phi,
    fb_psi,
    fischer,
    min_map,
    natural_residual,
    normal_map,
    residual_report,
)

INF = np.inf


# -------------------------------------------------------------------------- fischer
def _phi_exact(a: float, b: float) -> float:
    getcontext().prec = 80
    A, B = Decimal(a), Decimal(b)
    return float((A * A + B * B).sqrt() - A - B)


@pytest.mark.parametrize(
    "a,b",
    [(1e8, 1e-8), (3e5, 7e5), (1e200, 1e200), (1e-200, 3e-200), (1.0, 1e-20), (1e300, 1e290),
     (12345.678, 0.001), (1e15, 1e15), (2.0, 3.0)],
)
def test_fischer_accurate_for_positive_arguments(a, b):
    exact = _phi_exact(a, b)
    got = float(fischer(a, b))
    assert exact < 0
    assert abs(got - exact) <= 4e-16 * abs(exact), (got, exact)
    assert float(fischer(b, a)) == pytest.approx(exact, rel=4e-16)


def test_fischer_signs_and_zeros():
    a = np.array([0.0, 0.0, 2.0, -1.0, 0.0, -3.0, 1.0])
    b = np.array([0.0, 5.0, 0.0, 2.0, -4.0, -3.0, 1.0])
    phi = fischer(a, b)
    assert np.all(phi[:3] == 0.0)
    np.testing.assert_allclose(phi[3:], [np.sqrt(5) - 1, 8.0, 3 * np.sqrt(2) + 6,
                                         np.sqrt(2) - 2], rtol=1e-15)
    # well-defined for mixed huge / tiny magnitudes
    assert np.isfinite(fischer(1e308, 1e308)) and fischer(1e308, 1e308) < 0
    assert fischer(1e-310, 1e-310) < 0


# ------------------------------------------------------- Phi = 0 iff natural residual = 0
_finite = st.floats(min_value=-50, max_value=50, allow_nan=False, allow_subnormal=False)


@st.composite
def _points(draw):
    """Random rows of all bound types (free, lower, upper, boxed, fixed) with z and F
    drawn so that complementary and violating rows both occur often."""
    n = draw(st.integers(1, 8))
    lb, ub, z, f = (np.empty(n) for _ in range(4))
    for i in range(n):
        kind = draw(st.sampled_from(["free", "lower", "upper", "box", "fixed"]))
        lo = draw(st.integers(-5, 5)) * 0.5
        width = draw(st.integers(1, 6)) * 0.5
        lb[i] = lo if kind in ("lower", "box", "fixed") else -INF
        ub[i] = {"upper": lo, "box": lo + width, "fixed": lo}.get(kind, INF)
        where = draw(st.sampled_from(["lower", "upper", "inside", "any"]))
        if where == "lower" and np.isfinite(lb[i]):
            z[i] = lb[i]
        elif where == "upper" and np.isfinite(ub[i]):
            z[i] = ub[i]
        elif where == "inside":
            z[i] = project(lo + 0.25 * width, lb[i], ub[i])
        else:
            z[i] = draw(_finite)
        fsign = draw(st.sampled_from(["zero", "pos", "neg", "any"]))
        mag = draw(st.floats(1e-6, 1e3))
        f[i] = {"zero": 0.0, "pos": mag, "neg": -mag}.get(fsign, draw(_finite))
    return z, f, lb, ub


@settings(max_examples=400, derandomize=True, deadline=None)
@given(_points())
def test_phi_zero_iff_natural_residual_zero(pt):
    z, f, lb, ub = pt
    phi = fb_phi(z, f, lb, ub)
    mm = min_map(z, f, lb, ub)
    np.testing.assert_array_equal(phi == 0.0, mm == 0.0)
    assert (np.max(np.abs(phi)) == 0.0) == (natural_residual(z, f, lb, ub) == 0.0)
    # the normal-map residual of the report vanishes exactly at solutions too
    rep = residual_report(z, f, lb, ub)
    if natural_residual(z, f, lb, ub) == 0.0:
        assert rep.normal_map_inf == 0.0 and rep.fb_norm == 0.0
    else:
        assert rep.fb_norm > 0.0


def test_phi_by_bound_type_and_fixed():
    # columns: free, lower, upper, box, fixed
    lb = np.array([-INF, 0.0, -INF, -1.0, 2.0])
    ub = np.array([INF, INF, 1.0, 1.0, 2.0])
    # solutions: free with F = 0; at lower with F > 0; at upper with F < 0; box interior
    # with F = 0; fixed with any F
    z = np.array([3.0, 0.0, 1.0, 0.5, 2.0])
    f = np.array([0.0, 2.0, -3.0, 0.0, 7.0])
    assert np.all(fb_phi(z, f, lb, ub) == 0)
    assert natural_residual(z, f, lb, ub) == 0
    bad = fb_phi(z, -f, lb, ub)
    assert bad[0] == 0 and bad[1] != 0 and bad[2] != 0 and bad[3] == 0 and bad[4] == 0
    # free row: Phi = -F
    assert fb_phi(z, f + 1.5, lb, ub)[0] == -1.5
    # fixed variable: Phi vanishes for every F
    assert np.all(fb_phi(np.full(3, 2.0), np.array([-5.0, 0.0, 5.0]),
                         np.full(3, 2.0), np.full(3, 2.0)) == 0)
    # scalar bounds are accepted
    assert np.all(fb_phi(np.array([0.0, 1.0]), np.array([1.0, 0.0]), 0.0, INF) == 0)


@pytest.mark.parametrize("name,factory", [
    ("pmat_mixed", lambda: gen.p_matrix_lcp(300, "grid", 1, "mixed", 0.2)),
    ("structured", lambda: gen.structured_quadratic(500, 2, bound_mix=(1, 1, 1, 1))),
    ("obstacle", lambda: gen.obstacle_problem(15, 4)),
])
def test_phi_zero_at_known_solutions_and_not_elsewhere(name, factory):
    G = factory()
    p, z = G.problem, G.solution
    f = p.F(z)
    assert np.max(np.abs(fb_phi(z, f, p.lb, p.ub))) <= 1e-12
    rng = np.random.default_rng(0)
    for _ in range(5):
        y = project(z + rng.normal(scale=0.1, size=p.n), p.lb, p.ub)
        fy = p.F(y)
        assert np.linalg.norm(fb_phi(y, fy, p.lb, p.ub)) > 1e-6
        assert natural_residual(y, fy, p.lb, p.ub) > 1e-6


# ----------------------------------------------------------------------- gradient
def _smooth_problem(n, seed):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.3, random_state=seed, format="csc") + sp.identity(n) * 2
    A = sp.csc_matrix(A)
    c = rng.uniform(-1, 1, n)

    def F(z):
        return A @ z + 0.3 * np.sin(z) + c

    def J(z):
        return sp.csc_matrix(A + sp.diags(0.3 * np.cos(z)))

    kinds = np.arange(n) % 4
    lb = np.where((kinds == 1) | (kinds == 3), rng.uniform(-1, 0, n), -INF)
    ub = np.where(kinds == 2, rng.uniform(0, 1, n),
                  np.where(kinds == 3, lb + rng.uniform(0.5, 2, n), INF))
    return F, J, lb, ub, rng


@pytest.mark.parametrize("seed", range(4))
def test_gradient_matches_central_differences(seed):
    n = 16
    F, J, lb, ub, rng = _smooth_problem(n, seed)
    psi = lambda z: fb_psi(fb_phi(z, F(z), lb, ub))  # noqa: E731
    for _ in range(3):
        # generic points (inside and outside the box, away from the kinks a = b = 0)
        z = rng.uniform(-2, 2, n)
        g = fb_gradient(z, F(z), J(z), lb, ub)
        h = 1e-6
        gfd = np.array([(psi(z + h * e) - psi(z - h * e)) / (2 * h) for e in np.eye(n)])
        assert np.linalg.norm(g - gfd) <= 1e-6 * np.linalg.norm(g)


def _point_with_kinks(F, lb, rng):
    """(z, F(z)) at a random point with about 30% of its indices at their lower bound and
    half of those with F = 0 (the kinks of Phi)."""
    n = lb.size
    z = rng.uniform(-2, 2, n)
    at = rng.random(n) < 0.3
    z[at] = np.where(np.isfinite(lb[at]), lb[at], z[at])
    f = F(z)
    f[at & (rng.random(n) < 0.5)] = 0.0
    return z, f


@pytest.mark.parametrize("seed", range(6))
def test_compiled_gradient_gives_the_bits_of_the_array_formula(seed):
    """fb_gradient's one-pass kernel (the descent test of every major iteration) gives
    da Phi + J^T (db Phi) bit for bit, on all four bound kinds, points at the kinks
    (z at a bound with F = 0) and a matrix with stored zeros."""
    n = 24
    F, J, lb, ub, rng = _smooth_problem(n, 40 + seed)
    z, f = _point_with_kinks(F, lb, rng)
    Jm = sp.csc_matrix(J(z))
    Jm.data[rng.random(Jm.nnz) < 0.1] = 0.0
    phi = fb_phi(z, f, lb, ub)
    da, db = fb_jacobian_diagonals(z, f, lb, ub)
    ref = da * phi + Jm.T @ (db * phi)
    g = fb_gradient(z, f, Jm, lb, ub, phi)
    assert g.tobytes() == ref.tobytes()


@pytest.mark.parametrize("n", [1, 3, 24, 130])
def test_descent_test_directional_derivative_is_the_gradient_formulas(n):
    """fb_directional (the NMS descent test of every major iteration) gives
    grad Psi(z) . (zc - z) as the gradient formula and numpy's product do, bit for bit,
    at sizes below and above BLAS' unrolled lengths, with points at the kinks; a dense
    array J takes the array route and agrees to rounding."""
    F, J, lb, ub, rng = _smooth_problem(n, 70 + n)
    for _ in range(5):
        z, f = _point_with_kinks(F, lb, rng)
        Jm = sp.csc_matrix(J(z))
        phi = fb_phi(z, f, lb, ub)
        zc = z + rng.standard_normal(n)
        ref = float(fb_gradient(z, f, Jm, lb, ub, phi) @ (zc - z))
        assert fb_directional(z, f, Jm, lb, ub, phi, zc) == ref
        dense = fb_directional(z, f, Jm.toarray(), lb, ub, phi, zc)
        assert dense == pytest.approx(ref, rel=1e-12, abs=1e-12 * np.abs(phi).sum())


def test_generalized_jacobian_matches_directional_difference():
    n = 12
    F, J, lb, ub, rng = _smooth_problem(n, 9)
    z = rng.uniform(-2, 2, n)
    da, db = fb_jacobian_diagonals(z, F(z), lb, ub)
    H = sp.diags(da) + sp.diags(db) @ J(z)
    d = rng.normal(size=n)
    h = 1e-6
    zp, zm = z + h * d, z - h * d
    fd = (fb_phi(zp, F(zp), lb, ub) - fb_phi(zm, F(zm), lb, ub)) / (2 * h)
    np.testing.assert_allclose(H @ d, fd, rtol=1e-6, atol=1e-8)


def test_gradient_with_fixed_variables_is_finite_and_zero_rows():
    # a fixed variable contributes Phi_i = 0, so grad Psi only sees other rows
    lb = np.array([1.0, 0.0])
    ub = np.array([1.0, INF])
    z = np.array([1.0, 0.5])
    f = np.array([3.0, 1.0])
    Jm = sp.csc_matrix(np.array([[1.0, 0.0], [2.0, 1.0]]))
    phi = fb_phi(z, f, lb, ub)
    assert phi[0] == 0
    g = fb_gradient(z, f, Jm, lb, ub)
    assert np.all(np.isfinite(g))


# ----------------------------------------------------------- normal map and report
def test_normal_map_zero_at_solution():
    G = gen.p_matrix_lcp(200, "banded", 3, "mixed", 0.1)
    p, z = G.problem, G.solution
    f = p.F(z)
    x = z - f
    np.testing.assert_array_equal(project(x, p.lb, p.ub), z)
    fb = normal_map(x, p.F(project(x, p.lb, p.ub)), p.lb, p.ub)
    assert np.max(np.abs(fb)) <= 1e-12
    # not a zero elsewhere
    y = x + 0.01
    assert np.max(np.abs(normal_map(y, p.F(project(y, p.lb, p.ub)), p.lb, p.ub))) > 1e-4
    rep = residual_report(z, f, p.lb, p.ub)
    assert rep.normal_map_inf <= 1e-12 and rep.natural <= 1e-12 and rep.merit <= 1e-24


def test_residual_report_names_worst_row():
    n = 10
    lb, ub = np.zeros(n), np.full(n, INF)
    z = np.zeros(n)
    f = np.full(n, 1.0)  # all complementary
    f[6] = -4.0  # worst violation
    f[2] = -1.0
    names = [f"demand_{i}" for i in range(n)]
    rep = residual_report(z, f, lb, ub, names=names, k_worst=3)
    assert rep.worst_index == 6
    assert rep.worst[0][0] == "demand_6" and rep.worst[1][0] == "demand_2"
    assert "demand_6" in rep.summary()
    assert rep.fb_norm == pytest.approx(np.linalg.norm(fb_phi(z, f, lb, ub)))
    assert rep.natural == pytest.approx(4.0)
    assert rep.fb_inf == pytest.approx(8.0)  # phi(0, -4) = 4 + 4
    rep2 = residual_report(z, f, lb, ub, names=lambda i: f"row<{i}>")
    assert rep2.worst[0][0] == "row<6>"
    rep3 = residual_report(z, f, lb, ub)
    assert rep3.worst[0][0] == "F[6]"


def _report_by_arrays(z, f, lb, ub, k):
    """The residual report's numbers by array operations, as documented: maxima of |Phi|,
    of the min-map and of the normal map; ||Phi||_2 scaled by ||Phi||_inf; Psi; the k
    largest |Phi_i| by a stable sort (ties: the lower row first)."""
    from compass_sparse.merit import normal_map_at_arrays

    phi = fb_phi(z, f, lb, ub)
    aphi, mm = np.abs(phi), np.abs(min_map(z, f, lb, ub))
    nm = np.abs(normal_map_at_arrays(z, f, lb, ub)[1])
    m = float(np.max(aphi)) if z.size else 0.0
    norm = m if (m == 0.0 or not np.isfinite(m)) else m * float(np.sqrt(np.dot(phi / m,
                                                                               phi / m)))
    rows = np.argsort(-aphi, kind="stable")[:k].tolist()
    return ([m, float(np.max(mm)) if z.size else 0.0, float(np.max(nm)) if z.size else 0.0,
             norm, 0.5 * float(np.dot(phi, phi))], rows)


def _same_floats(a, b):
    return all((x == y) or (x != x and y != y) for x, y in zip(a, b))


@pytest.mark.parametrize("case", ["ties", "nan", "inf", "huge", "tiny", "empty", "solution"])
@pytest.mark.parametrize("k", [1, 3, 5, 12])
def test_residual_report_in_one_compiled_call_gives_the_array_formulas_bits(case, k):
    """The report's numbers come from one compiled call (round 15); they are the bits
    of the array formulas, NaN and infinity propagating as np.max does, and its worst
    rows are the stable sort's whenever they are unique (ties are then left to it)."""
    rng = np.random.default_rng(["ties", "nan", "inf", "huge", "tiny", "empty",
                                 "solution"].index(case) * 100 + k)
    n = 0 if case == "empty" else 9
    lb = np.where(rng.random(n) < 0.3, -INF, rng.integers(-2, 2, n).astype(float))
    ub = np.where(rng.random(n) < 0.3, INF, lb + rng.integers(0, 3, n))
    z = np.clip(rng.standard_normal(n), lb, ub)
    f = rng.standard_normal(n)
    if case == "ties":
        z, f = np.clip(np.round(z), lb, ub), np.round(f)
    elif case == "nan":
        f[3] = np.nan
    elif case == "inf":
        f[5] = -INF
    elif case == "huge":
        z, f = np.clip(z * 1e300, lb, ub), f * 1e300
    elif case == "tiny":
        f = f * 1e-300
    elif case == "solution":
        f = np.where(z > lb, 0.0, np.abs(f)) * np.where(np.isfinite(lb), 1.0, 0.0)
        f[(z < ub) & (z > lb)] = 0.0
    with np.errstate(all="ignore"):
        rep = residual_report(z, f, lb, ub, k_worst=k)
        want, rows = _report_by_arrays(z, f, lb, ub, min(k, n))
    got = [rep.fb_inf, rep.natural, rep.normal_map_inf, rep.fb_norm, rep.merit]
    assert _same_floats(got, want), (got, want)
    listed = [int(r[0][2:-1]) for r in rep.worst]
    aphi = np.abs(fb_phi(z, f, lb, ub))
    # the k largest |Phi_i|, largest first, whatever the order among equal values
    assert _same_floats(aphi[listed], aphi[rows]) and len(listed) == len(rows)
    top = np.sort(aphi)[::-1][:len(rows) + 1]
    if case != "nan" and np.all(np.diff(top) < 0):  # unique: the rows themselves
        assert listed == rows
    assert rep.worst_index == (listed[0] if listed else -1)


@pytest.mark.parametrize("x", [np.array([1.0, -3.0, 2.0]), np.array([-0.0]), np.zeros(0),
                               np.array([1.0, np.nan, -5.0]), np.array([np.inf, -1.0]),
                               np.arange(6.0)[::2] - 5.0, [1, -7, 2]])
def test_max_abs_agrees_with_numpy_nan_and_empty_included(x):
    """The compiled infinity norms answer as np.max(np.abs(.)) does: NaN when a NaN is
    there, 0 for an empty vector, any input through the general path."""
    ref = float(np.max(np.abs(np.asarray(x, dtype=float)))) if np.size(x) else 0.0
    got = max_abs(x)
    assert (np.isnan(ref) and np.isnan(got)) or got == ref
    y = np.asarray(x, dtype=float)[::-1].copy()
    ref2 = float(np.max(np.abs(np.asarray(x, dtype=float) - y))) if np.size(x) else 0.0
    got2 = max_abs_diff(np.asarray(x, dtype=float), y)
    assert (np.isnan(ref2) and np.isnan(got2)) or got2 == ref2


def test_csc_diagonal_kernel_agrees_with_scipy_duplicates_and_missing_entries():
    """The crash's compiled diagonal: scipy's A.diagonal() on canonical matrices, on
    duplicated entries (summed) and on missing diagonal entries (0)."""
    from compass_sparse.linalg._csc_kernels import csc_diagonal

    rng = np.random.default_rng(3)
    A = sp.random(30, 30, density=0.2, random_state=4, format="csc")
    indptr = np.array([0, 3, 3, 5], dtype=np.int32)  # column 0: row 0 twice, column 1 empty
    B = sp.csc_matrix((np.array([1.5, 2.0, -4.0, 7.0, 3.0]),
                       np.array([0, 0, 2, 1, 2], dtype=np.int32), indptr), shape=(3, 3))
    for M in (A, B, sp.csc_matrix(rng.normal(size=(5, 5)))):
        out = np.empty(M.shape[0])
        csc_diagonal(M.indptr, M.indices, M.data, out)
        np.testing.assert_array_equal(out, M.diagonal())


@pytest.mark.parametrize("seed", range(6))
def test_residual_report_worst_rows_compiled_pass_is_numpys(seed):
    """The k worst rows found in one compiled pass are numpy's partition and sort when
    the k largest |Phi_i| are distinct; a tie (or a NaN, or k > n) is left to numpy, whose
    tie order the pass does not imitate: the report is the same either way."""
    from compass_sparse._merit_kernels import top_abs_distinct
    from compass_sparse.merit import residual_report

    rng = np.random.default_rng(seed)
    for trial in range(300):
        n = int(rng.integers(1, 40))
        k = int(rng.integers(1, 7))
        v = rng.standard_normal(n)
        if trial % 3 == 0:
            v = np.round(v, 1)  # ties
        if trial % 5 == 0:
            v[rng.integers(0, n)] = -v[rng.integers(0, n)]  # equal magnitudes
        idx = np.empty(k, dtype=np.int64)
        ok = top_abs_distinct(v, idx)
        a = np.abs(v)
        s = np.sort(a)[::-1]
        unique = k <= n and all(s[j] > s[j + 1] for j in range(min(k, n - 1)))
        assert ok is unique
        if ok:
            ref = np.argpartition(-a, k - 1)[:k]
            assert np.array_equal(idx, ref[np.argsort(-a[ref])])
    assert not top_abs_distinct(np.array([1.0, np.nan, 0.5]), np.empty(2, dtype=np.int64))
    z = rng.uniform(0.0, 2.0, 50)
    f = rng.standard_normal(50)
    lb, ub = np.zeros(50), np.full(50, np.inf)
    rep = residual_report(z, f, lb, ub, k_worst=5)
    phi = np.abs(fb_phi(z, f, lb, ub))
    ref = np.argpartition(-phi, 4)[:5]
    ref = ref[np.argsort(-phi[ref])]
    assert [w[0] for w in rep.worst] == [f"F[{i}]" for i in ref]
    assert rep.worst_index == ref[0]
    # every row listed (n <= k): the stable sort's order, ties by the lower row first
    for trial in range(200):
        n = int(rng.integers(1, 6))
        z = rng.uniform(0.0, 2.0, n)
        f = np.round(rng.standard_normal(n), 1 if trial % 2 else 12)
        lb, ub = np.zeros(n), np.full(n, np.inf)
        rep = residual_report(z, f, lb, ub, k_worst=5)
        phi = np.abs(fb_phi(z, f, lb, ub))
        assert [w[0] for w in rep.worst] == [f"F[{i}]" for i in np.argsort(-phi,
                                                                           kind="stable")]


def test_residual_report_of_a_small_problem_lists_every_row_ties_lower_first():
    z = np.array([0.0, 1.0, 2.0, 3.0])
    f = np.array([0.5, 0.0, -0.5, 0.0])
    lb, ub = np.zeros(4), np.full(4, np.inf)
    rep = residual_report(z, f, lb, ub)
    aphi = np.abs(fb_phi(z, f, lb, ub))
    order = sorted(range(4), key=lambda i: (-aphi[i], i))
    assert aphi[1] == aphi[3] == 0.0  # a tie
    assert [w[0] for w in rep.worst] == [f"F[{i}]" for i in order]
    assert rep.worst_index == order[0]
    # above k_worst rows the partition route lists the same k largest
    big = residual_report(np.arange(9.0), np.linspace(-1, 1, 9), np.zeros(9),
                          np.full(9, np.inf), k_worst=3)
    assert len(big.worst) == 3
    assert [w[1] for w in big.worst] == sorted(
        np.abs(fb_phi(np.arange(9.0), np.linspace(-1, 1, 9), np.zeros(9),
                      np.full(9, np.inf))), reverse=True)[:3]


def _random_box(rng, n):
    lb = np.where(rng.random(n) < 0.5, -np.inf, rng.standard_normal(n))
    ub = np.where(rng.random(n) < 0.5, np.inf, np.nan_to_num(lb, neginf=0.0)
                  + np.abs(rng.standard_normal(n)))
    return lb, ub


def _stress_point(seed, at_bounds=0.0):
    """5000 entries over 600 orders of magnitude, every bound kind, infinite and NaN F
    values; a fraction ``at_bounds`` of the points on a finite lower bound (half of them
    with F = 0 there: the (0, 0) corner of the Fischer function)."""
    rng = np.random.default_rng(seed)
    n = 5000
    z = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
    f = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
    lb, ub = _random_box(rng, n)
    z = np.clip(z, lb, ub)
    if at_bounds:
        at = rng.random(n) < at_bounds
        z[at] = np.where(np.isfinite(lb[at]), lb[at], z[at])
        f[at & (rng.random(n) < 0.5)] = 0.0
    f[:10] = [np.inf, -np.inf, np.nan, 0.0, -0.0, 1e308, -1e308, 5e-324, -5e-324, 0.0]
    return z, f, lb, ub


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fb_phi_kernel_matches_array_formula_bitwise_across_magnitudes(seed):
    """Stress over 600 orders of magnitude, every bound kind, infinite and NaN entries."""
    z, f, lb, ub = _stress_point(seed)
    a = merit.fb_phi(z, f, lb, ub)
    with np.errstate(all="ignore"):  # inf - inf and NaN arguments on purpose
        b = merit.fb_phi_arrays(z, f, lb, ub)
    assert np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fb_diagonals_kernel_matches_array_formula_bitwise_across_magnitudes(seed):
    """The same stress for the diagonals (da, db) of the generalized Jacobian, with
    points at their bounds (the (0, 0) direction of the Fischer function)."""
    z, f, lb, ub = _stress_point(seed, at_bounds=0.2)
    da, db = merit.fb_jacobian_diagonals(z, f, lb, ub)
    with np.errstate(all="ignore"):
        ra, rb = merit.fb_jacobian_diagonals_arrays(z, f, lb, ub)
    assert np.array_equal(da, ra, equal_nan=True)
    assert np.array_equal(db, rb, equal_nan=True)
    # each partial of phi lies in [-2, 0]; a box row chains two: |da| <= 2 + 2 * 2
    assert (np.abs(da[np.isfinite(da)]) <= 6.0).all()
    assert (np.abs(db[np.isfinite(db)]) <= 4.0).all()


def test_fb_phi_scalar_bounds_still_broadcast():
    z = np.array([0.0, 1.0, 2.0])
    f = np.array([1.0, 0.0, -1.0])
    assert np.array_equal(merit.fb_phi(z, f, 0.0, np.inf), merit.fb_phi_arrays(z, f, 0.0, np.inf))


def test_fb_gradient_same_with_sparse_and_dense_jacobian():
    rng = np.random.default_rng(3)
    n = 12
    z, f = rng.standard_normal(n), rng.standard_normal(n)
    lb, ub = _random_box(rng, n)
    z = np.clip(z, lb, ub)
    J = sp.random(n, n, density=0.3, format="csc", random_state=3)
    g1 = merit.fb_gradient(z, f, J, lb, ub)
    g2 = merit.fb_gradient(z, f, sp.csr_matrix(J), lb, ub)
    assert np.allclose(g1, g2, rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_normal_map_kernel_matches_array_formula_bitwise_across_magnitudes(seed):
    """The compiled normal-map point and residual agree bit for bit (signed zeros
    included) with the array formulas, with fixed variables and points at bounds."""
    z, f, lb, ub = _stress_point(seed, at_bounds=0.3)
    fixed = np.random.default_rng(seed).random(z.size) < 0.1
    ub = ub.copy()
    ub[fixed] = lb[fixed]
    z = np.clip(z, lb, ub)
    with np.errstate(all="ignore"):
        got = merit.normal_map_at(z, f, lb, ub)
        ref = merit.normal_map_at_arrays(z, f, lb, ub)
    for a, b in zip(got, ref):
        assert np.array_equal(a, b, equal_nan=True)
        num = ~np.isnan(b)
        assert np.array_equal(np.signbit(a[num]), np.signbit(b[num]))
    # signed zeros at bounds: np.maximum(-0.0, 0.0) is 0.0, and z - w + v keeps the sign
    z0 = np.array([-0.0, 0.0, -0.0, 0.0, -0.0])
    f0 = np.array([-0.0, -0.0, 0.0, 0.0, -0.0])
    l0, u0 = np.array([0.0, 0.0, -0.0, 0.0, -1.0]), np.array([np.inf, 1.0, 0.0, 0.0, -0.0])
    for a, b in zip(merit.normal_map_at(z0, f0, l0, u0),
                    merit.normal_map_at_arrays(z0, f0, l0, u0)):
        assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_residual_report_maxima_match_array_formulas_across_magnitudes(seed):
    """The compiled maxima of the residual report (||Phi||_inf, the natural residual, the
    normal-map residual and every row's |min-map|) are those of the array formulas, NaN
    and infinite entries included; the scaled 2-norm is unchanged."""
    z, f, lb, ub = _stress_point(seed, at_bounds=0.3)
    for sl in (slice(10, None), slice(None)):  # finite F values; with inf and NaN
        zz, ff, ll, uu = z[sl], f[sl], lb[sl], ub[sl]
        with np.errstate(all="ignore"):
            rep = merit.residual_report(zz, ff, ll, uu)
            phi = merit.fb_phi(zz, ff, ll, uu)
            mm = np.abs(merit.min_map(zz, ff, ll, uu))
            nm = merit.normal_map_at_arrays(zz, ff, ll, uu)[1]
        np.testing.assert_array_equal(rep.fb_inf, np.max(np.abs(phi)))
        np.testing.assert_array_equal(rep.natural, np.max(mm))
        np.testing.assert_array_equal(rep.normal_map_inf, np.max(np.abs(nm)))
        for name, a, m in rep.worst:  # rows named F[i]
            i = int(name[2:-1])
            np.testing.assert_array_equal([a, m], [abs(phi[i]), mm[i]])
    rep = merit.residual_report(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))
    assert (rep.fb_norm, rep.fb_inf, rep.natural, rep.worst) == (0.0, 0.0, 0.0, [])


@pytest.mark.parametrize("seed", range(3))
def test_fb_phi_fast_path_on_views_and_mixed_inputs_matches_the_array_formula(seed):
    """fb_phi goes straight to the kernel for float vectors of one shape (the solver's own
    points), strided views included; other inputs (scalar bounds, lists, integers) take
    the general route.  Both give the array formula's values bit for bit, and fb_psi
    (the array's own dot) equals 0.5 * np.dot(phi, phi)."""
    from compass_sparse.merit import fb_phi, fb_phi_arrays, fb_psi

    rng = np.random.default_rng(seed)
    n = 40
    big = rng.standard_normal((4, 2 * n)) * 10.0 ** rng.integers(-8, 8, (4, 2 * n))
    z, f, lb, ub = (big[k, ::2] for k in range(4))  # strided views
    lb = np.where(rng.random(n) < 0.3, -np.inf, lb)
    ub = np.where(rng.random(n) < 0.3, np.inf, lb + np.abs(ub))
    ref = fb_phi_arrays(z, f, lb, ub)
    np.testing.assert_array_equal(fb_phi(z, f, lb, ub), ref)
    np.testing.assert_array_equal(fb_phi(z.copy(), f.copy(), lb, ub), ref)
    np.testing.assert_array_equal(fb_phi(list(z), f, lb, ub), ref)
    zi = np.arange(n) - n // 2
    np.testing.assert_array_equal(fb_phi(zi, f, 0.0, np.inf), fb_phi_arrays(zi, f, 0.0, np.inf))
    phi = fb_phi(z, f, lb, ub)
    assert fb_psi(phi) == 0.5 * float(np.dot(phi, phi))
    assert fb_psi(list(phi)) == 0.5 * float(np.dot(phi, phi))

