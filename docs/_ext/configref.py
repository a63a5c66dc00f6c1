"""Sphinx extension: the configuration reference, generated from the config dataclasses.

The directive ``d3-config-reference`` walks :class:`d3cli.config.Config` section by
section and writes, for every key, its type, its default, the accepted values (from the
range checks) and its meaning (the comment beside or above the field in
``d3cli/config/sections.py``).  The reference therefore cannot drift from the code: a key
added to a dataclass appears on the next build.

In a MyST page::

    ```{d3-config-reference}
    ```
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import io
import tokenize

from docutils import nodes
from sphinx.util.docutils import SphinxDirective


def _comments(source: str) -> dict[int, str]:
    """Map each source line number (1-based) to the text of its ``#`` comment."""
    found = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            found[tok.start[0]] = tok.string.lstrip("#").strip()
    return found


def _field_docs(cls) -> dict[str, tuple[str, str]]:
    """``{field: (annotation source, meaning)}`` of one dataclass, from its source.

    The meaning is the comment on the field's line(s), preceded by the block of comment
    lines directly above it (fields documented by a paragraph of comments).  A field with
    no comment of its own right after a commented one (no blank line between) belongs to
    that field's comment when the comment is a paragraph above it, names the field, or the
    two names differ in their last letter only (``cx``, ``cy``): its meaning is then
    ``see <that field>``.
    """
    source = inspect.getsource(cls)
    lines = source.splitlines()
    comments = _comments(source)
    out = {}
    head = None  # the commented field that the fields below it share a paragraph with
    for stmt in ast.parse(source).body[0].body:
        if not (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)):
            head = None
            continue
        if not lines[stmt.lineno - 2].strip():
            head = None
        above = []
        n = stmt.lineno - 1
        while n >= 1 and lines[n - 1].strip().startswith("#"):
            above.insert(0, comments[n])
            n -= 1
        beside = [comments[k] for k in range(stmt.lineno, stmt.end_lineno + 1) if k in comments]
        name = stmt.target.id
        text = " ".join(above + beside)
        if text:
            head = (name, text, bool(above))
        elif head is not None and (head[2] or name in head[1] or name[:-1] == head[0][:-1]):
            text = f"see {head[0]}"
        out[name] = (ast.get_source_segment(source, stmt.annotation), text)
    return out


def _yaml(value) -> str:
    """A default as it is written in a YAML config file."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple):
        return "[" + ", ".join(_yaml(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _meaning(section: str, text: str) -> list[nodes.Node]:
    """The meaning cell; ``see KEY`` becomes a reference to the row of that key."""
    if text.startswith("see ") and " " not in text[4:]:
        return [nodes.Text("see "), nodes.literal(text=f"{section}.{text[4:]}")]
    return [nodes.Text(text)]


def _table(header: list[str], rows: list[list[nodes.Node]], widths: list[int]) -> nodes.table:
    """A docutils table with a header row; each cell is a list of inline nodes."""
    table = nodes.table(classes=["d3-config-table"])
    group = nodes.tgroup(cols=len(header))
    table += group
    group.extend(nodes.colspec(colwidth=w) for w in widths)

    def row(cells):
        r = nodes.row()
        for cell in cells:
            entry = nodes.entry()
            entry += nodes.paragraph("", "", *cell)
            r += entry
        return r

    head = nodes.thead()
    head += row([[nodes.Text(h)] for h in header])
    body = nodes.tbody()
    body.extend(row(cells) for cells in rows)
    group += head
    group += body
    return table


class ConfigReference(SphinxDirective):
    """Directive ``d3-config-reference``: one section per config section, one row per key."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        """Build the sections and tables from :mod:`d3cli.config.sections`."""
        from d3cli.config import checks, sections

        ranges = getattr(checks, "_RANGES", {})  # accepted values where a check exists
        self.env.note_dependency(inspect.getsourcefile(sections))
        self.env.note_dependency(inspect.getsourcefile(checks))
        out = []
        for sec in dataclasses.fields(sections.Config):
            cls = sec.default_factory
            docs = _field_docs(cls)
            node = nodes.section(ids=[f"config-{sec.name}"], names=[f"config-{sec.name}"])
            node += nodes.title("", "", nodes.literal(text=sec.name))
            summary = inspect.getdoc(cls).split("\n\n")[0].replace("\n", " ")
            node += nodes.paragraph("", "", nodes.Text(f"{summary} (class "),
                                    nodes.literal(text=f"d3cli.config.{cls.__name__}"), nodes.Text(")."))
            rows = []
            for f in dataclasses.fields(cls):
                annotation, meaning = docs.get(f.name, (str(f.type), ""))
                default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
                check = ranges.get(f"{sec.name}.{f.name}")
                rows.append([
                    [nodes.literal(text=f"{sec.name}.{f.name}")],
                    [nodes.literal(text=annotation)],
                    [nodes.literal(text=_yaml(default))],
                    [nodes.Text(check[1] if check else "")],
                    _meaning(sec.name, meaning),
                ])
            node += _table(["key", "type", "default", "accepted", "meaning"], rows, [18, 12, 10, 18, 42])
            out.append(node)
        return out


def setup(app):
    """Register the directive."""
    app.add_directive("d3-config-reference", ConfigReference)
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
