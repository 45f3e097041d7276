"""The command line (compass_sparse.cli): help, demo, options, the progress flag and
the verbose levels."""

import pytest

import compass_sparse as cs


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
