"""The adversarial suite: what a hostile or unlucky user does to ``d3stereo run``.

Every case checks the whole contract at once: the exit code, the exact one-line
``Error:`` (and ``failed:``) lines, no traceback, and that no input file changed (hashes
before and after).  Signals land at seeded random moments of a running batch: exit 130
(SIGINT) or 143 (SIGTERM), run.json present and marked interrupted, no lock left, no pair
recorded as failed, and the rerun resumes to per-pair files byte-identical to an
uninterrupted run.  CLI cases use ``--method sgbm`` on tiny pairs (they test the batch
and the readers, not the method) and run in-process; the signal cases run the real
command in a subprocess.  About a minute in all.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import signal
import stat
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from d3cli.batch import LOCK_FILE, OUTPUT_FILES
from d3cli.cli import main
from d3cli.config import MAX_CONFIG_INT, MAX_YAML_DEPTH, MAX_YAML_NODES
from d3cli.data.formats import write_pfm
from tests.helpers import textured_pair, write_png

ALIAS_BOMB = "".join(
    f"{name}: &{name} [{', '.join([f'*{prev}'] * 9) if prev else ', '.join(['lol'] * 9)}]\n"
    for prev, name in zip([None, *"abcdefgh"], "abcdefghi")
)


# ----------------------------------------------------------------------------- helpers
def _pair(folder: Path, *, size=(48, 96), shift=5, seed=1, gt=True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    left, right, disp = textured_pair(shift, size, seed=seed)
    write_png(folder / "left.png", left)
    write_png(folder / "right.png", right)
    if gt:
        write_pfm(folder / "disp_gt.pfm", disp)
        (folder / "SOURCE.txt").write_text("gt_scale: 1\ngt_invalid: inf\n")
    return folder


def _png_claiming(path: Path, width: int, height: int) -> None:
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                     + chunk(b"IEND", b""))


def _hashes(root: Path) -> dict[str, str]:
    """sha256 of every regular file under ``root`` (links and FIFOs are not followed)."""
    found = {}
    for folder, dirs, files in os.walk(root):
        for name in files:
            path = Path(folder) / name
            if stat.S_ISREG(path.lstat().st_mode):
                found[str(path.relative_to(root))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def _invoke(args) -> tuple[int, list[str]]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    # no traceback: click ended the command (SystemExit), nothing escaped
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    return result.exit_code, result.output.splitlines()


def _check(tmp_path, args, *, code: int, error: str | None, failed: str | None = None, out: Path | None = None):
    """Run ``d3stereo run ARGS`` on the inputs under tmp_path/in; check the contract."""
    inputs = tmp_path / "in"
    before = _hashes(inputs)
    exit_code, lines = _invoke(args)
    assert exit_code == code, lines
    assert [line for line in lines if line.startswith("Error:")] == ([error] if error else []), lines
    if failed is not None:
        assert [line for line in lines if line.startswith("failed:")] == [failed], lines
    assert _hashes(inputs) == before  # no input file changed, none removed
    if out is not None and code != 2:
        assert not (out / LOCK_FILE).exists()
    return lines


# ----------------------------------------------------------------------------- hostile YAML
YAML_CASES = {
    "alias bomb": (ALIAS_BOMB.encode(), "{path}: YAML aliases expand to more than " f"{MAX_YAML_NODES} values (an "
                   "alias bomb?); write the values out instead of nesting aliases"),
    "deep nesting": (("cost: " + "[" * 5000 + "]" * 5000 + "\n").encode(),
                     f"{{path}}: YAML nested more than {MAX_YAML_DEPTH} levels deep; write a flat config or "
                     "manifest (a config needs 3 levels)"),
    "not UTF-8": (b"diffusion:\n  tau: \xff\xfe\n", "{path}:2: cannot read {what} (not UTF-8 text: byte 0xff at "
                  "offset 18; is it a YAML file?); give a readable UTF-8 YAML file"),
    "NUL bytes": (b"diffusion:\n  tau: 2\x00\n", "{path}:2: cannot read {what} (a NUL byte: binary data, not "
                  "YAML); give a readable UTF-8 YAML file"),
    "recursive alias": (b"cost: &x\n  window: *x\n", "{path}:1: a recursive YAML alias; write the value out instead"),
}


@pytest.mark.parametrize("case", sorted(YAML_CASES))
def test_hostile_yaml_config(tmp_path, case):
    data, message = YAML_CASES[case]
    _pair(tmp_path / "in" / "pairs" / "p")
    path = tmp_path / "in" / "hostile.yaml"
    path.write_bytes(data)
    out = tmp_path / "out"
    _check(tmp_path, ["run", tmp_path / "in" / "pairs", "-c", path, "-o", out, "--method", "sgbm"], code=1,
           error="Error: " + message.format(path=path, what="config file"))
    assert not out.exists()  # refused before anything was written


@pytest.mark.parametrize("case", sorted(set(YAML_CASES) - {"recursive alias"}))
def test_hostile_yaml_manifest(tmp_path, case):
    data, message = YAML_CASES[case]
    path = tmp_path / "in" / "pairs.yaml"
    path.parent.mkdir(parents=True)
    path.write_bytes(data.replace(b"cost:", b"pairs:"))
    _check(tmp_path, ["run", path, "-o", tmp_path / "out", "--method", "sgbm"], code=1,
           error="Error: " + message.format(path=path, what="manifest file"))


@pytest.mark.parametrize("text, what", [
    ("diffusion:\n  max_sweeps: 1e20\n", f"diffusion.max_sweeps must be an integer of at most {MAX_CONFIG_INT} in "
                                          "size, got 100000000000000000000"),
    ("diffusion:\n  max_sweeps: 99999999999999999999999\n",
     f"diffusion.max_sweeps must be an integer of at most {MAX_CONFIG_INT} in size, got 99999999999999999999999"),
    ("aggregation:\n  sigma_color: 1e400\n", "aggregation.sigma_color must be a number, got inf"),
])
def test_huge_numbers_in_a_config(tmp_path, text, what):
    _pair(tmp_path / "in" / "pairs" / "p")
    path = tmp_path / "in" / "c.yaml"
    path.write_text(text)
    key = what.split()[0]
    _check(tmp_path, ["run", tmp_path / "in" / "pairs", "-c", path, "-o", tmp_path / "out", "--method", "sgbm"],
           code=1, error=f"Error: {path}:2: {what}; fix the value of {key} (see d3cli/presets/default.yaml)")


# ----------------------------------------------------------------------------- odd images
def _write_grey_pair(folder: Path, left: np.ndarray, right: np.ndarray, ext: str = "png") -> None:
    folder.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(folder / f"left.{ext}"), left) and cv2.imwrite(str(folder / f"right.{ext}"), right)


@pytest.mark.parametrize("kind", ["12-bit in 16-bit PNG", "10-bit", "two grey levels", "float32 TIFF 0-1",
                                  "float64 TIFF", "RGBA", "16-bit RGB"])
def test_odd_bit_depths_are_read(tmp_path, kind):
    left, right, _ = textured_pair(5, (48, 96), seed=2)
    make = {
        "12-bit in 16-bit PNG": lambda a: a.astype(np.uint16) << 4,
        "10-bit": lambda a: a.astype(np.uint16) << 2,
        "two grey levels": lambda a: (a > 128).astype(np.uint8),
        "float32 TIFF 0-1": lambda a: a.astype(np.float32) / 255,
        "float64 TIFF": lambda a: a.astype(np.float64),
        "RGBA": lambda a: np.dstack([a, a, a, np.full_like(a, 255)]),
        "16-bit RGB": lambda a: np.dstack([a, a, a]).astype(np.uint16) * 257,
    }[kind]
    ext = "tif" if "TIFF" in kind else "png"
    _write_grey_pair(tmp_path / "in" / "p", make(left), make(right), ext)
    out = tmp_path / "out"
    _check(tmp_path, ["run", tmp_path / "in", "-o", out, "--method", "sgbm"], code=0, error=None, out=out)
    assert json.loads((out / "run.json").read_text())["n_failed"] == 0
    assert all((out / "p" / name).is_file() for name in OUTPUT_FILES)


def _failed_pair(tmp_path, pair_message: str, *, args=(), eval_failure=False):
    out = tmp_path / "out"
    _check(tmp_path, ["run", tmp_path / "in", "-o", out, "--method", "sgbm", *args], code=1,
           error=f"Error: 1 of 1 pair failed (see {out / 'run.json'})", failed=f"failed: p: {pair_message}", out=out)
    run = json.loads((out / "run.json").read_text())
    assert run["n_failed"] == 1 and run["interrupted"] is False
    if eval_failure:  # the maps are kept, only the evaluation failed
        assert all((out / "p" / name).is_file() for name in OUTPUT_FILES)
    else:
        assert not (out / "p" / "result.json").exists()


@pytest.mark.parametrize("height, width", [(1, 1), (50, 1)])
def test_images_too_narrow_for_any_disparity(tmp_path, height, width):
    image = (np.arange(height * width) % 251).astype(np.uint8).reshape(height, width)
    _write_grey_pair(tmp_path / "in" / "p", image, image)
    _failed_pair(tmp_path, "an image 1 pixel wide has no disparity to search; give images at least 2 pixels wide")


# 2 and 3 pixels wide: disparity 1 is searched, as with --max-disparity 1 (was refused as
# "no disparity range").
@pytest.mark.parametrize("height, width", [(1, 50), (5, 200), (200, 5), (2, 3), (4, 2)])
def test_thin_images_give_maps_of_their_size(tmp_path, height, width):
    rng = np.random.default_rng(height * 1000 + width)
    image = rng.integers(0, 256, (height, width), dtype=np.uint8)
    _write_grey_pair(tmp_path / "in" / "p", image, image)
    out = tmp_path / "out"
    _check(tmp_path, ["run", tmp_path / "in", "-o", out, "--method", "sgbm"], code=0, error=None, out=out)
    disp = cv2.imread(str(out / "p" / "valid.png"), cv2.IMREAD_UNCHANGED)
    assert disp.shape == (height, width)


def test_left_and_right_of_different_sizes(tmp_path):
    _pair(tmp_path / "in" / "p")
    _, right, _ = textured_pair(5, (48, 90), seed=2)
    write_png(tmp_path / "in" / "p" / "right.png", right)
    _failed_pair(tmp_path, "left is 48x96 but right is 48x90; a stereo pair needs equal sizes")


def test_truncated_png(tmp_path):
    folder = _pair(tmp_path / "in" / "p")
    data = (folder / "left.png").read_bytes()
    (folder / "left.png").write_bytes(data[: len(data) // 2])
    _failed_pair(tmp_path, f"{folder / 'left.png'}: cannot read image (corrupt or not an image); give an 8/16-bit "
                           "PNG, JPEG, PPM/PGM or TIFF file")


def test_truncated_pfm_ground_truth_fails_only_the_evaluation(tmp_path):
    folder = _pair(tmp_path / "in" / "p")
    data = (folder / "disp_gt.pfm").read_bytes()
    (folder / "disp_gt.pfm").write_bytes(data[: len(data) // 2])
    missing = len(data) - len(data) // 2
    _failed_pair(tmp_path, f"evaluation failed, maps kept: {folder / 'disp_gt.pfm'}: truncated PFM: 96x48x1 needs "
                           f"18432 bytes of data, found {18432 - missing}; re-download or re-write the file",
                 args=["--eval"], eval_failure=True)


def test_header_claiming_a_huge_image(tmp_path):
    folder = _pair(tmp_path / "in" / "p")
    _png_claiming(folder / "left.png", 32000, 32000)
    _png_claiming(folder / "right.png", 32000, 32000)
    _failed_pair(tmp_path, f"{folder / 'left.png'}: image of 32000x32000 pixels is larger than 268435456 pixels "
                           "(about 6.1 GB to decode); give an image of at most 16384x16384 pixels, or crop or "
                           "downscale it")


def test_header_beyond_opencvs_limit(tmp_path):
    folder = _pair(tmp_path / "in" / "p")
    _png_claiming(folder / "left.png", 2_000_000, 1)
    _png_claiming(folder / "right.png", 2_000_000, 1)
    _failed_pair(tmp_path, f"{folder / 'left.png'}: image of 2000000x1 pixels has a side longer than 1048576 pixels, "
                           "the most OpenCV decodes; crop or downscale it (a stereo pair this wide is likely a "
                           "mistake)")


# ----------------------------------------------------------------------------- unreadable inputs
@pytest.mark.parametrize("kind", ["folder", "fifo", "dangling link", "symlink loop"])
def test_left_image_that_cannot_be_read(tmp_path, kind):
    folder = _pair(tmp_path / "in" / "p")
    left = folder / "left.png"
    left.unlink()
    if kind == "folder":
        left.mkdir()
    elif kind == "fifo":
        os.mkfifo(left)
    elif kind == "dangling link":
        left.symlink_to(folder / "gone.png")
    else:
        left.symlink_to(left)
    # A folder or a FIFO exists: named as what it is (it was taken for a missing left image).
    message = {"folder": f"{left}: is a folder, not a file; give the file itself",
               "fifo": f"{left}: not a regular file (a FIFO); give the file itself"}.get(
        kind, f"{folder}: found a right image but no left image; add left.png or remove the folder")
    _failed_pair(tmp_path, message)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their mode")
def test_left_image_without_read_permission(tmp_path):
    folder = _pair(tmp_path / "in" / "p")
    (folder / "left.png").chmod(0)
    try:
        _failed_pair(tmp_path, f"{folder / 'left.png'}: cannot read file (Permission denied); check its permissions")
    finally:
        (folder / "left.png").chmod(0o644)


def test_input_root_that_is_a_symlink_loop(tmp_path):
    loop = tmp_path / "in" / "data"
    loop.parent.mkdir()
    loop.symlink_to(loop)
    _check(tmp_path, ["run", loop, "-o", tmp_path / "out", "--method", "sgbm"], code=1,
           error=f"Error: {loop}: a symlink loop (the link leads back to itself); point it at the data or remove it")


# ----------------------------------------------------------------------------- unwritable OUT
@pytest.mark.skipif(os.geteuid() == 0, reason="root writes whatever the mode (tests/test_cli.py simulates it)")
def test_read_only_out(tmp_path):
    _pair(tmp_path / "in" / "p")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        _check(tmp_path, ["run", tmp_path / "in", "-o", locked, "--method", "sgbm"], code=1,
               error=f"Error: {locked}: cannot write to the output folder (Permission denied); choose another "
                     "folder with -o or fix its permissions")
    finally:
        locked.chmod(0o755)


def test_out_below_a_file(tmp_path):
    _pair(tmp_path / "in" / "p")
    (tmp_path / "in" / "file").write_text("x")
    out = tmp_path / "in" / "file" / "out"
    _check(tmp_path, ["run", tmp_path / "in" / "p", "-o", out, "--method", "sgbm"], code=1,
           error=f"Error: {out}: cannot write to the output folder (Not a directory); choose another folder with -o "
                 "or fix its permissions")


def test_out_inside_the_input(tmp_path):
    folder = _pair(tmp_path / "in" / "p")
    _check(tmp_path, ["run", tmp_path / "in", "-o", folder, "--method", "sgbm"], code=1,
           error=f"Error: {folder}: the output folder holds input files of pair p ({folder / 'left.png'}); "
                 "choose an output folder outside the input data with -o (a new folder beside the inputs is fine)")


# ----------------------------------------------------------------------------- signals
N_PAIRS = 10


@pytest.fixture(scope="module")
def signal_inputs(tmp_path_factory):
    """Ten small pairs and the per-pair files of an uninterrupted run over them."""
    root = tmp_path_factory.mktemp("signals")
    for i in range(N_PAIRS):
        _pair(root / "in" / f"p{i}", size=(120, 200), shift=3 + i % 6, seed=i)
    reference = root / "reference"
    exit_code, lines = _invoke(["run", root / "in", "-o", reference, "--method", "sgbm", "-q"])
    assert exit_code == 0, lines
    return root / "in", reference


def _per_pair_files(out: Path) -> dict[str, bytes]:
    """Every per-pair output file but result.json (which holds timings)."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.glob("p*/*"))
            if p.is_file() and p.name != "result.json"}


def _default_sigint():
    """In the child before exec: SIGINT back to its default.  A shell starts background jobs
    with SIGINT ignored, children inherit that, and Python then installs no Ctrl-C handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupt_at_a_random_moment(inputs: Path, out: Path, sig: int, rng: random.Random):
    """Start the batch, wait until it holds the lock (the batch has begun), then send
    ``sig`` after a seeded delay spread over the batch."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [os.getcwd(), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "d3cli", "run", str(inputs), "-o", str(out), "--method", "sgbm",
                             "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_default_sigint)
    try:
        deadline = time.monotonic() + 120
        while not (out / LOCK_FILE).exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.002)
        time.sleep(rng.uniform(0.0, 0.6))
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    return proc.returncode, stderr


@pytest.mark.parametrize("seed", range(6))
def test_signal_at_a_random_moment_of_a_batch(tmp_path, signal_inputs, seed):
    inputs, reference = signal_inputs
    rng = random.Random(seed)
    sig = signal.SIGINT if seed % 2 == 0 else signal.SIGTERM
    before = _hashes(inputs)
    out = tmp_path / "out"
    code, stderr = _interrupt_at_a_random_moment(inputs, out, sig, rng)
    assert "Traceback" not in stderr, stderr
    run = json.loads((out / "run.json").read_text())
    assert run["n_failed"] == 0 and all(p["status"] == "ok" for p in run["pairs"]), run["pairs"]
    assert not (out / LOCK_FILE).exists()
    assert not list(out.rglob("*.tmp-*"))
    if code == 0:  # the signal came after the batch: it is ignored, everything is written
        assert run["interrupted"] is False and len(run["pairs"]) == N_PAIRS
    else:
        assert code == (130 if sig == signal.SIGINT else 143), (code, stderr)
        what = "Interrupted" if sig == signal.SIGINT else "Terminated (SIGTERM)"
        assert stderr.splitlines() in (
            [f"{what}: {len(run['pairs'])} of {N_PAIRS} pairs done; rerun the same command to resume"],
            ["Interrupted; rerun the same command to resume"],  # after the batch, before the command ended
        ), stderr
        assert run["interrupted"] is True or stderr.startswith("Interrupted;"), run
        # the pairs run.json lists are complete; any other pair folder is complete too (the
        # signal came after its result.json, before it was counted) or absent: none is partial
        for folder in out.glob("p*"):
            assert (folder / "result.json").is_file() and all((folder / n).is_file() for n in OUTPUT_FILES), folder
        assert {p["pair"] for p in run["pairs"]} <= {folder.name for folder in out.glob("p*")}
    again, lines = _invoke(["run", inputs, "-o", out, "--method", "sgbm", "-q"])
    assert again == 0, lines
    assert _per_pair_files(out) == _per_pair_files(reference)
    assert _hashes(inputs) == before
