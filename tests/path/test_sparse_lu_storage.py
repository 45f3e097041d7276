"""The sparse engine's factor storage: the size the memory budget is checked against is
the size allocated."""

import pytest

from compass_sparse.path import _sparse_lu as SL


@pytest.mark.parametrize("n, update_limit, nnz_guess", [
    (1, 1, 0), (10, 50, 100), (912, 50, 9000), (2452, 100, 30000), (5000, 7, 10**6)])
def test_storage_bytes_is_what_allocate_takes(n, update_limit, nnz_guess):
    S = SL.allocate(n, update_limit, nnz_guess)
    assert SL.storage_bytes(n, update_limit, nnz_guess) == sum(a.nbytes for a in S)


def test_grown_size_doubles_the_storage_of_l():
    S = SL.allocate(100, 20, 5000)
    n, lim, cap = SL.grown_size(S)
    assert (n, lim, cap) == (100, 20, 2 * S[2].shape[0])
    assert SL.storage_bytes(n, lim, cap) > sum(a.nbytes for a in S)
