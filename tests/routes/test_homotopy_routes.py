"""The compiled path tracker (reverse communication: one compiled call between two
evaluations) against its Python route (option engine = "reference"): the same statuses,
evaluations, steps and bits, past rejected corrector points too, and the Python route
where numba offers no LAPACK binding."""

import copy


import known_problems as kp

import compass_sparse.homotopy.tracker as hom
from compass_sparse import solve_mcp
from compass_sparse.generators import thesis_family
from compass_sparse.status import Status


def _route_runs():
    g = [(f"thesis {fam} n{n} s{seed}", thesis_family(n, fam, seed).problem)
         for fam in (1, 2) for n in (10, 20) for seed in (1, 2, 3)]
    runs = [(name, (p,), {"homotopy": "only"}) for name, p in g]
    runs += [(name + " auto", (p,), {}) for name, p in g[:3]]
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    runs.append(("stationary", (F, J, lb, ub, x0), {"homotopy": "only"}))
    runs.append(("stationary, tight tracking", (F, J, lb, ub, x0),
                 {"homotopy": "only", "homotopy_initial_step": 1e-3}))
    return runs


def _record(res):
    hp = res.passes["homotopy"]
    return (res.status, res.nit, res.nfev, res.njev, res.domain_errors, hp.iterations,
            hp.factorizations, hp.reason, res.x.tobytes())


def _homotopy_log(records):
    """The lines of the log's homotopy sections (compass_sparse.nms.log)."""
    lines, inside = [], False
    for r in records:
        m = r.getMessage()
        if m in ("Crash Log", "Major Iteration Log", "Homotopy Log"):
            inside = m == "Homotopy Log"
        elif inside:
            lines.append(m)
    return tuple(lines)


def test_compiled_tracker_follows_the_python_routes_points_bit_for_bit(monkeypatch, caplog):
    """The compiled tracker (reverse communication: one compiled call between two
    evaluations) against the Python route it replaces on dense problems: the same statuses,
    evaluations, steps, factorizations, pass reasons, log lines and bits of x."""
    import logging

    calls = {"n": 0}
    dense = hom.hk.follow_dense

    def counted(*args):
        calls["n"] += 1
        return dense(*args)

    monkeypatch.setattr(hom.hk, "follow_dense", counted)
    out = {}
    for compiled in (False, True):
        engine = "auto" if compiled else "reference"
        records = []
        for _, args, opts in _route_runs():
            caplog.clear()
            with caplog.at_level(logging.INFO, logger="compass_sparse"):
                res = solve_mcp(*args, options={**opts, "verbosity": 2, "time_limit": 60,
                                                "engine": engine})
            assert res.routes["homotopy"] == ("compiled" if compiled else "python")
            records.append(_record(res) + (_homotopy_log(caplog.records),))
        out[compiled] = records
        assert (calls["n"] > 0) is compiled
    for (name, *_), a, b in zip(_route_runs(), out[False], out[True]):
        assert a == b, (name, [(u, w) for u, w in zip(a, b) if u != w])
    assert sum(r[0] is Status.SOLVED for r in out[True]) >= 12
    assert any(line.split()[0].isdigit() for r in out[True] for line in r[-1])  # steps


def test_compiled_tracker_carries_on_past_rejected_corrector_points(monkeypatch):
    """F rejected at every third corrector iterate (an exception or NaN there): the
    compiled tracker halves the step and goes on, as the Python route does, to the same
    points."""
    def run(compiled):
        calls = {"n": 0}
        once = hom.Tracker.__init__

        def init(self, evalr, *args, **kw):
            once(self, evalr, *args, **kw)
            inner = evalr.f_once

            def flaky(x):
                calls["n"] += 1
                if calls["n"] % 3 == 0:
                    return evalr._reject("ValueError('flaky')")
                return inner(x)

            self.ev = copy.copy(evalr)
            self.ev.f_once = flaky

        monkeypatch.setattr(hom.Tracker, "__init__", init)
        res = solve_mcp(thesis_family(10, 2, 1).problem,
                        options={"homotopy": "only",
                                 "engine": "auto" if compiled else "reference"})
        monkeypatch.setattr(hom.Tracker, "__init__", once)
        return res, calls["n"]

    (a, na), (b, nb) = run(False), run(True)
    assert nb >= 3 and na == nb
    assert _record(a) == _record(b)
    assert b.domain_errors >= 1 and b.passes["homotopy"].ran
    assert b.success or b.status is Status.NO_PROGRESS


def test_tracker_keeps_its_python_route_when_numba_offers_no_getrf(monkeypatch):
    """getrf is bound through numba's internal LAPACK interface; a numba without it (the
    binding fails) leaves the tracker on its Python route, with the same points; the
    solve's routes say so."""
    g = thesis_family(10, 2, 1).problem
    ref = solve_mcp(g, options={"homotopy": "only"})
    assert ref.routes["homotopy"] == "compiled"
    calls = []
    monkeypatch.setattr(hom.hk, "bind_lapack", lambda: calls.append(1) or False)
    monkeypatch.setattr(hom.hk, "follow_dense", lambda *a: 1 / 0)
    res = solve_mcp(g, options={"homotopy": "only"})
    assert calls and res.success and res.routes["homotopy"] == "python"
    assert _record(res) == _record(ref)
