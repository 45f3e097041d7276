"""The one log of a solve (compass_sparse.nms.log): each pass under its own title and
header, the homotopy's steps logged, the summary once per solve, and the passes' times
shown nested; the progress line moves during the crash too."""
from __future__ import annotations

import logging

import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse.generators import p_matrix_lcp, thesis_family
from compass_sparse.nms.log import CRASH_HEADER, HEADER, HOMOTOPY_HEADER, SectionLog


@pytest.fixture
def log_lines(caplog):
    def run(call, **opts):
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="compass_sparse"):
            res = call(opts)
        return res, [r.getMessage() for r in caplog.records]
    return run


def _sections(lines):
    """{title: [its lines]} (a section that comes back continues its list)."""
    out, cur = {}, None
    for line in lines:
        if line in ("Crash Log", "Major Iteration Log", "Homotopy Log"):
            cur = out.setdefault(line, [])
        elif cur is not None:
            cur.append(line)
    return out


def test_section_log_writes_each_title_and_header_when_its_section_starts():
    lines = []
    log = SectionLog(lines.append)
    crash, major = log.writer("crash"), log.writer("major")
    crash("c1")
    crash("c2")
    major("m1")
    crash("c3")  # a restart's crash: its header again
    assert lines == ["Crash Log", CRASH_HEADER, "c1", "c2", "Major Iteration Log", HEADER,
                     "m1", "Crash Log", CRASH_HEADER, "c3"]
    assert SectionLog(None).writer("crash") is None


def test_crash_and_major_iterations_have_their_own_headers(log_lines):
    g = thesis_family(20, family=1, seed=5)
    res, lines = log_lines(lambda o: cs.solve_mcp(g.problem, options=o), verbosity=2)
    sec = _sections(lines)
    assert res.crash_iterations > 0 and res.nit > 0
    crash = sec["Crash Log"]
    assert crash[0] == CRASH_HEADER
    steps = [s for s in crash[1:] if s[:5].strip().isdigit()]
    assert len(steps) == res.crash_iterations
    assert all(len(s.split()) == len(CRASH_HEADER.split()) for s in steps)
    assert any(s.startswith("crash: ") for s in lines)  # why the crash stopped
    assert sec["Major Iteration Log"][0] == HEADER
    assert lines.index("Crash Log") < lines.index("Major Iteration Log")


def test_the_homotopys_steps_are_logged_and_its_pass_is_a_major_line(log_lines):
    g = thesis_family(10, family=2, seed=4)
    res, lines = log_lines(lambda o: cs.solve_mcp(g.problem, options=o), verbosity=2,
                           homotopy="only")
    assert res.success and res.passes["homotopy"].ran
    hom = _sections(lines)["Homotopy Log"]
    assert hom[0] == HOMOTOPY_HEADER
    steps = [s for s in hom[1:] if s.split()[0].isdigit()]
    assert len(steps) == res.passes["homotopy"].iterations
    lam = [float(s.split()[1]) for s in steps]
    assert steps and all(0.0 < v for v in lam) and max(lam) > 0.5
    majors = _sections(lines)["Major Iteration Log"]
    # the pass, one major iteration of the log
    assert [s.split()[0] for s in majors if s.endswith(" -H")] == [str(res.nit)]


@pytest.mark.parametrize("case", ["mcp", "lcp", "lcp handed over"])
def test_the_summary_is_logged_once_per_solve(case, log_lines):
    g = p_matrix_lcp(30, "banded", 2, "mixed")
    M, q, lb, ub = g.lcp
    if case == "mcp":
        call = lambda o: cs.solve_mcp(thesis_family(10, 1, 1).problem, options=o)
        res, lines = log_lines(call, verbosity=1)
    elif case == "lcp":
        res, lines = log_lines(lambda o: cs.solve_lcp(M, q, lb, ub, options=o), verbosity=1)
    else:  # one pivot allowed: the path stops and the general method takes over
        res, lines = log_lines(lambda o: cs.solve_lcp(M, q, lb, ub, options=o), verbosity=1,
                               minor_iteration_limit=1, crash_method="none")
        assert res.passes["nms"].ran
    assert res.success
    assert sum(s.startswith("status  ") for s in lines) == 1


def test_passes_nested_in_nms_are_shown_within_its_time():
    res = cs.solve_mcp(thesis_family(20, family=1, seed=5).problem)
    line = res.passes_line()
    nms = res.passes["nms"]
    inner = [k for k in ("crash", "path", "homotopy") if res.passes[k].ran]
    assert inner and line.startswith(f"nms {nms.time:.3f} s (") and line.endswith(" within)")
    for k in inner:
        assert f"{k} {res.passes[k].time:.3f} s" in line
        assert res.passes[k].time <= nms.time
    assert "passes        " + line in res.summary()


def test_progress_line_moves_during_the_crash(monkeypatch, capsys):
    from compass_sparse import progress

    monkeypatch.setattr(progress, "PROGRESS_AFTER", 0.0)
    monkeypatch.setattr(progress, "stderr_is_terminal", lambda: True)
    res = cs.solve_mcp(thesis_family(20, family=1, seed=5).problem,
                       options={"progress": True})
    err = capsys.readouterr().err
    assert res.crash_iterations > 0
    assert "[compass_sparse] crash     F evaluations" in err
    assert err.index("[compass_sparse] crash") < err.index("[compass_sparse] major")
    assert np.isfinite(res.residual.fb_norm)


def test_an_lcps_crash_has_its_header_and_moves_the_progress_line(monkeypatch, capsys,
                                                                  log_lines):
    from compass_sparse import progress
    from compass_sparse.generators import obstacle_problem

    M, q, lb, ub = obstacle_problem(20, seed=0).lcp
    res, lines = log_lines(lambda o: cs.solve_lcp(M, q, lb, ub, options=o), verbosity=2)
    assert res.success and res.passes["crash"].ran and res.crash_iterations > 0
    assert _sections(lines)["Crash Log"][0] == CRASH_HEADER
    monkeypatch.setattr(progress, "PROGRESS_AFTER", 0.0)
    monkeypatch.setattr(progress, "stderr_is_terminal", lambda: True)
    cs.solve_lcp(M, q, lb, ub, options={"progress": True})
    err = capsys.readouterr().err
    assert "[compass_sparse] crash     F evaluations" in err and err.endswith("\n")
