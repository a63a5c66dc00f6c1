"""Bundled sample stereo pairs (pair-folder layout)."""
