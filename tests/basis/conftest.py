"""The basis manager's tests run under each LU backend and ordering: the automatic choice
and the forced ones (through ``COMPASS_SPARSE_LU``, which replaces "auto" options only).
The automatic choice uses COLAMD on the small blocks of these tests, so the symmetric
orderings and UMFPACK would otherwise go untested here.  A module asks for them with
``pytestmark = pytest.mark.usefixtures("lu_choice")``; the end-to-end tests of the LU
options and of factor reuse choose their backends themselves.

The dense reference solves of these tests run on one BLAS thread: on a loaded 2-core
machine a threaded 150 x 150 solve took 0.3 s (measured), and the tests make thousands."""

import pytest
from threadpoolctl import threadpool_limits

LU_CHOICES = ["auto", "superlu:colamd", "superlu:amd", "superlu:metis", "umfpack"]


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread():
    with threadpool_limits(limits=1, user_api="blas"):
        yield


@pytest.fixture(params=LU_CHOICES)
def lu_choice(request, monkeypatch):
    if request.param == "auto":
        monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    else:
        monkeypatch.setenv("COMPASS_SPARSE_LU", request.param)
    return request.param
