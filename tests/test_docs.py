"""The documentation site builds with warnings as errors, offline, and says what it must.

One Sphinx build (about 35 s on 2 cores) shared by the checks through a module fixture.
"""

import dataclasses
import html
import re
import subprocess
import sys
from pathlib import Path

import pytest

from d3cli.config import Config

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = ["index", "getting-started", "cli", "datasets", "configuration", "road", "scaling", "gpu",
         "failures", "method", "metrics", "results", "paper", "performance", "design", "api"]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """Build the site into a temporary folder with ``sphinx-build -W``; return the folder."""
    out = tmp_path_factory.mktemp("site")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
           "-d", str(out / "doctrees"), str(DOCS), str(out / "html")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stderr == ""  # -q: only warnings would print, and -W makes them errors
    return out / "html"


def _text(page: Path) -> str:
    """The visible text of an HTML page, entities decoded, whitespace collapsed."""
    raw = re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8"))
    return " ".join(html.unescape(raw).split())


def test_every_page_is_built(site):
    missing = [name for name in PAGES if not (site / f"{name}.html").is_file()]
    assert missing == []


def test_the_configuration_reference_lists_every_key_of_every_section(site):
    text = _text(site / "configuration.html")
    page = (site / "configuration.html").read_text(encoding="utf-8")
    for section in dataclasses.fields(Config):
        assert f'id="config-{section.name}"' in page
        for key in dataclasses.fields(section.default_factory):
            assert f"{section.name}.{key.name}" in text
    # Default, accepted values and the field's comment of one key, as the code has them.
    reference = text[text.index("Every section and key, generated"):]
    row = reference[reference.index("seeds.pkrn_exclusion"):][:200]
    assert row.startswith("seeds.pkrn_exclusion int 0 an integer >= 0 0: naive PKRN; r > 0: c2 ignores")


def test_the_api_reference_is_generated_from_the_docstrings(site):
    text = _text(site / "generated" / "d3cli.D3Stereo.html")
    assert "compute" in text
    assert (site / "generated" / "d3cli.load_config.html").is_file()


def test_readme_is_short_and_sends_nobody_to_a_folder_outside_the_repository():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 250
    texts = [readme] + [p.read_text(encoding="utf-8") for p in sorted(DOCS.glob("*.md"))]
    assert [t for t in texts if "../shared" in t] == []


def test_readme_starts_with_the_two_commands_for_a_fresh_machine():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = readme.split("```bash\n", 1)[1].split("```", 1)[0]
    assert block == (
        'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && d3stereo run --eval -o out\n'
        "python -m pytest -q\n"
    )


def test_readme_picture_is_in_the_repository_and_small():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", readme)
    assert pictures == ["docs/_static/panel-motorcycle.png"]
    assert (ROOT / pictures[0]).stat().st_size < 300_000
