"""The Sioux Falls traffic equilibrium generator (compass_sparse.generators.traffic):
sizes, the exact Jacobian, and that the solver's point is a Wardrop equilibrium that
agrees with the published optimum of the same data."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from compass_sparse import Status, solve_mcp
from compass_sparse.generators import traffic_equilibrium

# The solver stops at ||Phi_FB||_2 <= 1e-6 (its default convergence_tolerance); a flow
# below FLOW_TOL counts as no flow, and an arc is on a shortest path when its reduced
# time v_a + d(j) - d(i) is within TIME_TOL.  Arc times are 2 ... 100 here, so TIME_TOL
# is ~1e-8 relative, far above the solution's accuracy and far below any arc time.
FLOW_TOL = 1e-6
TIME_TOL = 1e-6

# The primal (Beckmann) NLP's optimum for all 24 destinations on the same data, as the
# GAMSPy model library's ``traffic`` example records it from its CONOPT solve
# (pnlp 5148.830098447451; the dual NLP 5148.830098449257).  The MCP's equilibrium
# minimizes the same objective, so both values must agree at our point, to 1e-6
# relative (the objective is flat at its minimum: a flow error e changes it by O(e^2)).
PUBLISHED_BECKMANN_ALL = 5148.830098447451
PUBLISHED_RTOL = 1e-6


@pytest.fixture(scope="module")
def solved8():
    gp = traffic_equilibrium(8)
    return gp, solve_mcp(gp.problem)


@pytest.fixture(scope="module")
def solved24():
    gp = traffic_equilibrium(24)
    return gp, solve_mcp(gp.problem)


def test_sizes_are_the_model_librarys():
    # every arc not leaving a destination, every node but the destination, v and x
    assert traffic_equilibrium(8).problem.n == 912
    assert traffic_equilibrium(24).problem.n == 2452
    assert traffic_equilibrium(8).info["destinations"] == [10, 16, 22, 17, 11, 15, 20, 8]
    gp = traffic_equilibrium([1, 2])  # nodes 1 and 2 have 2 arcs out each
    assert gp.problem.n == 76 * 2 - 4 + 23 * 2 + 2 * 76
    net = gp.info["network"]
    assert net.m == 76 and np.all(net.A[:38] == net.A[38:])  # every street both ways


@pytest.mark.parametrize("destinations", [3, 24])
def test_jacobian_matches_central_differences(destinations):
    gp = traffic_equilibrium(destinations)
    net = gp.info["network"]
    rng = np.random.default_rng(7)
    z = rng.uniform(0.0, 3.0, net.n)
    z[net.off_x:] = rng.uniform(-5.0, 30.0, net.m)  # both signs of the aggregate flow
    J = sp.csc_matrix(net.jac(z)).toarray()
    h = 1e-5
    fd = np.empty_like(J)
    for j in range(net.n):
        e = np.zeros(net.n)
        e[j] = h
        fd[:, j] = (net.F(z + e) - net.F(z - e)) / (2 * h)
    # central differences of a quartic: error h^2 |f'''| / 6 <= ~1e-8 here
    assert np.max(np.abs(J - fd)) <= 1e-6 * max(1.0, np.max(np.abs(J)))
    # the declared pattern holds every entry of J, and the constant part is the constant
    pattern = net.L.copy()
    pattern.data[:] = 1.0
    assert np.all((J != 0) <= (pattern.toarray() != 0))
    J2 = sp.csc_matrix(net.jac(2.0 * z)).toarray()
    mask = net.constant_pattern().toarray() != 0
    assert np.array_equal(J[mask], J2[mask])


def _check_wardrop(gp, res):
    net = gp.info["network"]
    assert res.status is Status.SOLVED
    y, t, v, x = net.split(res.x)
    assert np.allclose(v, net.arc_times(x), rtol=0, atol=TIME_TOL)  # v is the arc time
    G = sp.csr_matrix((v, (net.tail, net.head)), shape=(24, 24))
    to_dest = dijkstra(G.T.tocsr(), indices=net.dest)  # shortest time from every node to k
    used = 0
    for d in range(net.dest.size):
        dist = to_dest[d]
        reduced = v + dist[net.head] - dist[net.tail]
        assert np.all(reduced >= -TIME_TOL)  # (a shortest-path property, a sanity check)
        flow = y[d] > FLOW_TOL
        used += int(flow.sum())
        # Wardrop: every arc carrying flow towards k lies on a shortest path to k ...
        assert np.all(reduced[flow] <= TIME_TOL), np.max(reduced[flow])
        # ... and the model's node times are the shortest times where flow leaves a node
        origins = np.unique(net.tail[flow])
        assert np.allclose(t[d, origins], dist[origins], rtol=0, atol=TIME_TOL)
    assert used > 0


def _check_conservation(gp, res):
    net = gp.info["network"]
    y, _, _, x = net.split(res.x)
    assert np.all(y >= 0.0)
    tol = 1e-7  # |F| at the solution is ~1e-8 (within the FB norm's 1e-6)
    for d, k in enumerate(net.dest):
        net_out = (np.bincount(net.tail, y[d], 24) - np.bincount(net.head, y[d], 24))
        others = np.arange(24) != k
        assert np.allclose(net_out[others], net.trips[others, k], rtol=0, atol=tol)
        # what arrives at k is all the demand for k (the sum of 23 balances: 23 tol)
        assert abs(-net_out[k] - net.trips[:, k].sum()) <= 23 * tol
        assert np.all(y[d][net.tail == k] == 0)  # no variable, no flow out of k
    assert np.allclose(x, y.sum(axis=0), rtol=0, atol=tol)


def test_eight_destinations_is_a_wardrop_equilibrium(solved8):
    _check_wardrop(*solved8)
    _check_conservation(*solved8)


def test_all_destinations_is_a_wardrop_equilibrium(solved24):
    _check_wardrop(*solved24)
    _check_conservation(*solved24)


def test_all_destinations_agrees_with_the_published_optimum(solved24):
    gp, res = solved24
    net = gp.info["network"]
    x = net.split(res.x)[3]
    assert net.beckmann(x) == pytest.approx(PUBLISHED_BECKMANN_ALL, rel=PUBLISHED_RTOL)
    assert net.dual_objective(res.x) == pytest.approx(PUBLISHED_BECKMANN_ALL,
                                                      rel=PUBLISHED_RTOL)
    # the total travel time equals the demand times the equilibrium times (t at origins)
    _, t, _, _ = net.split(res.x)
    demand_time = float(np.sum(net.trips[:, net.dest].T * t))
    assert net.total_travel_time(res.x) == pytest.approx(demand_time, rel=1e-7)


def test_non_monotone_excursion_is_not_a_stall_on_traffic(solved8, solved24):
    """Regression: the stall rule counted an accepted non-monotone climb (merit 31 -> 700
    -> 214 by d-steps, then back below the reference value) as no progress and restarted
    after 3 major iterations, throwing its pivots away (1098 pivots and a restart at
    n = 912, PATH 566; 3370 at n = 2452).  Counting from the reference value, the run
    goes on: no restart, at most 650 pivots at n = 912 (the target set against PATH's
    566) and 2000 at n = 2452."""
    for (_, res), most in ((solved8, 650), (solved24, 2000)):
        assert res.status is Status.SOLVED
        assert res.restarts == 0
        assert res.minor_iterations <= most, res.minor_iterations


def test_crash_that_raises_the_merit_is_stopped_early_on_traffic(solved8):
    """Regression: the crash climbed 21.1 -> 31.3 -> ... -> 36.8 in six steps, handed on
    its start (its best point) and so was dropped, but cost 37 of the solve's 76
    factorizations.  It now stops before its first step, which raises ||Phi||."""
    _, res = solved8
    crash = res.passes["crash"]
    assert crash.reason == "raised the merit"
    assert res.crash_iterations == 0
    assert crash.factorizations < 10 and res.factorizations <= 40, (
        crash.factorizations, res.factorizations)
