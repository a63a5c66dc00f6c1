"""Sphinx configuration of the d3stereo documentation.

Builds offline (no intersphinx, no remote images) so that ``sphinx-build -W`` passes in CI
without network access.  The pages are MyST Markdown; the API reference comes from the
numpydoc docstrings of the package; the configuration reference is generated from the
frozen dataclasses of :mod:`d3cli.config.sections` by the local ``configref`` extension,
the metric columns from :mod:`d3cli.evaluation.definitions` by ``metricref``.
"""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
# The package from this checkout (not an installed copy), and the local extension.
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE / "_ext"))

import d3cli  # noqa: E402

project = "d3stereo"
author = "the d3stereo authors"
copyright = "the d3stereo authors, MIT licence"
version = release = d3cli.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "configref",
    "metricref",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]

# MyST: anchors for ## and ### headings, so pages can link to sections.
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence", "dollarmath"]

# API reference: one page per public object, generated at build time (not committed).
autosummary_generate = True
autosummary_imported_members = False
autodoc_typehints = "none"  # numpydoc lists the parameter types from the docstrings
autodoc_default_options = {"members": True, "show-inheritance": False}

# numpydoc: no autosummary table of every method on class pages (autosummary lists
# them already), and no cross-reference guessing of free-text types ("float32 (H, W)").
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
# Check the docstrings of the documented API for what makes a page wrong: an object
# without a docstring (GL08), a parameter not documented (PR01), documented but absent
# (PR02) or out of order (PR03).  Style-only checks (summary punctuation, "int" spelled
# "integer", See Also, examples) are not errors here.
numpydoc_validation_checks = {"GL08", "PR01", "PR02", "PR03"}
# Dataclasses: numpydoc reads the generated __init__ as parameters; their fields are
# documented beside each field (comments) or in the class docstring, not as parameters.
# Private names and __init__ are not on the pages.
numpydoc_validation_exclude = {
    r"\.__init__$",
    r"\._[a-z]",
    r"^d3cli\.(Config|DisparityResult)$",
    r"^d3cli\.data\.layouts\.Pair$",
    r"^d3cli\.road\.(pointcloud\.Camera|plane\.RoadPlane|defects\.Defect)$",
}

html_theme = "alabaster"
html_static_path = ["_static"]
html_title = f"d3stereo {release}"
html_theme_options = {"description": "Decisive disparity diffusion stereo matching", "fixed_sidebar": True}
# The site is the rendered pages only (the Markdown sources are in the repository).
html_copy_source = False
