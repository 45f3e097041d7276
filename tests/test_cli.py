"""The command line (compass_sparse.cli): help, demo, options, the progress flag and
the verbose levels; mistakes are one line and exit code 2, found before any solving;
--version; -v before the command; the summary once; option lines that fit the terminal;
Ctrl-C in a batch says how many scenarios are saved and how to resume, Ctrl-C in one
solve exits 130; output paths that cannot be written and scenario parameters the model
refuses are mistakes found before solving; a shortened sweep table says so."""

import os

import pytest

import compass_sparse as cs
from compass_sparse import cli


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


def test_cli_progress_flag_and_verbose_levels():
    from compass_sparse.cli import _opts, main

    class A:
        verbose, tol, time_limit, progress = 2, 1e-6, None, True

    o = cs.Options.from_dict(_opts(A))
    assert o.verbosity == 3 and o.progress
    assert main(["demo", "--problem", "kojshin", "--progress"]) == 0



@pytest.mark.parametrize("argv, says", [
    (["cge", "--regions", "-1"], "--regions must be at least 1"),
    (["cge", "--sectors", "0"], "--sectors must be at least 1"),
    (["cge", "--scenarios-file", "/no/such/scenarios.csv"], "no such file"),
    (["cge", "--csv", "/no/such/folder/report.csv"], "does not exist"),
    (["cge", "--csv", "."], "is a folder; give a file name"),
    (["cge", "--top", "-2"], "--top must be 0 or more"),
    (["cge", "--regions", "2", "--scenarios", "foo=0:1:3"],
     "unknown scenario parameter 'foo': the parameters are tariff"),
    (["cge", "--regions", "2", "--scenarios", "tariff=0:1:0"], "count a positive integer"),
    (["cge", "--regions", "2", "--scenarios", "tariff=0:x:3"], "scenario axis"),
    (["cge", "--regions", "2", "--scenarios", "tariff"], "expected name=start:stop:count"),
    (["cge", "--tariff", "0.1"], "--regions 2 or more"),
    (["cge", "--workers", "-3"], "--workers must be 0 or more"),
    (["demo", "--time-limit", "-1"], "--time-limit must be positive"),
    (["demo", "--tol", "0"], "--tol must be positive"),
    (["demo", "--n", "0"], "--n must be at least 1"),
])
def test_cli_mistake_is_one_line_and_exit_code_2_before_any_solve(argv, says, capsys,
                                                                  monkeypatch):
    def no_solve(*a, **k):  # a mistake must be found before anything is solved
        raise AssertionError("solved despite a mistake on the command line")
    for name in ("solve_mcp", "solve_lcp", "solve_batch"):
        monkeypatch.setattr(cli, name, no_solve)
    assert cli.main(argv) == cli.EXIT_USAGE
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"compass-sparse {argv[0]}: ")
    if says is not None:
        assert says in err


def test_cli_version(capsys):
    from compass_sparse import __version__

    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"compass-sparse {__version__}"


def test_cli_verbose_before_the_command_logs_and_prints_the_summary_once(capsys, caplog):
    caplog.set_level("INFO", logger="compass_sparse")
    assert cli.main(["-v", "demo", "--problem", "kojshin"]) == 0
    out = capsys.readouterr().out
    assert "major   minor" in caplog.text  # the major-iteration log's header
    assert (out + caplog.text).count("status        SOLVED") == 1


def test_cli_options_lines_fit_the_terminal(capsys, monkeypatch):
    for width in (100, 60):
        monkeypatch.setenv("COLUMNS", str(width))
        assert cli.main(["options"]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert max(len(s) for s in lines) < width
        assert any(s.startswith("convergence_tolerance") for s in lines)


def test_cli_batch_interrupt_says_how_to_resume(capsys, monkeypatch, tmp_path):
    def interrupted(*a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "solve_batch", interrupted)
    out = tmp_path / "runs"
    rc = cli.main(["cge", "--regions", "2", "--sectors", "3", "--scenarios",
                   "tariff=0:0.2:3", "--output", str(out), "--workers", "0"])
    assert rc == cli.EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert str(out) in err and "again to resume" in err


def test_cli_sweep_table_says_how_many_rows_it_shows(capsys, tmp_path):
    pytest.importorskip("pyarrow", reason="the batch extra (pyarrow) is not installed")
    out = tmp_path / "runs"
    rc = cli.main(["cge", "--regions", "2", "--sectors", "3", "--scenarios",
                   "tariff=0:0.24:13", "--output", str(out), "--workers", "0"])
    assert rc == 0
    text = capsys.readouterr().out
    assert f"(11 of 13 scenarios shown, evenly spaced; every row is in {out}/)" in text


def _no_solve(monkeypatch):
    def no_solve(*a, **k):  # a mistake must be found before anything is solved
        raise AssertionError("solved despite a mistake on the command line")
    for name in ("solve_batch",):
        monkeypatch.setattr(cli, name, no_solve)


def _one_line_usage(capsys, argv, says):
    assert cli.main(argv) == cli.EXIT_USAGE
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("compass-sparse cge: "), err
    assert says in err, err


def test_cli_output_folder_under_a_file_is_a_mistake_found_before_solving(tmp_path, capsys,
                                                                         monkeypatch):
    """The old command built the model, printed its header and died in os.makedirs with a
    NotADirectoryError (or FileExistsError) traceback, exit 1."""
    _no_solve(monkeypatch)
    afile = tmp_path / "afile"
    afile.write_text("")
    base = ["cge", "--regions", "2", "--sectors", "3", "--scenarios", "tariff=0:0.1:2",
            "--workers", "0", "--output"]
    _one_line_usage(capsys, base + [str(afile / "runs")], "is a file, so the folder cannot")
    _one_line_usage(capsys, base + [str(afile)], "is a file, not a folder")


def test_cli_csv_that_is_a_folder_is_a_mistake_found_before_solving(tmp_path, capsys,
                                                                   monkeypatch):
    """The old command solved, printed the report and then died with IsADirectoryError."""
    def no_solve(*a, **k):
        raise AssertionError("solved despite a mistake on the command line")
    monkeypatch.setattr(cli, "solve_mcp", no_solve)
    _one_line_usage(capsys, ["cge", "--sectors", "3", "--csv", str(tmp_path)],
                    "is a folder; give a file name")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into any folder")
def test_cli_output_in_a_folder_that_is_not_writable_is_a_mistake(tmp_path, capsys,
                                                                   monkeypatch):
    _no_solve(monkeypatch)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _one_line_usage(capsys, ["cge", "--sectors", "3", "--csv", str(ro / "r.csv")],
                        "is not writable")
        _one_line_usage(capsys, ["cge", "--regions", "2", "--sectors", "3", "--scenarios",
                                 "tariff=0:0.1:2", "--output", str(ro / "runs")],
                        "not writable")
    finally:
        ro.chmod(0o755)


def test_cli_scenario_value_the_model_refuses_is_a_mistake_not_failed_rows(capsys,
                                                                           monkeypatch,
                                                                           tmp_path):
    """The old command solved the batch and stored an ERROR row for tariff = -1 (and for
    an unknown parameter name, a row per scenario), exit 1."""
    _no_solve(monkeypatch)
    base = ["cge", "--regions", "2", "--sectors", "3", "--workers", "0", "--output",
            str(tmp_path / "runs"), "--scenarios"]
    _one_line_usage(capsys, base + ["tariff=-1:0.1:3"], "scenario tariff = -1.0: tariffs "
                    "must be > -1")
    _one_line_usage(capsys, base + ["output_tax=0:1:3"], "scenario output_tax = 1.0")
    assert not (tmp_path / "runs").exists()


def test_cli_batch_interrupt_says_how_many_scenarios_are_saved(capsys, monkeypatch,
                                                               tmp_path):
    """A real batch stopped by Ctrl-C at its third scenario (one scenario per task, so the
    first two are written): the message counts them, and the same command resumes them.
    The old message did not say how many were saved."""
    pytest.importorskip("pyarrow", reason="the batch extra (pyarrow) is not installed")
    real = cli.solve_batch

    class StopAtThird:
        def __init__(self, model):
            self.inner = cli.CGEScenarioModel(model)

        def __call__(self, **params):
            if params["tariff"] == 0.2:
                raise KeyboardInterrupt
            return self.inner(**params)

    def batch(model, scenarios, **kw):
        return real(StopAtThird(model), scenarios, chunk_size=1, **kw)

    monkeypatch.setattr(cli, "solve_batch", batch)
    out = tmp_path / "runs"
    argv = ["cge", "--regions", "2", "--sectors", "3", "--scenarios", "tariff=0:0.2:3",
            "--output", str(out), "--workers", "0"]
    assert cli.main(argv) == cli.EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert f"2 of 3 scenarios saved in {out}/" in err and "again to resume" in err
    monkeypatch.setattr(cli, "solve_batch", real)
    assert cli.main(argv) == 0
    assert "3 scenarios (1 solved now, 2 resumed)" in capsys.readouterr().out


def test_cli_ctrl_c_in_one_solve_exits_130_after_its_summary(capsys, monkeypatch):
    """Ctrl-C inside a solve ends it with USER_INTERRUPT and its best point; the old
    command printed the economics of that point and exited 1, as for a failed solve."""
    real = cli.solve_mcp

    def interrupted_solve(problem, options=None, **kw):
        if options.get("major_iteration_limit") == 0:  # (the benchmark replication)
            return real(problem, options=options, **kw)

        def ctrl_c(info):
            raise KeyboardInterrupt
        return real(problem, options=options, callback=ctrl_c, **kw)

    monkeypatch.setattr(cli, "solve_mcp", interrupted_solve)
    rc = cli.main(["cge", "--sectors", "3", "--output-tax", "0.3"])
    out = capsys.readouterr().out
    assert rc == cli.EXIT_INTERRUPTED
    assert "USER_INTERRUPT" in out and "economics of the counterfactual" not in out
    monkeypatch.setattr(cli, "solve_mcp", real)
    assert cli.main(["cge", "--sectors", "3", "--output-tax", "0.3"]) == 0
    assert "economics of the counterfactual\n" in capsys.readouterr().out
