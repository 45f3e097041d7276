"""Compiled kernels on first use (compass_sparse._jit): ``import compass_sparse`` does not
load numba, the cold start is decided once per solve (interpreted while numba is not
loaded, for the first small solves of a process) and never switches within a solve,
interpreted kernels solve the small problems as the compiled ones do, lazily built
kernels call each other, and Python callers reach a built kernel's dispatcher."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import known_problems as kp
import numpy as np

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

