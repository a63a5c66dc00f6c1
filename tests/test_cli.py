"""The d3stereo command line and the batch runner: outputs, resume, errors, atomicity.

CLI runs use ``--method sgbm`` so that they test the command line, not the pipeline.
"""

from __future__ import annotations

import importlib.util
import json
import os
import tempfile

import numpy as np
import pytest
from click.testing import CliRunner
from tests.helpers import write_png

from d3cli import __version__
import d3cli.batch.dispatch
import d3cli.batch.outputs
import d3cli.batch.runner
import d3cli.data.formats
import d3cli.method.pipeline
from d3cli.batch import OUTPUT_FILES, run_batch
from d3cli.cli import main
from d3cli.config import Config

PER_PAIR = (*OUTPUT_FILES, "result.json")


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def assert_user_error(result, code=1, contains=""):
    """One ``Error:`` line, the exit code, and no traceback anywhere."""
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    error_lines = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(error_lines) == 1, result.output
    assert contains in error_lines[0] or contains in result.output, result.output
    return error_lines[0]


def run_json(out):
    return json.loads((out / "run.json").read_text())


def leftover_temp_files(folder):
    return [p.name for p in folder.rglob("*") if ".tmp-" in p.name or p.name.startswith(".d3stereo-probe")]


# ----------------------------------------------------------------------------- happy path
def test_run_eval_writes_everything(tmp_path, pairs_root):
    out = tmp_path / "out"
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    assert result.exit_code == 0, result.output
    for name in "abc":
        for f in (*PER_PAIR, "error.png"):
            assert (out / name / f).is_file(), (name, f)
        stored = json.loads((out / name / "result.json").read_text())
        assert stored["method"] == "sgbm"
        assert stored["color_range"]["how"] == "1-99th percentile" and stored["color_range"]["max"] <= stored["max_disparity"]
        assert stored["metrics"]["epe"] < 1.0
        assert {"mse", "psnr", "ssim", "coverage"} <= set(stored["metrics"])
        assert stored["timings"]["wall"] > 0
    info = run_json(out)
    assert info["method"] == "sgbm"
    assert info["config"] == Config().to_dict() | {"run": {**Config().to_dict()["run"], "method": "sgbm"}}
    assert set(info["versions"]) == {"d3stereo", "numpy", "numba", "cv2", "skimage"}
    assert info["python"] and info["platform"] and info["backend"] == "auto"
    assert [p["status"] for p in info["pairs"]] == ["ok", "ok", "ok"]
    assert all(p["wall_s"] > 0 for p in info["pairs"])
    assert info["n_failed"] == 0 and info["failed"] == []
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "sgbm"
    assert summary["counts"]["ok"] == 3
    assert summary["overall"]["means"]["epe"] < 1.0
    assert (out / "summary.md").is_file() and (out / "metrics.csv").is_file()
    assert "EPE" in result.output
    assert leftover_temp_files(out) == []


def test_disparity_is_read_back_in_pixels(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", shift=6, size=(48, 96))
    out = tmp_path / "out"
    assert invoke("run", root, "-o", out, "--method", "sgbm", "--no-fill").exit_code == 0
    disp = d3cli.data.formats.read_pfm(out / "p" / "disp.pfm")
    inner = disp[8:-8, 40:-8]
    assert np.nanmedian(np.where(np.isfinite(inner), inner, np.nan)) == pytest.approx(6, abs=0.25)
    assert np.isinf(disp[:, :8]).all()  # --no-fill leaves SGBM's border invalid
    valid = d3cli.data.formats.read_image(out / "p" / "valid.png")
    assert set(np.unique(valid)) <= {0, 255}


def test_rerun_skips_complete_pairs_and_overwrite_redoes(tmp_path, pairs_root):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval").exit_code == 0
    stamp = {n: (out / n / "result.json").stat().st_mtime_ns for n in "abc"}

    again = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    assert again.exit_code == 0, again.output
    assert {n: (out / n / "result.json").stat().st_mtime_ns for n in "abc"} == stamp
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped"] * 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"]["ok"] == 3 and summary["overall"]["means"]["epe"] is not None

    redo = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", "--overwrite")
    assert redo.exit_code == 0, redo.output
    assert all((out / n / "result.json").stat().st_mtime_ns != stamp[n] for n in "abc")
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok"] * 3


def test_changed_settings_recompute(tmp_path, pairs_root):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    stamp = (out / "a" / "result.json").stat().st_mtime_ns
    # Settings that cannot change an SGBM result keep the pair complete ...
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--backend", "cpu",
                  "--set", "diffusion.tau=2").exit_code == 0
    assert (out / "a" / "result.json").stat().st_mtime_ns == stamp
    # ... its own settings and the disparity range do not.
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--set", "sgbm.block_size=7").exit_code == 0
    stamp2 = (out / "a" / "result.json").stat().st_mtime_ns
    assert stamp2 != stamp
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--set", "sgbm.block_size=7",
                  "--max-disparity", "20").exit_code == 0
    assert (out / "a" / "result.json").stat().st_mtime_ns != stamp2


def test_incomplete_pair_is_recomputed(tmp_path, pairs_root):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    (out / "b" / "disp.png").unlink()
    stamp_a = (out / "a" / "result.json").stat().st_mtime_ns
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    assert (out / "b" / "disp.png").is_file()
    assert (out / "a" / "result.json").stat().st_mtime_ns == stamp_a
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "ok", "skipped"]


def test_failed_rerun_keeps_the_earlier_complete_result(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", size=(48, 96))
    out = tmp_path / "out"
    assert invoke("run", root, "-o", out, "--method", "sgbm").exit_code == 0
    stamp = (out / "p" / "result.json").stat().st_mtime_ns
    result = invoke("run", root, "-o", out, "--method", "sgbm", "--max-disparity", "200")
    assert_user_error(result, contains="1 of 1 pair failed")
    assert result.output.count("failed: p: ") == 1 and "p: p:" not in result.output
    assert (out / "p" / "result.json").stat().st_mtime_ns == stamp
    assert invoke("run", root, "-o", out, "--method", "sgbm").exit_code == 0
    assert run_json(out)["pairs"][0]["status"] == "skipped"


def test_eval_added_on_rerun_scores_stored_predictions(tmp_path, pairs_root):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    assert result.exit_code == 0, result.output
    assert json.loads((out / "a" / "result.json").read_text())["metrics"]["epe"] < 1.0


def test_bundled_samples_run_by_default(tmp_path):
    out = tmp_path / "out"
    result = invoke("run", "-o", out, "--method", "sgbm", "--eval", "-q")
    assert result.exit_code == 0, result.output
    names = sorted(p["pair"] for p in run_json(out)["pairs"])
    assert names == ["motorcycle", "road"]
    for name, bound in (("motorcycle", 2.0), ("road", 0.5)):
        assert json.loads((out / name / "result.json").read_text())["metrics"]["epe"] < bound


@pytest.mark.skipif(not hasattr(d3cli.method.pipeline, "D3Stereo"), reason="d3cli.method.pipeline.D3Stereo is not implemented yet")
def test_run_d3stereo_method(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", shift=6, size=(128, 256))
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "d3stereo", "--eval", "--backend", "cpu")
    assert result.exit_code == 0, result.output
    assert json.loads((out / "p" / "result.json").read_text())["metrics"]["epe"] < 1.0


def test_warnings_are_logged_and_stored(tmp_path, make_pair_folder, monkeypatch):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p")
    real = d3cli.baselines.sgbm_disparity

    def with_warning(*args, **kwargs):
        res = real(*args, **kwargs)
        res.warnings.append("few seeds")
        return res

    monkeypatch.setattr(d3cli.baselines.sgbm, "sgbm_disparity", with_warning)  # the entry point of --method sgbm
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0
    assert "WARNING: p: few seeds" in result.output
    assert json.loads((out / "p" / "result.json").read_text())["warnings"] == ["few seeds"]


# ----------------------------------------------------------------------------- bad inputs
def test_missing_right_image(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    (make_pair_folder(root, "p") / "right.png").unlink()
    line = assert_user_error(invoke("run", root, "-o", tmp_path / "out", "--method", "sgbm"))
    assert "right" in line or "right" in line.lower()


def test_size_mismatch(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    folder = make_pair_folder(root, "p", size=(48, 96))
    write_png(folder / "right.png", np.zeros((48, 90), np.uint8))
    result = invoke("run", root, "-o", tmp_path / "out", "--method", "sgbm")
    assert_user_error(result, contains="1 of 1 pair failed")
    assert "48x96" in result.output and "48x90" in result.output


def test_corrupt_image(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    folder = make_pair_folder(root, "p")
    (folder / "left.png").write_bytes(b"\x89PNG\r\n\x1a\n this is not an image")
    result = invoke("run", root, "-o", tmp_path / "out", "--method", "sgbm")
    assert_user_error(result, contains="1 of 1 pair failed")
    assert "left.png" in result.output


def test_empty_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    assert_user_error(invoke("run", tmp_path / "empty", "-o", tmp_path / "out", "--method", "sgbm"),
                      contains=str(tmp_path / "empty"))


def test_missing_input(tmp_path):
    assert_user_error(invoke("run", tmp_path / "nope", "-o", tmp_path / "out", "--method", "sgbm"))


def test_gt_of_another_size(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    folder = make_pair_folder(root, "p", size=(48, 96))
    d3cli.data.formats.write_pfm(folder / "disp_gt.pfm", np.full((40, 96), 5, np.float32))
    result = invoke("run", root, "-o", tmp_path / "out", "--method", "sgbm", "--eval")
    assert_user_error(result, contains="1 of 1 pair failed")
    assert "disp_gt.pfm" in result.output or "ground truth" in result.output


@pytest.mark.parametrize("value", ["0", "-3"])
def test_max_disparity_not_positive_is_usage_error(tmp_path, pairs_root, value):
    result = invoke("run", pairs_root, "-o", tmp_path / "out", "--method", "sgbm", "--max-disparity", value)
    assert_user_error(result, code=2, contains="--max-disparity")


def test_max_disparity_not_below_width(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", size=(48, 96))
    result = invoke("run", root, "-o", tmp_path / "out", "--method", "sgbm", "--max-disparity", "96")
    assert_user_error(result, contains="1 of 1 pair failed")
    assert "max" in result.output.lower() and "96" in result.output


def test_bad_method_is_usage_error(tmp_path, pairs_root):
    assert_user_error(invoke("run", pairs_root, "-o", tmp_path / "out", "--method", "magic"), code=2)


def test_unknown_config_key(tmp_path, pairs_root):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("diffusion:\n  tua: 2\n")
    line = assert_user_error(invoke("run", pairs_root, "-o", tmp_path / "out", "-c", cfg))
    assert line.startswith(f"Error: {cfg}:2: unknown key 'diffusion.tua'; valid keys of diffusion: tau, kappa_d, ")


def test_output_folder_not_writable_chmod(tmp_path, pairs_root):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("running as root: chmod does not stop writes (see the monkeypatch test)")
        line = assert_user_error(invoke("run", pairs_root, "-o", locked / "out", "--method", "sgbm"))
        assert str(locked / "out") in line
    finally:
        locked.chmod(0o755)


def test_output_folder_not_writable_simulated(tmp_path, pairs_root, monkeypatch):
    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    out = tmp_path / "out"
    line = assert_user_error(invoke("run", pairs_root, "-o", out, "--method", "sgbm"))
    assert line == (f"Error: {out}: cannot write to the output folder (Permission denied); "
                    "choose another folder with -o or fix its permissions")
    assert not any(p.is_dir() and p.name in "abc" for p in out.iterdir())


def test_output_path_is_a_file(tmp_path, pairs_root):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    line = assert_user_error(invoke("run", pairs_root, "-o", blocker, "--method", "sgbm"))
    assert str(blocker) in line


def test_failing_pair_in_the_middle(tmp_path, pairs_root):
    (pairs_root / "b" / "left.png").write_bytes(b"garbage")
    out = tmp_path / "out"
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    line = assert_user_error(result)
    assert line == f"Error: 1 of 3 pairs failed (see {out / 'run.json'})"
    assert "failed: b:" in result.output
    for name in "ac":
        assert (out / name / "result.json").is_file()
    assert not (out / "b" / "result.json").exists()
    info = run_json(out)
    assert [p["status"] for p in info["pairs"]] == ["ok", "failed", "ok"]
    assert info["n_failed"] == 1 and info["failed"][0]["pair"] == "b"
    assert "left.png" in info["failed"][0]["error"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"ok": 2, "failed": 1, "skipped": 0, "total": 3}
    assert summary["failures"][0]["pair"] == "b"


def test_unexpected_exception_in_a_pair_is_recorded(tmp_path, pairs_root, monkeypatch):
    real = d3cli.batch.runner.compute_pair

    def flaky(method, cfg, left, right, *, max_disparity, **kwargs):
        flaky.calls += 1
        if flaky.calls == 2:  # the second pair, b
            raise ValueError("kernel exploded")
        return real(method, cfg, left, right, max_disparity=max_disparity, **kwargs)

    flaky.calls = 0
    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", flaky)
    out = tmp_path / "out"
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm")
    assert_user_error(result, contains="1 of 3 pairs failed")
    failed = run_json(out)["failed"]
    assert failed == [{"pair": "b", "error": "b: internal error in matching (sgbm) (ValueError: kernel exploded); please report it"}]


# ----------------------------------------------------------------------------- atomicity
def test_writer_failure_leaves_no_half_written_files(tmp_path, pairs_root, monkeypatch):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    real = d3cli.batch.outputs.write_kitti_png

    def half_then_crash(path, disp):
        folder = os.path.basename(os.path.dirname(path))  # b, or its staging folder .b.partial-XXXX
        if folder == "b" or folder.startswith(".b.partial"):
            def partial(tmp):
                with open(tmp, "wb") as fh:
                    fh.write(b"\x89PNG\r\n\x1a\n-half")
                raise RuntimeError("disk on fire")

            return d3cli.data.formats.atomic_write(path, partial)
        return real(path, disp)

    monkeypatch.setattr(d3cli.batch.outputs, "write_kitti_png", half_then_crash)
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--overwrite")
    assert_user_error(result, contains="1 of 3 pairs failed")
    assert leftover_temp_files(out) == []
    # b's old result.json is gone (it no longer describes b's files): b is incomplete.
    assert not (out / "b" / "result.json").exists()
    # Whatever final files exist are complete and readable.
    for f in OUTPUT_FILES:
        path = out / "b" / f
        if path.exists():
            if f.endswith(".pfm"):
                d3cli.data.formats.read_pfm(path)
            else:
                d3cli.data.formats.read_image(path)
    monkeypatch.setattr(d3cli.batch.outputs, "write_kitti_png", real)
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "ok", "skipped"]


def test_keyboard_interrupt_propagates_and_is_recorded(tmp_path, pairs_root, monkeypatch):
    from d3cli.data.layouts import discover

    calls = []

    def interrupt(method, cfg, left, right, *, max_disparity, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return d3cli.baselines.sgbm_disparity(left, right, max_disparity=max_disparity, cfg=cfg.sgbm)

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", interrupt)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_batch(discover([pairs_root]), out, cfg=Config(), method="sgbm", progress=False)
    info = run_json(out)
    assert info["interrupted"] is True
    assert [p["pair"] for p in info["pairs"]] == ["a"]


# ----------------------------------------------------------------------------- eval
def test_eval_one_folder(tmp_path, pairs_root):
    out = tmp_path / "sgbm"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    rep = tmp_path / "rep"
    result = invoke("eval", out, "--gt", pairs_root, "-o", rep)
    assert result.exit_code == 0, result.output
    summary = json.loads((rep / "summary.json").read_text())
    assert summary["method"] == "sgbm"  # from run.json
    assert summary["counts"]["ok"] == 3 and summary["overall"]["means"]["epe"] < 1.0
    assert (rep / "metrics.csv").is_file() and (rep / "summary.md").is_file()


def test_eval_side_by_side(tmp_path, pairs_root):
    filled, holes = tmp_path / "filled", tmp_path / "holes"
    assert invoke("run", pairs_root, "-o", filled, "--method", "sgbm").exit_code == 0
    assert invoke("run", pairs_root, "-o", holes, "--method", "sgbm", "--no-fill").exit_code == 0
    report_dir = tmp_path / "report"
    result = invoke("eval", filled, holes, "--gt", pairs_root, "-o", report_dir)
    assert result.exit_code == 0, result.output
    table = (report_dir / "comparison.md").read_text()
    assert "filled" in table and "holes" in table  # same method: named by folder
    assert "filled" in result.output
    for name in ("filled", "holes"):
        assert json.loads((report_dir / name / "summary.json").read_text())["counts"]["ok"] == 3
        assert (report_dir / name / "a" / "error.png").is_file()
    assert not (filled / "a" / "error.png").exists()  # the prediction folders are only read


def test_eval_missing_prediction_is_listed_not_compared(tmp_path, pairs_root):
    out = tmp_path / "sgbm"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    for name in ("disp.pfm", "disp.png"):
        (out / "c" / name).unlink()
    rep = tmp_path / "rep"
    result = invoke("eval", out, "--gt", pairs_root, "-o", rep)
    assert result.exit_code == 0, result.output
    summary = json.loads((rep / "summary.json").read_text())
    assert summary["counts"]["ok"] == 2
    assert summary["extra"]["not_compared"] == ["c"]


def test_eval_needs_gt(tmp_path):
    assert invoke("eval", tmp_path, "-o", tmp_path / "r").exit_code == 2


def test_eval_missing_prediction_folder(tmp_path, pairs_root):
    assert_user_error(invoke("eval", tmp_path / "nope", "--gt", pairs_root, "-o", tmp_path / "r"),
                      contains="prediction folder not found")


# ----------------------------------------------------------------------------- info, synth
def test_info():
    result = invoke("info")
    assert result.exit_code == 0, result.output
    assert f"d3stereo {__version__}" in result.output
    for word in ("numpy", "numba threads", "cv2", "skimage", "cpu count", "cuda", "config"):
        assert word in result.output
    assert "Traceback" not in result.output


def test_version():
    result = invoke("--version")
    assert result.exit_code == 0
    assert result.output == f"d3stereo, version {__version__}\n"
    assert __version__ == "1.0.0"


@pytest.mark.skipif(importlib.util.find_spec("d3cli.data.synth") is None, reason="d3cli.data.synth is not written yet")
def test_synth_then_run(tmp_path):
    data = tmp_path / "synth"
    result = invoke("synth", data, "--n", "2", "--seed", "1", "--width", "160", "--height", "96")
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    result = invoke("run", data, "-o", out, "--method", "sgbm", "--eval")
    assert result.exit_code == 0, result.output
    assert run_json(out)["n_pairs"] == 2


def test_cuda_backend_unavailable_fails_up_front(tmp_path, pairs_root):
    from d3cli.kernels import cuda_status

    if cuda_status()[0]:
        pytest.skip("CUDA is usable here")
    out = tmp_path / "out"
    line = assert_user_error(invoke("run", pairs_root, "-o", out, "--method", "d3stereo", "--backend", "cuda"))
    assert line.startswith("Error: --backend cuda: ")
    assert not (out / "a").exists()


@pytest.mark.parametrize("method", ["sgbm", "elas"])
def test_a_method_without_kernels_says_once_that_it_runs_on_the_cpu(tmp_path, pairs_root, method, monkeypatch):
    """--backend cuda with a method that does not run d3stereo's kernels: one warning, no
    CUDA check (the method never touches the device), the pairs computed."""
    import dataclasses

    from d3cli.config import methods as declarations

    spec = declarations.method_spec(method)
    monkeypatch.setattr(declarations, "METHOD_SPECS", tuple(
        dataclasses.replace(s, requires=(), compute=declarations.method_spec("sgbm").compute, section="sgbm")
        if s.name == method else s for s in declarations.METHOD_SPECS))
    result = invoke("run", pairs_root, "-o", tmp_path / "out", "--method", method, "--backend", "cuda")
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.output.splitlines() if line.startswith("WARNING:")]
    assert warnings == [f"WARNING: --backend cuda: {spec.name} does not run d3stereo's kernels; it runs on the CPU"]


def test_bundled_samples_are_reproducible(tmp_path):
    """scripts/make_samples.py regenerates the bundled pairs (same pixels, same ground truth)."""
    import runpy
    from pathlib import Path

    from d3cli.cli import samples_dir

    script = Path(__file__).resolve().parents[1] / "scripts" / "make_samples.py"
    runpy.run_path(str(script), run_name="make_samples")["main"](["--out", str(tmp_path)])
    for name in ("motorcycle", "road"):
        for f in ("left.png", "right.png"):
            np.testing.assert_array_equal(d3cli.data.formats.read_image(tmp_path / name / f),
                                          d3cli.data.formats.read_image(samples_dir() / name / f))
        np.testing.assert_array_equal(d3cli.data.formats.read_pfm(tmp_path / name / "disp_gt.pfm"),
                                      d3cli.data.formats.read_pfm(samples_dir() / name / "disp_gt.pfm"))
    total = sum(p.stat().st_size for p in samples_dir().glob("*/*") if p.parent.name != "__pycache__")
    assert total < 1.5e6


# ----------------------------------------------------------------------------- point clouds, PT record


def test_pointcloud_from_calib_matches_the_disparity(tmp_path):
    from d3cli.data import formats as io
    from d3cli.road.pointcloud import read_ply

    data = tmp_path / "synth"
    assert invoke("synth", data, "--n", "1", "--seed", "2", "--width", "160", "--height", "96").exit_code == 0
    out = tmp_path / "out"
    result = invoke("run", data, "-o", out, "--method", "sgbm", "--pointcloud", "-q")
    assert result.exit_code == 0, result.output
    (pair_dir,) = [p for p in out.iterdir() if p.is_dir()]
    points, colours = read_ply(pair_dir / "cloud.ply")
    valid = io.read_mask(pair_dir / "valid.png")
    disp = io.read_pfm(pair_dir / "disp.pfm")
    calib = io.read_calib(data / pair_dir.name / "calib.txt")
    doffs = calib.get("doffs", 0.0)
    keep = valid & (disp + doffs > 0)  # a zero disparity has no finite depth
    assert keep.sum() > 0.9 * valid.sum()
    assert points.shape == (int(keep.sum()), 3) and colours.shape == points.shape
    depth = calib["f"] * calib["baseline"] / (disp[keep] + doffs)
    np.testing.assert_allclose(np.sort(points[:, 2]), np.sort(depth), rtol=1e-5)


def test_pointcloud_added_on_rerun_without_recomputing(tmp_path):
    data = tmp_path / "synth"
    assert invoke("synth", data, "--n", "1", "--seed", "2", "--width", "160", "--height", "96").exit_code == 0
    out = tmp_path / "out"
    assert invoke("run", data, "-o", out, "--method", "sgbm", "-q").exit_code == 0
    (pair_dir,) = [p for p in out.iterdir() if p.is_dir()]
    before = (pair_dir / "disp.pfm").stat().st_mtime_ns
    assert not (pair_dir / "cloud.ply").exists()
    assert invoke("run", data, "-o", out, "--method", "sgbm", "--pointcloud", "-q").exit_code == 0
    assert (pair_dir / "cloud.ply").stat().st_size > 0
    assert (pair_dir / "disp.pfm").stat().st_mtime_ns == before
    assert run_json(out)["pairs"][0]["status"] == "skipped"


def test_pointcloud_without_camera_is_a_warning(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "p", shift=6)
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "sgbm", "--pointcloud", "-q")
    assert result.exit_code == 0, result.output
    assert not (out / "p" / "cloud.ply").exists()
    warnings = json.loads((out / "p" / "result.json").read_text())["warnings"]
    assert any(w.startswith("no cloud.ply: focal length or baseline unknown") for w in warnings)


def test_pt_model_is_recorded_per_pair_in_run_json(tmp_path):
    data = tmp_path / "synth"
    assert invoke("synth", data, "--n", "1", "--seed", "4", "--width", "320", "--height", "192").exit_code == 0
    out = tmp_path / "out"
    result = invoke("run", data, "-o", out, "--backend", "cpu", "--set", "pt.enabled=true", "-q")
    assert result.exit_code == 0, result.output
    record = run_json(out)["pairs"][0]
    assert {"a0", "a1", "theta_deg", "inlier_share", "fallback"} <= set(record["pt"])
    assert record["pt"]["fallback"] is False and record["pt"]["inlier_share"] > 0.5


def test_python_dash_m_d3cli_is_the_d3stereo_command():
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "d3cli", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("Usage: d3stereo ") and "run" in done.stdout and "synth" in done.stdout


def test_config_by_name_finds_the_repository_configs(tmp_path, monkeypatch):
    from d3cli.cli import config_by_name

    monkeypatch.chdir(tmp_path)
    assert config_by_name("road").name == "road.yaml" and config_by_name("road").is_file()
    assert config_by_name("no-such-config") == "no-such-config"  # left for the file-not-found error
    (tmp_path / "road").write_text("")  # an existing file of that name wins
    assert config_by_name("road") == "road"


def test_color_range_option_fixes_the_range_for_the_batch_and_recomputes(tmp_path, pairs_root):
    import json

    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "-q").exit_code == 0
    first = json.loads((out / "a" / "result.json").read_text())["color_range"]
    assert first["how"].endswith("percentile")
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "-q", "--color-range", "0:40")
    assert result.exit_code == 0, result.output
    stored = json.loads((out / "a" / "result.json").read_text())
    assert stored["color_range"] == {"min": 0.0, "max": 40.0, "how": "fixed range"}
    bad = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--color-range", "40:10")
    assert bad.exit_code == 2 and "--color-range" in bad.output and "0 <= MIN < MAX" in bad.output
