"""benchmarks/bench_path_kernels.py replays captured paths on copies of their arguments:
the copies must be the same types to the compiled kernels as the originals."""
import importlib.util
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_path_kernels.py"


def _module():
    import sys
    sys.path.insert(0, str(SCRIPT.parent))  # (its own helper module _revision)
    try:
        spec = importlib.util.spec_from_file_location("bench_path_kernels", SCRIPT)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(SCRIPT.parent))
    return mod


def test_replay_copies_keep_the_fortran_layout_of_the_dense_placeholders():
    """The sparse engine's argument tuple holds Fortran-ordered placeholders; copied to C
    order they made the first replay compile the path kernels again inside its timing
    (61 s of "path kernels" with --repeats 1)."""
    mod = _module()
    args = (np.zeros((2, 2), order="F"), (np.zeros(3), np.zeros((2, 3), order="F")), 1.5)
    copy = mod._copy(args)
    assert copy[0].flags.f_contiguous and not copy[0].flags.c_contiguous
    assert copy[1][1].flags.f_contiguous and not copy[1][1].flags.c_contiguous
    assert copy[0] is not args[0] and copy[1][0] is not args[1][0] and copy[2] == 1.5
