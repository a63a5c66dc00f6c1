"""d3stereo export: the KITTI and MiddEval3 submission layouts, read back with readers
written as the benchmarks' devkits read them (not with d3cli's own readers)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from d3cli.batch.export import export_submission
from d3cli.cli import main
from d3cli.data.formats import write_pfm
from d3cli.errors import InputError, OutputError

INF = np.inf
#: A 2x3 map: sub-pixel values, the largest KITTI keeps exactly, and an invalid pixel.
DISP = np.array([[0.5, 10.25, 255.5], [INF, 3.0, 64.75]], dtype=np.float32)


def kitti_devkit_read(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """As the KITTI stereo devkit (io_disp.h) reads a disparity PNG: uint16 / 256, valid where > 0."""
    png = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert png is not None and png.dtype == np.uint16 and png.ndim == 2
    return png.astype(np.float64) / 256.0, png > 0


def middeval3_read_pfm(path: Path) -> np.ndarray:
    """As MiddEval3's ReadFilePFM reads: 'Pf', 'W H', scale < 0 = little-endian, rows bottom to top."""
    data = path.read_bytes()
    ident, size, scale, raster = data.split(b"\n", 3)
    assert ident == b"Pf"
    width, height = (int(v) for v in size.split())
    assert float(scale) < 0  # little-endian
    values = np.frombuffer(raster, dtype="<f4", count=width * height).reshape(height, width)
    return values[::-1]


def make_pair(out: Path, name: str, left: str, disp=DISP, total: float | None = 1.25) -> Path:
    folder = out / name
    folder.mkdir(parents=True)
    write_pfm(folder / "disp.pfm", disp)
    timings = {"wall": 2.5} if total is None else {"total": total, "wall": 2.5}
    result = {"pair": name, "inputs": {"left": left, "right": left.replace("im0", "im1"), "gt": None},
              "timings": timings}
    (folder / "result.json").write_text(json.dumps(result))
    return folder


@pytest.fixture
def run_out(tmp_path) -> Path:
    out = tmp_path / "out"
    make_pair(out, "kitti2015-000001_10", "/data/kitti/training/image_2/000001_10.png")
    make_pair(out, "middlebury2014-adirondack-Q", "/data/MiddEval3/trainingQ/Adirondack/im0.png",
              disp=DISP * 2, total=0.5)
    make_pair(out, "synth-0000", "/data/synth/synth-0000/left.png", total=None)
    (out / "broken").mkdir()  # a failed pair: no result.json
    (out / "run.json").write_text("{}")
    return out


def tree(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def digests(folder: Path) -> dict[str, str]:
    return {name: hashlib.sha256((folder / name).read_bytes()).hexdigest() for name in tree(folder)}


def test_kitti_layout_reads_back_with_the_devkit(run_out, tmp_path):
    before = digests(run_out)
    sub = tmp_path / "kitti"
    done = export_submission(run_out, sub, "kitti")
    assert tree(sub) == ["disp_0/000001_10.png", "disp_0/middlebury2014-adirondack-Q_10.png",
                         "disp_0/synth-0000_10.png"]
    assert done.incomplete == ["broken"]
    disp, valid = kitti_devkit_read(sub / "disp_0" / "000001_10.png")
    assert valid.tolist() == [[True, True, True], [False, True, True]]
    assert disp[valid].tolist() == [0.5, 10.25, 255.5, 3.0, 64.75]  # exact: multiples of 1/256
    assert disp[1, 0] == 0.0  # invalid is 0
    assert digests(run_out) == before  # OUT is only read


def test_middeval3_layout_reads_back_with_its_pfm_reader(run_out, tmp_path):
    sub = tmp_path / "mid"
    done = export_submission(run_out, sub, "middeval3", algorithm="D3S", split="trainingH")
    assert tree(sub) == [
        "trainingH/kitti2015-000001_10/disp0D3S.pfm", "trainingH/kitti2015-000001_10/timeD3S.txt",
        "trainingH/synth-0000/disp0D3S.pfm", "trainingH/synth-0000/timeD3S.txt",
        "trainingQ/Adirondack/disp0D3S.pfm", "trainingQ/Adirondack/timeD3S.txt",  # split and scene from the path
    ]
    assert done.pairs == ["kitti2015-000001_10", "middlebury2014-adirondack-Q", "synth-0000"]
    pfm = sub / "trainingQ" / "Adirondack" / "disp0D3S.pfm"
    assert pfm.read_bytes().startswith(b"Pf\n3 2\n-1.0\n")
    values = middeval3_read_pfm(pfm)
    assert values.dtype == np.float32
    np.testing.assert_array_equal(values, DISP * 2)  # inf stays inf: MiddEval3's invalid
    assert np.isinf(values[1, 0])
    assert (sub / "trainingQ" / "Adirondack" / "timeD3S.txt").read_text() == "0.500\n"  # timings.total
    assert (sub / "trainingH" / "synth-0000" / "timeD3S.txt").read_text() == "2.500\n"  # wall without total


def test_middeval3_nan_is_written_as_inf(tmp_path):
    out = tmp_path / "out"
    make_pair(out, "middlebury2014-teddy-F", "/d/testF/Teddy/im0.png",
              disp=np.array([[np.nan, 1.5]], dtype=np.float32))
    export_submission(out, tmp_path / "sub", "middeval3")
    values = middeval3_read_pfm(tmp_path / "sub" / "testF" / "Teddy" / "disp0D3Stereo.pfm")
    assert values.tolist() == [[INF, 1.5]]


def test_cli_export_and_its_errors(run_out, tmp_path):
    runner = CliRunner()
    result = runner.invoke(main, ["export", str(run_out), "--format", "kitti", "-o", str(tmp_path / "k")])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [
        "skipped 1 pair folders without a complete result: broken",
        f"wrote 3 pairs (kitti, 3 files) to {tmp_path / 'k'}"]
    result = runner.invoke(main, ["export", str(run_out), "--format", "middeval3", "-o", str(tmp_path / "m")])
    assert result.exit_code == 1
    assert result.output.splitlines()[-1] == (
        "Error: kitti2015-000001_10: the MiddEval3 split is not in the path of its left image "
        "/data/kitti/training/image_2/000001_10.png; pass --split (e.g. --split trainingQ)")
    result = runner.invoke(main, ["export", str(run_out), "--format", "kitti", "-o", str(run_out / "sub")])
    assert result.exit_code == 1
    assert result.output == (f"Error: {run_out / 'sub'}: is inside the run folder {run_out}; "
                             "write the submission to a folder outside it\n")
    missing = tmp_path / "nothing"
    result = runner.invoke(main, ["export", str(missing), "--format", "kitti", "-o", str(tmp_path / "k2")])
    assert result.exit_code == 1
    assert result.output == f"Error: {missing}: no such folder; give the output folder of d3stereo run\n"


@pytest.mark.parametrize("kwargs, message", [
    (dict(algorithm="my alg"), "my alg: not a usable algorithm name; give 1-40 letters, digits, '_' or '-' "
                               "(it goes into file names)"),
    (dict(split="trainQ"), "trainQ: not a MiddEval3 split; give training or test followed by Q, H or F "
                           "(e.g. trainingQ)"),
])
def test_bad_algorithm_and_split(run_out, tmp_path, kwargs, message):
    with pytest.raises(InputError) as exc:
        export_submission(run_out, tmp_path / "s", "middeval3", **kwargs)
    assert str(exc.value) == message


def test_empty_run_folder_and_name_clash(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(InputError) as exc:
        export_submission(out, tmp_path / "s", "kitti")
    assert str(exc.value) == (f"{out}: no complete pair (no <pair>/result.json with disp.pfm); "
                              "give the output folder of d3stereo run")
    make_pair(out, "kitti2012-000003_10", "/k12/colored_0/000003_10.png")
    make_pair(out, "kitti2015-000003_10", "/k15/image_2/000003_10.png")
    with pytest.raises(InputError) as exc:
        export_submission(out, tmp_path / "s", "kitti")
    assert str(exc.value) == (f"{out}: pairs kitti2012-000003_10 and kitti2015-000003_10 both give "
                              "disp_0/000003_10.png; export runs of one dataset, one pair folder each")


def test_submission_inside_out_is_an_output_error(run_out):
    with pytest.raises(OutputError):
        export_submission(run_out, run_out, "kitti")


def test_export_of_a_real_run_matches_its_disp_png(tmp_path, pairs_root):
    runner = CliRunner()
    out = tmp_path / "out"
    assert runner.invoke(main, ["run", str(pairs_root), "-o", str(out), "--method", "sgbm", "-q"]).exit_code == 0
    result = runner.invoke(main, ["export", str(out), "--format", "kitti", "-o", str(tmp_path / "k"), "-q"])
    assert result.exit_code == 0 and result.output == ""
    for pair in sorted(p.name for p in out.iterdir() if (p / "result.json").is_file()):
        ours = kitti_devkit_read(tmp_path / "k" / "disp_0" / f"{pair}_10.png")[0]
        stored = kitti_devkit_read(out / pair / "disp.png")[0]  # the run's own KITTI PNG
        np.testing.assert_array_equal(ours, stored)
