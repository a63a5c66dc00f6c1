"""Tests of the finishing kernels (``d3cli.kernels.finishing``), by concern as the package."""
