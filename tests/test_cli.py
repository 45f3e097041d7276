"""The command line (compass_sparse.cli): help, demo, options, the progress flag and
the verbose levels; mistakes are one line and exit code 2, found before any solving;
--version; -v before the command; the summary once; option lines that fit the terminal;
Ctrl-C in a batch says how to resume; a shortened sweep table says so."""

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
