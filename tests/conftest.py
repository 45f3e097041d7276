"""Test-session settings.

The dense reference computations of the tests are small; a multithreaded BLAS on a
machine whose cores are busy spends its time spinning threads (measured here: an LU of
order 150 took 0.47 s with two BLAS threads and 0.4 ms with one; a 200-step random basis
sequence at n = 150 took 280 s), so the tests run BLAS single-threaded.  threadpoolctl
only reaches libraries already loaded, hence the imports first (numpy and scipy each
bring their own OpenBLAS).
"""
import os
import sys
import time
from pathlib import Path

# The shared test problems (known_problems.py) import by name from every folder of tests/.
sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
# The kernels compile from their first call (no interpreted cold start: compass_sparse._jit),
# so that the tests of the compiled kernels test compiled code; the cold start's own tests
# run it in subprocesses without this variable (test_jit.py, routes/test_kernel_routes.py).
os.environ.setdefault("COMPASS_SPARSE_JIT", "always")

import numpy  # noqa: E402,F401
import pytest  # noqa: E402
import scipy.linalg  # noqa: E402,F401
import scipy.sparse.linalg  # noqa: E402,F401
from threadpoolctl import threadpool_limits  # noqa: E402

_blas_limit = threadpool_limits(limits=1, user_api="blas")

# The one-time notice that kernels are being compiled goes to stderr; the first test to
# compile on a cold cache would see it in what it captured (tests/test_jit.py tests the
# notice in fresh processes).
from compass_sparse import _jit  # noqa: E402

_jit.quiet_compile_notice()


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "gams: needs a GAMS system that runs (installed, licence accepted); skipped "
        "with the reason GAMS' probe gives otherwise (compass_sparse.interfaces.gams_state)")


def pytest_collection_modifyitems(config, items):
    """Skip the tests marked ``gams`` with the probe's reason where GAMS cannot run (GAMSPy
    not installed, or GAMS refusing its licence: e.g. its time-limited demo licence expired).
    The probe runs once, and only when such a test was collected."""
    marked = [item for item in items if item.get_closest_marker("gams") is not None]
    if not marked:
        return
    import pytest

    from compass_sparse.interfaces.gams_state import gams_state

    state = gams_state()
    if state.runs:
        return
    skip = pytest.mark.skip(reason=f"GAMS cannot run: {state.reason}")
    for item in marked:
        item.add_marker(skip)


class SimulatedClock:
    """A simulated ``time.perf_counter`` for time-limit tests: the test's costly functions
    advance ``now``; nothing reads the wall clock."""

    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


@pytest.fixture
def clock(monkeypatch):
    """``time.perf_counter`` replaced by a :class:`SimulatedClock` for the test."""
    c = SimulatedClock()
    monkeypatch.setattr(time, "perf_counter", c)
    return c
