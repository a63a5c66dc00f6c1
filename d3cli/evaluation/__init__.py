"""Scoring and reporting: metrics, summary files, plausibility diagnostics.

- ``metrics``: EPE, PEP, density, photometric MSE/PSNR/SSIM, error maps
  (docs/design.md, 'Metrics');
- ``report``: per-pair CSV, summary JSON and Markdown (row columns and tables re-exported);
- ``summary``: the row columns, counts and means of rows (:func:`summarize`);
- ``tables``: summary.md, the side-by-side comparison, the terminal table;
- ``definitions``: name, unit and exact definition of every metric column (one table for
  report.html, summary.md and the terminal);
- ``pictures``: disparity and error colour pictures, validity overlay, panel;
- ``html``: report.html;
- ``diagnostics``: warnings for results that look like an unrectified or swapped pair.

May import: :mod:`d3cli.data`, :mod:`d3cli.errors`.  Never the method or the batch.
"""
