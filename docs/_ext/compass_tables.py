"""Sphinx directives that build the reference tables from the code at docs-build time, so
the documentation cannot drift from it:

* ``.. compass-options::``       every field of :class:`compass_sparse.Options`, grouped as
  in the source, with its default, valid range (from the field metadata the options use to
  validate themselves), PATH's name and its meaning;
* ``.. compass-path-names::``    PATH 5.2's option names and ours (``Options.path_name``);
* ``.. compass-statuses::``      every :class:`compass_sparse.Status` with its code, PATH's
  termination code (``Status.path_code()``) and meaning;
* ``.. compass-point-statuses::`` every :class:`compass_sparse.PointStatus`;
* ``.. compass-step-codes::``    the pivotal path's one-letter codes (``LinearCode``);
* ``.. compass-benchmark-records::`` every ``benchmarks/*.md``, verbatim;
* ``.. compass-markdown-table:: <file>`` the Markdown table of a file of the docs (the
  bad-input table, ``bad_inputs.md``: one source for the page and its tests).

Tables are built from docutils nodes (no RST re-parsing), so option texts need no escaping.
"""
from __future__ import annotations

import dataclasses
import inspect
import math
import re

from docutils import nodes
from sphinx.util.docutils import SphinxDirective


def _cell(content):
    entry = nodes.entry()
    if isinstance(content, nodes.Node):
        entry += content if isinstance(content, nodes.paragraph) else nodes.paragraph("", "",
                                                                                      content)
    else:
        entry += nodes.paragraph(text=str(content))
    return entry


def _literal(text):
    return nodes.paragraph("", "", nodes.literal(text=str(text)))


def _table(headers, rows, widths, cls):
    table = nodes.table(classes=[cls])
    group = nodes.tgroup(cols=len(headers))
    table += group
    for w in widths:
        group += nodes.colspec(colwidth=w)
    head = nodes.thead()
    hrow = nodes.row()
    for h in headers:
        hrow += _cell(h)
    head += hrow
    group += head
    body = nodes.tbody()
    for r in rows:
        row = nodes.row()
        for c in r:
            row += _cell(c)
        body += row
    group += body
    return table


def _fmt(v) -> str:
    if isinstance(v, float):
        if math.isinf(v):
            return "inf"
        r = repr(v)
        return r if len(r) <= 10 else f"{v:.6g}"
    return repr(v)


def option_range(f) -> str:
    """The valid range of an option field, in words, from the metadata ``validate`` uses."""
    m = f.metadata
    if m.get("choices") is not None:
        text = "one of " + ", ".join(repr(c) for c in m["choices"])
    elif isinstance(f.default, bool) or str(f.type) == "bool":
        text = "True or False"
    else:
        lo, hi = m.get("lo"), m.get("hi")
        integer = "int" in str(f.type)
        kind = "integer" if integer else "real"
        if lo is not None and hi is not None:
            text = f"{kind} in {'(' if m.get('lo_open') else '['}{_fmt(lo)}, {_fmt(hi)}]"
        elif lo is not None:
            text = f"{kind} {'>' if m.get('lo_open') else '>='} {_fmt(lo)}"
        elif hi is not None:
            text = f"{kind} <= {_fmt(hi)}"
        else:
            text = kind
    if m.get("nullable"):
        text += ", or None"
    return text


def option_groups(cls):
    """(group title, [fields]) in source order; groups are the ``# --- title ---`` comments
    of the class body."""
    src = inspect.getsource(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    groups, current = [], None
    for line in src.splitlines():
        g = re.match(r"\s*# -+ (.+?) -*$", line)
        if g:
            current = (g.group(1).strip(), [])
            groups.append(current)
            continue
        d = re.match(r"\s{4}(\w+)\s*:", line)
        if d and d.group(1) in fields:
            if current is None:
                current = ("general", [])
                groups.append(current)
            current[1].append(fields.pop(d.group(1)))
    if fields:  # defined in a way the scan missed: still documented
        groups.append(("other", list(fields.values())))
    return [(t, fs) for t, fs in groups if fs]


class OptionsTable(SphinxDirective):
    has_content = False

    def run(self):
        from compass_sparse import Options

        out = []
        for title, fields in option_groups(Options):
            rows = []
            for f in fields:
                name = nodes.paragraph("", "", nodes.literal(text=f.name))
                rows.append([name, _literal(_fmt(f.default)), option_range(f),
                             f.metadata.get("doc", "")])
            sec = nodes.rubric(text=title[0].upper() + title[1:])
            # PATH's names are a table of their own (PathNamesTable): a column here repeated
            # the option's own name on almost every row and squeezed the meaning
            out += [sec, _table(["option", "default", "range", "meaning"], rows,
                                [20, 9, 14, 57], "compass-options")]
        return out


class PathNamesTable(SphinxDirective):
    def run(self):
        from compass_sparse import Options

        pairs = sorted((Options.path_name(f.name), f.name)
                       for f in dataclasses.fields(Options) if Options.path_name(f.name))
        rows = [[_literal(p), _literal(o), "same name" if p == o else "renamed"]
                for p, o in pairs]
        missing = [f.name for f in dataclasses.fields(Options) if not Options.path_name(f.name)]
        out = [_table(["PATH 5.2 option", "compass_sparse option", ""], rows, [30, 30, 12],
                      "compass-path-names")]
        if missing:
            para = nodes.paragraph(text="Ours only (PATH has no such option): ")
            for i, m in enumerate(missing):
                if i:
                    para += nodes.Text(", ")
                para += nodes.literal(text=m)
            para += nodes.Text(".")
            out.append(para)
        return out


class StatusTable(SphinxDirective):
    def run(self):
        from compass_sparse import Status

        when = member_comments(Status)
        rows = [[_literal(f"Status.{s.name}"), str(int(s)), str(s.path_code()), s.description,
                 when.get(s.name, "")] for s in Status]
        return [_table(["status", "code", "PATH code", "message", "when"], rows,
                       [26, 5, 6, 30, 33], "compass-statuses")]


def member_comments(cls) -> dict:
    """The ``#:`` comments of an enum's members, by member name: on the member's line
    (``NAME = value  #: text``) or on the comment lines just above it."""
    out, above = {}, []
    for line in inspect.getsource(cls).splitlines():
        c = re.match(r"\s*#:\s*(.+)$", line)
        if c:
            above.append(c.group(1).strip())
            continue
        m = re.match(r"\s*(\w+)\s*=.*?(?:#:\s*(.+))?$", line)
        if m and (m.group(2) or above):
            out[m.group(1)] = (m.group(2) or " ".join(above)).strip()
        above = []
    return out


class PointStatusTable(SphinxDirective):
    def run(self):
        from compass_sparse import PointStatus

        doc = member_comments(PointStatus)
        rows = [[_literal(f"PointStatus.{s.name}"), str(int(s)), doc.get(s.name, "")]
                for s in PointStatus]
        return [_table(["point status", "code", "meaning"], rows, [28, 6, 58],
                       "compass-point-statuses")]


class StepCodeTable(SphinxDirective):
    def run(self):
        from compass_sparse.path.outcome import LinearCode

        words = {
            "SOLVED": "the path reached the Newton point of the linearization",
            "RAY": "ray termination: the entering variable is unbounded",
            "CYCLE": "a variable entered the basis more than lemke_cycle_limit times",
            "MINOR_LIMIT": "the pivot limit of one path was reached",
            "SINGULAR": "the basis was singular and could not be repaired",
            "TOLERANCE": "accuracy was lost along the path (ratio test tolerances)",
            "ERROR": "another failure of the path",
        }
        rows = [[_literal(c.value), _literal(f"LinearCode.{c.name}"), words.get(c.name, "")]
                for c in LinearCode]
        return [_table(["letter", "code", "meaning"], rows, [6, 26, 60], "compass-step-codes")]


class BenchmarkRecords(SphinxDirective):
    """Every ``benchmarks/*.md`` as a subsection holding its Markdown source."""

    def run(self):
        from pathlib import Path

        root = Path(self.env.srcdir).parent / "benchmarks"
        out = []
        for md in sorted(root.glob("*.md")):
            text = md.read_text(encoding="utf-8")
            first = text.splitlines()[0] if text else md.stem
            title = first.lstrip("# ").strip() or md.stem
            self.env.note_dependency(str(md))
            sec = nodes.section(ids=[f"benchmark-{md.stem}"])
            sec += nodes.title(text=f"{md.name}: {title}")
            block = nodes.literal_block(text, text)
            block["language"] = "markdown"
            sec += block
            out.append(sec)
        return out


def _inline(text):
    """A paragraph of Markdown cell text: ``code`` spans as literals, the rest as text."""
    para = nodes.paragraph()
    for k, part in enumerate(re.split(r"`([^`]*)`", text)):
        if part:
            para += nodes.literal(text=part) if k % 2 else nodes.Text(part)
    return para


def markdown_table(lines):
    """The cells of the first Markdown table in ``lines`` (its header row first): the
    lines before it are skipped (a comment, an introduction), the table ends at the first
    line that is not a row; ``\\|`` is a literal bar in a cell."""
    rows = []
    for line in lines:
        if not line.startswith("|"):
            if rows:
                break
            continue
        cells = [c.strip().replace("\\|", "|")
                 for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
        if not all(re.fullmatch(r":?-+:?", c) for c in cells):
            rows.append(cells)
    return rows


class MarkdownTable(SphinxDirective):
    """The Markdown table of a file of the docs (its path relative to ``docs/``): one
    source that a page shows and the tests read (the bad-input table, docs/bad_inputs.md),
    easy to extend by a row."""

    required_arguments = 1

    def run(self):
        from pathlib import Path

        path = Path(self.env.srcdir) / self.arguments[0]
        self.env.note_dependency(str(path))
        try:
            rows = markdown_table(path.read_text(encoding="utf-8").splitlines())
        except OSError as exc:
            raise self.error(f"cannot read {path}: {exc}") from None
        if len(rows) < 2:
            raise self.error(f"no Markdown table in {path}")
        table = nodes.table(classes=["compass-markdown-table"])
        group = nodes.tgroup(cols=len(rows[0]))
        table += group
        for _ in rows[0]:
            group += nodes.colspec(colwidth=10)
        head, body = nodes.thead(), nodes.tbody()
        for k, cells in enumerate(rows):
            row = nodes.row()
            for c in cells:
                row += _cell(_inline(c))
            (head if k == 0 else body).append(row)
        group += head
        group += body
        return [table]


def setup(app):
    app.add_directive("compass-options", OptionsTable)
    app.add_directive("compass-path-names", PathNamesTable)
    app.add_directive("compass-statuses", StatusTable)
    app.add_directive("compass-point-statuses", PointStatusTable)
    app.add_directive("compass-step-codes", StepCodeTable)
    app.add_directive("compass-benchmark-records", BenchmarkRecords)
    app.add_directive("compass-markdown-table", MarkdownTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
