"""Stationary points of the merit function that solve nothing (compass_sparse.nms.stationarity):
the threshold, and the diagnosis that names the row."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import Status, solve_mcp


# ------------------------------------------------------------------ stationary points
def test_no_solution_stationary_point_is_diagnosed_and_names_the_row():
    F = lambda x: np.array([x[0] ** 2 + 1, x[1] - 1 + 0.1 * x[0]])  # noqa: E731
    J = lambda x: sp.csc_matrix(np.array([[2 * x[0], 0], [0.1, 1]]))  # noqa: E731
    r = solve_mcp(F, J, -np.inf, np.inf, np.array([2.0, 0.0]), var_names=["p", "q"],
                  options={"restart_limit": 20})
    assert r.status is Status.STATIONARY_POINT, r.message
    assert "F(p)" in r.message and "F(q)" not in r.message
    assert r.status.path_code() == 2


@pytest.mark.parametrize("x, stationary", [(0.0, True), (0.01, True), (0.02, True),
                                           (0.2, False), (1.0, False)])
def test_stationarity_threshold_on_x_squared_plus_one(x, stationary):
    # ratio = |2x (x^2 + 1)| max(1, |x|) / (0.5 (x^2 + 1)^2) = 4|x| / (x^2 + 1) near 0
    from compass_sparse.nms.stationarity import STATIONARY_RTOL, stationarity

    z = np.array([x])
    st = stationarity(z, z ** 2 + 1, sp.csc_matrix([[2 * x]]), np.array([-np.inf]),
                      np.array([np.inf]))
    assert st.stationary is stationary
    assert (4 * abs(x) / (x * x + 1) <= STATIONARY_RTOL) is stationary


