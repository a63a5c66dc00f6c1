"""The README's picture and the figures it quotes about the bundled samples, from a run.

Runs ``d3stereo run --eval`` on the two bundled samples (the Middlebury 2014 Motorcycle
at one-eighth size and a synthetic road pair) in a temporary folder, then

- writes ``docs/_static/panel-motorcycle.png``: the Motorcycle sample's ``panel.png``
  reduced to 256 colours (so the repository stays light), with the panel's title and the
  command that made it in the PNG's text chunks (``Title``, ``Software``);
- rewrites the block between ``<!-- samples:begin -->`` and ``<!-- samples:end -->`` in
  README.md: the picture's caption with its title, and each sample's scores as the run
  printed them.

``tests/test_docs_figures.py`` runs the samples and checks the picture's title and the
README's block against that run, so a change that moves the samples' scores fails the
tests until this script is run again.

Usage::

    python scripts/make_docs_figures.py            # rewrite the picture and the README block
    python scripts/make_docs_figures.py --check    # exit 1 if either differs from a fresh run
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, PngImagePlugin

ROOT = Path(__file__).resolve().parents[1]
PICTURE = ROOT / "docs" / "_static" / "panel-motorcycle.png"
README = ROOT / "README.md"
BEGIN, END = "<!-- samples:begin -->", "<!-- samples:end -->"
SAMPLES = ("motorcycle", "road")
#: The README shows this pair's panel.
PANEL_PAIR = "motorcycle"
SOFTWARE = "scripts/make_docs_figures.py (d3stereo run --eval on the bundled samples)"


def run_samples(out: Path) -> dict[str, dict]:
    """Run the bundled samples with ``--eval`` into ``out``; each pair's result.json."""
    cmd = [sys.executable, "-m", "d3cli", "run", "--eval", "-q", "-o", str(out)]
    subprocess.run(cmd, check=True)
    return {name: json.loads((out / name / "result.json").read_text(encoding="utf-8")) for name in SAMPLES}


def panel_title(name: str, result: dict) -> str:
    """The title ``panel.png`` carries for this pair (the batch's own formatting)."""
    from d3cli.batch.outputs import panel_title as title

    return title(name, result.get("metrics"))


def samples_block(results: dict[str, dict]) -> str:
    """The README's block: the picture's caption and the samples' scores, from the run."""
    rows = []
    for name in SAMPLES:
        m = results[name]["metrics"]
        rows.append(f"| {name} | {results[name]['shape'][1]}x{results[name]['shape'][0]} | {m['epe']:.3f} | "
                    f"{m['pep_1']:.2f} | {m['d1_all']:.2f} | {m['psnr']:.2f} |")
    title = panel_title(PANEL_PAIR, results[PANEL_PAIR])
    return "\n".join([
        BEGIN,
        "![panel.png of the bundled Middlebury sample: left image, d3stereo's disparity, its error against "
        "the ground truth in KITTI colours, and the pixels it filled](docs/_static/panel-motorcycle.png)",
        "",
        f"*`panel.png` of the Motorcycle sample, titled `{' '.join(title.split())}`: left image |"
        " disparity | error against the ground truth (KITTI log colours) | validity (red: filled).*",
        "",
        "The samples as the first command scores them (default config):",
        "",
        "| sample | size | EPE [px] | PEP1 [%] | D1 [%] | PSNR [dB] |",
        "|---|---|---|---|---|---|",
        *rows,
        END,
    ])


def picture(results: dict[str, dict], out: Path) -> Image.Image:
    """The panel of :data:`PANEL_PAIR`, reduced to 256 colours, with its text chunks."""
    rgb = np.asarray(Image.open(out / PANEL_PAIR / "panel.png").convert("RGB"))
    reduced = Image.fromarray(rgb).quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    reduced.info = {"Title": panel_title(PANEL_PAIR, results[PANEL_PAIR]), "Software": SOFTWARE}
    return reduced


def save_picture(image: Image.Image, path: Path) -> None:
    """Write ``image`` as a PNG with its ``Title`` and ``Software`` chunks."""
    chunks = PngImagePlugin.PngInfo()
    for key in ("Title", "Software"):
        chunks.add_text(key, image.info[key])
    tmp = path.with_suffix(".tmp.png")
    image.save(tmp, pnginfo=chunks, optimize=True)
    tmp.replace(path)


def replace_block(text: str, block: str) -> str:
    """``text`` with its samples block replaced by ``block``."""
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{README}: no {BEGIN} ... {END} block; add one where the picture goes")
    head, rest = text.split(BEGIN, 1)
    return head + block + rest.split(END, 1)[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 on a difference")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="d3stereo-figures-") as tmp:
        out = Path(tmp) / "out"
        results = run_samples(out)
        image = picture(results, out)
        readme = README.read_text(encoding="utf-8")
        new_readme = replace_block(readme, samples_block(results))
        if args.check:
            stale = []
            if new_readme != readme:
                stale.append(f"{README.name}'s samples block")
            if Image.open(PICTURE).info.get("Title") != image.info["Title"]:
                stale.append(PICTURE.name)
            for what in stale:
                print(f"stale: {what}; run python scripts/make_docs_figures.py")
            return 1 if stale else 0
        save_picture(image, PICTURE)
        README.write_text(new_readme, encoding="utf-8")
    print(f"wrote {PICTURE.relative_to(ROOT)} ({PICTURE.stat().st_size} bytes) and README.md's samples block")
    print(image.info["Title"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
