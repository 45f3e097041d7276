"""Batches killed at random points and resumed lose nothing and mix nothing.

A property test of the results folders (compass_sparse.batch: the lock, the model's
fingerprint, the parts written under temporary names with fsync, the merge): random
batches of a small Cournot model are run in child processes that are killed -- SIGKILL or
SIGINT, sent by the child itself at the k-th file operation or model build (a point
chosen at random, reproducible: every choice comes from a seeded generator), or by this
process after a random delay -- alone or with a second batch on the same folder at the
same time, then resumed.  In the end every scenario is stored exactly once, as a solved
row whose point is verified here on the model (its natural residual recomputed), no
temporary or part file is left, and a resume with another model refuses.  The children
interpret their solves (COMPASS_SPARSE_JIT=interpret: no numba in ~20 short processes).
The trials found one defect, pinned by the last test: a batch killed while it ran a
process pool left the pool's workers running.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from compass_sparse.batch import read_results, scenario_key, solve_batch
from compass_sparse.exceptions import CompassError

pytest.importorskip("pyarrow", reason="the batch results need the pyarrow extra")
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

MODEL = textwrap.dedent('''
    """The Cournot model of compass_sparse.examples.cournot with two markets, its demand
    scaled by d and its costs shifted by c: n = 10."""
    import numpy as np
    from compass_sparse import MCP
    from compass_sparse.examples import cournot

    on_build = None  # (a child's hook: called at every model build)

    def model(d, c, markets=2):
        if on_build is not None:
            on_build()
        data = cournot.data(markets, seed=0)
        data["D"] = data["D"] * d
        data["c"] = data["c"] + c
        f = cournot.callables(data)
        return MCP(f["F"], f["jac"], f["lb"], f["ub"], f["x0"], var_names=f["var_names"])

    def other(d, c):
        return model(d, c, markets=3)
    ''')

CHILD = textwrap.dedent('''
    import json, os, signal, sys
    args = json.loads(sys.argv[1])
    sys.path[:0] = [args["root"], args["here"]]
    import batch_kill_model as m
    from compass_sparse.batch import solve_batch
    from compass_sparse.exceptions import CompassError

    main, count = os.getpid(), [0]

    def fire():
        # the k-th event of this (main) process: die here, or be interrupted here
        if os.getpid() != main:
            return
        count[0] += 1
        if count[0] == args["k"]:
            if args["signal"] == "KILL":
                os.kill(main, signal.SIGKILL)
            signal.raise_signal(signal.SIGINT)

    def hooked(real):
        def call(*a, **kw):
            fire()
            return real(*a, **kw)
        return call

    if args["k"]:
        import pyarrow.parquet as pq
        for name in ("replace", "remove", "fsync"):
            setattr(os, name, hooked(getattr(os, name)))
        pq.write_table = hooked(pq.write_table)
        m.on_build = fire
    try:
        print("READY", flush=True)
        b = solve_batch(m.model, args["scenarios"], workers=args["workers"],
                        chunk_size=args["chunk"], output=args["out"], progress=None,
                        lock_timeout=args["wait"])
        print("DONE", b.solved_now, b.resumed, flush=True)
    except KeyboardInterrupt:
        print("INTERRUPTED", flush=True)
        sys.exit(130)
    except CompassError as exc:
        print("REFUSED", type(exc).__name__, flush=True)
    try:
        sys.stdin.readline()  # (a signal sent after the batch ended falls here)
    except KeyboardInterrupt:
        pass
    ''')


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    here = tmp_path_factory.mktemp("kills")
    (here / "batch_kill_model.py").write_text(MODEL)
    (here / "child.py").write_text(CHILD)
    sys.path.insert(0, str(here))
    yield here
    sys.path.remove(str(here))


def _env(out):
    # (BATCH_KILL_RUN marks the processes of a run: the child and its pool's workers)
    return dict(os.environ, COMPASS_SPARSE_JIT="interpret", OPENBLAS_NUM_THREADS="1",
                BATCH_KILL_RUN=str(out))


def _start(files, out, scenarios, *, k=0, sig="KILL", workers=0, chunk=1, wait=0.0):
    args = dict(root=ROOT, here=str(files), out=str(out), scenarios=scenarios, k=k,
                signal=sig, workers=workers, chunk=chunk, wait=wait)
    proc = subprocess.Popen([sys.executable, str(files / "child.py"), json.dumps(args)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(out), cwd=ROOT)
    assert proc.stdout.readline().strip() == "READY"
    return proc


def _end(proc):
    """(how the child ended, its stderr): DONE, REFUSED <error>, INTERRUPTED or KILLED."""
    try:
        proc.stdin.write("\n")  # (the child waits for it after its batch)
        proc.stdin.close()
    except BrokenPipeError:  # (killed before it read its stdin)
        pass
    # (not communicate: the read of READY may have buffered the lines after it)
    out, err = proc.stdout.read(), proc.stderr.read()
    proc.wait(timeout=300)
    if proc.returncode == -signal.SIGKILL:
        return "KILLED", err
    # a child that was not killed ends in one of its own lines, never in a traceback
    assert proc.returncode in (0, 130) and "Traceback" not in err, (proc.returncode, err)
    return out.split("\n")[0].strip(), err


def _trial(rng, files, out, scenarios):
    """One random kill (and perhaps a second batch on the folder meanwhile), then the
    resume; returns what happened, for the failure messages."""
    concurrent = rng.random() < 0.4
    sig = "KILL" if rng.random() < 0.5 else "INT"
    timed = rng.random() < 0.25
    workers = 2 if rng.random() < 0.15 else 0
    chunk = int(rng.integers(1, 4))
    # (a batch of N scenarios in tasks of `chunk` makes about 10 + N + 5 N / chunk file
    # operations and model builds, its merge included: k falls anywhere in them)
    events = 10 + len(scenarios) + 5 * -(-len(scenarios) // chunk)
    k = 0 if timed else int(rng.integers(1, events + 1))
    a = _start(files, out, scenarios, k=k, sig=sig, workers=workers, chunk=chunk)
    b = None
    if concurrent:  # a second batch on the folder: it waits for the lock, or refuses
        b = _start(files, out, scenarios, chunk=int(rng.integers(1, 4)),
                   wait=30.0 if rng.random() < 0.7 else 0.0)
    if timed:
        time.sleep(float(rng.uniform(0.0, 1.0)))  # (where the signal falls, not a limit)
        a.send_signal(signal.SIGKILL if sig == "KILL" else signal.SIGINT)
    ends = [_end(a)[0]] + ([_end(b)[0]] if b is not None else [])
    for end in ends:
        assert end.split()[0] in ("DONE", "INTERRUPTED", "KILLED") or \
            end == "REFUSED FolderLockedError", ends
    import batch_kill_model as m  # (the resume: here, the children are gone)

    again = solve_batch(m.model, scenarios, workers=0, output=out, progress=None,
                        chunk_size=int(rng.integers(1, 4)))
    return dict(sig=sig, k=k, timed=timed, concurrent=concurrent, workers=workers,
                chunk=chunk, ends=ends, resumed=again.resumed)


def _check_folder(out, scenarios, what):
    """Every scenario stored exactly once, solved, its point verified on the model; no
    part or temporary file left; another model refused."""
    import batch_kill_model as m

    table = read_results(out)
    keys = table.column("key").to_pylist()
    assert sorted(keys) == sorted(scenario_key(s) for s in scenarios), what
    assert len(set(keys)) == len(keys), what
    for row in table.to_pylist():
        assert row["status"] == "SOLVED" and row["success"], (what, row["message"])
        params = json.loads(row["params"])
        p = m.model(**params)
        x = np.asarray(row["x"], dtype=float)
        natural = float(np.max(np.abs(x - np.clip(x - p.F(x), p.lb, p.ub))))
        assert natural <= 1e-6 * max(1.0, float(np.max(np.abs(x)))), (what, params, natural)
    names = os.listdir(out)
    assert not [f for f in names if f.endswith(".tmp") or f.startswith("part-")], (what, names)
    assert not os.path.exists(os.path.join(out, "quarantine")), what
    with pytest.raises(CompassError, match="another model"):
        solve_batch(m.other, scenarios, workers=0, output=out, progress=None)
    assert read_results(out).num_rows == len(scenarios)  # (the refusal changed nothing)


SCENARIOS = [{"d": float(d), "c": float(c)} for d in (0.8, 0.9, 1.0, 1.1, 1.2)
             for c in (0.0, 0.5, 1.0)]


@pytest.mark.parametrize("seed", range(8))
def test_batches_killed_at_random_points_and_resumed_store_every_scenario_once(
        files, tmp_path, seed):
    """Seeded trials (a trial's seed reproduces its choices): a batch of 4 to 10 of the
    15 scenarios killed by SIGKILL or SIGINT at a random point, alone or with a second
    batch on the folder, then resumed; the folder then holds every scenario once, each
    solved and verified, and refuses another model."""
    rng = np.random.default_rng(1000 + seed)
    pick = rng.choice(len(SCENARIOS), size=int(rng.integers(4, 11)), replace=False)
    scenarios = [SCENARIOS[i] for i in sorted(pick)]
    out = tmp_path / "out"
    what = _trial(rng, files, out, scenarios)
    _check_folder(str(out), scenarios, what)


def _processes_of(out) -> list[int]:
    """Pids of the processes of the run writing to ``out`` (see :func:`_env`)."""
    marker = f"BATCH_KILL_RUN={out}\0".encode()
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/environ", "rb") as fh:
                    if marker in fh.read():
                        pids.append(int(d))
            except OSError:  # gone, or not ours
                pass
    return pids


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads /proc")
def test_a_batch_killed_with_a_process_pool_leaves_no_worker_running(files, tmp_path):
    """A batch on a local pool of 2 workers, killed (SIGKILL) while its first parts are
    written: its workers end within a second.  Found by the property test above: the old
    workers waited for tasks forever, holding their memory and the killed batch's output
    pipes (the trial that read the batch's output hung until they were killed)."""
    out = tmp_path / "out"
    proc = _start(files, out, SCENARIOS[:8], k=6, sig="KILL", workers=2, chunk=1)
    proc.wait(timeout=300)  # (not its output: a worker left running would hold the pipes)
    for pipe in (proc.stdin, proc.stdout, proc.stderr):
        pipe.close()
    assert proc.returncode == -signal.SIGKILL
    t, left = time.monotonic(), _processes_of(out)
    while left and time.monotonic() - t < 60:  # (a hang detector, not a measure of time)
        time.sleep(0.1)
        left = _processes_of(out)
    for pid in left:  # (the old workers: ended here, not left behind by the test)
        os.kill(pid, signal.SIGKILL)
    assert left == [], "pool workers left running"
    import batch_kill_model as m  # the folder resumes

    again = solve_batch(m.model, SCENARIOS[:8], workers=0, output=out, progress=None)
    assert again.solved_now + again.resumed == 8
    _check_folder(str(out), SCENARIOS[:8], "pool killed")
