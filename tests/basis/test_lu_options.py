"""Options lu_backend and lu_ordering reach every sparse LU of a solve: the basis manager's
and the crash's (and win over the environment's choice, which replaces only 'auto')."""

import numpy as np
import pytest

from compass_sparse import OptionError, Options, Status, solve_mcp
from compass_sparse.basis import backends, manager

COMBINATIONS = [("superlu", "colamd"), ("superlu", "amd"), ("superlu", "metis"),
                ("umfpack", "auto")]


@pytest.fixture(scope="module")
def cge():
    from compass_sparse.generators.cge import static_cge

    return static_cge(regions=6, sectors=30, factors=2, households=2,
                      seed=1).with_shock(tariff=(0, 0.25))


def _spy(monkeypatch):
    """Record the (backend, ordering) each sparse LU of the solve was made with."""
    calls = []
    real = backends.make_backend

    def spy(name="auto", ordering="auto", *args, **kwargs):
        calls.append((name, ordering))
        return real(name, ordering, *args, **kwargs)

    monkeypatch.setattr(backends, "make_backend", spy)
    monkeypatch.setattr(manager, "make_backend", spy)
    return calls


@pytest.mark.parametrize("backend,ordering", COMBINATIONS)
def test_lu_options_reach_the_crash_and_the_basis_and_the_solve_is_right(
        monkeypatch, cge, backend, ordering):
    if backend == "umfpack" and not backends.umfpack_available():
        pytest.skip("kvxopt (UMFPACK) is not installed")
    if ordering == "metis" and not backends.metis_available():
        pytest.skip("pymetis is not installed")
    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)
    calls = _spy(monkeypatch)
    p = cge.problem
    assert p.n > 500          # the sparse basis manager, not the dense engine
    res = solve_mcp(p, options={"lu_backend": backend, "lu_ordering": ordering,
                                "factor_reuse": False})
    assert res.status is Status.SOLVED
    z = res.x
    assert np.abs(z - np.clip(z - cge.F(z), p.lb, p.ub)).max() <= 1e-6
    assert calls and set(calls) == {(backend, ordering)}
    assert res.lu["backend"] == backend
    if backend == "superlu":
        assert res.lu["ordering"] == ordering


def test_lu_options_win_over_the_environment(monkeypatch, cge):
    monkeypatch.setenv("COMPASS_SPARSE_LU", "superlu:amd")
    calls = _spy(monkeypatch)
    res = solve_mcp(cge.problem, options={"lu_ordering": "colamd", "factor_reuse": False})
    assert res.status is Status.SOLVED
    assert res.lu["ordering"] == "colamd"
    assert all(o == "colamd" for _, o in calls)


def test_umfpack_with_a_forced_ordering_is_an_option_error_naming_both():
    with pytest.raises(OptionError, match="lu_ordering='metis'.*lu_backend='superlu'"):
        Options(lu_backend="umfpack", lu_ordering="metis")
    with pytest.raises(OptionError, match="lu_backend"):
        Options(lu_backend="pardiso")
