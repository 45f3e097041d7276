"""Sparse direct solvers of one-off systems: the direct Newton step's blocks M_FF and the
crash's reduced Jacobians J_II of moderate order.

KLU (SuiteSparse, through kvxopt: block triangular form, AMD, a diagonal preference, no
supernodes) factors a block while it fills little, its symbolic analysis kept per
pattern; SuperLU with COLAMD factors the blocks that fill (see :class:`DirectFactors`).
Whether the solver may choose these at all is :func:`automatic_lu`: the options
``lu_backend`` and ``lu_ordering`` and the environment variable ``COMPASS_SPARSE_LU`` leave
the choice to it.  The basis manager's factors, which it updates and reuses, come from
:mod:`compass_sparse.basis.backends` instead.
"""
from __future__ import annotations

import ctypes
import inspect
import os
import threading

import numpy as np
from scipy.sparse import csc_array

from ._csc_kernels import csc_is_canonical, csc_same_pattern

__all__ = ["KLU_FILL_LIMIT", "LU_ENVIRONMENT", "DirectFactors", "automatic_lu",
           "klu_available", "superlu_colamd"]

LU_ENVIRONMENT = "COMPASS_SPARSE_LU"
"""The environment variable that overrides the automatic LU choices for every solve of the
process, "backend" or "backend:ordering" (e.g. "superlu:metis", "umfpack";
:func:`compass_sparse.basis.backends.resolve`): lets the whole test suite run under every
combination."""


def automatic_lu(backend="auto", ordering="auto") -> bool:
    """Whether the sparse LU is left to the solver: the options ``lu_backend`` and
    ``lu_ordering`` are "auto" and the environment does not choose them either
    (``COMPASS_SPARSE_LU``).  Only then do the direct step and the crash pick KLU."""
    if backend != "auto" or ordering != "auto":
        return False
    return not os.environ.get(LU_ENVIRONMENT)


class DirectFactors:
    """The sparse LUs of one solve's direct steps.

    KLU (SuiteSparse, through kvxopt: block triangular form, AMD, a diagonal preference,
    no supernodes) factors the blocks while they fill little: on such blocks it is 3-5x
    faster than SuperLU, whose set-up dominates there (0.13 against 0.40 ms at n = 362,
    0.33 against 0.83 ms at n = 992 on the Ramsey model's M_FF), and its symbolic analysis
    of a block pattern is kept across solves (:data:`_KLU_CACHE`).  On blocks that fill,
    SuperLU with COLAMD is the faster (2x on the static CGE model's, 1.3e5 entries from
    8e3), so a KLU factorization holding more than ``KLU_FILL_LIMIT`` times its block's
    entries returns the rest of the solve to SuperLU: a block that fills costs one slow
    factorization at most.  (SuperLU used to factor the first block, to learn its fill
    before KLU was tried: KLU first takes 6% off a Ramsey solve at n = 363 and 13% at
    n = 993, measured in one process, with the same major iterations.)
    Without kvxopt, or with ``klu=False``, SuperLU factors every block.  ``lu_nnz`` is
    the size of the last LU (L + U, and KLU's off-diagonal blocks); ``method`` its
    (backend, ordering).  ``dense``: the blocks of a small problem (order below the direct
    step's ``DIRECT_MIN_N``) are solved densely by the step itself
    (:mod:`compass_sparse.path.direct_step`), and only counted here."""

    def __init__(self, klu: bool = True, dense: bool = False, rank_tolerance: float = 1e-9):
        #: small problems (order below ``DIRECT_MIN_N``): M_FF is solved densely in one
        #: compiled pass with the end point (:mod:`compass_sparse.path.direct_step`), no
        #: sparse LU; a block singular to the compiled engine's ``rank_tolerance`` is left
        #: to the path
        self.dense = dense
        self.rank_tolerance = float(rank_tolerance)
        self.klu = klu and not dense and klu_available()
        self.lu_nnz = 0
        self.method = ("", "")
        self._held = None  # (indptr, indices, kvxopt matrix, KLU symbolic) of the last block

    def dense_done(self, nf: int) -> int:
        """Record a dense direct step on a block of order ``nf``; returns its LU's entries."""
        self.method = ("dense", "partial pivoting")
        self.lu_nnz = nf * nf
        return self.lu_nnz

    def solve(self, K, rhs):
        """x with K x = rhs, or None when K is singular (as the factorization finds)."""
        if self.klu:
            return self._klu_solve(K, rhs)
        self.method = ("superlu", "colamd")
        try:
            lu = superlu_colamd(K)
        except RuntimeError:  # exactly singular
            self.lu_nnz = 0
            return None
        self.lu_nnz = int(lu.nnz)
        return lu.solve(rhs)

    def _klu_solve(self, K, rhs):
        klu = _klu_module()
        # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
        from kvxopt import matrix

        self.method = ("klu", "btf+amd")
        h = self._held
        # (kvxopt keeps each column's entries sorted by row: new values can be copied in
        # only when K's are in that order too)
        if (h is not None and csc_same_pattern(K.indptr, K.indices, h[0], h[1])
                and csc_is_canonical(K.indptr, K.indices, K.shape[0], K.indptr[-1])):
            # the block of the last step (the active set did not move): KLU's symbolic
            # analysis (BTF, AMD) depends on the pattern only, so it is kept; only the
            # values change (~40% of a factorization at n = 362 saved)
            A, Fs, info = h[2], h[3], h[4]
            A.V = matrix(K.data[:K.indptr[-1]])
        else:
            A, Fs, info = _klu_analysis(K)
            if Fs is not None:
                self._held = (K.indptr.copy(), K.indices[:K.indptr[-1]].copy(), A, Fs, info)
                A.V = matrix(K.data[:K.indptr[-1]])
        try:
            if Fs is None:  # a block that is not canonical: analysed for itself
                Fs = klu.symbolic(A)
            Fn = klu.numeric(A, Fs)
        except ArithmeticError:  # singular
            self.lu_nnz = 0
            return None
        self.lu_nnz = _klu_lu_nnz(A, Fs, Fn, info)
        if self.lu_nnz > KLU_FILL_LIMIT * max(K.nnz, 1):
            self.klu = False  # SuperLU for the rest of the solve
        b = matrix(np.ascontiguousarray(rhs, dtype=np.float64))
        klu.solve(A, Fs, Fn, b)
        return np.array(b, dtype=np.float64).ravel()


def superlu_colamd(K):
    """``splu(K, permc_spec="COLAMD")``.  For the direct step's blocks (float64 data,
    int32 canonical index arrays: nothing for splu to sum, cast or sort) the factorization
    routine is called with splu's own arguments directly, without its wrapper's checks and
    conversions (~15 us of a 0.15 ms factorization at n = 100): the same call, so the same
    factors.  Anything else, or a scipy without that routine, goes through splu."""
    # (lazy: scipy's linalg adds ~0.15 s to the package's import)
    from scipy.sparse.linalg import splu

    gstrf = _superlu_gstrf()
    n = K.shape[0]
    if (gstrf is None or K.shape[1] != n or K.data.dtype != np.float64
            or K.indices.dtype != np.int32 or K.indptr.dtype != np.int32
            or not csc_is_canonical(K.indptr, K.indices, n, K.indptr[-1])):
        return splu(K, permc_spec="COLAMD")
    nnz = int(K.indptr[-1])
    return gstrf(n, nnz, K.data[:nnz], K.indices[:nnz], K.indptr,
                 csc_construct_func=_superlu_gstrf.csc_array, ilu=False,
                 options=dict(DiagPivotThresh=None, ColPerm="COLAMD", PanelSize=None,
                              Relax=None))


def _superlu_gstrf():
    """scipy's SuperLU factorization routine when its splu passes exactly the arguments
    :func:`superlu_colamd` passes (checked once from splu's signature and source), else
    None."""
    if not hasattr(_superlu_gstrf, "fn"):
        _superlu_gstrf.fn = None
        try:
            # (lazy: scipy's linalg adds ~0.15 s to the package's import)
            from scipy.sparse.linalg._dsolve import _superlu, linsolve

            sig = inspect.signature(linsolve.splu)
            src = inspect.getsource(linsolve.splu)
            defaults = {k: sig.parameters[k].default for k in
                        ("permc_spec", "diag_pivot_thresh", "relax", "panel_size", "options")}
            if (defaults == dict(permc_spec=None, diag_pivot_thresh=None, relax=None,
                                 panel_size=None, options=None)
                    and "_options = dict(DiagPivotThresh=diag_pivot_thresh, "
                        "ColPerm=permc_spec,\n                    PanelSize=panel_size, "
                        "Relax=relax)" in src
                    and "return _superlu.gstrf(N, A.nnz, A.data, indices, indptr,\n"
                        "                          csc_construct_func=csc_construct_func,\n"
                        "                          ilu=False, options=_options)" in src):
                _superlu_gstrf.fn = _superlu.gstrf
                _superlu_gstrf.csc_array = csc_array
        except Exception:  # pragma: no cover - another scipy: splu itself
            _superlu_gstrf.fn = None
    return _superlu_gstrf.fn


_KLU_CACHE: list = []
"""KLU analyses of recent block patterns, newest last: (indptr, indices, kvxopt matrix
holding the pattern, symbolic factorization).  A loop of solves of one model meets the
same M_FF patterns in every solve; the analysis (BTF, AMD, ~0.25 ms at n = 992) and the
kvxopt matrix (~0.1 ms) depend on the pattern alone and are made once.  Entries are
found by exact comparison of the index arrays, never by a hash; the cached matrix is a
template that is never handed out (each solve gets its own copy to write values into) and
the symbolic object is only read by KLU's factorization and solve."""


_KLU_LOCK = threading.Lock()


KLU_CACHE_SIZE = 8
"""Patterns kept in :data:`_KLU_CACHE`."""


KLU_CACHE_MAX_NNZ = 200_000
"""Largest block (stored entries) whose analysis is kept: the cache lives as long as the
process, and eight analyses of blocks this size hold ~30 MB; larger blocks are analysed
for their own solve only (their factorization dwarfs the analysis anyway)."""


def _klu_analysis(K):
    """(kvxopt matrix with K's pattern, KLU symbolic analysis of it, [entries of the
    off-diagonal blocks, once known]) from the cache or made and cached; (matrix, None,
    [None]) for a K that is not canonical (kvxopt sorts the entries it is given: the
    values of such a K could not be copied in later), whose analysis the caller makes
    and does not keep."""
    # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
    from kvxopt import matrix, spmatrix

    with _KLU_LOCK:  # (solves in several threads share the cache)
        for i in range(len(_KLU_CACHE) - 1, -1, -1):
            e = _KLU_CACHE[i]
            if csc_same_pattern(K.indptr, K.indices, e[0], e[1]):
                if i != len(_KLU_CACHE) - 1:
                    _KLU_CACHE.append(_KLU_CACHE.pop(i))
                return +e[2], e[3], e[4]  # unary plus: a copy of the template
    n = K.shape[0]
    nnz = int(K.indptr[-1])
    cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(K.indptr))
    A = spmatrix(matrix(K.data[:nnz]), matrix(K.indices[:nnz].astype(np.int64)), matrix(cols),
                 (n, n))
    if not csc_is_canonical(K.indptr, K.indices, n, nnz):
        return A, None, [None]
    Fs = _klu_module().symbolic(A)
    info = [None]
    if nnz > KLU_CACHE_MAX_NNZ:
        return A, Fs, info
    with _KLU_LOCK:
        _KLU_CACHE.append((K.indptr.copy(), K.indices[:nnz].copy(), +A, Fs, info))
        if len(_KLU_CACHE) > KLU_CACHE_SIZE:
            _KLU_CACHE.pop(0)
    return A, Fs, info


def _klu_lu_nnz(A, Fs, Fn, info):
    """nnz(L) + nnz(U) + nnz(off-diagonal blocks) of a KLU factorization.  kvxopt gives
    them only as copies of the factors (get_numeric: ~40 us at n = 992, twice per solve);
    the first two are the leading counts of KLU's numeric object (n, nblocks, lnz, unz:
    its layout since KLU 1.0), read there, the third is fixed by the symbolic analysis
    (the pattern's block triangular form) and kept in ``info`` from the first
    factorization of the pattern.  Every get_numeric made checks the counts read against
    the factors' own; a mismatch (another layout) turns the reading off for good."""
    counts = _klu_counts(Fn) if info[0] is not None else None
    if counts is not None:
        return counts[0] + counts[1] + info[0]
    parts = _klu_module().get_numeric(A, Fs, Fn)  # L, U, P, Q, R, F, r (copies)
    nnz_l, nnz_u, nnz_off = len(parts[0]), len(parts[1]), len(parts[5])
    read = _klu_counts(Fn)
    if read is not None and read != (nnz_l, nnz_u):
        _KLU_COUNTS[:] = [None]  # not the layout assumed
    elif read is not None:
        info[0] = nnz_off
    return nnz_l + nnz_u + nnz_off


_KLU_COUNTS: list = []
"""[PyCapsule_GetPointer] once the counts of KLU's numeric object may be read, [None]
when they may not (empty until first asked)."""


def _klu_counts(Fn):
    """(lnz, unz) of a kvxopt KLU numeric factorization (int64 fields 2 and 3 of the
    struct its capsule holds), or None when they cannot be read."""
    if not _KLU_COUNTS:
        try:
            get = ctypes.pythonapi.PyCapsule_GetPointer
            get.restype = ctypes.c_void_p
            get.argtypes = [ctypes.py_object, ctypes.c_char_p]
            _KLU_COUNTS[:] = [(get, ctypes.c_int64 * 4)]
        except Exception:  # pragma: no cover - no ctypes: the factors' copies
            _KLU_COUNTS[:] = [None]
    st = _KLU_COUNTS[0]
    if st is None:
        return None
    try:
        ptr = st[0](Fn, b"KLU NUM D FACTOR")
    except Exception:  # another capsule (name): not the object assumed
        return None
    if not ptr:
        return None
    head = st[1].from_address(ptr)
    return int(head[2]), int(head[3])


KLU_FILL_LIMIT = 8.0
"""Largest nnz(LU) / nnz(block) of a KLU factorization before the direct step returns
to SuperLU for the rest of the solve."""


def klu_available() -> bool:
    """Whether KLU (kvxopt) can be used."""
    return _klu_module() is not None


_KLU_MODULE: list = []
"""[kvxopt's klu module, or None without kvxopt] once looked up (an import statement
costs a few microseconds at every factorization)."""


def _klu_module():
    if not _KLU_MODULE:
        try:
            # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
            from kvxopt import klu
        except ImportError:  # pragma: no cover - kvxopt is a dependency
            klu = None
        _KLU_MODULE.append(klu)
    return _KLU_MODULE[0]
