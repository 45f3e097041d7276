"""Scenario batches: executors agree, warm starts save major iterations, results are written
as tasks finish and a rerun resumes, failures are rows, the scenario tree and the progress
display."""
from __future__ import annotations

import io
import json
import logging
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from compass_sparse import MCP
from compass_sparse.batch import (
    CGEScenarioModel,
    grid,
    parse_axis,
    read_results,
    read_scenarios,
    scenario_key,
    scenario_tree,
    solve_batch,
)
from compass_sparse.batch.runner import _Counts
from compass_sparse.batch.tree import paths as _paths
from compass_sparse.exceptions import OptionError
from compass_sparse.progress import Progress

pytest.importorskip("pyarrow", reason="the batch results need the pyarrow extra")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def cge():
    from compass_sparse.generators.cge import static_cge

    # n = 332: above the dense-basis threshold, 3-4 major iterations from the benchmark
    return static_cge(regions=2, sectors=40, households=1, seed=1)


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def _ncp(a, b):
    """A small parametric NCP: z _|_ M z + q(a, b), with M a P-matrix."""
    M = np.array([[4.0, -1, 0, 0], [-1, 4, -1, 0], [0, -1, 4, -1], [0, 0, -1, 4]])
    q = np.array([-1.0, a, -2 + b, 1 - a])
    return MCP(lambda z: M @ z + q, lambda z: M, 0.0, np.inf, np.zeros(4))


CGE_GRID = grid(tariff=[0.0, 0.1, 0.2, 0.3], sigma_armington=[1.5, 3.0])


def test_local_pool_and_in_process_runs_give_identical_results(cge):
    a = solve_batch(cge, CGE_GRID, workers=0, progress=None)
    b = solve_batch(cge, CGE_GRID, workers=2, progress=None, chunk_size=2)
    assert a.statuses == b.statuses == ["SOLVED"] * len(CGE_GRID)
    assert np.max(np.abs(a.x - b.x)) <= 1e-10
    # the solutions solve their own scenarios (recomputed here, not the solver's word)
    model = CGEScenarioModel(cge)
    for s, x in zip(CGE_GRID[::3], a.x[::3]):
        assert model.cge(**s).natural_residual(x) <= 1e-6


@pytest.mark.slow
def test_dask_local_cluster_and_local_pool_give_identical_results(cge):
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    local = solve_batch(cge, CGE_GRID, workers=2, progress=None, chunk_size=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        dask = solve_batch(cge, CGE_GRID, executor=client, progress=None, chunk_size=2)
    assert dask.executor == "dask"
    assert dask.statuses == local.statuses
    assert np.max(np.abs(dask.x - local.x)) <= 1e-10


def test_warm_starts_along_the_grid_take_fewer_major_iterations_than_cold(cge):
    sc = grid(tariff=np.linspace(0, 0.3, 7))
    cold = solve_batch(cge, sc, workers=0, warm_start=False, progress=None)
    warm = solve_batch(cge, sc, workers=0, predictor=False, progress=None)
    pred = solve_batch(cge, sc, workers=0, progress=None)
    for b in (cold, warm, pred):
        assert b.failed == 0
    assert warm.column("nit").mean() < cold.column("nit").mean()
    assert pred.column("nit").mean() <= warm.column("nit").mean()
    assert "predicted" in [r["start"] for r in pred.rows]
    assert np.max(np.abs(pred.x - cold.x)) < 1e-6


def test_failed_scenario_is_a_row_with_its_status_not_an_exception():
    def model(a, b):
        if a > 1.5:
            raise ValueError("no model for a > 1.5")
        return _ncp(a, b)

    sc = grid(a=[0.0, 1.0, 2.0], b=[0.0, 1.0])
    out = solve_batch(model, sc, workers=0, progress=None,
                      options={"major_iteration_limit": 50})
    st = {(s["a"], s["b"]): r for s, r in zip(sc, out.rows)}
    assert st[(2.0, 0.0)]["status"] == "ERROR" and "a > 1.5" in st[(2.0, 0.0)]["message"]
    assert sum(r["success"] for r in out.rows) == 4 and out.failed == 2
    # a limit is a status too
    lim = solve_batch(_ncp, grid(a=[0.0, 1.0], b=[0.0]), workers=0, warm_start=False,
                      progress=None, options={"major_iteration_limit": 0})
    assert {r["status"] for r in lim.rows} == {"MAJOR_ITERATION_LIMIT"}


def test_rerun_with_the_same_output_resumes_without_solving_again(tmp_path):
    sc = grid(a=[0.0, 0.5, 1.0], b=[0.0, 1.0])
    first = solve_batch(_ncp, sc, workers=0, output=tmp_path, progress=None)
    # the merged results, the model's fingerprint and the (released) lock file
    assert first.solved_now == 6
    assert sorted(os.listdir(tmp_path)) == [".lock", "model.json", "results.parquet"]
    again = solve_batch(_ncp, sc, workers=0, output=tmp_path, progress=None)
    assert again.solved_now == 0 and again.resumed == 6
    np.testing.assert_array_equal(again.x, first.x)
    more = solve_batch(_ncp, sc + [{"a": 2.0, "b": 0.0}], workers=0, output=tmp_path,
                       progress=None)
    assert more.solved_now == 1 and more.failed == 0
    table = read_results(tmp_path)
    assert table.num_rows == 7 and len(set(table.column("key").to_pylist())) == 7
    assert set(table.column("param.a").to_pylist()) == {0.0, 0.5, 1.0, 2.0}


_KILL_SCRIPT = """
import sys, time
sys.path.insert(0, {root!r})
import numpy as np
from compass_sparse import MCP
from compass_sparse.batch import solve_batch, grid

M = np.array([[3.0, -1.0], [-1.0, 3.0]])
def model(a):
    time.sleep(0.3)  # slow enough to be killed halfway
    with open({log!r}, "a") as fh:
        fh.write(repr(a) + "\\n")
    q = np.array([-1.0 - a, a])
    return MCP(lambda z: M @ z + q, lambda z: M, 0.0, np.inf, np.zeros(2))

b = solve_batch(model, grid(a=np.linspace(0, 1, 16)), workers=0, chunk_size=1,
                output={out!r}, progress=None)
print(b.solved_now, b.resumed)
"""


@pytest.mark.slow
def test_batch_killed_halfway_and_restarted_solves_every_scenario_exactly_once(tmp_path):
    out, log = str(tmp_path / "out"), str(tmp_path / "built.log")
    script = tmp_path / "run.py"
    script.write_text(_KILL_SCRIPT.format(root=ROOT, log=log, out=out))
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE)
    deadline = time.time() + 120
    while time.time() < deadline:
        parts = [f for f in os.listdir(out) if f.startswith("part-")] \
            if os.path.isdir(out) else []
        if len(parts) >= 5:
            break
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    parts = [f for f in os.listdir(out) if f.startswith("part-")]
    assert 5 <= len(parts) < 16, "the batch was not killed halfway"
    finished = len(read_results(out))
    rerun = subprocess.run([sys.executable, str(script)], stdout=subprocess.PIPE, text=True,
                           check=True, timeout=120)
    solved_now, resumed = map(int, rerun.stdout.split())
    assert resumed == finished and solved_now == 16 - finished
    table = read_results(out)
    keys = table.column("key").to_pylist()
    assert len(keys) == 16 and len(set(keys)) == 16
    assert all(table.column("success").to_pylist())
    built = [float(s) for s in Path(log).read_text().split()]
    # every scenario was built once, except at most the one in flight when killed (and
    # the first one, the folder's reference scenario, once more per run: its fingerprint)
    counts = {a: built.count(a) for a in set(built)}
    counts[0.0] -= 2
    assert len(counts) == 16 and sum(c - 1 for c in counts.values()) <= 1


def test_record_keeps_only_the_named_variables(cge):
    names = ["U[r1,h1]", "M[r2,h1]"]
    out = solve_batch(cge, CGE_GRID[:3], workers=0, record=names, progress=None)
    r = out.rows[1]
    assert r["x"] is None and {f"var.{s}" for s in names} <= set(r)
    full = solve_batch(cge, CGE_GRID[:3], workers=0, progress=None)
    assert r["var.U[r1,h1]"] == pytest.approx(full.x[1][cge.index("U[r1,h1]")], abs=1e-8)


def test_scenario_tree_on_a_grid_is_a_comb_of_unit_steps():
    sc = grid(t=np.linspace(0, 1, 6), s=[1.0, 2.0, 3.0])
    parent = scenario_tree(sc)
    assert (parent == -1).sum() == 1
    for i, p in enumerate(parent):
        if p >= 0:  # one grid step in one parameter
            diff = [k for k in sc[i] if sc[i][k] != sc[p][k]]
            assert len(diff) == 1
    # branches along the longer axis: the spine continues into the last one, so 3 paths
    paths = _paths(parent, list(range(len(sc))), chunk_size=100)
    assert sorted(len(p) for p, _ in paths) == [5, 5, 8]
    # chunks never exceed chunk_size and cover every scenario once
    paths = _paths(parent, list(range(len(sc))), chunk_size=4)
    nodes = [i for p, _ in paths for i in p]
    assert sorted(nodes) == list(range(len(sc))) and max(len(p) for p, _ in paths) <= 4


def test_scenario_tree_of_random_draws_links_near_neighbours():
    rng = np.random.default_rng(0)
    sc = [{"a": float(a), "b": float(b)} for a, b in rng.random((200, 2))]
    parent = scenario_tree(sc)
    assert (parent == -1).sum() == 1
    P = np.array([[s["a"], s["b"]] for s in sc])
    step = np.array([np.linalg.norm(P[i] - P[p]) for i, p in enumerate(parent) if p >= 0])
    assert step.max() < 0.2  # a random pairing would have steps ~0.5
    for i in range(len(sc)):  # every scenario reaches the root
        seen, j = 0, i
        while parent[j] >= 0 and seen <= len(sc):
            j, seen = parent[j], seen + 1
        assert parent[j] == -1


def test_scenario_axes_and_files(tmp_path):
    assert parse_axis("tariff=0:0.5:51")[1].size == 51
    np.testing.assert_allclose(parse_axis("s=1,2.5")[1], [1.0, 2.5])
    with pytest.raises(OptionError, match="tariff=0:0.5"):
        parse_axis("tariff=0:0.5")
    (tmp_path / "s.csv").write_text("tariff,sigma_armington\n0.1,2\n0.2,3\n")
    assert read_scenarios(tmp_path / "s.csv") == [{"tariff": 0.1, "sigma_armington": 2.0},
                                                  {"tariff": 0.2, "sigma_armington": 3.0}]
    (tmp_path / "s.json").write_text(json.dumps([{"tariff": 0.3}]))
    assert read_scenarios(tmp_path / "s.json") == [{"tariff": 0.3}]
    assert scenario_key({"a": 1.0, "b": 2}) == scenario_key({"b": 2, "a": np.float64(1.0)})


def test_elasticity_scenarios_rebuild_the_model_with_the_same_benchmark(cge):
    m = CGEScenarioModel(cge)
    low = m.cge(sigma_armington=0.5)
    assert low.fb_norm() < 1e-10  # still calibrated to the same benchmark
    hi, lo = m.cge(sigma_armington=4.0, tariff=0.2), m.cge(sigma_armington=0.5, tariff=0.2)
    assert np.max(np.abs(hi.F(cge.benchmark) - lo.F(cge.benchmark))) > 1e-3


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_draws_a_bar_only_on_a_terminal(caplog):
    caplog.set_level(logging.INFO, logger="compass_sparse")
    lg = logging.getLogger("compass_sparse")
    lg.addHandler(caplog.handler)  # also when an earlier verbose solve stopped propagation
    tty, pipe = _Tty(), io.StringIO()
    try:
        for stream in (tty, pipe):
            p = _Counts(10, 2, Progress(True, stream=stream, after=0.0, every=0.0))
            p.update(3, 1)
            p.close()
    finally:
        lg.removeHandler(caplog.handler)
    assert "5/10 scenarios  failed 1" in tty.getvalue() and "\r[" in tty.getvalue()
    assert pipe.getvalue() == ""
    assert any("5/10 scenarios" in r.getMessage() for r in caplog.records)


def test_cli_cge_scenarios_writes_results_and_prints_headlines(tmp_path, capsys):
    from compass_sparse.cli import main

    out = tmp_path / "res"
    code = main(["cge", "--regions", "2", "--sectors", "40", "--workers", "0",
                 "--scenarios", "tariff=0:0.2:3", "--output", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "tariff" in text and "welfare" in text and text.count("SOLVED") == 3
    table = read_results(out)
    assert table.num_rows == 3 and all(table.column("success").to_pylist())
    assert main(["cge", "--regions", "1", "--workers", "0", "--scenarios",
                 "tariff=0:0.2:3", "--output", str(out)]) == 2


def test_record_of_named_variables_does_not_lose_warm_starts_within_a_path(cge):
    sc = grid(tariff=np.linspace(0, 0.3, 4))
    named = solve_batch(cge, sc, workers=0, record=["U[r1,h1]"], chunk_size=4, progress=None)
    starts = [r["start"] for r in named.rows]
    assert starts[0] == "cold" and "cold" not in starts[1:]
    assert all(r["x"] is None for r in named.rows)


def _dies_at_two(a, b):
    if a == 2.0:
        os._exit(3)  # a crash of the worker process, not an exception
    return _ncp(a, b)


def test_worker_process_that_dies_fails_only_its_own_scenario_and_the_batch_goes_on():
    sc = grid(a=[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], b=[0.0])
    out = solve_batch(_dies_at_two, sc, workers=2, warm_start=False, chunk_size=1,
                      progress=None)
    rows = {s["a"]: r for s, r in zip(sc, out.rows)}
    assert rows[2.0]["status"] == "ERROR" and "task failed" in rows[2.0]["message"]
    # tasks in flight in the broken pool are retried alone: every other scenario is solved
    assert [a for a, r in rows.items() if not r["success"]] == [2.0]


_CRASH_SCRIPT = """
import os, sys
sys.path.insert(0, {root!r})
import numpy as np
from compass_sparse import MCP
from compass_sparse.batch import solve_batch, grid

def model(a):
    if a == 2.0:
        os._exit(3)
    M = np.array([[3.0, -1.0], [-1.0, 3.0]])
    q = np.array([-1.0 - a, a])
    return MCP(lambda z: M @ z + q, lambda z: M, 0.0, np.inf, np.zeros(2))

# no `if __name__ == "__main__"` guard: the pool (and its replacement) must fork
out = solve_batch(model, grid(a=[0.0, 1.0, 2.0, 3.0, 4.0]), workers=2, warm_start=False,
                  chunk_size=1, progress=None)
print(" ".join(r["status"] for r in out.rows))
"""


@pytest.mark.skipif(sys.platform != "linux", reason="the pool forks only on Linux")
def test_replacement_pool_after_a_worker_crash_forks_like_the_first_in_an_unguarded_script(
        tmp_path):
    script = tmp_path / "crash.py"
    script.write_text(_CRASH_SCRIPT.format(root=ROOT))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["SOLVED", "SOLVED", "ERROR", "SOLVED", "SOLVED"]
