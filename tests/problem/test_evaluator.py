"""The evaluation layer: one owner of the user's F and J (copies, memo, counters, guards)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.exceptions import JacobianPatternError, ShapeError
from compass_sparse.problem.evaluator import Evaluator


def _counting_ncp(n, seed=0, cubic=0.1):
    """F(x) = A x + cubic x^3 + b (A tridiagonal, diagonally dominant) with call logs of
    F and J; also returns A."""
    rng = np.random.default_rng(seed)
    A = sp.diags([np.full(n - 1, -1.0), np.full(n, 4.0), np.full(n - 1, -1.0)], [-1, 0, 1],
                 format="csc")
    b = rng.normal(size=n)
    calls = {"F": [], "J": []}

    def F(x):
        calls["F"].append(x.copy())
        return A @ x + cubic * x ** 3 + b

    def J(x):
        calls["J"].append(x.copy())
        return (A + sp.diags(3 * cubic * x ** 2)).tocsc()

    return F, J, calls, A


def _at(points, x0):
    return sum(1 for p in points if np.array_equal(p, x0))


@pytest.mark.parametrize("crash", ["pnewton", "none"])
def test_start_point_is_evaluated_once_before_the_first_iteration(crash):
    n = 50
    F, J, calls, _ = _counting_ncp(n)
    x0 = np.full(n, 0.5)
    seen = {}

    def cb(info):
        if not seen:
            seen["F"], seen["J"] = len(calls["F"]), len(calls["J"])
            seen["F0"], seen["J0"] = _at(calls["F"], x0), _at(calls["J"], x0)

    r = cs.solve_mcp(F, J, 0.0, np.inf, x0, callback=cb,
                     options={"crash_method": crash, "crash_minimum_dimension": 1})
    assert r.success
    # One call of F and one of J at x0 over the whole solve (the problem's start check),
    # none repeated before the first major iteration.
    assert _at(calls["F"], x0) == 1 and _at(calls["J"], x0) == 1
    assert seen["F0"] == 1 and seen["J0"] == 1
    if crash == "none":
        assert (seen["F"], seen["J"]) == (1, 1)
    # The counters count exactly the user's calls.
    assert (r.nfev, r.njev) == (len(calls["F"]), len(calls["J"]))


def test_start_point_is_evaluated_once_with_presolve():
    n = 40
    F, J, calls, A = _counting_ncp(n, seed=3, cubic=0.0)  # linear: presolve applies
    x0 = np.full(n, 0.25)
    lb = np.zeros(n)
    ub = np.full(n, np.inf)
    lb[:5] = ub[:5] = 1.0  # fixed variables: presolve removes them
    x0[:5] = 1.0
    r = cs.solve_mcp(F, J, lb, ub, x0, constant_jac=A)
    assert r.success and r.passes["presolve"].ran
    assert _at(calls["F"], x0) == 1 and _at(calls["J"], x0) == 1
    assert (r.nfev, r.njev) == (len(calls["F"]), len(calls["J"]))


def test_evaluator_copies_memoizes_and_counts():
    seen = []

    def F(x):
        seen.append(x)
        x[0] = 99.0  # a callback that writes into its argument does not hurt the caller
        return np.ones(3)

    ev = Evaluator(F, lambda x: sp.identity(3, format="csc"), 3)
    x = np.zeros(3)
    f = ev.F(x)
    f[:] = -1.0  # nor does a caller that writes into its F values
    assert np.all(x == 0.0) and np.all(ev.F(x) == 1.0)
    assert ev.counters.nfev == 1 and len(seen) == 1
    ev.forget()
    ev.F(x)
    assert ev.counters.nfev == 2


def test_evaluator_rejects_nan_and_exceptions_without_raising():
    def F(x):
        if x[0] < 0:
            raise ValueError("log of a negative number")
        return np.array([np.nan if x[0] > 1 else 1.0, 0.0])

    ev = Evaluator(F, lambda x: sp.identity(2, format="csc"), 2)
    assert ev.f(np.array([-1.0, 0.0])) is None and "log of a negative" in ev.last_error
    assert ev.f(np.array([2.0, 0.0])) is None and "NaN" in ev.last_error
    assert ev.f(np.array([0.5, 0.0])) is not None
    assert ev.counters.domain_errors == 2
    with pytest.raises(ValueError):
        ev.F(np.array([-1.0, 0.0]))


def test_evaluator_shape_and_pattern_errors_propagate_from_guarded_calls():
    ev = Evaluator(lambda x: np.ones(4), lambda x: sp.identity(3, format="csc"), 3)
    with pytest.raises(ShapeError):
        ev.f(np.zeros(3))
    k = {"i": 0}

    def J(x):
        k["i"] += 1
        return sp.csc_matrix(np.eye(3) if k["i"] == 1 else np.eye(3) + np.eye(3, k=1))

    ev = Evaluator(lambda x: np.ones(3), J, 3, pattern=sp.identity(3, format="csc"))
    ev.jac(np.zeros(3))
    with pytest.raises(JacobianPatternError):
        ev.jac(np.ones(3))  # an entry outside the declared pattern


def test_jac_true_one_call_serves_f_and_j_and_the_pinned_start_survives():
    n = 4
    calls = []

    def FJ(x):
        calls.append(x.copy())
        return 2.0 * x + 1.0, sp.diags(np.full(n, 2.0), format="csc")

    ev = Evaluator(FJ, True, n)
    x0, y = np.zeros(n), np.ones(n)
    ev.check_at(x0)  # pins the start point
    assert (ev.counters.nfev, ev.counters.njev, len(calls)) == (1, 1, 1)
    ev.F(y)  # an F-only call: its J is kept, counted only when used
    assert (ev.counters.nfev, ev.counters.njev) == (2, 1)
    ev.J(y)
    assert (ev.counters.nfev, ev.counters.njev, len(calls)) == (2, 2, 2)
    ev.J(2 * y)
    ev.F(2 * y)
    assert (ev.counters.nfev, ev.counters.njev, len(calls)) == (3, 3, 3)
    ev.FJ(x0)  # still in the memo
    assert len(calls) == 3 and ev.counters.nfev == len(calls)
    ev.forget()
    ev.F(x0)
    assert len(calls) == 4


def test_repeated_solves_do_not_reuse_start_values_from_before_the_data_changed():
    # A scenario loop changes the data F reads after the problem was built: the values of
    # F at x0 remembered by the start-point check are stale and must not be trusted (they
    # made the first solve report "the start point is a solution" with residual 0.5).
    n = 20
    data = {"b": np.zeros(n)}

    def F(x):
        return 2.0 * x - data["b"]

    def J(x):
        return 2.0 * sp.identity(n, format="csc")

    problem = cs.MCP(F, J, -np.inf, np.inf, np.zeros(n))
    data["b"] = np.linspace(1.0, 2.0, n)
    r = cs.MCPSolver(problem).solve()
    assert r.success and np.allclose(r.x, data["b"] / 2)
    data["b"] = np.linspace(3.0, 4.0, n)
    r = cs.solve_mcp(problem)
    assert r.success and np.allclose(r.x, data["b"] / 2)


def test_memo_compares_points_as_equal_values_signed_zeros_alike_nan_never():
    """The evaluation memo's byte keys answer exactly as an elementwise == would: -0.0
    hits the value stored at 0.0, a point with a NaN is never a hit, a different point or
    shape misses, and the pinned point survives later evaluations."""
    from compass_sparse.problem.memo import Memo

    m = Memo()
    assert m.get(np.zeros(2)) is None
    m.put(np.array([0.0, 1.0]), "a")
    assert m.get(np.array([-0.0, 1.0])) == "a"
    # a strided view (a non-contiguous vector for the kernel) answers alike
    assert m.get(np.array([-0.0, 7.0, 1.0])[::2]) == "a"
    assert m.get(np.array([np.nan, 7.0, 1.0])[::2]) is None
    assert m.get(np.array([0.0, 1.0 + 2e-16])) is None
    assert m.get(np.array([0.0, 1.0, 0.0])) is None
    m.pin(np.array([0.0, 1.0]))
    m.put(np.array([np.nan, 1.0]), "nan")
    assert m.get(np.array([np.nan, 1.0])) is None
    assert m.get(np.array([-0.0, 1.0])) == "a"  # the pinned value
    m.put(np.array([0.0, 1.0]), "b")  # a new value at the pinned point replaces it
    m.put(np.array([5.0, 5.0]), "c")
    assert m.get(np.array([0.0, 1.0])) == "b"
    assert m.get(np.array([5.0, 5.0])) == "c"
    m.clear()
    assert m.get(np.array([5.0, 5.0])) is None


@pytest.mark.parametrize("case", ["canonical", "unsorted", "duplicates", "int64", "zeros"])
def test_canonical_csc_fast_path_matches_scipys_canonical_form(case):
    """A canonical float CSC Jacobian is copied without scipy's constructor; every other
    form goes through scipy: both give the same sorted, duplicate-free matrix (explicit
    zeros kept) that owns its arrays."""
    from compass_sparse.linalg._csc_kernels import csc_is_canonical
    from compass_sparse.linalg.csc import canonical_csc

    n = 5
    indptr = np.array([0, 2, 3, 3, 5, 6], dtype=np.int32)
    indices = np.array([0, 3, 1, 2, 4, 0], dtype=np.int32)
    data = np.arange(1.0, 7.0)
    if case == "unsorted":
        indices[[0, 1]] = indices[[1, 0]]
    elif case == "duplicates":
        indices[4] = 2
    elif case == "zeros":
        data[2] = 0.0
    J = sp.csc_matrix((data, indices, indptr), shape=(n, n))
    if case == "int64":
        J.indices, J.indptr = J.indices.astype(np.int64), J.indptr.astype(np.int64)
    assert csc_is_canonical(indptr, indices, n, 6) is (case in ("canonical", "int64", "zeros"))
    C = canonical_csc(J, n)
    ref = J.copy()
    ref.sum_duplicates()
    ref.sort_indices()
    assert C.has_canonical_format
    assert np.array_equal(C.indptr, ref.indptr) and np.array_equal(C.indices, ref.indices)
    assert np.array_equal(C.data, ref.data)
    assert C.data is not J.data and C.indices is not J.indices
    assert not csc_is_canonical(np.array([0, 1], np.int32), np.array([7], np.int32), 5, 1)


@pytest.mark.parametrize("case", ["same", "unsorted", "duplicates", "missing", "int64",
                                  "longer_arrays", "csc_array", "coo"])
def test_user_jacobian_on_the_pattern_fast_path_is_the_general_route(case):
    """A J the user returns holding exactly the stored pattern is copied in one compiled
    pass; any other form takes canonical_csc and _fix_pattern.  Either way the evaluator
    hands out the general route's matrix (same index arrays and values, bit for bit),
    which owns its arrays (neither the user's nor the pattern's)."""
    from compass_sparse.linalg.csc import canonical_csc

    n = 5
    indptr = np.array([0, 2, 3, 3, 5, 6], dtype=np.int32)
    indices = np.array([0, 3, 1, 2, 4, 0], dtype=np.int32)
    P = sp.csc_matrix((np.ones(6), indices.copy(), indptr.copy()), shape=(n, n))
    ev = Evaluator(lambda x: np.zeros(n), None, n, pattern=P)
    data = np.arange(1.0, 7.0)
    J = sp.csc_matrix((data.copy(), indices.copy(), indptr.copy()), shape=(n, n))
    if case == "unsorted":
        J.indices[[0, 1]] = J.indices[[1, 0]]
        J.data[[0, 1]] = J.data[[1, 0]]
    elif case == "duplicates":  # (2, 3) given as two parts
        J = sp.csc_matrix((np.array([1.0, 2.0, 3.0, 4.0, 0.5, 5.0, 6.0]),
                           np.array([0, 3, 1, 2, 2, 4, 0], np.int32),
                           np.array([0, 2, 3, 3, 6, 7], np.int32)), shape=(n, n))
    elif case == "missing":
        J = sp.csc_matrix((np.array([1.0, 2.0, 4.0, 5.0, 6.0]),
                           np.array([0, 3, 2, 4, 0], np.int32),
                           np.array([0, 2, 2, 2, 4, 5], np.int32)), shape=(n, n))
    elif case == "int64":
        J.indices, J.indptr = J.indices.astype(np.int64), J.indptr.astype(np.int64)
    elif case == "longer_arrays":  # room beyond nnz, as scipy may leave after pruning
        J.indices = np.concatenate([J.indices, np.array([4, 4], np.int32)])
        J.data = np.concatenate([J.data, [9.0, 9.0]])
    elif case == "csc_array":
        J = sp.csc_array(J)
    elif case == "coo":
        J = J.tocoo()
    ref = ev._fix_pattern(canonical_csc(J, n))
    got = ev._user_J_on_pattern(J)
    for a in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(got, a), getattr(ref, a)), a
        assert getattr(got, a).dtype == getattr(ref, a).dtype
        assert getattr(got, a) is not getattr(ev.pattern_ref, a)
    if sp.issparse(J) and J.format == "csc":
        assert got.data is not J.data and got.indices is not J.indices
    assert got.has_canonical_format and got.shape == (n, n)
    ev2 = Evaluator(lambda x: np.zeros(n), lambda x: J, n, pattern=P)
    assert np.array_equal(ev2.J(np.zeros(n)).toarray(), ref.toarray())


def test_user_jacobian_outside_a_declared_pattern_still_raises():
    """The fast path only takes a J with exactly the pattern: an entry outside a declared
    pattern still raises, an undeclared pattern still grows."""
    n = 3
    P = sp.csc_matrix(np.eye(n))
    J = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    ev = Evaluator(lambda x: np.zeros(n), lambda x: J, n, pattern=P)
    with pytest.raises(JacobianPatternError):
        ev.J(np.zeros(n))
    Js = [sp.csc_matrix(np.eye(n)), J]
    ev = Evaluator(lambda x: np.zeros(n), lambda x: Js.pop(0), n)
    ev.J(np.zeros(n))
    assert np.array_equal(ev.J(np.ones(n)).toarray(), J.toarray())
    assert ev.pattern_growths == 1


@pytest.mark.parametrize("order", ["C", "F"])
def test_dense_jacobian_on_the_full_pattern_is_a_copy_equal_to_the_general_route(order):
    """A dense float J on the full pattern stored already is copied column after column
    (the small problems' route): the general route's matrix, bit for bit, in either memory
    order of the user's array, and a copy -- the user writing into their array later does
    not change the evaluator's J."""
    from compass_sparse.linalg.csc import dense_csc

    n = 4
    rng = np.random.default_rng(3)
    A = np.asarray(rng.normal(size=(n, n)), order=order)
    A[1, 2] = 0.0  # a zero stays stored on the full pattern
    ev = Evaluator(lambda x: np.zeros(n), lambda x: A, n)
    first = ev.J(np.zeros(n))  # stores the full pattern
    assert first.nnz == n * n
    got = ev._user_J_on_pattern(A)
    ref = ev._fix_pattern(dense_csc(A, n))
    for a in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(got, a), getattr(ref, a)), a
        assert getattr(got, a).dtype == getattr(ref, a).dtype
        assert getattr(got, a) is not getattr(ev.pattern_ref, a)
    assert np.array_equal(got.toarray(), A)
    kept = ev.J(np.ones(n))
    A[0, 0] += 1.0  # the user's array changes after the evaluation
    assert kept.toarray()[0, 0] == A[0, 0] - 1.0


def test_f_once_is_f_without_the_memo_on_every_kind_of_evaluator():
    """f_once (the homotopy corrector's evaluations): the values of f, counted at every
    call (no memo: the same point twice is two evaluations), NaN and exceptions rejected
    and counted as domain errors, our own errors passed on -- on the user's problem and
    its scaled form (whose evaluator goes through the user's)."""
    from compass_sparse.exceptions import ShapeError
    from compass_sparse.scaling import equilibrate, scale_problem

    def F(x):
        if x[0] < -5:
            raise ValueError("outside F's domain")
        return np.array([np.nan if x[0] > 5 else 3.0 * x[0] + x[1], 1e4 * x[1] - 2.0])

    def J(x):
        return sp.csc_matrix(np.array([[3.0, 1.0], [0.0, 1e4]]))

    p = cs.MCP(F, J, np.full(2, -10.0), np.full(2, 10.0), np.zeros(2))
    sc = equilibrate(J(np.zeros(2)))
    scaled = scale_problem(p, sc)
    rng = np.random.default_rng(0)
    for prob in (p, scaled):
        ev = prob.evaluator
        for _ in range(5):
            x = rng.uniform(-4, 4, 2)
            n0 = ev.counters.nfev
            a = ev.f_once(x)
            b = ev.f_once(x)
            assert ev.counters.nfev == n0 + 2  # no memo
            assert np.array_equal(a, ev.f(x)) and np.array_equal(a, b)
        e0 = ev.counters.domain_errors
        bad = np.array([6.0, 0.0]) if prob is p else np.array([6.0, 0.0]) / sc.col
        assert ev.f_once(bad) is None and "NaN" in ev.last_error
        worse = np.array([-6.0, 0.0]) if prob is p else np.array([-6.0, 0.0]) / sc.col
        assert ev.f_once(worse) is None and "domain" in ev.last_error
        assert ev.counters.domain_errors == e0 + 2
    wrong = Evaluator(lambda x: np.ones(3), None, 2, pattern=sp.identity(2, format="csc"))
    with pytest.raises(ShapeError):
        wrong.f_once(np.zeros(2))



def test_dense_jacobian_on_its_full_pattern_matches_the_general_route():
    """A dense float J (the user's array) on the stored full pattern is copied straight
    into the pattern's column order: the same matrix as canonical_csc + _fix_pattern, its
    zeros kept, owning its arrays (the pattern's stay untouched); an integer array or a
    Fortran-ordered one give that route's matrix too."""
    from compass_sparse.linalg.csc import canonical_csc
    from compass_sparse.problem.evaluator import Evaluator

    n = 4
    A = np.arange(16.0).reshape(n, n)
    A[1, 2] = 0.0
    ev = Evaluator(lambda x: np.zeros(n), lambda x: A, n)
    ev.J(np.zeros(n))  # records the (full) pattern
    for J in (A, np.asfortranarray(A), A.astype(np.int64), A[:, ::-1].copy()):
        ref = ev._fix_pattern(canonical_csc(J, n))
        got = ev._user_J_on_pattern(J)
        for a in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(got, a), getattr(ref, a)), a
            assert getattr(got, a) is not getattr(ev.pattern_ref, a)
        assert got.nnz == n * n and np.array_equal(got.toarray(), J)
        got.data[:] = -1.0
        assert np.array_equal(ev._user_J_on_pattern(J).toarray(), J)  # no shared buffer


def test_dense_jacobian_in_fortran_order_is_copied_not_viewed():
    from compass_sparse.linalg.csc import canonical_csc

    A = np.asfortranarray(np.arange(9.0).reshape(3, 3))
    C = canonical_csc(A, 3)
    A[:] = -1.0
    np.testing.assert_array_equal(C.toarray(), np.arange(9.0).reshape(3, 3))


def test_evaluators_jacobians_are_marked_canonical_only_when_they_are():
    """A J the evaluator returns (dense, on the stored pattern, a canonical CSC copy)
    carries the canonical mark, which lets without_duplicates return it unscanned; every
    marked matrix passes the scan; an unmarked matrix with duplicates is still summed."""
    from compass_sparse.linalg._csc_kernels import csc_is_canonical
    from compass_sparse.linalg.csc import _CANONICAL, trusted_csc, without_duplicates
    from compass_sparse.problem.evaluator import Evaluator

    rng = np.random.default_rng(3)
    A = sp.random(6, 6, density=0.5, format="csc", random_state=4) + sp.eye(6, format="csc")
    A = A.tocsc()
    A.indices, A.indptr = A.indices.astype(np.int32), A.indptr.astype(np.int32)
    for jac in (lambda x: A.toarray(), lambda x: A.copy()):
        ev = Evaluator(lambda x: x, jac, 6)
        for _ in range(3):
            J = ev.J(rng.standard_normal(6))
            assert J.__dict__.get(_CANONICAL) is True
            assert csc_is_canonical(J.indptr, J.indices, 6, J.indptr[-1])
            assert without_duplicates(J) is J
    dup = trusted_csc(np.array([1.0, 2.0]), np.array([0, 0], dtype=np.int32),
                      np.array([0, 2], dtype=np.int32), (1, 1))
    assert dup.__dict__.get(_CANONICAL) is None
    summed = without_duplicates(dup)
    assert summed is not dup and summed.nnz == 1 and summed.data[0] == 3.0

