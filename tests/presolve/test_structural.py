"""Structural-rank diagnostics by maximum bipartite matching."""
import numpy as np
import scipy.sparse as sp

from compass_sparse.presolve import presolve, structural_rank_check
from compass_sparse.problem import MCP

INF = np.inf


def model(pattern, lb=-INF, ub=INF, names=None, eqns=None):
    P = sp.csc_matrix(np.asarray(pattern, dtype=float))
    n = P.shape[0]
    return MCP(lambda z: P @ z + 1.0, lambda z: P, lb, ub, np.zeros(n), var_names=names,
               eqn_names=eqns)


def test_full_rank_is_ok():
    r = structural_rank_check(model(np.eye(3) + np.eye(3, k=1)))
    assert r.ok and r.rank == 3 and "nonsingular" in r.message


def test_singular_pattern_names_rows_and_variables():
    # both market rows depend only on the price of good 1; nothing determines p2
    pat = [[1, 0, 0], [1, 0, 0], [1, 1, 1]]
    p = model(pat, names=["p1", "p2", "income"],
              eqns=["market_good1", "market_good2", "income_balance"])
    r = structural_rank_check(p)
    assert not r.ok and r.rank == 2 and r.deficiency == 1
    assert r.row_names[0] in ("market_good1", "market_good2")
    assert r.var_names[0] in ("p2", "income")
    assert "structurally singular" in r.message and "numeraire" in r.message
    assert r.row_names[0] in r.message


def test_fixed_variables_are_left_out():
    pat = [[1, 1, 0], [1, 1, 0], [1, 1, 1]]
    p = model(pat, lb=[-INF, -INF, -INF], ub=INF)
    assert structural_rank_check(p).ok
    pat2 = [[1, 0, 0], [1, 0, 1], [1, 0, 1]]  # column 1 empty
    assert not structural_rank_check(model(pat2)).ok
    fixed = model(pat2, lb=[-INF, 0.0, -INF], ub=[INF, 0.0, INF])
    # fixing var 1 drops it and its row 1: rows 0, 2 match vars 0, 2
    assert structural_rank_check(fixed).ok


def test_presolve_reports_structure_of_the_reduced_problem():
    pat = [[1, 0, 0, 0], [1, 0, 0, 0], [1, 1, 1, 0], [0, 0, 0, 1]]
    P = sp.csc_matrix(np.asarray(pat, dtype=float))
    p = MCP(lambda z: P @ z + 1.0, lambda z: P, -INF, INF, np.zeros(4),
            var_names=["a", "b", "c", "d"])
    res = presolve(p)  # no linear information: nothing removed, structure still checked
    assert res.reduced is p
    assert res.structural is not None and not res.structural.ok
    # with the entries declared linear the system is consistent and presolve solves it,
    # picking one of its solutions
    q = MCP(lambda z: P @ z + 1.0, lambda z: P, -INF, INF, np.zeros(4), constant_jac=P)
    res = presolve(q)
    assert res.reduced is None and res.infeasible is None
    x = res.postsolve(np.zeros(0))
    assert np.allclose(P @ x + 1.0, 0.0)


def test_presolve_makes_the_structural_report_once_per_pattern_and_set_of_fixed_variables(
        monkeypatch):
    """The matching reads only the pattern and which variables are fixed: a loop of solves
    of one model makes it once, a new set of fixed variables (with_bounds) anew."""
    import compass_sparse.presolve.core as core

    calls = []
    real = core.structural_rank_check
    monkeypatch.setattr(core, "structural_rank_check",
                        lambda p, **kw: calls.append(1) or real(p, **kw))
    pat = [[1, 0, 0], [1, 0, 1], [1, 0, 1]]  # column 1 empty: singular until it is fixed
    p = model(pat)
    first = presolve(p).structural
    assert not first.ok and len(calls) == 1
    again = presolve(p.with_start(np.ones(3))).structural
    assert again is first and len(calls) == 1
    # the same evaluator (the same pattern) with variable 1 fixed
    fixed = MCP.from_evaluator(p.evaluator, [-INF, 0.0, -INF], [INF, 0.0, INF], np.zeros(3))
    assert presolve(fixed).structural.ok and len(calls) == 2
    assert presolve(p).structural is first and len(calls) == 2
    # other names on the same evaluator: a report of its own (it names them)
    named = MCP.from_evaluator(p.evaluator, -INF, INF, np.zeros(3), var_names=["a", "b", "c"])
    assert "b" in presolve(named).structural.var_names and len(calls) == 3

