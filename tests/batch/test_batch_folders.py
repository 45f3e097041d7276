"""Results folders that lose nothing and mix nothing: the model's fingerprint, the folder's
lock, per-writer temporary names, fsync around renames, and damaged parts quarantined and
solved again.  The kill-and-resume property test is in test_batch_kills.py."""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest

from compass_sparse import MCP
from compass_sparse.batch import grid, read_results, solve_batch
from compass_sparse.exceptions import CompassError

pytest.importorskip("pyarrow", reason="the batch results need the pyarrow extra")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def markets(n, scale=1.0):
    """A family of n-variable parametric NCPs (a P-matrix M, q depending on a): an
    n-market model whose data can be changed by ``scale``."""
    M = 4.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)

    def model(a):
        q = -scale * (1.0 + a) * np.linspace(1.0, 2.0, n)
        return MCP(lambda z: M @ z + q, lambda z: M, 0.0, np.inf, np.zeros(n))

    return model


SC = grid(a=[0.0, 0.5, 1.0])


# ------------------------------------------------------------ item 1: the model's fingerprint
def test_resume_with_another_model_refuses_instead_of_returning_the_first_models_rows(
        tmp_path):
    """b6f9c1f: the 10-variable model's batch "resumed" all 3 rows of the 15-variable
    one and returned x of shape (3, 15)."""
    first = solve_batch(markets(15), SC, workers=0, output=tmp_path, progress=None)
    assert first.x.shape == (3, 15)
    with pytest.raises(CompassError, match=r"variables \(n\): 10 here, 15 in the "
                       "folder") as err:
        solve_batch(markets(10), SC, workers=0, output=tmp_path, progress=None)
    assert type(err.value).__name__ == "ModelMismatchError"
    assert str(tmp_path) in str(err.value) and len(str(err.value).splitlines()) == 1
    # same order, other data: F differs
    with pytest.raises(CompassError, match="F at the start point differs"):
        solve_batch(markets(15, scale=2.0), SC, workers=0, output=tmp_path, progress=None)
    # a tighter tolerance makes the stored rows mean something else
    with pytest.raises(CompassError, match="convergence_tolerance: 1e-10 here"):
        solve_batch(markets(15), SC, workers=0, output=tmp_path, progress=None,
                    options={"convergence_tolerance": 1e-10})
    # the same model resumes
    again = solve_batch(markets(15), SC, workers=0, output=tmp_path, progress=None)
    assert again.resumed == 3 and again.solved_now == 0


def test_resume_with_another_model_into_a_fresh_store_keeps_the_old_results(tmp_path):
    """(A new argument, on_mismatch; b6f9c1f mixed the two models' rows.)"""
    solve_batch(markets(15), SC, workers=0, output=tmp_path, progress=None)
    fresh = solve_batch(markets(10), SC, workers=0, output=tmp_path, progress=None,
                        on_mismatch="new")
    assert fresh.solved_now == 3 and fresh.x.shape == (3, 10)
    prev = [d for d in os.listdir(tmp_path) if d.startswith("previous-")]
    assert len(prev) == 1
    kept = read_results(tmp_path / prev[0])
    assert kept.num_rows == 3 and len(kept.column("x")[0]) == 15  # nothing lost
    assert read_results(tmp_path).num_rows == 3
    assert len(read_results(tmp_path).column("x")[0]) == 10


def test_fingerprint_tolerance_separates_rounding_from_changed_data():
    """(New module: b6f9c1f kept no fingerprint.)  FINGERPRINT_RTOL = 1e-9: data rebuilt with relative errors of 1e-13 (another BLAS)
    match, data changed by 1e-7 do not; elasticity-like changes that leave the start a
    solution (F(x0) = 0) are seen by F near the start."""
    from compass_sparse.batch.fingerprint import FINGERPRINT_RTOL, compare, model_fingerprint

    n = 30
    rng = np.random.default_rng(0)
    A = rng.standard_normal((n, n))
    x0 = rng.uniform(0, 1, n)

    def mcp(A):
        b = A @ x0  # F(x0) = 0 whatever A: the start is a solution
        return MCP(lambda z: A @ z - b, lambda z: A, -np.inf, np.inf, x0)

    ref = model_fingerprint(mcp(A), 1e-6)
    assert FINGERPRINT_RTOL == 1e-9
    assert compare(model_fingerprint(mcp(A * (1 + 1e-13 * rng.standard_normal((n, n)))),
                                     1e-6), ref) == []
    diffs = compare(model_fingerprint(mcp(A * (1 + 1e-7 * rng.standard_normal((n, n)))),
                                      1e-6), ref)
    assert [d[0] for d in diffs] == ["F near the start point"]


def test_cli_batch_resume_with_another_model_exits_2_with_one_line(tmp_path, capsys):
    """b6f9c1f: the second command reported "3 resumed" and printed the first model's
    numbers (exit 0)."""
    from compass_sparse.cli import main

    out = str(tmp_path / "res")
    base = ["cge", "--sectors", "10", "--workers", "0", "--scenarios", "tariff=0:0.2:2",
            "--output", out]
    assert main(base[:1] + ["--regions", "3"] + base[1:]) == 0
    capsys.readouterr()
    assert main(base[:1] + ["--regions", "2"] + base[1:]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "another model" in err and "n" in err
    assert main(base[:1] + ["--regions", "2"] + base[1:] + ["--fresh"]) == 0


# ------------------------------------------------------------ item 5: two runs on one folder
def test_second_batch_on_a_locked_folder_refuses_naming_the_owner_or_waits(tmp_path):
    """(New: b6f9c1f had no lock, and a second batch ran alongside the first; see
    test_two_batches_on_one_folder_never_crash_and_lose_no_row.)"""
    from compass_sparse.batch.lock import FolderLock
    from compass_sparse.exceptions import FolderLockedError

    with FolderLock(tmp_path):
        with pytest.raises(FolderLockedError, match=f"pid {os.getpid()}") as err:
            solve_batch(markets(4), SC, workers=0, output=tmp_path, progress=None)
        assert err.value.owner["pid"] == os.getpid()
    # a batch that waits gets the folder when the other lets go
    held = FolderLock(tmp_path)
    held.acquire()
    threading.Timer(0.5, held.release).start()
    t = time.monotonic()
    out = solve_batch(markets(4), SC, workers=0, output=tmp_path, progress=None,
                      lock_timeout=30)
    assert out.solved_now == 3 and time.monotonic() - t >= 0.4


def test_stale_lock_of_a_dead_process_is_taken_over(tmp_path, caplog):
    """(New: b6f9c1f had no lock.)"""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    pid = int(dead.stdout)
    (tmp_path / ".lock").write_text(json.dumps({"pid": pid, "host": os.uname().nodename,
                                                "started": "2026-01-01T00:00:00+00:00"}))
    with caplog.at_level(logging.INFO, logger="compass_sparse"):
        out = solve_batch(markets(4), SC, workers=0, output=tmp_path, progress=None)
    assert out.solved_now == 3
    assert any(f"pid {pid}" in r.getMessage() and "took over" in r.getMessage()
               for r in caplog.records)
    assert (tmp_path / ".lock").read_text() == ""  # released


_CONCURRENT = """
import sys
sys.path.insert(0, {root!r})
import numpy as np
from compass_sparse import MCP
from compass_sparse.batch import solve_batch, grid
from compass_sparse.exceptions import CompassError

M = 4.0 * np.eye(3) - np.eye(3, k=1) - np.eye(3, k=-1)
def model(a):
    q = -(1.0 + a) * np.ones(3)
    return MCP(lambda z: M @ z + q, lambda z: M, 0.0, np.inf, np.zeros(3))

try:
    b = solve_batch(model, grid(a=np.linspace(0, 1, 24)), workers=0, chunk_size=1,
                    output={out!r}, progress=None)
    print("DONE", b.solved_now, b.resumed)
except CompassError as exc:
    print("REFUSED", type(exc).__name__, str(exc).splitlines()[0])
"""


def test_two_batches_on_one_folder_never_crash_and_lose_no_row(tmp_path):
    """b6f9c1f: both runs merged through the same temporary name and deleted the parts
    the other had listed: a raw FileNotFoundError in ~80 % of the trials, finished rows
    lost in some."""
    for trial in range(3):
        out = str(tmp_path / f"out{trial}")
        script = tmp_path / f"run{trial}.py"
        script.write_text(_CONCURRENT.format(root=ROOT, out=out))
        procs = [subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for _ in range(2)]
        outs = [p.communicate(timeout=300) for p in procs]
        for p, (o, e) in zip(procs, outs):
            assert p.returncode == 0, e[-3000:]
            assert o.startswith("DONE") or o.startswith("REFUSED FolderLockedError"), o
        rerun = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                               timeout=300)
        assert rerun.stdout.startswith("DONE"), rerun.stderr[-3000:]
        keys = read_results(out).column("key").to_pylist()
        assert len(keys) == 24 and len(set(keys)) == 24
        assert sorted(f for f in os.listdir(out) if f.endswith(".parquet")) == \
            ["results.parquet"]


def test_each_writer_has_its_own_temporary_names(tmp_path, monkeypatch):
    """b6f9c1f: every merge wrote ".results.parquet.tmp", the same name for every
    process."""
    from compass_sparse.batch.store import ResultStore

    seen = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (seen.append(os.path.basename(a)),
                                                     real(a, b))[1])
    rows = solve_batch(markets(3), SC, workers=0, progress=None).rows
    a, b = ResultStore(tmp_path), ResultStore(tmp_path)
    a.write(rows[:1])
    b.write(rows[1:2])
    a.compact()
    b.write(rows[2:])
    b.compact()
    tmps = [s for s in seen if s.endswith(".tmp")]
    merges = [s for s in tmps if "results.parquet" in s]
    assert len(merges) == 2 and merges[0] != merges[1]
    assert len(set(tmps)) == len(tmps)
    assert read_results(tmp_path).num_rows == 3


def test_reader_that_lists_a_part_a_merge_deletes_reads_again(tmp_path, monkeypatch):
    """b6f9c1f: a reader that listed a part the merge then deleted raised a raw
    FileNotFoundError."""
    from compass_sparse.batch.store import ResultStore

    rows = solve_batch(markets(3), SC, workers=0, progress=None).rows
    w = ResultStore(tmp_path)
    for r in rows:
        w.write([r])
    real = ResultStore.files
    listing = real(w)
    calls = []

    def stale_then_fresh(self):
        calls.append(1)
        if len(calls) == 1:
            w.compact()  # merged and deleted after the reader listed the parts
            return listing
        return real(self)

    monkeypatch.setattr(ResultStore, "files", stale_then_fresh)
    table = read_results(tmp_path)
    assert table.num_rows == 3 and len(calls) >= 2


# ------------------------------------------------------------ item 6: damaged parts, fsync
def test_truncated_part_is_quarantined_and_its_scenarios_solved_again(tmp_path):
    """b6f9c1f: every later resume raised pyarrow's raw ArrowInvalid."""
    sc = grid(a=np.linspace(0, 1, 6))
    solve_batch(markets(4), sc, workers=0, output=tmp_path, progress=None, chunk_size=2,
                compact=False)
    parts = sorted(p for p in os.listdir(tmp_path) if p.startswith("part-"))
    assert len(parts) >= 2
    bad = tmp_path / parts[0]
    data = bad.read_bytes()
    bad.write_bytes(data[: len(data) // 2])  # a crash in the middle of the write
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = solve_batch(markets(4), sc, workers=0, output=tmp_path, progress=None)
    msgs = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert any(parts[0] in m and "quarantine" in m for m in msgs), msgs
    assert again.solved_now >= 1 and again.solved_now + again.resumed == 6
    assert all(again.column("success"))
    assert (tmp_path / "quarantine" / parts[0]).exists()  # kept, not deleted
    keys = read_results(tmp_path).column("key").to_pylist()
    assert len(keys) == 6 and len(set(keys)) == 6


def test_reader_skips_an_unreadable_file_with_a_warning_and_moves_nothing(tmp_path):
    solve_batch(markets(4), SC, workers=0, output=tmp_path, progress=None, chunk_size=1,
                compact=False)
    part = sorted(p for p in os.listdir(tmp_path) if p.startswith("part-"))[0]
    (tmp_path / part).write_bytes(b"PAR1 not a parquet file")
    with pytest.warns(RuntimeWarning, match="skipped"):
        table = read_results(tmp_path)
    assert table.num_rows == 2 and (tmp_path / part).exists()


def test_parts_are_flushed_to_disk_before_and_after_the_rename(tmp_path, monkeypatch):
    """b6f9c1f renamed parts into place without fsync: a machine crash could leave a
    truncated file under a final name."""
    from compass_sparse.batch.store import ResultStore

    events = []
    real_fsync, real_replace, real_open = os.fsync, os.replace, os.open
    names = {}

    def op(path, flags, *a):
        fd = real_open(path, flags, *a)
        names[fd] = os.path.basename(os.fspath(path)) or os.fspath(path)
        return fd

    monkeypatch.setattr(os, "open", op)
    monkeypatch.setattr(os, "fsync", lambda fd: (events.append(("fsync", names.get(fd))),
                                                 real_fsync(fd))[1])
    monkeypatch.setattr(os, "replace", lambda a, b: (events.append(
        ("replace", os.path.basename(a), os.path.basename(b))), real_replace(a, b))[1])
    rows = solve_batch(markets(3), SC[:1], workers=0, progress=None).rows
    ResultStore(tmp_path).write(rows)
    k = next(i for i, e in enumerate(events) if e[0] == "replace")
    tmp, final = events[k][1], events[k][2]
    assert final.startswith("part-") and tmp.endswith(".tmp")
    assert ("fsync", tmp) in events[:k]  # the file's data before its rename
    assert ("fsync", os.path.basename(str(tmp_path))) in events[k + 1:]  # the folder after
