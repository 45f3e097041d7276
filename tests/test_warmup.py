"""The warm-up (compass_sparse.warmup): Ctrl-C stops it and its workers cleanly."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _processes_with(marker: str) -> list[int]:
    """Pids of this user's processes whose environment holds ``marker``."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if marker.encode() in (d / "environ").read_bytes():
                    pids.append(int(d.name))
            except OSError:  # gone, or not ours
                pass
    return pids


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_ctrl_c_in_the_warm_up_stops_its_workers_without_a_traceback(tmp_path):
    """Ctrl-C on the terminal (SIGINT to the foreground process group) once the warm-up's
    worker has compiled its first kernel on an empty cache: exit code 130 with one line,
    no traceback, no worker left.  The old workers shared the terminal's process group:
    each got the interrupt in numba's compiler and printed a traceback through numba's
    frames, and an interrupt sent to the warm-up alone left them compiling."""
    cache = tmp_path / "numba-cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "compass_sparse.cli", "warmup",
                             "--jobs", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=ROOT, start_new_session=True)
    assert proc.stdout.readline().startswith("compiling the solver's kernels")
    t = time.monotonic()
    while not list(cache.rglob("*.nbi")):  # the first kernel compiled and saved
        assert proc.poll() is None and time.monotonic() - t < 300, "no kernel compiled"
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)  # (the terminal's Ctrl-C: the whole group)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().endswith("compass-sparse warmup: "
                                                            "interrupted"), err
    assert _processes_with(str(cache)) == []
