"""The sparse engine's factor storage: the size the memory budget is checked against is
the size allocated; and a path's memory."""

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


def test_a_path_keeps_no_copies_of_its_points():
    """Every path recorded its point at each new largest t, up to 200 copies of n numbers
    in a buffer made afresh per path, which nothing read: the peak memory of a solve of
    a banded LCP at n = 6000 by one path of 2115 pivots on the sparse engine was 51 MB;
    without them 33 MB (traced by tracemalloc)."""
    import tracemalloc

    from compass_sparse import solve_mcp
    from compass_sparse.generators import p_matrix_lcp

    problem = p_matrix_lcp(6000, "banded", 3, "mixed").problem
    opts = {"crash_method": "none"}
    solve_mcp(problem, options=opts)  # (compiled kernels and caches outside the trace)
    tracemalloc.start()
    try:
        res = solve_mcp(problem.with_start(problem.x0), options=opts)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert res.success and res.routes["path"] == "sparse engine"
    assert res.minor_iterations > 200  # (enough new largest t to have filled the buffer)
    assert peak <= 40e6, peak
