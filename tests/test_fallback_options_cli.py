"""Fallback steps (LM with CHOLMOD or SuperLU, projected gradient), options, statuses, CLI."""
import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.fallback import cholmod_available, gradient_steps, lm_step, spd_solve
from compass_sparse.merit import fb_phi, fb_psi
from compass_sparse.generators import structured_quadratic


def _spd(n, seed):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=5 / n, random_state=seed, format="csc")
    return (B.T @ B + sp.identity(n) * rng.uniform(0.5, 1.0)).tocsc()


@pytest.mark.suitesparse
@pytest.mark.skipif(not cholmod_available(),
                    reason="optional suitesparse extra (scikit-sparse/CHOLMOD) not installed")
def test_spd_solve_uses_cholmod_and_agrees_with_dense():
    import sksparse.cholmod  # noqa: F401  (the extra is really importable)

    A = _spd(300, 1)
    b = np.random.default_rng(2).normal(size=300)
    x = spd_solve(A, b)
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)
    assert np.allclose(x, np.linalg.solve(A.toarray(), b), rtol=1e-9, atol=1e-12)


def test_spd_solve_without_cholmod_matches(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_sksparse(name, *a, **k):
        if name.startswith("sksparse"):
            raise ImportError("hidden for this test")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_sksparse)
    A = _spd(200, 3)
    b = np.ones(200)
    x = spd_solve(A, b)
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lm_and_gradient_steps_decrease_psi(seed):
    g = structured_quadratic(400, seed=seed)
    p = g.problem
    rng = np.random.default_rng(seed)
    z = np.clip(g.solution + rng.normal(scale=0.5, size=p.n), p.lb, p.ub)
    ev = p.evaluator
    f = ev.f(z)
    psi0 = fb_psi(fb_phi(z, f, p.lb, p.ub))
    opt = cs.Options()
    out = lm_step(ev, z, f, None, p.lb, p.ub, opt)
    assert out is not None
    zt, ft, phit, psit, mu = out
    assert np.all(zt >= p.lb) and np.all(zt <= p.ub)
    assert psit < psi0 and np.isclose(psit, fb_psi(fb_phi(zt, p.F(zt), p.lb, p.ub)))
    g_out = gradient_steps(ev, z, f, None, p.lb, p.ub, opt)
    assert g_out is not None and g_out[3] < psi0


def test_options_validation_and_dict():
    o = cs.Options.from_dict({"convergence_tolerance": 1e-8, "crash_method": "none"})
    assert o.convergence_tolerance == 1e-8 and o.crash_method == "none"
    with pytest.raises(cs.OptionError, match="did you mean 'convergence_tolerance'"):
        cs.Options.from_dict({"convergence_tolerence": 1e-8})
    with pytest.raises(cs.OptionError, match="must be > 0"):
        cs.Options(convergence_tolerance=0.0)
    with pytest.raises(cs.OptionError, match="expected one of"):
        cs.Options(crash_method="newton")
    with pytest.raises(cs.OptionError, match="integer"):
        cs.Options(major_iteration_limit=2.5)
    with pytest.raises(cs.OptionError):
        o.replace(no_such_option=1)
    assert "nms_memory_size" in cs.Options.describe()


def test_status_codes_match_path():
    assert [int(s) for s in list(cs.Status)[:10]] == list(range(1, 11))
    assert cs.Status.CALLBACK_STOP.path_code() == 6
    assert cs.Status.SOLVED.path_code() == 1


def test_cli_help_and_demo(capsys):
    from compass_sparse.cli import main

    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    assert "demo" in capsys.readouterr().out
    assert main(["demo", "--problem", "kojshin"]) == 0
    out = capsys.readouterr().out
    assert "SOLVED" in out and "recomputed" in out
    assert main(["demo", "--problem", "structured", "--n", "2000"]) == 0
    assert main(["options"]) == 0


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


def test_every_option_is_read_somewhere():
    """An option that no code reads is a promise the solver does not keep."""
    import dataclasses
    import pathlib
    import re

    root = pathlib.Path(cs.__file__).parent
    src = "\n".join(p.read_text() for p in root.rglob("*.py")
                    if p.name != "_options_base.py")
    unread = [f.name for f in dataclasses.fields(cs.Options)
              if not re.search(r"\.\s*" + f.name + r"\b", src)]
    assert unread == []


def test_cli_progress_flag_and_verbose_levels():
    from compass_sparse.cli import _opts, main

    class A:
        verbose, tol, time_limit, progress = 2, 1e-6, None, True

    o = cs.Options.from_dict(_opts(A))
    assert o.verbosity == 3 and o.progress
    assert main(["demo", "--problem", "kojshin", "--progress"]) == 0