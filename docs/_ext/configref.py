"""Sphinx extension: the configuration reference, generated from the config dataclasses.

The directive ``d3-config-reference`` walks :class:`d3cli.config.Config` section by
section and writes, for every key, its type, its default, the accepted values (from the
check) and its meaning, all read from the key's declaration,
``setting(default, doc, check, expected)`` in ``d3cli/config/sections.py`` (the ``doc``
is also the comment of the key's line in ``configs/default.yaml``; tests/config checks
that).  The reference therefore cannot drift from the code: a key added to a dataclass
appears on the next build.

In a MyST page::

    ```{d3-config-reference}
    ```
"""

from __future__ import annotations

import dataclasses
import inspect

from docutils import nodes
from sphinx.util.docutils import SphinxDirective


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
        from d3cli.config import sections

        self.env.note_dependency(inspect.getsourcefile(sections))
        out = []
        for sec in dataclasses.fields(sections.Config):
            cls = sec.default_factory
            node = nodes.section(ids=[f"config-{sec.name}"], names=[f"config-{sec.name}"])
            node += nodes.title("", "", nodes.literal(text=sec.name))
            summary = inspect.getdoc(cls).split("\n\n")[0].replace("\n", " ")
            node += nodes.paragraph("", "", nodes.Text(f"{summary} (class "),
                                    nodes.literal(text=f"d3cli.config.{cls.__name__}"), nodes.Text(")."))
            rows = []
            for f in dataclasses.fields(cls):
                default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
                rows.append([
                    [nodes.literal(text=f"{sec.name}.{f.name}")],
                    [nodes.literal(text=str(f.type))],
                    [nodes.literal(text=_yaml(default))],
                    [nodes.Text(f.metadata.get("expected", ""))],
                    [nodes.Text(f.metadata.get("doc", ""))],
                ])
            node += _table(["key", "type", "default", "accepted", "meaning"], rows, [18, 12, 10, 18, 42])
            out.append(node)
        return out


def setup(app):
    """Register the directive."""
    app.add_directive("d3-config-reference", ConfigReference)
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
