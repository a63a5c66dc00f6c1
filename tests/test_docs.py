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
PAGES = ["index", "getting-started", "cli", "datasets", "configuration", "road", "survey", "scaling", "gpu",
         "failures", "method", "metrics", "results", "paper", "performance", "design", "api"]
#: The pages that describe the product (using it, the method, the reference): no project
#: history and no numbers the program cannot keep true.
PRODUCT_PAGES = ["index", "getting-started", "cli", "datasets", "configuration", "failures", "method",
                 "metrics", "paper", "design", "development", "api", "results", "road", "survey", "scaling", "gpu",
                 "performance"]


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


def _markdown(name: str) -> str:
    return (DOCS / f"{name}.md").read_text(encoding="utf-8")


def test_the_compile_notice_quoted_in_the_docs_is_the_one_the_code_prints(monkeypatch):
    from d3cli.batch.warmup import CompileProgress
    from d3cli.kernels import cache_location

    # What a first run prints where no earlier compile was recorded: the built-in estimate.
    monkeypatch.setattr(cache_location, "compile_estimate", lambda method: dict(cache_location.COLD_ESTIMATE))
    monkeypatch.setattr(cache_location, "cache_root", lambda cache_dir=None: "DIR")
    notice = f"NOTE: {cache_location.compile_notice('d3stereo')}"
    texts = {path.name: path.read_text(encoding="utf-8")
             for path in [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]}
    quoted = {name: re.findall(r"NOTE: compiling the kernels[^`\n]*", text) for name, text in texts.items()}
    estimates = [(name, line) for name, lines in quoted.items() for line in lines if re.search(r"about \d", line)]
    assert ("failures.md", notice) in estimates
    assert [(name, line) for name, line in estimates if line != notice] == []
    # The progress lines, as failures.md writes them with placeholders.
    progress = CompileProgress(expected=300)
    progress.compiled = 40
    template = re.search(r"`NOTE: (compiled K of about N kernel functions \(S s\))`", texts["failures.md"])
    assert template is not None
    assert template.group(1).replace("K", "40").replace("N", "300").replace("S s", "31 s") == progress.line(31.4)


def test_the_bundled_motorcycle_sample_is_described_by_its_size():
    from d3cli.data.formats import read_image

    left = read_image(ROOT / "d3cli" / "data" / "samples" / "motorcycle" / "left.png")
    height, width = left.shape[:2]
    assert f"one-eighth size, {width}x{height}" in _markdown("getting-started")


def test_the_product_pages_tell_no_history_and_no_fragile_counts():
    found = []
    for name in PRODUCT_PAGES:
        for number, line in enumerate(_markdown(name).splitlines(), 1):
            if re.search(r"session \d+|issue \d+|\b20\d\d-\d\d-\d\d\b|\b\d+ kernel functions", line, re.I):
                found.append(f"{name}.md:{number}: {line.strip()}")
    assert found == []


def test_configuration_prose_restates_no_default_and_its_example_edits_the_road_config(tmp_path):
    page = _markdown("configuration")
    prose = page[:page.index("## Reference")]
    # Defaults live in the generated reference only: no "key: value" or "key = value" of the
    # default config in the prose above it.
    cfg = Config()
    restated = []
    for section in dataclasses.fields(Config):
        for key in dataclasses.fields(section.default_factory):
            value = getattr(getattr(cfg, section.name), key.name)
            for text in (f"{key.name}: {value}", f"{key.name} = {value}", f"{key.name}={value}"):
                if text in prose:
                    restated.append(text)
    assert restated == []
    # "copy configs/road.yaml and change cost.window" gives the config that
    # "-c road --set cost.window=N" gives.
    from d3cli import load_config

    window = int(re.search(r"-c road --set cost\.window=(\d+)", prose).group(1))
    assert f"`window: {window}`" in prose and "cp configs/road.yaml my-road.yaml" in prose
    road = (ROOT / "configs" / "road.yaml").read_text(encoding="utf-8")
    edited, count = re.subn(r"(?m)^(  window:) \d+", rf"\1 {window}", road)
    assert count == 1
    (tmp_path / "my-road.yaml").write_text(edited, encoding="utf-8")
    mine = load_config(tmp_path / "my-road.yaml")
    assert mine == load_config("road", [f"cost.window={window}"])
    assert mine.cost.window != load_config("road").cost.window


def test_the_performance_page_is_figures_not_a_chronicle():
    # The current figures, how to reproduce them and a short table of alternatives not taken.
    assert len(_markdown("performance").splitlines()) <= 300
