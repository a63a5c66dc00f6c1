"""d3stereo export: the KITTI and MiddEval3 submission layouts, read back with readers
written as the benchmarks' devkits read them (not with d3cli's own readers)."""

from __future__ import annotations

import hashlib
import json
import os
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
    """A complete pair folder as ``d3stereo run`` leaves it: disp.pfm, and result.json
    recording its inputs, timings and the size and SHA-256 of disp.pfm."""
    folder = out / name
    folder.mkdir(parents=True)
    write_pfm(folder / "disp.pfm", disp)
    timings = {"wall": 2.5} if total is None else {"total": total, "wall": 2.5}
    data = (folder / "disp.pfm").read_bytes()
    result = {"pair": name, "inputs": {"left": left, "right": left.replace("im0", "im1"), "gt": None},
              "timings": timings,
              "files": {"disp.pfm": {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}}}
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
        "WARNING: files the KITTI devkit does not read (no frame id like 000000_10 in the pair's name or its "
        "left image's name): disp_0/middlebury2014-adirondack-Q_10.png, disp_0/synth-0000_10.png",
        "WARNING: middlebury2014-adirondack-Q: 1 pixel has a disparity >= 256 px, written as 255.996 px in "
        "disp_0/middlebury2014-adirondack-Q_10.png (the most a KITTI PNG holds)",
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


# ----------------------------------------------------------------------------- damaged run folders

RERUN_RESULT = "delete it and rerun the same d3stereo run command (that computes the pair again)"
RERUN_MAP = "rerun the same d3stereo run command (that computes the pair again)"


def export_cli(*args) -> "click.testing.Result":
    result = CliRunner().invoke(main, ["export", *map(str, args)])
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result


@pytest.fixture
def kitti_out(tmp_path) -> Path:
    """Three KITTI frames, as run on the KITTI layout."""
    out = tmp_path / "out"
    for i in range(3):
        make_pair(out, f"kitti2015-00000{i}_10", f"/data/kitti/training/image_2/00000{i}_10.png")
    return out


def _edit_result(folder: Path, edit) -> None:
    path = folder / "result.json"
    result = json.loads(path.read_text())
    edit(result)
    path.write_text(json.dumps(result))


def _pop_record(result: dict) -> None:
    del result["files"]["disp.pfm"]


@pytest.mark.parametrize("content, what", [
    (b"[1, 2]", "holds a JSON array, not the object d3stereo writes"),
    (b"{\"pair\": ", "not JSON (Expecting value: line 1 column 10 (char 9))"),
    (b"\xff\xfe{}", "not UTF-8 text (byte 0xff at offset 0)"),
    (b"\"text\"", "holds a JSON string, not the object d3stereo writes"),
    (b"[" * 100_000 + b"]" * 100_000, "not JSON (nested too deeply)"),
])
def test_a_damaged_result_json_fails_its_pair_and_the_others_export(kitti_out, tmp_path, content, what):
    damaged = kitti_out / "kitti2015-000001_10" / "result.json"
    damaged.write_bytes(content)
    before = digests(kitti_out)
    sub = tmp_path / "sub"
    result = export_cli(kitti_out, "--format", "kitti", "-o", sub)
    assert result.exit_code == 1
    assert result.output.splitlines() == [
        f"failed: {damaged}: {what}; {RERUN_RESULT}",
        f"wrote 2 pairs (kitti, 2 files) to {sub}",
        f"Error: {kitti_out}: 1 of 3 pairs not exported (see the failed: lines); "
        "fix each as its line says, then export again"]
    assert tree(sub) == ["disp_0/000000_10.png", "disp_0/000002_10.png"]
    assert digests(kitti_out) == before  # OUT is only read


@pytest.mark.parametrize("edit, what", [
    (lambda r: r.update(inputs=[1, 2]), "inputs is a JSON array, not an object of input file paths"),
    (lambda r: r["inputs"].update(left=7), "inputs.left is a JSON number, not a file path"),
    (lambda r: r.update(files="x"), "records no size and SHA-256 of disp.pfm, so the map cannot be checked"),
    (_pop_record, "records no size and SHA-256 of disp.pfm, so the map cannot be checked"),
    (lambda r: r["files"]["disp.pfm"].update(size=True), "records no size and SHA-256 of disp.pfm, so the map "
                                                         "cannot be checked"),
    (lambda r: r["files"]["disp.pfm"].update(sha256=None), "records no size and SHA-256 of disp.pfm, so the map "
                                                           "cannot be checked"),
])
def test_result_json_fields_of_the_wrong_type_fail_their_pair(kitti_out, tmp_path, edit, what):
    folder = kitti_out / "kitti2015-000000_10"
    _edit_result(folder, edit)
    result = export_cli(kitti_out, "--format", "kitti", "-o", tmp_path / "sub", "-q")
    assert result.exit_code == 1
    assert result.output.splitlines() == [
        f"failed: {folder / 'result.json'}: {what}; {RERUN_RESULT}",
        f"Error: {kitti_out}: 1 of 3 pairs not exported (see the failed: lines); "
        "fix each as its line says, then export again"]
    assert tree(tmp_path / "sub") == ["disp_0/000001_10.png", "disp_0/000002_10.png"]


@pytest.mark.parametrize("timings", [[1.0], "1.0", {"total": "1"}, {"total": True}, {"total": -1.0},
                                     {"total": float("nan")}, {"total": 10 ** 400}, None])
def test_middeval3_timings_of_the_wrong_type_fail_their_pair(tmp_path, timings):
    out = tmp_path / "out"
    make_pair(out, "middlebury2014-adirondack-Q", "/d/trainingQ/Adirondack/im0.png")
    folder = make_pair(out, "middlebury2014-teddy-Q", "/d/trainingQ/Teddy/im0.png")
    _edit_result(folder, lambda r: r.update(timings=timings))
    result = export_cli(out, "--format", "middeval3", "-o", tmp_path / "sub", "-q")
    assert result.exit_code == 1
    assert result.output.splitlines()[0] == (
        f"failed: {folder / 'result.json'}: no timings.total (seconds) to write; {RERUN_RESULT}")
    assert tree(tmp_path / "sub") == ["trainingQ/Adirondack/disp0D3Stereo.pfm",
                                      "trainingQ/Adirondack/timeD3Stereo.txt"]


def test_result_json_a_folder_and_disp_pfm_missing_fail_their_pairs(kitti_out, tmp_path):
    (kitti_out / "kitti2015-000000_10" / "result.json").unlink()
    (kitti_out / "kitti2015-000000_10" / "result.json").mkdir()
    (kitti_out / "kitti2015-000002_10" / "disp.pfm").unlink()
    result = export_cli(kitti_out, "--format", "kitti", "-o", tmp_path / "sub", "-q")
    assert result.exit_code == 1
    assert result.output.splitlines() == [
        f"failed: {kitti_out / 'kitti2015-000000_10' / 'result.json'}: is a folder, not a file; {RERUN_RESULT}",
        f"failed: {kitti_out / 'kitti2015-000002_10' / 'disp.pfm'}: missing, though result.json says the pair "
        f"is complete; {RERUN_MAP}",
        f"Error: {kitti_out}: 2 of 3 pairs not exported (see the failed: lines); "
        "fix each as its line says, then export again"]
    assert tree(tmp_path / "sub") == ["disp_0/000001_10.png"]


def test_a_replaced_or_changed_disp_pfm_is_refused(kitti_out, tmp_path):
    replaced = kitti_out / "kitti2015-000000_10" / "disp.pfm"
    size = replaced.stat().st_size
    write_pfm(replaced, np.ones((4, 5), np.float32))  # another map, another size
    changed = kitti_out / "kitti2015-000002_10" / "disp.pfm"
    data = bytearray(changed.read_bytes())
    data[-1] ^= 0x01  # one bit of one value: same size
    changed.write_bytes(bytes(data))
    result = export_cli(kitti_out, "--format", "kitti", "-o", tmp_path / "sub")
    assert result.exit_code == 1
    assert result.output.splitlines() == [
        f"failed: {replaced}: has {replaced.stat().st_size} bytes, {size} when the run wrote it; {RERUN_MAP}",
        f"failed: {changed}: changed since the run wrote it (SHA-256 differs from result.json's); {RERUN_MAP}",
        f"wrote 1 pair (kitti, 1 file) to {tmp_path / 'sub'}",
        f"Error: {kitti_out}: 2 of 3 pairs not exported (see the failed: lines); "
        "fix each as its line says, then export again"]
    assert tree(tmp_path / "sub") == ["disp_0/000001_10.png"]


def test_a_disp_pfm_changed_after_a_real_run_is_refused(tmp_path, make_pair_set):
    """The record export checks is the one ``d3stereo run`` writes."""
    root = make_pair_set(tmp_path / "pairs", ["kitti2015-000000_10", "kitti2015-000001_10"])
    out = tmp_path / "out"
    runner = CliRunner()
    assert runner.invoke(main, ["run", str(root), "-o", str(out), "--method", "sgbm", "-q"]).exit_code == 0
    result = export_cli(out, "--format", "kitti", "-o", tmp_path / "k", "-q")
    assert result.exit_code == 0 and result.output == ""
    assert tree(tmp_path / "k") == ["disp_0/000000_10.png", "disp_0/000001_10.png"]
    disp = out / "kitti2015-000001_10" / "disp.pfm"
    write_pfm(disp, np.full((48, 96), 5.0, np.float32))  # same size, other values
    result = export_cli(out, "--format", "kitti", "-o", tmp_path / "k2", "-q")
    assert result.exit_code == 1
    assert result.output.splitlines()[0] == (
        f"failed: {disp}: changed since the run wrote it (SHA-256 differs from result.json's); {RERUN_MAP}")
    assert tree(tmp_path / "k2") == ["disp_0/000000_10.png"]
    # the fix the line gives: the rerun computes the pair again, then it exports
    assert runner.invoke(main, ["run", str(root), "-o", str(out), "--method", "sgbm", "-q"]).exit_code == 0
    assert export_cli(out, "--format", "kitti", "-o", tmp_path / "k2", "-q").exit_code == 0


# ----------------------------------------------------------------------------- bad destinations

def test_a_destination_that_cannot_be_a_folder_is_one_error_line(kitti_out, tmp_path):
    a_file = tmp_path / "a-file"
    a_file.write_text("mine")
    cases = [
        (a_file, f"Error: {a_file}: is a file, not a folder; move it away or choose another -o folder"),
        (a_file / "sub", f"Error: {a_file / 'sub'}: {a_file} is a file, not a folder; choose another -o folder"),
        (Path("/proc/d3stereo-sub"), "Error: /proc/d3stereo-sub: cannot create the folder (No such file or "
                                     "directory); choose another -o folder"),
    ]
    for target, line in cases:
        result = export_cli(kitti_out, "--format", "kitti", "-o", target)
        assert (result.exit_code, result.output) == (1, line + "\n"), target
    assert a_file.read_text() == "mine"
    sub = tmp_path / "sub"
    (sub / "disp_0").parent.mkdir()
    (sub / "disp_0").write_text("mine")
    result = export_cli(kitti_out, "--format", "kitti", "-o", sub)
    assert (result.exit_code, result.output) == (
        1, f"Error: {sub / 'disp_0'}: is a file, not a folder; move it away or choose another -o folder\n")
    assert (sub / "disp_0").read_text() == "mine"


def test_a_read_only_destination_is_one_error_line(kitti_out, tmp_path, monkeypatch):
    """A read-only mount, simulated: creating a folder under SUB fails with EROFS (root
    ignores permission bits, so a folder without write permission would not fail)."""
    import errno

    sub = tmp_path / "sub"
    sub.mkdir()
    real_mkdir = os.mkdir

    def read_only(path, *args, **kwargs):
        if Path(path).parent == sub:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", read_only)
    result = export_cli(kitti_out, "--format", "kitti", "-o", sub)
    assert (result.exit_code, result.output) == (
        1, f"Error: {sub / 'disp_0'}: cannot create the folder (Read-only file system); choose another -o folder\n")


def test_a_destination_leading_into_the_run_folder_is_refused(kitti_out, tmp_path):
    before = digests(kitti_out)
    link = tmp_path / "link"
    link.symlink_to(kitti_out / "kitti2015-000000_10")
    result = export_cli(kitti_out, "--format", "kitti", "-o", link)
    assert (result.exit_code, result.output) == (
        1, f"Error: {link}: leads into the run folder {kitti_out} (to {kitti_out / 'kitti2015-000000_10'}); "
           "write the submission to a folder outside it\n")
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "disp_0").symlink_to(kitti_out)
    result = export_cli(kitti_out, "--format", "kitti", "-o", sub)
    assert (result.exit_code, result.output) == (
        1, f"Error: {sub / 'disp_0'}: leads into the run folder {kitti_out} (to {kitti_out}); "
           "write the submission to a folder outside it\n")
    assert digests(kitti_out) == before


def test_a_run_folder_where_the_layout_writes_is_refused(tmp_path):
    """``export SUB/disp_0 -o SUB`` would write the maps into the run folder itself."""
    sub = tmp_path / "sub"
    out = sub / "disp_0"
    make_pair(out, "kitti2015-000000_10", "/k/image_2/000000_10.png")
    before = digests(out)
    result = export_cli(out, "--format", "kitti", "-o", sub)
    assert (result.exit_code, result.output) == (
        1, f"Error: {out}: is the run folder {out}; write the submission to a folder outside it\n")
    assert digests(out) == before
    # a run folder inside SUB where the layout writes nothing is fine
    other = tmp_path / "sub2"
    make_pair(other / "runs" / "out", "kitti2015-000000_10", "/k/image_2/000000_10.png")
    result = export_cli(other / "runs" / "out", "--format", "kitti", "-o", other, "-q")
    assert result.exit_code == 0, result.output
    assert (other / "disp_0" / "000000_10.png").is_file()


# ----------------------------------------------------------------------------- what KITTI and MiddEval3 read

def test_kitti_disparities_beyond_its_png_are_named_per_pair(tmp_path):
    out = tmp_path / "out"
    big = np.array([[255.99, 256.0, 300.0], [INF, 1000.0, 3.0]], dtype=np.float32)
    make_pair(out, "kitti2015-000000_10", "/k/image_2/000000_10.png", disp=big)
    make_pair(out, "kitti2015-000001_10", "/k/image_2/000001_10.png")
    result = export_cli(out, "--format", "kitti", "-o", tmp_path / "sub")
    assert result.exit_code == 0
    assert result.output.splitlines() == [
        "WARNING: kitti2015-000000_10: 3 pixels have a disparity >= 256 px, written as 255.996 px in "
        "disp_0/000000_10.png (the most a KITTI PNG holds)",
        f"wrote 2 pairs (kitti, 2 files) to {tmp_path / 'sub'}"]
    disp, valid = kitti_devkit_read(tmp_path / "sub" / "disp_0" / "000000_10.png")
    assert disp[valid].tolist() == [65533 / 256, 65535 / 256, 65535 / 256, 65535 / 256, 3.0]


def test_pair_folders_of_kitti_and_middlebury_frames_get_the_benchmark_names(tmp_path):
    """The pair-folder layout (``kitti2015-000000_10/left.png``): the frame and scene come
    from the pair name, as the KITTI devkit and the MiddEval3 SDK look them up."""
    out = tmp_path / "out"
    make_pair(out, "kitti2015-000000_10", "/dev/kitti2015-000000_10/left.png")
    make_pair(out, "kitti2012-testing-000007_10", "/dev/kitti2012-testing-000007_10/left.png")
    result = export_cli(out, "--format", "kitti", "-o", tmp_path / "k")
    assert result.exit_code == 0 and result.output == f"wrote 2 pairs (kitti, 2 files) to {tmp_path / 'k'}\n"
    assert tree(tmp_path / "k") == ["disp_0/000000_10.png", "disp_0/000007_10.png"]

    out = tmp_path / "out2"
    make_pair(out, "middlebury2014-adirondack-Q", "/dev/middlebury2014-adirondack-Q/left.png")
    make_pair(out, "middlebury2014-motorcyclee-Q", "/dev/middlebury2014-motorcyclee-Q/left.png")
    make_pair(out, "middlebury2014-australiap-F", "/dev/middlebury2014-australiap-F/left.png")
    result = export_cli(out, "--format", "middeval3", "-o", tmp_path / "m")
    assert result.exit_code == 0 and result.output == f"wrote 3 pairs (middeval3, 6 files) to {tmp_path / 'm'}\n"
    assert tree(tmp_path / "m") == [
        "testF/AustraliaP/disp0D3Stereo.pfm", "testF/AustraliaP/timeD3Stereo.txt",
        "trainingQ/Adirondack/disp0D3Stereo.pfm", "trainingQ/Adirondack/timeD3Stereo.txt",
        "trainingQ/MotorcycleE/disp0D3Stereo.pfm", "trainingQ/MotorcycleE/timeD3Stereo.txt"]


def test_names_the_benchmark_does_not_read_are_written_with_a_warning(run_out, tmp_path):
    result = export_cli(run_out, "--format", "middeval3", "--split", "trainingH", "-o", tmp_path / "m")
    assert result.exit_code == 0
    assert result.output.splitlines() == [
        "WARNING: folders the MiddEval3 SDK does not read (not a MiddEval3 scene of their split): "
        "trainingH/kitti2015-000001_10, trainingH/synth-0000",
        "skipped 1 pair folders without a complete result: broken",
        f"wrote 3 pairs (middeval3, 6 files) to {tmp_path / 'm'}"]
    out = tmp_path / "many"
    for i in range(12):
        make_pair(out, f"synth-{i:04d}", f"/s/synth-{i:04d}/left.png")
    result = export_cli(out, "--format", "kitti", "-o", tmp_path / "k")
    assert result.exit_code == 0
    assert result.output.splitlines()[0] == (
        "WARNING: files the KITTI devkit does not read (no frame id like 000000_10 in the pair's name or its left "
        "image's name): " + ", ".join(f"disp_0/synth-{i:04d}_10.png" for i in range(10)) + ", and 2 more")


def test_a_scene_of_the_other_split_is_named(tmp_path):
    out = tmp_path / "out"
    make_pair(out, "middlebury2014-teddy-F", "/d/testF/Teddy/im0.png")
    result = export_cli(out, "--format", "middeval3", "-o", tmp_path / "m", "-q")
    assert result.exit_code == 0 and result.output == ""
    result = export_cli(out, "--format", "middeval3", "-o", tmp_path / "m")
    assert result.output.splitlines()[0] == (
        "WARNING: folders the MiddEval3 SDK does not read (not a MiddEval3 scene of their split): testF/Teddy")
