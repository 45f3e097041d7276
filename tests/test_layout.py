"""The package's layout rules (docs/design.rst, "Rules"), read from its source with ast:
no import cycle, function-level imports only for optional extras and deliberately lazy
heavy imports (each with its reason), files and functions of bounded size, no module
reaching into another's private names, and every subpackage listed in pyproject.toml."""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "compass_sparse"

LAZY_OK = ("gamspy", "gams", "gamspy_base", "pyomo", "casadi", "pandas", "pyarrow",
           "matplotlib", "distributed", "dask", "cloudpickle",  # optional extras
           "numba", "scipy.linalg", "scipy.sparse.linalg", "scipy.optimize", "kvxopt",
           "pymetis", "threadpoolctl", "llvmlite")  # deliberately lazy heavy imports
"""Top-level modules a function may import: the optional extras, and the heavy imports
kept out of ``import compass_sparse`` (numba and its LLVM binding, scipy's linalg,
scipy.optimize's HiGHS for the feasibility LP, SuiteSparse, METIS)."""

LAZY_OWN = {("compass_sparse.solve", "compass_sparse.presolve")}
"""(module, package module) pairs a function may import lazily: the preprocessor, whose
import costs a third of ``import compass_sparse`` and which most small solves skip."""

MAX_FILE_LINES = 800
MAX_FUNCTION_LINES = 100
KERNELS_EXEMPT = {("path/_path_kernels.py", "path_loop"),
                  ("path/_sparse_lu.py", "factor"),
                  ("path/_sparse_lu.py", "replace_column"),
                  ("presolve/_kernels.py", "simple_reductions_screen")}
"""Compiled kernels whose length is the algorithm (their docstrings say so)."""

FOREIGN_PRIVATE = {("interfaces/gamspy.py", "_gmo")}
"""Private names of other libraries read on purpose (GAMSPy gives a model's GMO handle
only as ``model.instance._gmo``)."""


def _modules():
    """{dotted name: (path, ast)} of the package's modules (not the generators, which are
    data/generators mapped into the package)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if "generators" in rel.parts or "__pycache__" in rel.parts:
            continue
        name = ".".join(rel.with_suffix("").parts)
        if name.endswith(".__init__"):
            name = name[: -len(".__init__")]
        out[name] = (path, ast.parse(path.read_text()))
    return out


MODULES = _modules()


def _package_of(name):
    path = MODULES[name][0]
    return name if path.name == "__init__.py" else name.rpartition(".")[0]


def _imports(name):
    """(node, target module, in a function?) of every import of module ``name`` that
    names a module of the package (``from X import y``: X.y when that is a module)."""
    pkg = _package_of(name)
    tree = MODULES[name][1]
    in_function = set()
    for f in ast.walk(tree):
        if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)):
            in_function.update(id(n) for n in ast.walk(f))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node, a.name, id(node) in in_function
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = pkg.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1]
                                + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for a in node.names:
                sub = f"{base}.{a.name}"
                yield node, sub if sub in MODULES else base, id(node) in in_function


def test_the_import_graph_has_no_cycle():
    """Module-level and function-level imports alike: the modules import each other in
    one order, top-down (the pipeline above the passes, the passes above their tools)."""
    graph = {m: sorted({t for _, t, _ in _imports(m) if t in MODULES and t != m})
             for m in MODULES}
    state, stack = {}, []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for t in graph[m]:
            if state.get(t) == "open":
                cycle = stack[stack.index(t):] + [t]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = "done"

    for m in graph:
        if m not in state:
            visit(m)
    assert len(graph) > 60


def test_function_level_imports_are_optional_extras_or_lazy_heavy_ones_with_their_reason():
    """No function imports a module of the package (but the allow-listed lazy one) or a
    cheap one (that would only hide a cycle or a dependency); the others say why they
    wait, in a comment "# (...)" on the import or in the comment block above its block."""
    bad = []
    for name, (path, _tree) in MODULES.items():
        lines = path.read_text().split("\n")
        for node, target, in_function in _imports(name):
            if not in_function:
                continue
            where = f"{path.relative_to(ROOT)}:{node.lineno}"
            own = any(name == m and (target == t or target.startswith(t + "."))
                      for m, t in LAZY_OWN)
            if not own and (node_level(node) or not any(
                    target == m or target.startswith(m + ".") for m in LAZY_OK)):
                bad.append(f"{where}: {lines[node.lineno - 1].strip()}")
                continue
            k = node.lineno - 1
            while k > 0 and re.match(r"\s*(from [\w.]+ import|import [\w.]+)", lines[k - 1]):
                k -= 1  # the first import of the block
            above = []  # the comment block above the import block
            while k > 0 and lines[k - 1].strip().startswith("#"):
                above.append(lines[k - 1].strip())
                k -= 1
            if not re.search(r"#\s*\(", lines[node.lineno - 1]) and \
                    not any(c.startswith("# (") for c in above):
                bad.append(f"{where}: no reason given")
    assert not bad, "\n".join(bad)


def node_level(node) -> int:
    return getattr(node, "level", 0) or 0


def test_files_and_functions_stay_within_their_size_limits():
    """At most 800 lines per file and 100 per function, except the compiled kernels whose
    length is the algorithm (named here; their docstrings say so)."""
    bad = []
    for name, (path, tree) in MODULES.items():
        rel = path.relative_to(PACKAGE).as_posix()
        n = len(path.read_text().splitlines())
        if n > MAX_FILE_LINES:
            bad.append(f"{rel}: {n} lines")
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if (rel, node.name) in KERNELS_EXEMPT:
                    assert "exempt" in (ast.get_docstring(node) or ""), (rel, node.name)
                elif length > MAX_FUNCTION_LINES:
                    bad.append(f"{rel}: {node.name}, {length} lines")
    assert not bad, "\n".join(bad)


def _defined_names(tree) -> set:
    """Every name a module defines or binds: its functions, classes, assignments,
    attributes set, arguments, imports."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def test_no_module_touches_another_modules_private_names():
    """A private name (one leading underscore) is read only in the module that defines
    it: no ``from X import _name`` of a name (private modules are the package's own), and
    no ``obj._name`` of an attribute the module does not set itself."""
    bad = []
    for name, (path, tree) in MODULES.items():
        rel = path.relative_to(PACKAGE).as_posix()
        own = _defined_names(tree)
        for node, target, _ in _imports(name):
            if not (isinstance(node, ast.ImportFrom) and target.startswith("compass_sparse")):
                continue
            for a in node.names:
                private = a.name.startswith("_") and not a.name.startswith("__")
                if private and target != f"{target.rpartition('.')[0]}.{a.name}":
                    bad.append(f"{rel}:{node.lineno}: imports {a.name} from {target}")
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__") and node.attr not in own
                    and (rel, node.attr) not in FOREIGN_PRIVATE):
                bad.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not bad, "\n".join(bad)


def test_every_subpackage_is_listed_in_pyproject():
    """pyproject.toml lists the packages explicitly: a new subpackage must be there, or
    an installed compass_sparse lacks it."""
    text = (ROOT / "pyproject.toml").read_text()
    listed = set(re.search(r"packages = \[([^\]]*)\]", text).group(1).replace('"', "")
                 .replace(" ", "").split(","))
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in PACKAGE.rglob("__init__.py")
             if "generators" not in p.parts and "__pycache__" not in p.parts}
    assert found <= listed, sorted(found - listed)
