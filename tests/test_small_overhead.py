"""Fixed per-solve overhead of small problems: compiled merit kernels agree with the array
formulas, numba is not imported by ``import compass_sparse``, lazily built kernels call
each other, the BLAS thread limit reuses one controller, dense Jacobians keep a canonical
full pattern."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import known_problems as kp
import numpy as np
import pytest
import scipy.sparse as sp
from compass_sparse.generators import thesis_family

from compass_sparse import _jit, merit, solve_mcp
from compass_sparse.linalg._csc_kernels import csc_rmatvec

ROOT = Path(__file__).resolve().parent.parent


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


@pytest.mark.parametrize("n,density", [(1, 1.0), (7, 0.5), (60, 0.1)])
def test_csc_rmatvec_is_transpose_product(n, density):
    rng = np.random.default_rng(n)
    A = sp.random(n, n, density=density, format="csc", random_state=n)
    u = rng.standard_normal(n)
    out = np.empty(n)
    csc_rmatvec(A.indptr, A.indices, A.data, u, out)
    assert np.allclose(out, A.T @ u, rtol=1e-14, atol=1e-14)


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


def test_import_does_not_load_numba():
    """Kernels are compiled or loaded on first use: ``import compass_sparse`` leaves numba
    (0.2-0.4 s of import time) unloaded."""
    code = "import sys, compass_sparse; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def _cold_env(**extra):
    """The environment of a fresh process with the default cold start (the test session
    itself compiles from the first call: conftest.py)."""
    env = {k: v for k, v in os.environ.items() if k != "COMPASS_SPARSE_JIT"}
    env.update(extra)
    return env


def _run_fresh(code, **env):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=_cold_env(**env), cwd=ROOT)
    return out.stdout.strip().splitlines()[-1]


def test_first_small_solve_of_a_process_does_not_load_numba():
    """A fresh process's first solve of a small problem runs the kernels interpreted (its
    route, recorded in Result.routes): numba (0.5-0.8 s with its first kernel) is not
    loaded, and the solve succeeds.  With COMPASS_SPARSE_JIT=always the same solve
    compiles and loads it."""
    code = ("import sys; sys.path.insert(0, 'tests'); import known_problems as kp; "
            "from compass_sparse import solve_mcp; from compass_sparse._jit import cold_start; "
            "q = kp.kojima_shindo(); r = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0); "
            "print(r.status.name, r.residual.natural <= 1e-6, 'numba' in sys.modules, "
            "cold_start()['interpreting'], r.routes['kernels'])")
    assert _run_fresh(code).split() == ["SOLVED", "True", "False", "True", "interpreted"]
    assert _run_fresh(code, COMPASS_SPARSE_JIT="always").split() == [
        "SOLVED", "True", "True", "False", "compiled"]


def test_interpreted_kernels_solve_the_small_problems_as_the_compiled_ones():
    """With every small solve interpreted (COMPASS_SPARSE_JIT=interpret), a fresh process
    solves the known problems and thesis instances at n = 10 with interpreted kernels
    only; statuses, major iterations, pivots, F and J evaluations are the compiled
    kernels' (this process), and both points pass the tolerance."""
    code = textwrap.dedent("""
        import sys, json
        sys.path.insert(0, "tests")
        import known_problems as kp
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        out, routes = {}, set()
        def row(r):
            routes.add(r.routes["kernels"])
            return [r.status.name, r.nit, r.minor_iterations, r.nfev, r.njev,
                    r.residual.natural]
        for name, make in kp.ALL_SOLVABLE.items():
            q = make()
            out[name] = row(solve_mcp(q.F, q.J, q.lb, q.ub, q.x0))
        for fam in (1, 2):
            for seed in (1, 2, 3):
                out[f"f{fam}s{seed}"] = row(solve_mcp(thesis_family(10, fam, seed).problem))
        print(json.dumps([out, "numba" in sys.modules, sorted(routes)]))
        """)
    interpreted, numba_loaded, routes = json.loads(_run_fresh(code, COMPASS_SPARSE_JIT="interpret"))
    assert not numba_loaded and routes == ["interpreted"]
    compiled = {}
    for name, make in kp.ALL_SOLVABLE.items():
        q = make()
        compiled[name] = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0)
    for fam in (1, 2):
        for seed in (1, 2, 3):
            compiled[f"f{fam}s{seed}"] = solve_mcp(thesis_family(10, fam, seed).problem)
    assert set(compiled) == set(interpreted) and len(compiled) > 10
    for key, r in compiled.items():
        assert r.routes["kernels"] == "compiled"
        status, nit, minor, nfev, njev, natural = interpreted[key]
        assert (status, nit, minor, nfev, njev) == (
            r.status.name, r.nit, r.minor_iterations, r.nfev, r.njev), key
        if r.success:
            assert natural <= 1e-6 and r.residual.natural <= 1e-6, key


def test_cold_start_is_decided_once_per_solve_from_the_process_and_the_size():
    """Whether a solve's kernels are interpreted is decided when it starts, never from the
    clock: the first INTERPRET_SOLVES solves of small problems (n <= INTERPRET_MAX_N) are
    interpreted, the next compiles (and loads numba), and so does every solve after a
    compiled one; a solve of a larger problem compiles at once.  Outside a solve a kernel
    with a large array compiles.  Every kernel of an interpreted solve is interpreted,
    whatever its arrays' sizes."""
    code = textwrap.dedent("""
        import sys
        sys.path.insert(0, "tests")
        import known_problems as kp
        import compass_sparse._jit as J
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        q = kp.cournot_duopoly()
        kinds = [solve_mcp(q.F, q.J, q.lb, q.ub, q.x0).routes["kernels"]
                 for _ in range(J.INTERPRET_SOLVES + 1)]
        print(kinds.count("interpreted"), kinds[-1], "numba" in sys.modules)
        """)
    from compass_sparse._jit import INTERPRET_MAX_N, INTERPRET_SOLVES

    assert _run_fresh(code).split() == [str(INTERPRET_SOLVES), "compiled", "True"]
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, "tests")
        import known_problems as kp
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        big = solve_mcp(thesis_family({INTERPRET_MAX_N + 1}, 1, 1).problem)
        q = kp.cournot_duopoly()
        small = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0)
        print(big.routes["kernels"], small.routes["kernels"], "numba" in sys.modules)
        """)
    assert _run_fresh(code).split() == ["compiled", "compiled", "True"]
    code = textwrap.dedent(f"""
        import sys, numpy as np
        import compass_sparse._jit as J
        from compass_sparse._merit_kernels import all_finite_kernel, max_abs_kernel
        a = max_abs_kernel(np.array([1.0, -3.0]), np.array([1.0, -3.0]), False)
        first = "numba" in sys.modules
        b = all_finite_kernel(np.ones({2 * 4096}))
        print(a, bool(b), first, "numba" in sys.modules)
        """)
    assert _run_fresh(code).split() == ["3.0", "True", "False", "True"]


def test_lazy_kernels_calling_each_other_compile_on_first_use(tmp_path, monkeypatch):
    """A lazily built kernel whose body calls other lazy kernels (of its own module and of
    another one) compiles: the stand-ins are replaced by dispatchers before numba types
    it, and a caller holding a stand-in still reaches the dispatcher."""
    (tmp_path / "lazy_a.py").write_text(
        "from compass_sparse._jit import njit\n"
        "@njit\n"
        "def twice(x):\n    return 2.0 * x\n")
    (tmp_path / "lazy_b.py").write_text(
        "from compass_sparse._jit import njit\n"
        "from lazy_a import twice\n"
        "@njit(inline='always')\n"
        "def plus_one(x):\n    return x + 1.0\n"
        "@njit()\n"
        "def outer(x):\n    return plus_one(twice(x))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import lazy_b

    from compass_sparse._jit import LazyKernel

    stand_in = lazy_b.outer
    assert isinstance(stand_in, LazyKernel)
    assert stand_in(3.0) == 7.0
    assert not isinstance(lazy_b.__dict__["twice"], LazyKernel)
    assert lazy_b.outer(0.5) == 2.0


def test_python_callers_of_a_built_kernel_call_its_dispatcher():
    """Once a kernel is built, the package's modules that imported its stand-in by name
    call the dispatcher itself (a forwarded call costs an extra Python frame at every
    evaluated point)."""
    from compass_sparse import merit
    from compass_sparse._jit import LazyKernel

    z = np.array([1.0, -2.0])
    phi = merit.fb_phi(z, np.array([0.5, 3.0]), np.zeros(2), np.full(2, np.inf))
    assert np.allclose(phi, merit.fb_phi_arrays(z, np.array([0.5, 3.0]), np.zeros(2),
                                                np.full(2, np.inf)))
    assert not isinstance(merit.fb_phi_kernel, LazyKernel)


def test_nested_single_threaded_blas_blocks_set_threads_once_and_restore_after():
    """A single-threaded BLAS block inside another sets nothing and restores nothing; the
    outer block restores each library's own count when it closes."""
    from compass_sparse.linalg import blas as _blas

    with _blas.single_threaded_blas():
        pass
    libs = _blas._BLAS_LIBS[0]
    if not libs:
        pytest.skip("no BLAS library under threadpoolctl's control")
    calls = []

    class Spy:
        def __init__(self, c):
            self.c = c

        def get_num_threads(self):
            return self.c.get_num_threads()

        def set_num_threads(self, k):
            calls.append(k)
            self.c.set_num_threads(k)

    before = [c.get_num_threads() for c in libs]
    for c in libs:
        c.set_num_threads(2)
    # what each library took (one whose count is pinned, or that shares its state with
    # another, may not show 2)
    want = [c.get_num_threads() for c in libs]
    spies = [Spy(c) for c in libs]
    try:
        with _blas._OneThread(spies):
            assert all(c.get_num_threads() == 1 for c in libs)
            for _ in range(3):
                with _blas._OneThread(spies):
                    assert all(c.get_num_threads() == 1 for c in libs)
            assert all(c.get_num_threads() == 1 for c in libs)
        assert [c.get_num_threads() for c in libs] == want
        assert len(calls) <= 2 * len(libs)  # the outer block only: one set, one restore
        assert calls[:len(calls) // 2] == [1] * (len(calls) // 2)
    finally:
        for c, k in zip(libs, before):
            c.set_num_threads(k)


def test_blas_limit_reuses_one_controller():
    from compass_sparse.linalg import blas as _blas
    from compass_sparse import solve as S

    with S.blas_threads(50):
        pass
    first = list(_blas._CONTROLLER)
    with _blas.single_threaded_blas():
        pass
    assert len(_blas._CONTROLLER) == 1 and _blas._CONTROLLER[0] is first[0]


def test_blas_limit_is_one_thread_inside_and_restored_after():
    from threadpoolctl import threadpool_info

    from compass_sparse.linalg import blas as _blas

    def blas_threads():
        return [d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"]

    before = blas_threads()
    with _blas.single_threaded_blas():
        assert all(k == 1 for k in blas_threads())
        with _blas.single_threaded_blas():  # nested: still one, and the outer restores
            assert all(k == 1 for k in blas_threads())
        assert all(k == 1 for k in blas_threads())
    assert blas_threads() == before


def test_dense_jacobian_gets_canonical_full_pattern_each_call():
    from compass_sparse.linalg.csc import canonical_csc as _canonical_csc

    A = np.arange(9.0).reshape(3, 3)
    C1 = _canonical_csc(A, 3)
    C1.indices[:] = 0  # a caller mutating its matrix must not touch the next one
    C2 = _canonical_csc(A, 3)
    assert np.array_equal(C2.toarray(), A) and C2.has_canonical_format
    assert C2.nnz == 9



def test_dense_jacobian_on_its_full_pattern_matches_the_general_route():
    """A dense float J (the user's array) on the stored full pattern is copied straight
    into the pattern's column order: the same matrix as canonical_csc + _fix_pattern, its
    zeros kept, owning its arrays (the pattern's stay untouched); an integer array or a
    Fortran-ordered one give that route's matrix too."""
    from compass_sparse.problem.evaluator import Evaluator
    from compass_sparse.linalg.csc import canonical_csc

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


# ---------------------------------------------------------------- fixed per-solve cost
def _valid_csc_arrays(rng, n, density, sort=True):
    cols = [np.flatnonzero(rng.random(n) < density) for _ in range(n)]
    if not sort:
        cols = [rng.permutation(c) for c in cols]
    indptr = np.concatenate([[0], np.cumsum([c.size for c in cols])]).astype(np.int32)
    indices = (np.concatenate(cols) if cols else np.zeros(0)).astype(np.int32)
    return rng.standard_normal(indices.size), indices, indptr


@pytest.mark.parametrize("sort", [True, False])
def test_trusted_csc_equals_the_checked_constructor(sort):
    from compass_sparse.linalg.csc import trusted_csc

    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 30):
        data, indices, indptr = _valid_csc_arrays(rng, n, 0.4, sort=sort)
        T = trusted_csc(data, indices, indptr, (n, n))
        C = sp.csc_matrix((data, indices, indptr), shape=(n, n))
        assert type(T) is type(C) and T.shape == C.shape
        # the flags are computed from the arrays, not assumed
        assert T.has_sorted_indices == C.has_sorted_indices
        assert T.has_canonical_format == C.has_canonical_format
        x = rng.standard_normal(n)
        np.testing.assert_array_equal(T @ x, C @ x)
        np.testing.assert_array_equal(T.toarray(), C.toarray())
        np.testing.assert_array_equal((T + T).toarray(), (C + C).toarray())
        np.testing.assert_array_equal(T.tocsr().toarray(), C.toarray())


def test_trusted_csc_with_int64_indices_falls_back_to_the_checked_constructor():
    from compass_sparse.linalg.csc import trusted_csc

    T = trusted_csc(np.ones(2), np.array([0, 1]), np.array([0, 1, 2]), (2, 2))
    np.testing.assert_array_equal(T.toarray(), np.eye(2))


def test_dense_jacobian_in_fortran_order_is_copied_not_viewed():
    from compass_sparse.linalg.csc import canonical_csc

    A = np.asfortranarray(np.arange(9.0).reshape(3, 3))
    C = canonical_csc(A, 3)
    A[:] = -1.0
    np.testing.assert_array_equal(C.toarray(), np.arange(9.0).reshape(3, 3))


def test_linearizer_pattern_is_jacobian_pattern_union_diagonal():
    from compass_sparse.path.linearize import Linearizer

    rng = np.random.default_rng(5)
    for n in (1, 3, 12, 40):
        J = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        J.sort_indices()
        J.data[: J.nnz // 2] = 0.0  # stored zeros keep their place
        L = Linearizer(J)
        ones = sp.csc_matrix((np.ones(J.nnz), J.indices, J.indptr), shape=J.shape)
        P = (ones + sp.identity(n, format="csc")).tocsc()
        P.sort_indices()
        np.testing.assert_array_equal(L.M.indptr, P.indptr)
        np.testing.assert_array_equal(L.M.indices, P.indices)
        M = L(J, 0.25)
        np.testing.assert_array_equal(M.toarray(), J.toarray() + 0.25 * np.eye(n))
        assert M.nnz == P.nnz


def test_maxnorms_equal_scipy_row_and_column_max_of_scaled_matrix():
    from compass_sparse import scaling

    rng = np.random.default_rng(11)
    for n in (1, 4, 25):
        A = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        A.data *= 10.0 ** rng.uniform(-9, 9, A.nnz) * rng.choice([-1.0, 1.0], A.nnz)
        row, col = 2.0 ** rng.integers(-6, 6, n), 2.0 ** rng.integers(-6, 6, n)
        r, c = scaling._maxnorms(A, row, col)
        B = abs(sp.diags(row) @ A @ sp.diags(col))
        np.testing.assert_array_equal(r, B.max(axis=1).toarray().ravel())
        np.testing.assert_array_equal(c, B.max(axis=0).toarray().ravel())


def test_maxnorm_spread_sums_duplicate_entries_first():
    from compass_sparse.scaling import spread

    # two stored entries (1, 1) of 3 and -3 cancel: the matrix is diag(1, 0) plus a
    # 1e-4 entry in row 1, column 0 -> row norms 1 and 1e-4
    A = sp.csc_matrix((np.array([1.0, 1e-4, 3.0, -3.0]), np.array([0, 1, 1, 1]),
                       np.array([0, 2, 4])), shape=(2, 2))
    assert spread(A) == pytest.approx(1e4)


def test_flat_tail_verdict_same_for_duplicate_csr_and_canonical_csc_jacobian():
    from compass_sparse.nms.acceptance import judge

    z = np.array([1.0, 2.0])
    f = np.array([1e-9, -1e-9])
    canonical = sp.csc_matrix(np.array([[1e-12, 0.0], [0.0, 2.0]]))
    # the same matrix with the (0, 0) entry split in two stored parts, as CSR
    dup = sp.csr_matrix((np.array([3e-12, -2e-12, 2.0]), np.array([0, 0, 1]),
                         np.array([0, 2, 3])), shape=(2, 2))
    a = judge(z, f, np.zeros(2), np.full(2, np.inf), 1e-6, jac=lambda _: canonical)
    b = judge(z, f, np.zeros(2), np.full(2, np.inf), 1e-6, jac=lambda _: dup)
    assert not a.solved and a.small_residual and a.flat_row == 0
    assert (b.solved, b.small_residual, b.flat_row) == (a.solved, a.small_residual, a.flat_row)
    assert b.step == pytest.approx(a.step, rel=1e-9)


def test_options_from_equal_dicts_shared_but_true_and_one_stay_apart():
    from compass_sparse import Options
    from compass_sparse.exceptions import OptionError

    a = Options.coerce({"verbosity": 1, "time_limit": 5.0})
    assert Options.coerce({"time_limit": 5.0, "verbosity": 1}) is a
    assert Options.coerce(None) is Options.coerce({})
    with pytest.raises(OptionError):
        Options.coerce({"verbosity": True})  # equal to 1, but not an integer option value
    with pytest.raises(OptionError):
        Options.coerce({"time_limit": float("nan")})
    assert Options.coerce({"time_limit": float("inf")}).time_limit == float("inf")


def test_options_replace_shares_equal_copies_and_still_validates():
    """Restarts replace fields of the same options: the copy is built and validated once
    and shared (frozen), equal to a fresh dataclasses.replace; values that differ only in
    type (True and 1) give different copies, and invalid values still raise."""
    import dataclasses

    from compass_sparse import Options
    from compass_sparse.exceptions import OptionError

    base = Options.coerce({"time_limit": 7.0})
    a = base.replace(crash_method="none", nms_memory_size=2)
    assert base.replace(nms_memory_size=2, crash_method="none") is a
    assert a == dataclasses.replace(base, crash_method="none", nms_memory_size=2)
    assert a.time_limit == 7.0 and a.crash_method == "none" and base.crash_method != "none"
    assert Options.coerce({"time_limit": 8.0}).replace(crash_method="none") is not a
    with pytest.raises(OptionError):
        base.replace(nms_memory_size=True)   # equal to 1, but not an integer
    with pytest.raises(OptionError):
        base.replace(no_such_option=1)
    with pytest.raises(OptionError):
        base.replace(time_limit=float("nan"))


@pytest.mark.parametrize("n,density", [(1, 1.0), (5, 0.6), (40, 0.1)])
def test_csc_abs_maxima_matches_array_formulas(n, density):
    """Row and column max-norms and the diagonal of a canonical CSC in one compiled pass
    agree with numpy's (a NaN entry poisons its row and column, as np.maximum does)."""
    from compass_sparse.linalg._csc_kernels import csc_abs_maxima

    A = sp.random(n, n, density=density, format="csc", random_state=n) - 0.5 * sp.random(
        n, n, density=density, format="csc", random_state=n + 1)
    A = sp.csc_matrix(A)
    A.sum_duplicates()
    if A.nnz and n > 1:
        A.data[A.nnz // 2] = np.nan
    rows, cols, diag = np.zeros(n), np.empty(n), np.empty(n)
    csc_abs_maxima(A.indptr, A.indices, A.data, rows, cols, diag)
    dense = np.abs(A.toarray())  # absent entries are 0, below every |stored| but NaN
    with np.errstate(invalid="ignore"):
        assert np.array_equal(rows, np.max(dense, axis=1), equal_nan=True)
        assert np.array_equal(cols, np.max(dense, axis=0), equal_nan=True)
    assert np.array_equal(diag, A.diagonal(), equal_nan=True)


def test_verdict_shared_by_the_solver_and_the_result_agrees_with_a_fresh_judgement():
    """The acceptance verdict that stops the solve is reused by the Result (not taken
    twice); on every known problem it is the verdict a fresh judgement of the returned
    point gives on the user's problem."""
    import known_problems as kp

    from compass_sparse import MCP, solve_mcp
    from compass_sparse.nms.acceptance import judge

    makers = dict(kp.ALL_SOLVABLE)
    makers.update(sqrt_ncp=kp.sqrt_ncp, billups=kp.billups)
    for name, make in makers.items():
        p = make()
        res = solve_mcp(MCP(p.F, p.J, p.lb, p.ub, p.x0))
        f = np.asarray(p.F(res.x), dtype=float)
        v = judge(res.x, f, res.lb, res.ub, res.tolerance, jac=lambda y: sp.csc_matrix(p.J(y)))
        assert v.solved == res.success, name
        assert res.success, name


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


@pytest.mark.parametrize("kind", ["full", "with diagonal", "without diagonal"])
def test_linearizer_on_patterns_that_hold_the_diagonal(kind):
    """A full pattern and a pattern that stores the whole diagonal give M = J + eps I on
    J's own pattern (stored zeros kept); one without it gets the diagonal added."""
    from compass_sparse.linalg.csc import canonical_csc
    from compass_sparse.path.linearize import Linearizer

    rng = np.random.default_rng(8)
    n = 9
    if kind == "full":
        J = canonical_csc(rng.standard_normal((n, n)) * (rng.random((n, n)) < 0.5), n)
    else:
        J = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        if kind == "with diagonal":
            J = (J + sp.diags(rng.standard_normal(n))).tocsc()
            J.data[::3] = 0.0  # stored zeros, some on the diagonal
        else:
            J = J.tolil()
            J.setdiag(0.0)
            J = J.tocsc()
            J.eliminate_zeros()
            J[0, 1] = 1.0
        J.sort_indices()
    L = Linearizer(J)
    if kind == "without diagonal":
        assert L.M.nnz == J.nnz + n
    else:
        np.testing.assert_array_equal(L.M.indptr, J.indptr)
        np.testing.assert_array_equal(L.M.indices, J.indices)
    for eps in (0.0, 0.5):
        M = L(J, eps)
        np.testing.assert_array_equal(M.toarray(), J.toarray() + eps * np.eye(n))


@pytest.mark.parametrize("kind", ["full", "with diagonal", "without diagonal"])
def test_one_pass_linearization_gives_the_array_formulas_bits(kind):
    """Linearizer.linearize: M = J + eps I, q = f - M z and r = f + x - z of a major
    iteration in one compiled pass give the array formulas' bits (M's entries and pattern,
    q with M z summed column by column, r), on J's own pattern and with the diagonal
    added; a vector that is not the solver's float vector takes the array route."""
    from compass_sparse.linalg._csc_kernels import csc_matvec
    from compass_sparse.linalg.csc import canonical_csc
    from compass_sparse.path.linearize import Linearizer

    rng = np.random.default_rng(21)
    n = 11
    if kind == "full":
        J = canonical_csc(rng.standard_normal((n, n)), n)
    else:
        J = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        J = (J + sp.diags(rng.standard_normal(n))).tocsc() if kind == "with diagonal" \
            else J
        J = J.tolil()
        if kind == "without diagonal":
            J.setdiag(0.0)
        J = canonical_csc(J.tocsc(), n)
        J.eliminate_zeros()
    L = Linearizer(J)
    z, f, x = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n) for _ in range(3))
    for eps in (0.0, 1e-3):
        M, q, r = L.linearize(J, eps, z, f, x)
        ref = L(J, eps)
        Mz = np.empty(n)
        csc_matvec(ref.indptr, ref.indices, ref.data, z, Mz)
        for a in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(M, a), getattr(ref, a)), a
        assert np.array_equal(q, f - Mz) and np.array_equal(r, f + x - z)
        M2, q2, r2 = L.linearize(J, eps, list(z), f, x)  # not a float vector: arrays
        assert np.array_equal(M2.data, ref.data) and np.array_equal(q2, q)
        assert np.array_equal(r2, r)


@pytest.mark.parametrize("seed", range(6))
def test_compiled_scale_test_gives_the_array_formula_verdict(seed):
    """The compiled flat-step test returns the verdict, the row and the step of the array
    formulas, on random sparse Jacobians with rows of every scale (flat rows included)
    and points at and between bounds."""
    from compass_sparse.nms.acceptance import _scale_test, _scale_test_arrays

    rng = np.random.default_rng(seed)
    n = 30
    lb, ub = _random_box(rng, n)
    z = np.clip(rng.standard_normal(n) * 10.0, lb, ub)
    at = rng.random(n) < 0.3
    z[at] = np.where(np.isfinite(lb), lb, z)[at]
    f = rng.standard_normal(n) * 10.0 ** rng.uniform(-12, -6, n)
    f[rng.random(n) < 0.2] = 0.0
    J = sp.random(n, n, density=0.2, random_state=seed, format="csc")
    J.data *= 10.0 ** rng.uniform(-9, 3, J.nnz)
    J = (J + sp.diags(rng.standard_normal(n) * (rng.random(n) < 0.7))).tocsc()
    # rows scaled down to 1e-14: F flat there, a Newton step would still move far
    J = (sp.diags(10.0 ** rng.uniform(-14 if seed % 2 else -2, 0, n)) @ J).tocsc()
    J.sort_indices()
    phi = merit.fb_phi(z, f, lb, ub)
    got = _scale_test(z, f, lb, ub, phi, J)
    ref = _scale_test_arrays(z, f, lb, ub, phi, J)
    assert (got.solved, got.flat_row) == (ref.solved, ref.flat_row)
    assert got.step == ref.step or np.isclose(got.step, ref.step, rtol=1e-15)
    assert got.solved == (seed % 2 == 0)  # both verdicts occur


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


def test_spread_of_positive_entries():
    from compass_sparse import scaling

    assert scaling._spread(np.array([0.0, 4.0, np.nan, 0.5, -3.0])) == 8.0
    assert scaling._spread(np.array([0.0, -1.0])) == 1.0


@pytest.mark.parametrize("n,density", [(1, 1.0), (7, 0.5), (60, 0.1)])
def test_csc_matvec_is_scipy_product_bitwise(n, density):
    """The linearization's M z in compiled code, bit for bit scipy's CSC product (same
    order of the sums), entries over 40 orders of magnitude."""
    from compass_sparse.linalg._csc_kernels import csc_matvec

    rng = np.random.default_rng(n)
    A = sp.random(n, n, density=density, format="csc", random_state=n)
    A.data *= 10.0 ** rng.uniform(-20, 20, A.nnz)
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-20, 20, n)
    out = np.full(n, np.nan)
    csc_matvec(A.indptr, A.indices, A.data, x, out)
    assert np.array_equal(out, A @ x)


def test_dense_engine_refills_its_matrix_in_place_from_each_linearization():
    """The engine's dense copy of M is allocated once per order and refilled by every
    set_matrix: CSC (duplicates summed, unsorted indices), other sparse formats and dense
    input give M exactly; a new order gets a new array."""
    from compass_sparse.path.dense_engine import DensePathEngine

    rng = np.random.default_rng(4)
    A = sp.random(6, 6, density=0.5, format="csc", random_state=4)
    eng = DensePathEngine(A)
    buf = eng.M
    np.testing.assert_array_equal(eng.M, A.toarray())
    dup = sp.csc_matrix((np.array([1.0, 2.0, 3.0]), np.array([4, 1, 4]),
                         np.array([0, 3, 3, 3, 3, 3, 3])), shape=(6, 6))
    eng.set_matrix(dup)
    assert eng.M is buf and eng.M.flags.f_contiguous
    np.testing.assert_array_equal(eng.M, dup.toarray())
    D = rng.standard_normal((6, 6))
    for M in (sp.csr_matrix(D), D):
        eng.set_matrix(M)
        assert eng.M is buf
        np.testing.assert_array_equal(eng.M, D)
    eng.set_matrix(sp.identity(3, format="csc"))
    assert eng.M.shape == (3, 3) and eng.n == 3
    np.testing.assert_array_equal(eng.M, np.eye(3))


def test_scaled_solve_judges_its_result_on_the_user_problem_again():
    """When the scaling pass changed the problem the solver works on, its verdict (taken
    on the scaled problem) is not handed to the Result: the Result's verdict is a fresh
    judgement of the returned point on the user's problem, and agrees with one."""
    from compass_sparse import MCP, solve_mcp
    from compass_sparse.nms.acceptance import judge

    d = np.array([1e-5, 1.0, 1e5])
    q = np.array([-1e-5, 2.0, -3e5])
    F = lambda x: d * x + q  # noqa: E731
    J = lambda x: sp.diags(d, format="csc")  # noqa: E731
    res = solve_mcp(MCP(F, J, np.zeros(3), np.full(3, np.inf), np.ones(3)))
    assert res.passes["scaling"].ran
    assert res.success
    v = judge(res.x, F(res.x), res.lb, res.ub, res.tolerance, jac=J)
    assert v.solved
    np.testing.assert_allclose(res.x, [1.0, 0.0, 3.0], atol=1e-6)


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


def test_csc_same_pattern_compares_pointers_and_the_stored_indices():
    """The pattern test of the evaluator, the preprocessor and the KLU cache: equal when
    the pointers and the first nnz row indices agree (room beyond nnz is ignored), and
    against numpy's comparison of the arrays on random patterns, equal and not."""
    from compass_sparse.linalg._csc_kernels import csc_same_pattern

    rng = np.random.default_rng(9)
    seen = set()
    for trial in range(200):
        n = int(rng.integers(1, 12))
        A = sp.csc_matrix(sp.random(n, n, density=0.4, random_state=rng))
        B = A.copy()
        if trial % 3 == 1 and B.nnz:
            B.indices[int(rng.integers(B.nnz))] = (B.indices[0] + 1) % n  # a row moved
        elif trial % 3 == 2:
            B = sp.csc_matrix(sp.random(n, n, density=0.4, random_state=rng))
        ref = (np.array_equal(A.indptr, B.indptr)
               and np.array_equal(A.indices[:A.nnz], B.indices[:B.nnz]))
        assert csc_same_pattern(B.indptr, B.indices, A.indptr, A.indices[:A.nnz]) == ref
        seen.add(ref)
    assert seen == {True, False}
    P = sp.csc_matrix(np.eye(3))
    longer = np.concatenate([P.indices, np.array([7, 7], np.int32)])
    assert csc_same_pattern(P.indptr, longer, P.indptr, P.indices)
    assert not csc_same_pattern(P.indptr[:-1], P.indices, P.indptr, P.indices)


@pytest.mark.parametrize("n, blocks", [(4, 0), (20, 1)])
def test_crash_limits_blas_threads_only_from_the_size_where_blas_could_use_threads(
        monkeypatch, n, blocks):
    """Below BLAS_LIMIT_MIN_N the crash leaves the BLAS thread count alone (OpenBLAS keeps
    kernels that small on one thread itself); from there on one block spans the crash."""
    import numpy as np

    from compass_sparse import solve_mcp
    from compass_sparse.crash import driver as C

    opened = []
    real = C.single_threaded_blas
    monkeypatch.setattr(C, "single_threaded_blas", lambda: opened.append(1) or real())
    rng = np.random.default_rng(3)
    A = rng.normal(size=(n, n)) * 0.1 + 3 * np.eye(n)
    b = rng.normal(size=n)
    r = solve_mcp(lambda x: A @ x + b, lambda x: A, np.zeros(n), np.full(n, np.inf),
                  np.ones(n), options={"crash_minimum_dimension": 1})
    assert r.success and r.passes["crash"].ran
    assert len(opened) == blocks


def test_project_gives_np_clip_bits_signed_zeros_and_infinite_bounds_included():
    """The start point's projection (box.project: np.minimum of np.maximum, which MCP
    uses instead of np.clip) gives np.clip's values bit for bit on validated bounds,
    signed zeros and infinite bounds included (20000 random boxes)."""
    from compass_sparse.box import project

    rng = np.random.default_rng(17)
    vals = np.array([0.0, -0.0, 1.0, -1.0, 2.5, -3e300, 5e-324, np.inf, -np.inf])
    for _ in range(20000):
        n = int(rng.integers(1, 7))
        x = rng.choice(vals[:7], n)
        a, b = rng.choice(vals, n), rng.choice(vals, n)
        lb, ub = np.minimum(a, b), np.maximum(a, b)
        assert project(x, lb, ub).tobytes() == np.clip(x, lb, ub).tobytes()


def test_evaluators_jacobians_are_marked_canonical_only_when_they_are():
    """A J the evaluator returns (dense, on the stored pattern, a canonical CSC copy)
    carries the canonical mark, which lets without_duplicates return it unscanned; every
    marked matrix passes the scan; an unmarked matrix with duplicates is still summed."""
    from compass_sparse.linalg.csc import _CANONICAL, trusted_csc, without_duplicates
    from compass_sparse.linalg._csc_kernels import csc_is_canonical
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


def test_a_solve_the_crash_ends_builds_no_newton_linearizer(monkeypatch):
    """The Newton linearizer (the index arrays of J + eps I) is made at the first major
    iteration: a solve that the crash ends builds none (cournot2), one with major
    iterations builds it, with the same point as before this change (kojshin)."""
    from compass_sparse.path.linearize import Linearizer

    built = []
    real = Linearizer.__init__
    monkeypatch.setattr(Linearizer, "__init__",
                        lambda self, J: built.append(1) or real(self, J))
    k = kp.cournot_duopoly()
    r = solve_mcp(k.F, k.J, k.lb, k.ub, k.x0)
    assert r.success and r.nit == 0 and r.crash_iterations > 0 and built == []
    k = kp.kojima_shindo()
    r = solve_mcp(k.F, k.J, k.lb, k.ub, k.x0, options={"crash_method": "none"})
    assert r.success and r.nit > 0 and len(built) == 1
    assert min(np.max(np.abs(r.x - s)) for s in k.solutions) < 1e-6
