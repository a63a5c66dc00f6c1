"""Scoring and reporting: metrics, summary files, plausibility diagnostics.

- ``metrics``: EPE, PEP, density, photometric MSE/PSNR/SSIM, error maps (DESIGN section 4);
- ``report``: per-pair CSV, summary JSON and Markdown, side-by-side tables;
- ``diagnostics``: warnings for results that look like an unrectified or swapped pair.

May import: :mod:`d3cli.data`, :mod:`d3cli.errors`.  Never the method or the batch.
"""
