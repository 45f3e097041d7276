"""A Result speaks the user's language: statuses print as names, the residual check and the
solution use the problem's names, and the variables at a bound are listed by name."""
from __future__ import annotations

import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse import PointStatus, Status


def _market():
    # two goods at their lower bound 0 (excess supply > 0 there), one price inside
    def F(x):
        return np.array([x[0] + 1.0, 2.0 * x[1] - 3.0, x[2] + 0.5])

    def J(x):
        return np.diag([1.0, 2.0, 1.0])

    return F, J


def test_statuses_print_as_their_names_and_still_compare_as_codes():
    assert str(Status.SOLVED) == "SOLVED" and f"{Status.NO_PROGRESS}" == "NO_PROGRESS"
    assert str(PointStatus.BEST_POINT) == "BEST_POINT"
    assert f"{Status.TIME_LIMIT:>12}" == "  TIME_LIMIT"
    # code that relies on the IntEnum's value keeps working
    assert Status.SOLVED == 1 and int(Status.STATIONARY_POINT) == 102
    assert f"{Status.SOLVED:d}" == "1" and f"{Status.FLAT_RESIDUAL:04d}" == "0101"
    assert {1: "x"}[Status.SOLVED] == "x" and Status(5) is Status.TIME_LIMIT


def test_print_of_a_results_status_gives_the_name(capsys):
    F, J = _market()
    res = cs.solve_mcp(F, J, 0.0, np.inf, np.ones(3))
    print(res.status, res.point_status)
    assert capsys.readouterr().out == "SOLVED SOLUTION\n"


def test_check_names_the_worst_rows_as_the_problem_does():
    F, J = _market()
    names = ["coal", "steel", "wheat"]
    res = cs.solve_mcp(F, J, 0.0, np.inf, np.ones(3), var_names=names,
                       eqn_names=["market[coal]", "market[steel]", "market[wheat]"])
    assert res.var_names == names
    x = res.x.copy()
    res.x[1] += 0.1  # steel's row is now the worst
    worst = res.check(F).worst
    assert worst[0][0] == "market[steel]"
    assert {w[0] for w in worst} == {"market[coal]", "market[steel]", "market[wheat]"}
    res.x[:] = x
    # with variable names only, rows are F(<variable>), as in the summary and the log
    res = cs.solve_mcp(F, J, 0.0, np.inf, np.ones(3), var_names=names)
    res.x[2] += 1.0
    assert res.check(F).worst[0][0] == "F(wheat)"
    assert res.check(F, names=lambda i: f"row {i}").worst[0][0] == "row 2"


def test_unnamed_problems_keep_index_names():
    F, J = _market()
    res = cs.solve_mcp(F, J, 0.0, np.inf, np.ones(3))
    res.x[0] += 1.0
    assert res.check(F).worst[0][0] == "F[0]"
    assert list(res.solution(as_series=False)) == ["x[0]", "x[1]", "x[2]"]


def test_solution_by_name_as_a_dict_and_a_pandas_series():
    F, J = _market()
    res = cs.solve_mcp(F, J, 0.0, np.inf, np.ones(3), var_names=["coal", "steel", "wheat"])
    d = res.solution(as_series=False)
    assert d == {"coal": 0.0, "steel": pytest.approx(1.5), "wheat": 0.0}
    pd = pytest.importorskip("pandas")
    s = res.solution()
    assert isinstance(s, pd.Series) and list(s.index) == ["coal", "steel", "wheat"]
    assert s["steel"] == pytest.approx(1.5)
    s["steel"] = 0.0  # a copy: the Result's point is untouched
    assert res.x[1] == pytest.approx(1.5)


def test_variables_at_a_bound_are_listed_by_name():
    F, J = _market()
    lb = np.array([0.0, 0.0, 2.0])
    ub = np.array([np.inf, 1.0, 2.0])
    res = cs.solve_mcp(F, J, lb, ub, np.array([1.0, 0.5, 2.0]),
                       var_names=["coal", "steel", "wheat"])
    assert res.success
    # coal at 0 (F > 0), steel at its upper bound 1 (F < 0), wheat fixed at 2
    assert res.at_bound() == {"coal": "lower", "steel": "upper", "wheat": "fixed"}
