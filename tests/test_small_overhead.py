"""Fixed per-solve overhead of small problems: compiled merit kernels agree with the array
formulas, numba is not imported by ``import compass_sparse``, lazily built kernels call
each other, the BLAS thread limit reuses one controller, dense Jacobians keep a canonical
full pattern."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import merit
from compass_sparse._merit_kernels import csc_rmatvec


def _random_box(rng, n):
    lb = np.where(rng.random(n) < 0.5, -np.inf, rng.standard_normal(n))
    ub = np.where(rng.random(n) < 0.5, np.inf, np.nan_to_num(lb, neginf=0.0)
                  + np.abs(rng.standard_normal(n)))
    return lb, ub


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fb_phi_kernel_matches_array_formula_bitwise_across_magnitudes(seed):
    """Stress over 600 orders of magnitude, every bound kind, infinite and NaN entries."""
    rng = np.random.default_rng(seed)
    n = 5000
    z = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
    f = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
    lb, ub = _random_box(rng, n)
    z = np.clip(z, lb, ub)
    f[:10] = [np.inf, -np.inf, np.nan, 0.0, -0.0, 1e308, -1e308, 5e-324, -5e-324, 0.0]
    a = merit.fb_phi(z, f, lb, ub)
    with np.errstate(all="ignore"):  # inf - inf and NaN arguments on purpose
        b = merit.fb_phi_arrays(z, f, lb, ub)
    assert np.array_equal(a, b, equal_nan=True)


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


def test_blas_limit_reuses_one_controller():
    from compass_sparse import _blas
    from compass_sparse import solve as S

    with S._blas_threads(10):
        pass
    first = list(_blas._CONTROLLER)
    with _blas.single_threaded_blas():
        pass
    assert len(_blas._CONTROLLER) == 1 and _blas._CONTROLLER[0] is first[0]


def test_dense_jacobian_gets_canonical_full_pattern_each_call():
    from compass_sparse.evaluation import canonical_csc as _canonical_csc

    A = np.arange(9.0).reshape(3, 3)
    C1 = _canonical_csc(A, 3)
    C1.indices[:] = 0  # a caller mutating its matrix must not touch the next one
    C2 = _canonical_csc(A, 3)
    assert np.array_equal(C2.toarray(), A) and C2.has_canonical_format
    assert C2.nnz == 9
