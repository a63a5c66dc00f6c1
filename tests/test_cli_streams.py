"""The command in real processes: names that are not UTF-8, the C locale, closed and broken
output streams, and environment variables that numba and OpenCV read."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.helpers import textured_pair, write_png


def _env(**extra):
    path = os.pathsep.join(filter(None, [os.getcwd(), os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": path, **extra}


def _d3stereo(*args, env=None, **kwargs):
    """``python -m d3cli ARGS`` in a child process: (returncode, stdout, stderr) as bytes."""
    proc = subprocess.run([sys.executable, "-m", "d3cli", *map(os.fsencode, args)], capture_output=True,
                          env=env or _env(), timeout=300, **kwargs)
    return proc.returncode, proc.stdout, proc.stderr


def _pairs(root, names=("a", "b"), *, broken=()):
    """Pair folders under ``root`` (a str that may hold surrogate-escaped bytes); the
    pairs in ``broken`` get a left.png that is no image."""
    from d3cli.data.formats import write_pfm

    for i, name in enumerate(names):
        folder = os.path.join(root, name)
        os.makedirs(folder)
        left, right, gt = textured_pair(4 + i, seed=i)
        # OpenCV cannot open a path that is not UTF-8: write under a plain name, then move
        for file, img in (("left.png", left), ("right.png", right)):
            tmp = os.path.join(os.path.dirname(os.fsencode(root)).decode("ascii"), file)
            write_png(tmp, img)
            os.replace(tmp, os.path.join(folder, file))
        write_pfm(os.path.join(folder, "disp_gt.pfm"), gt)
        with open(os.path.join(folder, "SOURCE.txt"), "w", encoding="utf-8") as fh:
            fh.write("gt_scale: 1\ngt_invalid: inf\n")
        if name in broken:
            with open(os.path.join(folder, "left.png"), "wb") as fh:
                fh.write(b"not an image")
    return root


def _utf8(path):
    with open(path, "rb") as fh:
        return fh.read().decode("utf-8")  # raises when a file is not UTF-8


# ----------------------------------------------------------------------------- names


def test_a_run_into_a_folder_whose_name_is_not_utf8_writes_every_report(tmp_path):
    inputs = _pairs(os.fsdecode(os.fsencode(str(tmp_path)) + b"/in\xe9"), ("a", "b", "c"), broken=("c",))
    out = os.fsdecode(os.fsencode(str(tmp_path)) + b"/out_\xe9")
    for attempt in range(2):  # the rerun resumes and writes the reports again
        rc, stdout, stderr = _d3stereo("run", inputs, "-o", out, "--eval", "--method", "sgbm", "-q")
        assert rc == 1, stderr
        assert b"Traceback" not in stderr
        assert stderr.decode("ascii").splitlines()[-2:] == [
            f"failed: c: {tmp_path}/in\\xe9/c/left.png: cannot read image (corrupt or not an image); "
            "give an 8/16-bit PNG, JPEG, PPM/PGM or TIFF file",
            f"Error: 1 of 3 pairs failed (see {tmp_path}/out_\\xe9/run.json)"]
        run = json.loads(_utf8(os.path.join(out, "run.json")))
        assert [p["status"] for p in run["pairs"]] == (["ok", "ok", "failed"] if attempt == 0
                                                       else ["skipped", "skipped", "failed"])
        html = _utf8(os.path.join(out, "report.html"))
        assert f"d3stereo run: {tmp_path}/out_\\xe9 (sgbm)" in html
        assert f"{tmp_path}/in\\xe9/c/left.png" in html
        assert f"{tmp_path}/in\\xe9/c/left.png" in _utf8(os.path.join(out, "metrics.csv"))
        assert f"{tmp_path}/in\\xe9/c/left.png" in _utf8(os.path.join(out, "summary.md"))


def test_non_ascii_names_under_the_c_locale_are_written_as_utf8(tmp_path):
    inputs = _pairs(str(tmp_path / "in_é"))
    out = tmp_path / "out_é"
    rc, stdout, stderr = _d3stereo("run", inputs, "-o", out, "--eval", "--method", "sgbm",
                                   env=_env(LC_ALL="C", LANG="C", PYTHONUTF8="0", PYTHONCOERCECLOCALE="0"))
    assert rc == 0, stderr
    assert f"d3stereo run: {out} (sgbm)" in _utf8(out / "report.html")
    assert stdout.decode("utf-8").splitlines()[-2:] == [f"report: {out}/report.html", f"summary: {out}/summary.md"]
    assert json.loads(_utf8(out / "run.json"))["n_computed"] == 2


def test_a_name_that_is_not_utf8_is_escaped_on_the_terminal(tmp_path):
    """A UTF-8 stdout takes no lone surrogate: the byte is shown as ``\\xe9``."""
    inputs = _pairs(str(tmp_path / "in"))
    out = os.fsdecode(os.fsencode(str(tmp_path)) + b"/out_\xe9")
    rc, stdout, stderr = _d3stereo("run", inputs, "-o", out, "--method", "sgbm", env=_env(PYTHONIOENCODING="utf-8"))
    assert rc == 0, stderr
    assert stdout.decode("utf-8").splitlines()[-1] == f"report: {tmp_path}/out_\\xe9/report.html"


def test_report_writers_escape_name_bytes_that_are_not_utf8(tmp_path):
    from d3cli.errors import readable
    from d3cli.evaluation.report import read_pair_csv, write_summary

    name = os.fsdecode(b"p\xe9-\xc3\xa9")
    assert readable(name) == "p\\xe9-é"
    assert readable("\ud800 plain") == "\\ud800 plain"  # a surrogate no file name decoding made
    rows = [{"pair": "a", "family": "", "status": "failed", "time_s": 0.1, "error": f"{name}/left.png: unreadable"}]
    write_summary(tmp_path, rows, method="sgbm")
    assert read_pair_csv(tmp_path / "metrics.csv")[0]["error"] == "p\\xe9-é/left.png: unreadable"
    assert "p\\xe9-é/left.png: unreadable" in _utf8(tmp_path / "summary.md")


# ----------------------------------------------------------------------------- streams


def _close(*fds):
    def preexec():
        for fd in fds:
            os.close(fd)

    return preexec


@pytest.mark.parametrize("fds", [(2,), (1,), (1, 2)], ids=["stderr", "stdout", "both"])
def test_a_run_with_closed_output_streams_does_its_work_and_exits_by_its_result(tmp_path, fds):
    inputs = _pairs(str(tmp_path / "in"), ("a", "b"))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "d3cli", "run", inputs, "-o", str(out), "--eval", "--method", "sgbm"],
                          env=_env(), timeout=300, preexec_fn=_close(*fds),
                          stdout=None if 1 in fds else subprocess.PIPE, stderr=None if 2 in fds else subprocess.PIPE)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((out / "run.json").read_text())["n_computed"] == 2
    assert {"metrics.csv", "report.html", "summary.md"} <= set(os.listdir(out))


def test_a_failed_pair_with_closed_stderr_still_exits_1(tmp_path):
    inputs = _pairs(str(tmp_path / "in"), ("a", "b"), broken=("b",))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "d3cli", "run", inputs, "-o", str(out), "--method", "sgbm"],
                          env=_env(), timeout=300, preexec_fn=_close(2), stdout=subprocess.PIPE)
    assert proc.returncode == 1
    assert json.loads((out / "run.json").read_text())["n_failed"] == 1


def _with_reader_gone(args):
    """Run ``d3stereo ARGS`` whose stdout's reader has closed the pipe: (returncode, stderr)."""
    read, write = os.pipe()
    os.close(read)  # the reader is gone before the command writes a line
    try:
        proc = subprocess.run([sys.executable, "-m", "d3cli", *args], stdout=write, stderr=subprocess.PIPE,
                              env=_env(), timeout=300)
    finally:
        os.close(write)
    return proc.returncode, proc.stderr


def test_configs_into_a_pipe_nobody_reads_ends_quietly_with_0():
    rc, stderr = _with_reader_gone(["configs"])
    assert (rc, stderr) == (0, b"")


def test_a_run_into_a_pipe_nobody_reads_writes_everything_and_exits_by_its_result(tmp_path):
    inputs = _pairs(str(tmp_path / "in"), ("a", "b", "c"), broken=("c",))
    out = tmp_path / "out"
    rc, stderr = _with_reader_gone(["run", inputs, "-o", str(out), "--eval", "--method", "sgbm"])
    assert rc == 1
    assert stderr.decode().splitlines()[-1] == f"Error: 1 of 3 pairs failed (see {out}/run.json)"
    assert json.loads((out / "run.json").read_text())["n_computed"] == 2
    assert (out / "report.html").is_file()


# ----------------------------------------------------------------------------- environment


@pytest.mark.parametrize(("name", "value", "message"), [
    ("NUMBA_NUM_THREADS", "0", "numba needs a whole number of threads, 1 or more; set it to a number such as 4, "
                               "or unset it (numba then uses one thread per core)"),
    ("NUMBA_NUM_THREADS", "-2", "numba needs a whole number of threads, 1 or more; set it to a number such as 4, "
                                "or unset it (numba then uses one thread per core)"),
    ("NUMBA_NUM_THREADS", "four", "numba needs a whole number of threads, 1 or more; set it to a number such as 4, "
                                  "or unset it (numba then uses one thread per core)"),
    ("NUMBA_THREADING_LAYER", "bogus", "numba knows default, safe, threadsafe, forksafe, workqueue, omp and tbb; "
                                       "set one of these, or unset it"),
    ("OPENCV_IO_MAX_IMAGE_WIDTH", "abc", "OpenCV needs a whole number of pixels, 0 or more (it aborts on anything "
                                         "else); set it to a number such as 1048576, or unset it"),
    ("OPENCV_IO_MAX_IMAGE_HEIGHT", "-5", "OpenCV needs a whole number of pixels, 0 or more (it aborts on anything "
                                         "else); set it to a number such as 1048576, or unset it"),
    ("OPENCV_IO_MAX_IMAGE_PIXELS", "", "OpenCV needs a whole number of pixels, 0 or more (it aborts on anything "
                                       "else); set it to a number such as 1073741824, or unset it"),
])
def test_a_bad_library_variable_is_one_error_line_before_any_work(tmp_path, name, value, message):
    inputs = _pairs(str(tmp_path / "in"), ("a",))
    out = tmp_path / "out"
    rc, stdout, stderr = _d3stereo("run", inputs, "-o", out, "--method", "sgbm", env=_env(**{name: value}))
    assert (rc, stdout) == (1, b"")
    assert stderr.decode() == f"Error: environment variable {name}={value}: {message}\n"
    assert not out.exists()


def test_a_long_variable_value_is_shortened_in_the_message():
    rc, _, stderr = _d3stereo("configs", env=_env(NUMBA_NUM_THREADS="9" * 100 + "x"))
    assert rc == 1
    assert stderr.decode().startswith(f"Error: environment variable NUMBA_NUM_THREADS={'9' * 57}...: ")


@pytest.mark.parametrize(("name", "value"), [("NUMBA_NUM_THREADS", "2"), ("OPENCV_IO_MAX_IMAGE_WIDTH", "4096"),
                                             ("NUMBA_THREADING_LAYER", "workqueue")])
def test_good_library_variables_pass(tmp_path, name, value):
    inputs = _pairs(str(tmp_path / "in"), ("a",))
    rc, _, stderr = _d3stereo("run", inputs, "-o", tmp_path / "out", "--method", "sgbm", "-q",
                              env=_env(**{name: value}))
    assert rc == 0, stderr


def test_a_batch_in_a_program_without_stderr_runs(tmp_path, monkeypatch):
    """A library caller whose stderr is None (closed where it started): no bar, no lines, the batch runs."""
    from d3cli.batch import run_batch
    from d3cli.config import load_config
    from d3cli.data.layouts import discover

    inputs = _pairs(str(tmp_path / "in"), ("a", "b"))
    monkeypatch.setattr(sys, "stderr", None)
    result = run_batch(discover([inputs]), tmp_path / "out", cfg=load_config(None), method="sgbm", progress=True)
    assert (result.n_computed, result.failures) == (2, [])
