"""The documentation cannot rot: it builds with warnings as errors, its code examples run,
and its tables say what the code says (options, defaults, PATH names, statuses, the log
and summary formats)."""
from __future__ import annotations

import ast
import dataclasses
import logging
import math
import os
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

import compass_sparse as cs
from compass_sparse.options import PATH_NAMES

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.rst"))


# ------------------------------------------------------------------ the build
@pytest.fixture(scope="module")
def built(tmp_path_factory):
    pytest.importorskip("sphinx", reason="sphinx (the docs extra) is not installed")
    out = tmp_path_factory.mktemp("docs_html")
    proc = subprocess.run(  # noqa: PLW1510 - the return code is asserted in the test
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
         str(DOCS), str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    return proc, out


def test_docs_build_with_warnings_as_errors(built):
    proc, out = built
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == ""
    for page in PAGES:
        assert (out / page.replace(".rst", ".html")).exists(), page


def test_docs_render_math_offline(built):
    # MathJax is part of the built site: the pages' mathematics renders with no network
    _, out = built
    page = (out / "getting_started.html").read_text(encoding="utf-8")
    scripts = re.findall(r'<script[^>]*src="([^"]*mathjax[^"]*)"', page)
    assert scripts and all(not s.startswith(("http:", "https:", "//")) for s in scripts)
    for s in scripts:
        assert (out / s.split("?")[0]).is_file(), s


class _Tables(HTMLParser):
    """Rows (lists of cell texts) of the tables carrying a given class."""

    def __init__(self, cls):
        super().__init__()
        self.cls, self.depth, self.rows, self.cell, self.row = cls, 0, [], None, None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            if self.depth or self.cls in (dict(attrs).get("class") or "").split():
                self.depth += 1
        elif self.depth and tag == "tr":
            self.row = []
        elif self.depth and tag in ("td", "th"):
            self.cell = ""

    def handle_endtag(self, tag):
        if tag == "table" and self.depth:
            self.depth -= 1
        elif self.depth and tag in ("td", "th") and self.cell is not None:
            self.row.append(" ".join(self.cell.split()))
            self.cell = None
        elif self.depth and tag == "tr":
            self.rows.append(self.row)

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data


def _table_rows(out, page, cls):
    p = _Tables(cls)
    p.feed((out / page).read_text(encoding="utf-8"))
    return [r for r in p.rows if r and r[0] not in ("option", "status", "point status",
                                                    "PATH 5.2 option", "letter")]


def _value(text):
    return math.inf if text == "inf" else ast.literal_eval(text)


def test_documented_option_table_lists_every_option_with_its_default_and_meaning(built):
    _, out = built
    rows = _table_rows(out, "options.html", "compass-options")
    fields = dataclasses.fields(cs.Options)
    assert sorted(r[0] for r in rows) == sorted(f.name for f in fields)
    by_name = {r[0]: r for r in rows}
    for f in fields:
        name, default, rng, meaning = by_name[f.name]
        if isinstance(f.default, float):
            assert _value(default) == pytest.approx(f.default, rel=1e-5), f.name
        else:
            assert _value(default) == f.default, f.name
        assert meaning == " ".join(f.metadata["doc"].split()), f.name
        assert rng, f.name


def test_documented_ranges_are_the_ranges_options_enforce(built):
    # Each numeric range's boundary: the documented bound is accepted or rejected exactly
    # as validate() does.
    _, out = built
    for name, _d, rng, _m in _table_rows(out, "options.html", "compass-options"):
        m = re.match(r"(integer|real) (>=|>) (\S+?)(, or None)?$", rng)
        if not m:
            continue
        lo = _value(m.group(3))
        if m.group(2) == ">":
            with pytest.raises(cs.OptionError):
                cs.Options(**{name: lo})
        else:
            cs.Options(**{name: int(lo) if m.group(1) == "integer" else lo})
            with pytest.raises(cs.OptionError):
                cs.Options(**{name: (int(lo) - 1) if m.group(1) == "integer" else lo - 1.0})


def test_documented_status_table_lists_every_status_with_its_path_code(built):
    _, out = built
    rows = _table_rows(out, "options.html", "compass-statuses")
    assert [r[0] for r in rows] == [f"Status.{s.name}" for s in cs.Status]
    for r, s in zip(rows, cs.Status):
        assert int(r[1]) == int(s) and int(r[2]) == s.path_code()
        assert r[4], f"Status.{s.name} has no '#:' comment saying when it is returned"
    pts = _table_rows(out, "options.html", "compass-point-statuses")
    assert [r[0] for r in pts] == [f"PointStatus.{s.name}" for s in cs.PointStatus]
    assert all(r[2] for r in pts)


def test_bad_input_table_on_the_trust_page_is_the_files(built):
    _, out = built
    p = _Tables("compass-markdown-table")
    p.feed((out / "trust.html").read_text(encoding="utf-8"))
    md = []
    for line in (DOCS / "bad_inputs.md").read_text(encoding="utf-8").splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            md.append([c.strip().replace("`", "") for c in line.strip().strip("|").split(" | ")])
    assert len(md) > 10 and p.rows == md


def test_path_name_table_covers_every_option_that_path_has(built):
    _, out = built
    rows = _table_rows(out, "options.html", "compass-path-names")
    have = {f.name for f in dataclasses.fields(cs.Options) if cs.Options.path_name(f.name)}
    assert {r[1] for r in rows} == have
    for path, ours, _ in rows:
        assert cs.Options.path_name(ours) == path


def _path_option_names():
    try:
        import gamspy_base
    except ImportError:
        pytest.skip("gamspy (the gams extra) is not installed: PATH's option list is absent")
    text = (Path(gamspy_base.__file__).parent / "optpath.def").read_text()
    return set(re.findall(r"^([a-z][a-z_0-9]*)\s+(?:boolean|integer|double|enumstr|string)",
                          text, re.M))


def test_path_option_map_names_real_path_options_and_misses_none():
    # Every option is either PATH's own name, mapped to PATH's name, or mapped to None.
    # A new option whose name PATH does not know must be added to PATH_NAMES.
    path = _path_option_names()
    for f in dataclasses.fields(cs.Options):
        pn = cs.Options.path_name(f.name)
        if pn is not None:
            assert pn in path, (
                f"option {f.name!r}: PATH has no option {pn!r}; map it in "
                "compass_sparse/options.py PATH_NAMES (None when PATH has no such option)")
    assert set(PATH_NAMES) <= {f.name for f in dataclasses.fields(cs.Options)}


# ------------------------------------------------------------------ the examples
def _code_blocks(page):
    """The ``.. code-block:: python`` bodies of a page, dedented, in order."""
    lines = (DOCS / page).read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].strip() == ".. code-block:: python":
            i += 1
            body = []
            while i < len(lines) and (not lines[i].strip() or lines[i].startswith("    ")):
                body.append(lines[i][4:])
                i += 1
            blocks.append("\n".join(body).strip("\n"))
        else:
            i += 1
    return blocks


_NAMESPACES = {}

# The optional extras a page's examples import, beyond matplotlib (every page may plot).
PAGE_EXTRAS = {
    "guides/modelling_languages.rst": [
        ("pyomo.environ", "the pyomo extra (pyomo) is not installed"),
        ("casadi", "the pyomo extra (casadi) is not installed"),
    ],
    "guides/batches.rst": [("pyarrow", "the batch extra (pyarrow) is not installed")],
}


def _run_page(page, tmp_path):
    if page not in _NAMESPACES:
        pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")
        for module, reason in PAGE_EXTRAS.get(page, []):
            pytest.importorskip(module, reason=reason)
        import matplotlib

        matplotlib.use("Agg")
        ns = {"__name__": f"docs_{page}"}
        cwd = os.getcwd()
        os.chdir(tmp_path)
        try:
            for k, block in enumerate(_code_blocks(page)):
                if not _needs_gams(block):
                    exec(compile(block, f"{page} (code block {k + 1})", "exec"), ns)
        finally:
            os.chdir(cwd)
            import matplotlib.pyplot as plt

            plt.close("all")
        _NAMESPACES[page] = ns
    return _NAMESPACES[page]


PAGES_WITH_CODE = [p for p in PAGES if _code_blocks(p)]


def _needs_gams(block):
    """A block that uses GAMSPy needs a GAMS that runs (a valid licence): it runs in
    test_docs_gams_examples_run, after the page's other blocks, and skips with the reason
    GAMS' probe gives where GAMS cannot run."""
    return "gamspy" in block


GAMS_PAGES = [p for p in PAGES_WITH_CODE if any(_needs_gams(b) for b in _code_blocks(p))]


def test_every_guide_page_has_a_tested_example():
    for page in ("getting_started.rst", "jacobian.rst", "guides/cge.rst", "guides/lcp.rst",
                 "guides/warm_start.rst", "guides/modelling_languages.rst",
                 "guides/batches.rst", "trust.rst", "guides/hard_problems.rst"):
        assert page in PAGES_WITH_CODE


@pytest.mark.parametrize("page", PAGES_WITH_CODE)
def test_docs_code_examples_run(page, tmp_path, capsys):
    _run_page(page, tmp_path)


@pytest.mark.gams
@pytest.mark.parametrize("page", GAMS_PAGES)
def test_docs_gams_examples_run(page, tmp_path, capsys):
    ns = _run_page(page, tmp_path)
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        for k, block in enumerate(_code_blocks(page)):
            if _needs_gams(block):
                exec(compile(block, f"{page} (code block {k + 1})", "exec"), ns)
    finally:
        os.chdir(cwd)


def test_the_gams_examples_are_found():
    # the GAMSPy section of the modelling-languages guide is held out of the page's run
    # (GAMS needs a licence), not lost
    assert GAMS_PAGES == ["guides/modelling_languages.rst"]


def test_getting_started_exchange_economy_is_an_equilibrium(tmp_path, capsys):
    ns = _run_page("getting_started.rst", tmp_path)
    res, F, lb, ub = ns["res"], ns["F"], ns["lb"], ns["ub"]
    z = res.x
    f = F(z)
    # The sign convention on the page: at the lower bound F >= 0, inside F = 0.
    assert np.all(z >= lb) and np.all(z <= ub)
    inside = (z > lb) & (z < ub)
    assert np.all(np.abs(f[inside]) <= 1e-8)
    assert np.all(f[np.isclose(z, lb) & ~np.isclose(lb, ub)] >= -1e-8)
    assert np.allclose(z, [1.0, 1.0, 1.7, 5.0, 12.5], rtol=1e-8)


def _literal_after(page, marker):
    """The first ``::`` literal block after the line containing ``marker``."""
    lines = (DOCS / page).read_text(encoding="utf-8").splitlines()
    i = next(k for k, line in enumerate(lines) if marker in line)
    while not lines[i].rstrip().endswith("::"):
        i += 1
    i += 1
    body = []
    while i < len(lines) and (not lines[i].strip() or lines[i].startswith("    ")):
        body.append(lines[i].strip())
        i += 1
    return [b for b in body if b]


def test_documented_summary_has_the_lines_of_a_real_summary(tmp_path, capsys):
    ns = _run_page("getting_started.rst", tmp_path)
    doc = _literal_after("getting_started.rst", "``print(res.summary())`` prints")
    real = ns["res"].summary().splitlines()
    assert [line.split()[0] for line in doc] == [line.split()[0] for line in real]
    # The explained labels are the summary's labels.
    text = (DOCS / "getting_started.rst").read_text(encoding="utf-8")
    for label in {line.split()[0] for line in real}:
        assert f"   * - ``{label}" in text, label


def test_documented_log_header_and_columns_are_the_logs(caplog):
    doc = _literal_after("getting_started.rst", "prints a PATH-like log")
    with caplog.at_level(logging.INFO, logger="compass_sparse"):
        cs.solve_mcp(lambda x: x**3 + x - 1.0, lambda x: np.diag(3 * x**2 + 1), lb=-np.inf,
                     ub=np.inf, x0=np.full(3, 3.0), options={"verbosity": 2})
    log = [r.getMessage() for r in caplog.records]
    text = (DOCS / "getting_started.rst").read_text(encoding="utf-8")
    for title, first in (("Crash Log", "crash"), ("Major Iteration Log", "major")):
        # the section's title and header, in the log and on the page
        header = log[log.index(title) + 1]
        assert header.split()[0] == first
        assert doc[doc.index(title) + 1].split() == header.split()
        for col in header.split():
            if col != "(label)":
                assert f"   * - ``{col}``" in text, col


# ------------------------------------------------------------------ the README
README = ROOT / "README.md"


def _readme_blocks():
    """The README's ```python blocks, in order."""
    return re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), re.M | re.S)


# The optional extras a README block imports, and the reason its test skips without them.
README_EXTRAS = {"pyomo": [("pyomo.environ", "the pyomo extra (pyomo) is not installed"),
                           ("casadi", "the pyomo extra (casadi) is not installed")]}


def test_readme_is_short():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) < 200, len(lines)
    assert len(_readme_blocks()) >= 4


@pytest.mark.parametrize("k", range(len(_readme_blocks())))
def test_readme_code_block_runs_as_pasted(k, tmp_path, capsys, monkeypatch):
    # each block on its own, in a fresh namespace, as a reader pastes it
    block = _readme_blocks()[k]
    for word, needs in README_EXTRAS.items():
        if f"import {word}" in block:
            for module, reason in needs:
                pytest.importorskip(module, reason=reason)
    monkeypatch.chdir(tmp_path)
    exec(compile(block, f"README.md (python block {k + 1})", "exec"), {"__name__": "readme"})
