"""The README's picture and every figure the docs quote about the bundled samples match a run.

One run of the bundled samples (``d3stereo run --eval``, as the README's first command)
shared by the checks; ``scripts/make_docs_figures.py`` writes what is checked here.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
TEXTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


@pytest.fixture(scope="module")
def figures():
    spec = importlib.util.spec_from_file_location("make_docs_figures", ROOT / "scripts" / "make_docs_figures.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("make_docs_figures", module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def run(figures, tmp_path_factory):
    out = tmp_path_factory.mktemp("samples") / "out"
    return out, figures.run_samples(out)


def test_the_readme_block_is_what_the_script_writes_from_a_run(figures, run):
    _, results = run
    readme = figures.README.read_text(encoding="utf-8")
    block = figures.samples_block(results)
    assert block in readme, "README.md's samples block is stale: run python scripts/make_docs_figures.py"
    assert f"| motorcycle | 370x250 | {results['motorcycle']['metrics']['epe']:.3f} |" in block


def test_the_picture_is_the_panel_of_a_run(figures, run):
    out, results = run
    stored = Image.open(figures.PICTURE)
    assert stored.info["Title"] == figures.panel_title("motorcycle", results["motorcycle"])
    assert stored.info["Title"].startswith("motorcycle   EPE 0.91 px   D1 6.9")
    fresh = np.asarray(Image.open(out / "motorcycle" / "panel.png").convert("RGB"), dtype=np.int16)
    kept = np.asarray(stored.convert("RGB"), dtype=np.int16)
    assert kept.shape == fresh.shape
    # 256 colours: the reduction moves a pixel by a few levels on average, a changed tile by far more.
    assert np.abs(kept - fresh).mean() < 4.0


# A pair's line as the terminal prints it (``[1/2]  motorcycle  ok  0.40 s  EPE 0.910 px``),
# and the panel's title (``motorcycle   EPE 0.91 px   D1 6.94%``), wherever a page quotes them.
TERMINAL_LINE = re.compile(r"\b(motorcycle|road)\s+ok\b[^\n]*?\bEPE(?: \[px\])?\s+([0-9]+\.[0-9]+)")
PANEL_TITLE = re.compile(r"\b(motorcycle|road)\s+EPE\s+([0-9]+\.[0-9]+) px\s+D1\s+([0-9]+\.[0-9]+)%")


def test_every_sample_figure_the_docs_quote_matches_the_run(run):
    _, results = run
    quoted = []
    for path in TEXTS:
        text = path.read_text(encoding="utf-8")
        for m in TERMINAL_LINE.finditer(text):
            epe = results[m[1]]["metrics"]["epe"]
            digits = len(m[2].split(".")[1])
            quoted.append((path.name, m[0], m[2], f"{epe:.{digits}f}"))
        for m in PANEL_TITLE.finditer(text):
            metrics = results[m[1]]["metrics"]
            quoted.append((path.name, m[0], m[2], f"{metrics['epe']:.2f}"))
            quoted.append((path.name, m[0], m[3], f"{metrics['d1_all']:.2f}"))
    assert quoted, "no page quotes the samples any more: drop this test or the pattern"
    wrong = [(page, line, said, actual) for page, line, said, actual in quoted if said != actual]
    assert wrong == []
