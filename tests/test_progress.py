"""The progress line (compass_sparse.progress) and the library's log: drawn only on a
terminal, and the logging configuration left to the application."""

import compass_sparse as cs


def test_progress_line_on_stderr(monkeypatch, capsys):
    import compass_sparse.progress as progress
    from compass_sparse.generators import thesis_family

    monkeypatch.setattr(progress, "PROGRESS_AFTER", 0.0)
    g = thesis_family(20, family=1, seed=3)
    opts = {"progress": True, "crash_method": "none"}
    # stderr is not a terminal under pytest: nothing is drawn
    r = cs.solve_mcp(g.problem, options=opts)
    assert capsys.readouterr().err == "" and r.nit >= 1
    monkeypatch.setattr(progress, "stderr_is_terminal", lambda: True)
    r = cs.solve_mcp(g.problem, options=opts)
    err = capsys.readouterr().err
    assert "[compass_sparse] major" in err and "residual" in err
    assert err.endswith("\n")
    assert r.nit >= 1


def test_library_logging_leaves_configuration_to_the_application(caplog, capsys):
    import logging

    from compass_sparse.generators import thesis_family

    lg = logging.getLogger("compass_sparse")
    before = (list(lg.handlers), lg.level, lg.propagate)
    assert any(isinstance(h, logging.NullHandler) for h in lg.handlers)
    g = thesis_family(30, family=1, seed=1)
    with caplog.at_level(logging.INFO, logger="compass_sparse"):
        r = cs.solve_mcp(g.problem, options={"verbosity": 3, "crash_method": "none"})
    assert (list(lg.handlers), lg.level, lg.propagate) == before
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""  # nothing written by the library itself
    recs = [rec for rec in caplog.records if rec.name.startswith("compass_sparse")]
    assert r.success and recs and all(rec.levelno == logging.INFO for rec in recs)
    text = "\n".join(rec.getMessage() for rec in recs)
    assert "status        SOLVED" in text  # the summary, at INFO
    assert "\nminor " in text and "major" in text  # verbosity 3 adds the pivots
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="compass_sparse"):
        cs.solve_mcp(g.problem, options={"verbosity": 2, "crash_method": "none"})
    msgs = [rec.getMessage() for rec in caplog.records]
    assert any(m.lstrip().startswith("major") for m in msgs)  # the major log header
    assert not any(m.startswith("minor ") for m in msgs)  # but no pivots at verbosity 2
