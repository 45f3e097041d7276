"""The crash's shifted reduced matrices: J_II + eps I written on one pattern made once
(compass_sparse.crash.reduced._ShiftedMatrix) equals scipy's sum bit for bit, for
diagonals present, absent and zero, and for unsorted input."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.crash.reduced import _ShiftedMatrix


@pytest.mark.parametrize("sort", [True, False], ids=["sorted", "unsorted"])
def test_shifted_matrix_equals_the_sum_with_eps_identity(sort):
    rng = np.random.default_rng(0)
    n = 60
    J = sp.random(n, n, density=0.08, random_state=1, format="csc")
    diag = np.where(rng.random(n) < 0.4, 0.0, rng.standard_normal(n))  # some absent
    diag[3] = -1e-3  # a diagonal that the shift 1e-3 cancels: kept as an explicit zero
    J = sp.csc_matrix(sp.lil_matrix(J))
    J = sp.csc_matrix(J - sp.diags(J.diagonal()) + sp.diags(diag))
    J.eliminate_zeros()
    if not sort:  # reverse each column's entries
        for j in range(n):
            a, b = J.indptr[j], J.indptr[j + 1]
            J.indices[a:b] = J.indices[a:b][::-1].copy()
            J.data[a:b] = J.data[a:b][::-1].copy()
        J.has_sorted_indices = False
    shifted = _ShiftedMatrix(J)
    for eps in (1e-12, 1e-3, 0.5, 1e3):
        A = shifted.at(eps)
        ref = sp.csc_matrix(J + eps * sp.identity(n, format="csc"))
        assert np.array_equal(A.toarray(), ref.toarray())
        assert np.array_equal(A.diagonal(), J.diagonal() + eps)
