"""The BLAS thread limit (compass_sparse.linalg.blas): one controller, nested blocks set
the threads once and restore them after."""

from __future__ import annotations

import pytest


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
    from compass_sparse import solve as S
    from compass_sparse.linalg import blas as _blas

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
