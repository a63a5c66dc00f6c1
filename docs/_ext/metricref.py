"""Sphinx extension: the metric columns, generated from the table the reports read.

The directive ``d3-metric-table`` lists every entry of
:data:`d3cli.evaluation.definitions.METRICS`: the key (``metrics.csv``, ``result.json``),
the column name with its unit as the terminal, ``summary.md`` and ``report.html`` show it,
and its definition.  The page therefore names the columns exactly as the reports do, and a
column added to the table appears on the next build.

In a MyST page::

    ```{d3-metric-table}
    ```
"""

from __future__ import annotations

import inspect

from configref import _table
from docutils import nodes
from sphinx.util.docutils import SphinxDirective


class MetricTable(SphinxDirective):
    """Directive ``d3-metric-table``: one row per metric column, then the rules of the means."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        """Build the table from :mod:`d3cli.evaluation.definitions`."""
        from d3cli.evaluation import definitions

        self.env.note_dependency(inspect.getsourcefile(definitions))
        rows = [[[nodes.literal(text=key)], [nodes.Text(m.label)], [nodes.Text(m.definition)]]
                for key, m in definitions.METRICS.items()]
        notes = [nodes.paragraph("", "", nodes.Text(text))
                 for text in (definitions.EVALUATED, definitions.PIXEL_SETS, definitions.MEANS)]
        return [_table(["key", "column", "definition"], rows, [16, 22, 62]), *notes]


def setup(app):
    """Register the directive."""
    app.add_directive("d3-metric-table", MetricTable)
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
