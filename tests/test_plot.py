"""Result.history (one record per major iteration) and the plots drawn from it."""
import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse import generators as gen
from compass_sparse.plot import profile_curve


def _thesis(n=30, seed=3):
    return gen.thesis_family(n, family=2, seed=seed).problem


def test_history_records_start_and_every_major_iteration_with_the_returned_residual():
    p = _thesis()
    r = cs.solve_mcp(p)
    assert r.success
    h = r.history
    assert h[0].nit == 0 and h[0].step == ""
    # The start record is the merit of the (projected) start point.
    f0 = p.F_uncounted(np.clip(p.x0, p.lb, p.ub))
    phi0 = cs.merit.fb_phi(np.clip(p.x0, p.lb, p.ub), f0, p.lb, p.ub)
    assert h[0].residual == pytest.approx(np.linalg.norm(phi0), rel=1e-12)
    assert all(a.nit < b.nit for a, b in zip(h, h[1:]))
    assert h[-1].nit == r.nit
    assert all(a.time <= b.time for a, b in zip(h, h[1:]))
    # The last record is the returned point (no preprocessor on this problem).
    assert h[-1].residual == pytest.approx(r.residual.fb_norm, rel=1e-6, abs=1e-14)


def test_history_step_types_are_the_logs_two_letter_codes():
    r = cs.solve_mcp(_thesis(50, seed=4))
    codes = [e.step for e in r.history[1:] if e.step]
    assert codes, "at least one logged major iteration"
    assert all(len(c) == 2 and c[0] in "SRCINTE-" and c[1] in "DMOWGLH" for c in codes)


def test_history_is_none_when_the_newton_method_never_ran():
    # The start point is the solution: no major iteration.
    r = cs.solve_mcp(lambda x: x - 1.0, lambda x: np.eye(2), lb=1.0, ub=np.inf,
                     x0=np.ones(2))
    assert r.success and r.history is None


def test_profile_curve_matches_a_hand_computed_profile():
    # Three instances, two solvers; solver B fails instance 3.
    costs = np.array([[1.0, 2.0], [3.0, 1.0], [2.0, np.inf]])
    rho = profile_curve(costs, np.array([1.0, 2.0, 3.0, np.inf]))
    np.testing.assert_allclose(rho[:, 0], [2 / 3, 2 / 3, 1.0, 1.0])
    np.testing.assert_allclose(rho[:, 1], [1 / 3, 2 / 3, 2 / 3, 2 / 3])


def test_convergence_plot_draws_the_history(tmp_path):
    pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")
    from compass_sparse.plot import convergence

    r = cs.solve_mcp(_thesis())
    fig = convergence(r, title="thesis family 2")
    line = fig.axes[0].get_lines()[0]
    np.testing.assert_allclose(line.get_ydata(), [e.residual for e in r.history])
    fig.savefig(tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 1000


def test_convergence_plot_refuses_a_result_without_history():
    pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")
    from compass_sparse.plot import convergence

    r = cs.solve_mcp(lambda x: x - 1.0, lambda x: np.eye(2), lb=1.0, ub=np.inf,
                     x0=np.ones(2))
    with pytest.raises(ValueError, match="no iteration history"):
        convergence(r)
