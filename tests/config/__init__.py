"""Tests of :mod:`d3cli.config`: sections and defaults, YAML reading, checks and their messages."""
