"""Compiled kernels on first use (compass_sparse._jit): ``import compass_sparse`` does not
load numba, the cold start is decided once per solve (interpreted while numba is not
loaded, for the first small solves of a process) and never switches within a solve,
interpreted kernels solve the small problems as the compiled ones do, lazily built
kernels call each other, and Python callers reach a built kernel's dispatcher."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import known_problems as kp
import numpy as np
import pytest

from compass_sparse import solve_mcp
from compass_sparse.generators import thesis_family

ROOT = Path(__file__).resolve().parent.parent


def test_import_does_not_load_numba():
    """Kernels are compiled or loaded on first use: ``import compass_sparse`` leaves numba
    (0.2-0.4 s of import time) unloaded."""
    code = "import sys, compass_sparse; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


def _cold_env(**extra):
    """The environment of a fresh process with the default cold start (the test session
    itself compiles from the first call: conftest.py)."""
    env = {k: v for k, v in os.environ.items() if k != "COMPASS_SPARSE_JIT"}
    env.update(extra)
    return env


def _run_fresh(code, **env):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=_cold_env(**env), cwd=ROOT)
    return out.stdout.strip().splitlines()[-1]


def test_first_small_solve_of_a_process_does_not_load_numba():
    """A fresh process's first solve of a small problem runs the kernels interpreted (its
    route, recorded in Result.routes): numba (0.5-0.8 s with its first kernel) is not
    loaded, and the solve succeeds.  With COMPASS_SPARSE_JIT=always the same solve
    compiles and loads it."""
    code = ("import sys; sys.path.insert(0, 'tests'); import known_problems as kp; "
            "from compass_sparse import solve_mcp; from compass_sparse._jit import cold_start; "
            "q = kp.kojima_shindo(); r = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0); "
            "print(r.status.name, r.residual.natural <= 1e-6, 'numba' in sys.modules, "
            "cold_start()['interpreting'], r.routes['kernels'])")
    assert _run_fresh(code).split() == ["SOLVED", "True", "False", "True", "interpreted"]
    assert _run_fresh(code, COMPASS_SPARSE_JIT="always").split() == [
        "SOLVED", "True", "True", "False", "compiled"]


def test_cold_start_is_decided_once_per_solve_from_the_process_and_the_size():
    """Whether a solve's kernels are interpreted is decided when it starts, never from the
    clock: the first INTERPRET_SOLVES solves of small problems (n <= INTERPRET_MAX_N) are
    interpreted, the next compiles (and loads numba), and so does every solve after a
    compiled one; a solve of a larger problem compiles at once.  Outside a solve a kernel
    with a large array compiles.  Every kernel of an interpreted solve is interpreted,
    whatever its arrays' sizes."""
    code = textwrap.dedent("""
        import sys
        sys.path.insert(0, "tests")
        import known_problems as kp
        import compass_sparse._jit as J
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        q = kp.cournot_duopoly()
        kinds = [solve_mcp(q.F, q.J, q.lb, q.ub, q.x0).routes["kernels"]
                 for _ in range(J.INTERPRET_SOLVES + 1)]
        print(kinds.count("interpreted"), kinds[-1], "numba" in sys.modules)
        """)
    from compass_sparse._jit import INTERPRET_MAX_N, INTERPRET_SOLVES

    assert _run_fresh(code).split() == [str(INTERPRET_SOLVES), "compiled", "True"]
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, "tests")
        import known_problems as kp
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        big = solve_mcp(thesis_family({INTERPRET_MAX_N + 1}, 1, 1).problem)
        q = kp.cournot_duopoly()
        small = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0)
        print(big.routes["kernels"], small.routes["kernels"], "numba" in sys.modules)
        """)
    assert _run_fresh(code).split() == ["compiled", "compiled", "True"]
    code = textwrap.dedent(f"""
        import sys, numpy as np
        import compass_sparse._jit as J
        from compass_sparse._merit_kernels import all_finite_kernel, max_abs_kernel
        a = max_abs_kernel(np.array([1.0, -3.0]), np.array([1.0, -3.0]), False)
        first = "numba" in sys.modules
        b = all_finite_kernel(np.ones({2 * 4096}))
        print(a, bool(b), first, "numba" in sys.modules)
        """)
    assert _run_fresh(code).split() == ["3.0", "True", "False", "True"]


def test_lazy_kernels_calling_each_other_compile_on_first_use(tmp_path, monkeypatch):
    """A lazily built kernel whose body calls other lazy kernels (of its own module and of
    another one) compiles: the stand-ins are replaced by dispatchers before numba types
    it, and a caller holding a stand-in still reaches the dispatcher."""
    (tmp_path / "lazy_a.py").write_text(
        "from compass_sparse._jit import njit\n"
        "@njit\n"
        "def twice(x):\n    return 2.0 * x\n")
    (tmp_path / "lazy_b.py").write_text(
        "from compass_sparse._jit import njit\n"
        "from lazy_a import twice\n"
        "@njit(inline='always')\n"
        "def plus_one(x):\n    return x + 1.0\n"
        "@njit()\n"
        "def outer(x):\n    return plus_one(twice(x))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import lazy_b

    from compass_sparse._jit import LazyKernel

    stand_in = lazy_b.outer
    assert isinstance(stand_in, LazyKernel)
    assert stand_in(3.0) == 7.0
    assert not isinstance(lazy_b.__dict__["twice"], LazyKernel)
    assert lazy_b.outer(0.5) == 2.0


def test_python_callers_of_a_built_kernel_call_its_dispatcher():
    """Once a kernel is built, the package's modules that imported its stand-in by name
    call the dispatcher itself (a forwarded call costs an extra Python frame at every
    evaluated point)."""
    from compass_sparse import merit
    from compass_sparse._jit import LazyKernel

    z = np.array([1.0, -2.0])
    phi = merit.fb_phi(z, np.array([0.5, 3.0]), np.zeros(2), np.full(2, np.inf))
    assert np.allclose(phi, merit.fb_phi_arrays(z, np.array([0.5, 3.0]), np.zeros(2),
                                                np.full(2, np.inf)))
    assert not isinstance(merit.fb_phi_kernel, LazyKernel)


def test_interpreted_kernels_solve_the_small_problems_as_the_compiled_ones():
    """With every small solve interpreted (COMPASS_SPARSE_JIT=interpret), a fresh process
    solves the known problems and thesis instances at n = 10 with interpreted kernels
    only; statuses, major iterations, pivots, F and J evaluations are the compiled
    kernels' (this process), and both points pass the tolerance."""
    code = textwrap.dedent("""
        import sys, json
        sys.path.insert(0, "tests")
        import known_problems as kp
        from compass_sparse import solve_mcp
        from compass_sparse.generators import thesis_family
        out, routes = {}, set()
        def row(r):
            routes.add(r.routes["kernels"])
            return [r.status.name, r.nit, r.minor_iterations, r.nfev, r.njev,
                    r.residual.natural]
        for name, make in kp.ALL_SOLVABLE.items():
            q = make()
            out[name] = row(solve_mcp(q.F, q.J, q.lb, q.ub, q.x0))
        for fam in (1, 2):
            for seed in (1, 2, 3):
                out[f"f{fam}s{seed}"] = row(solve_mcp(thesis_family(10, fam, seed).problem))
        print(json.dumps([out, "numba" in sys.modules, sorted(routes)]))
        """)
    interpreted, numba_loaded, routes = json.loads(_run_fresh(code, COMPASS_SPARSE_JIT="interpret"))
    assert not numba_loaded and routes == ["interpreted"]
    compiled = {}
    for name, make in kp.ALL_SOLVABLE.items():
        q = make()
        compiled[name] = solve_mcp(q.F, q.J, q.lb, q.ub, q.x0)
    for fam in (1, 2):
        for seed in (1, 2, 3):
            compiled[f"f{fam}s{seed}"] = solve_mcp(thesis_family(10, fam, seed).problem)
    assert set(compiled) == set(interpreted) and len(compiled) > 10
    for key, r in compiled.items():
        assert r.routes["kernels"] == "compiled"
        status, nit, minor, nfev, njev, natural = interpreted[key]
        assert (status, nit, minor, nfev, njev) == (
            r.status.name, r.nit, r.minor_iterations, r.nfev, r.njev), key
        if r.success:
            assert natural <= 1e-6 and r.residual.natural <= 1e-6, key



# A child's first solve, interrupted: F(x) = x - c on x >= 0 at n = 30 (above the cold
# start's INTERPRET_MAX_N: the solve loads numba and compiles), solution max(c, 0).  It
# prints READY before the solve, END with the Result after it, then waits for a line on
# stdin; AFTER when SIGINT came after the solve, ESCAPED (with the traceback's last file)
# when a KeyboardInterrupt left solve_mcp.  ``mode k``: SIGINT raised by the child itself
# at the k-th event of a kind ("import": a module of numba or llvmlite imported; "notify":
# LLVM's object-code callback, a ctypes callback), or "signal 0": sent by the parent.
_INTERRUPTED_CHILD = textwrap.dedent("""
    import signal, sys, traceback
    import numpy as np
    import scipy.sparse as sp
    import compass_sparse as cs
    mode, k = sys.argv[1], int(sys.argv[2])
    fired = [0]
    def fire():
        fired[0] += 1
        if fired[0] == k:
            signal.raise_signal(signal.SIGINT)
    if mode == "import":
        class Finder:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("numba", "llvmlite"):
                    fire()
        sys.meta_path.insert(0, Finder())
    elif mode == "notify":
        from numba.core import codegen
        hook = codegen.CPUCodeLibrary._object_compiled_hook.__func__
        def notify(cls, *args):
            fire()
            return hook(cls, *args)
        codegen.CPUCodeLibrary._object_compiled_hook = classmethod(notify)
    n = 30
    c = np.linspace(-1.0, 2.0, n)
    x_star = np.maximum(c, 0.0)
    problem = cs.MCP(lambda x: x - c, lambda x: sp.identity(n, format="csc"),
                     np.zeros(n), np.full(n, np.inf), x_star if mode == "signal" else c + 1.0)
    print("READY", flush=True)
    try:
        res = cs.solve_mcp(problem, options={"verbosity": 0})
    except KeyboardInterrupt as exc:
        print("ESCAPED", traceback.extract_tb(exc.__traceback__)[-1].filename, flush=True)
        sys.exit(0)
    try:
        print("END", res.status.name, res.point_status.name,
              float(np.max(np.abs(res.x - x_star))), float(np.max(np.abs(res.x - problem.x0))),
              flush=True)
        sys.stdin.readline()
    except KeyboardInterrupt:
        print("AFTER", flush=True)
    """)


def _start_child(mode, k, cache):
    env = _cold_env(NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-c", _INTERRUPTED_CHILD, mode, str(k)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)


def _finish_child(proc):
    """The child's lines after READY, split in words, once it exited."""
    try:
        proc.stdin.write("\n")  # (the child waits for it after the solve)
        proc.stdin.close()
    except BrokenPipeError:  # the child is gone: its exit code and stderr say why
        pass
    out, err = proc.stdout.read(), proc.stderr.read()  # (not communicate: READY's read
    proc.wait()  # may have buffered the next line in proc.stdout)
    assert proc.returncode == 0, err
    # No traceback of numba's (a half-imported numba, a half-built library), and no
    # interrupt printed and dropped inside one of LLVM's ctypes callbacks.
    assert "Traceback" not in err and "Exception ignored" not in err, err
    return [line.split() for line in out.splitlines()]


def _ready(proc) -> float:
    assert proc.stdout.readline().split() == ["READY"]
    return time.perf_counter()


def test_ctrl_c_while_numba_imports_is_a_user_interrupt_not_a_half_imported_numba(tmp_path):
    """Ctrl-C while the first solve imports numba (SIGINT at the 80th module of numba or
    llvmlite imported) ends in USER_INTERRUPT at the start point.  The old code let the
    KeyboardInterrupt cut numba's import short; the solve's handler then built its Result
    with kernels that imported numba again: ``AttributeError: module 'numba' has no
    attribute 'core'``, a traceback and exit code 1."""
    proc = _start_child("import", 80, tmp_path)
    _ready(proc)
    status, point, _, from_x0 = _finish_child(proc)[0][1:]
    assert (status, point, float(from_x0)) == ("USER_INTERRUPT", "START_POINT", 0.0)


def test_ctrl_c_inside_an_llvm_callback_is_neither_lost_nor_a_raw_error(tmp_path):
    """Ctrl-C while LLVM emits a kernel's object code (SIGINT inside its ctypes callback,
    at the 1st and the 3rd kernel compiled, empty cache) ends in USER_INTERRUPT.  The old
    code's KeyboardInterrupt was raised inside the callback, where ctypes prints and drops
    it: the solve went on and answered SOLVED as if no Ctrl-C had come (1st), or numba
    went on with a half-built library and the solve died with ``RuntimeError: no compiled
    object yet for <Library 'memo_key_kernel'>`` (3rd)."""
    children = [_start_child("notify", k, tmp_path / f"cache{k}") for k in (1, 3)]
    for proc in children:
        _ready(proc)
        assert _finish_child(proc)[0][1] == "USER_INTERRUPT"


def test_ctrl_c_at_any_moment_of_the_first_solve_is_a_user_interrupt_and_the_cache_stays_sound(
        tmp_path):
    """SIGINT sent to fresh processes at several delays after their first solve started
    (a solve at the solution: numba's import and the compilation of the start point's
    kernels, on an empty cache that all of them share): each ends in USER_INTERRUPT (or,
    when the solve was over, a KeyboardInterrupt after it), never in a traceback of
    numba's, never with the interrupt lost.  A fresh process then solves from the cache
    they wrote: the solution, exactly."""
    cache = tmp_path / "cache"
    delays = (0.1, 0.8, 2.5)  # numba's import, the first kernels, later ones
    children = [_start_child("signal", 0, cache) for _ in delays]
    ready = [_ready(proc) for proc in children]
    for proc, t, d in sorted(zip(children, ready, delays), key=lambda c: c[1] + c[2]):
        # (where the signal falls in the solve, not a limit on time)
        time.sleep(max(0.0, t + d - time.perf_counter()))
        proc.send_signal(signal.SIGINT)
    outcomes = [_finish_child(proc) for proc in children]
    for lines in outcomes:
        # the interrupt is never lost: a solve that ended otherwise saw it afterwards
        assert lines[0][:2] == ["END", "USER_INTERRUPT"] or lines[-1] == ["AFTER"], outcomes
    assert sum(lines[0][1] == "USER_INTERRUPT" for lines in outcomes) >= 2, outcomes
    proc = _start_child("signal", 0, cache)
    _ready(proc)
    lines = _finish_child(proc)
    assert lines[0][:4] == ["END", "SOLVED", "SOLUTION", "0.0"], lines


def test_a_sigint_held_while_numba_loads_is_delivered_once_at_the_end_or_at_a_safe_point():
    """Inside nested held sections a SIGINT is recorded, not raised; it is delivered once:
    when the outermost section ends, or earlier at an interrupt point (a kernel's
    compilation or compiler pass starting), to the handler that was in place (Python's
    raises KeyboardInterrupt, a user's is called).  An ignored SIGINT stays ignored."""
    from compass_sparse._jit import interrupt_point, interrupts_held

    reached = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            with interrupts_held():
                signal.raise_signal(signal.SIGINT)
                sum(range(1000))  # (bytecodes where Python would have raised)
                reached.append("inner")
            reached.append("outer")
    assert reached == ["inner", "outer"]
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            signal.raise_signal(signal.SIGINT)
            sum(range(1000))
            reached.append("before the point")
            interrupt_point()
            reached.append("after the point")  # (not reached)
    assert reached[-1] == "before the point"
    calls = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: calls.append(signum))
    try:
        with interrupts_held():
            signal.raise_signal(signal.SIGINT)
            sum(range(1000))
            assert calls == []
        assert calls == [signal.SIGINT]
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with interrupts_held():
            signal.raise_signal(signal.SIGINT)
        assert calls == [signal.SIGINT]
    finally:
        signal.signal(signal.SIGINT, previous)
    assert signal.getsignal(signal.SIGINT) is previous
