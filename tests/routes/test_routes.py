"""The routes of a solve (compass_sparse.routes): chosen once, from the problem's size and
the options, never from the log level; recorded in Result.routes; the options engine and
path_basis force the reference routes."""
from __future__ import annotations

import numpy as np
import pytest

import compass_sparse as cs
import compass_sparse.generators as gen
from compass_sparse.exceptions import OptionError
from compass_sparse.options import HOMOTOPY_DENSE_MAX_N, Options
from compass_sparse.routes import (COMPILED_NMS_MAX_N, DENSE_BASIS_MAX_N, DENSE_ENGINE_MAX_N,
                                   HAND_OVER_MAX_N,
                                   Routes, choose_routes)
from compass_sparse.path.sparse_engine import SPARSE_ENGINE_MAX_DENSITY

FIELDS = ("kernels", "path", "nms", "crash", "homotopy")


def test_every_solve_records_its_routes():
    r = cs.solve_mcp(gen.thesis_family(10, 2, 4).problem)
    assert tuple(r.routes) == FIELDS
    assert r.routes["kernels"] in ("compiled", "interpreted")


@pytest.mark.parametrize("verbosity", [0, 1, 2, 3])
def test_the_log_level_does_not_choose_a_route(verbosity):
    opt = Options(verbosity=verbosity)
    for n in (5, 250, 400, 600, 6000):
        assert choose_routes(n, opt) == choose_routes(n, Options())


def test_auto_routes_by_size():
    opt = Options()
    assert choose_routes(DENSE_ENGINE_MAX_N, opt).path == "dense engine"
    n = DENSE_ENGINE_MAX_N + 1
    assert choose_routes(n, opt).path == "sparse engine"  # (no entry count: sparse)
    assert choose_routes(n, opt, nnz=int(SPARSE_ENGINE_MAX_DENSITY * n)).path == \
        "sparse engine"
    assert choose_routes(n, opt, nnz=int(SPARSE_ENGINE_MAX_DENSITY * n) + 1).path == \
        "sparse basis to engine"
    big = HAND_OVER_MAX_N + 1
    assert choose_routes(big, opt, nnz=int(SPARSE_ENGINE_MAX_DENSITY * big) + 1).path == \
        "sparse basis"
    assert choose_routes(n, Options(lu_ordering="metis")).path == "sparse basis"
    assert choose_routes(COMPILED_NMS_MAX_N, opt).nms == "compiled"
    assert choose_routes(COMPILED_NMS_MAX_N + 1, opt).nms == "python"
    assert choose_routes(HOMOTOPY_DENSE_MAX_N + 1, opt).homotopy == "python"
    # the compiled major iterations judge points unscaled
    assert choose_routes(10, opt, scaled=True).nms == "python"
    # interpreted kernels run the Python loops (the same arithmetic, no compilation)
    assert choose_routes(10, opt, kernels="interpreted") == Routes(
        kernels="interpreted", nms="python", crash="compiled", homotopy="python")


def test_engine_reference_forces_every_python_loop():
    routes = choose_routes(10, Options(engine="reference"))
    assert (routes.nms, routes.crash, routes.homotopy) == ("python",) * 3
    r = cs.solve_mcp(gen.thesis_family(10, 2, 4).problem, options={"engine": "reference"})
    assert r.success and (r.routes["nms"], r.routes["crash"], r.routes["homotopy"]) == \
        ("python",) * 3


def test_path_basis_forces_the_reference_bases():
    assert choose_routes(50, Options(path_basis="dense")).path == "dense basis"
    assert choose_routes(DENSE_BASIS_MAX_N + 1, Options(path_basis="dense")).path == \
        "sparse basis"
    assert choose_routes(50, Options(path_basis="sparse")).path == "sparse basis"
    r = cs.solve_mcp(gen.thesis_family(10, 2, 4).problem, options={"path_basis": "sparse"})
    assert r.success and r.routes["path"] == "sparse basis"


def _cge_endowment_shock():
    """The static CGE model at n = 506 (9.6 Jacobian entries a column) with the first
    factor's endowment at a tenth in every region."""
    from compass_sparse.generators.cge import size_for, static_cge

    m = static_cge(**size_for(600), seed=0)
    R, F = m.block_shapes["W"]
    e = np.ones((R, F))
    e[:, 0] = 0.1
    return m.with_shock(endowment=e).problem


def test_path_basis_sparse_engine_runs_the_compiled_sparse_engine_at_any_order_and_density():
    """'sparse engine' takes the engine past the density rule (a CGE model, 9.6 entries a
    column, starts on the manager on 'auto') and below the dense engine's order; the CGE
    endowment shock at n = 506 is solved on it in the manager's pivots."""
    opt = Options(path_basis="sparse engine")
    assert choose_routes(DENSE_ENGINE_MAX_N + 1, opt, nnz=(DENSE_ENGINE_MAX_N + 1) ** 2).path \
        == "sparse engine"
    assert choose_routes(50, opt).path == "sparse engine"
    p = _cge_endowment_shock()
    runs = {pb: cs.solve_mcp(p, options={"path_basis": pb}) for pb in ("auto", "sparse engine")}
    assert runs["auto"].routes["path"] == "sparse basis to engine"
    assert runs["sparse engine"].routes["path"] == "sparse engine"
    for r in runs.values():
        assert r.success and r.residual.natural <= 1e-6
    assert runs["sparse engine"].minor_iterations == runs["auto"].minor_iterations


@pytest.mark.parametrize("other", [{"engine": "reference"}, {"lu_backend": "superlu"},
                                   {"lu_ordering": "amd"}])
def test_path_basis_sparse_engine_refuses_options_it_cannot_honour(other):
    with pytest.raises(OptionError, match="path_basis='sparse engine'"):
        Options(path_basis="sparse engine", **other)


@pytest.mark.parametrize("field,value", [("engine", "fast"), ("path_basis", "lu")])
def test_route_options_are_checked(field, value):
    with pytest.raises(OptionError, match=field):
        Options(**{field: value})


def test_a_dense_lcp_above_the_dense_engines_order_stays_on_the_basis_manager():
    """solve_lcp gave its routes no entry count, which the path route takes as sparse: a
    dense LCP of order 501 went to the compiled sparse engine, whose left-looking LU is
    for sparse bases.  The route now sees M's entries (and sensitivity's linearized MCP
    its own)."""
    import numpy as np

    n = DENSE_ENGINE_MAX_N + 1
    rng = np.random.default_rng(0)
    A = rng.normal(size=(n, n)) / n
    M = A @ A.T + np.eye(n)
    q = rng.normal(size=n)
    r = cs.solve_lcp(M, q, options={"crash_method": "none"})
    assert r.routes["path"] == "sparse basis to engine"
    assert r.success and r.residual.natural <= 1e-6
    banded = cs.solve_lcp(gen.p_matrix_lcp(n, "banded", seed=1).lcp[0],
                          gen.p_matrix_lcp(n, "banded", seed=1).lcp[1],
                          options={"crash_method": "none"})
    assert banded.routes["path"] == "sparse engine"


def test_a_long_path_on_the_manager_hands_the_paths_to_the_sparse_engine():
    """A dense LCP of order 501 (route "sparse basis to engine"): its path on the basis
    manager makes hand_over_pivots(n) pivots, stops, and the LCP is solved again on the
    compiled sparse engine -- the solution of the manager alone, in its pivots plus the
    ones spent, the factorizations of both counted, the engine's LU reported."""
    from compass_sparse.routes import hand_over_pivots

    n = DENSE_ENGINE_MAX_N + 1
    rng = np.random.default_rng(0)
    A = rng.normal(size=(n, n)) / n
    M = A @ A.T + np.eye(n)
    q = rng.normal(size=n)
    # (from the Lemke start: without it the start basis solves the LCP in no pivot)
    opts = {"crash_method": "none", "lemke_start": "always"}
    handed = cs.solve_lcp(M, q, options=opts)
    alone = cs.solve_lcp(M, q, options=dict(opts, path_basis="sparse"))
    assert alone.minor_iterations > hand_over_pivots(n)
    assert alone.lu["backend"] != "sparse engine" and handed.lu["backend"] == "sparse engine"
    assert handed.success and handed.residual.natural <= 1e-9
    assert np.max(np.abs(handed.x - alone.x)) <= 1e-9 * max(1.0, np.max(np.abs(alone.x)))
    assert handed.minor_iterations == alone.minor_iterations + hand_over_pivots(n)
    assert handed.factorizations >= alone.factorizations


def test_a_path_shorter_than_the_hand_over_stays_on_the_manager():
    """The CGE endowment shock at n = 506 (9.6 entries a column: route "sparse basis to
    engine") needs 4 pivots: every path stays on the manager."""
    r = cs.solve_mcp(_cge_endowment_shock())
    assert r.routes["path"] == "sparse basis to engine"
    assert r.success and r.lu["backend"] != "sparse engine" and r.minor_iterations < 100
