"""Property tests of ``d3stereo export`` on damaged run folders.

Whatever a pair's result.json holds (random JSON in any field it reads, random bytes) and
whatever its disp.pfm holds (random bytes, recorded or not), ``export`` never ends with a
traceback: the pair is exported, or left out with one ``failed:`` line naming its file,
the other pair is exported, and the command ends with exit 0, or 1 and one ``Error:``
line.  The run folder is only read.

Examples are derandomized, so a failure reproduces on every run.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from d3cli.cli import main
from d3cli.data.formats import write_pfm

# D3_HYPOTHESIS_EXAMPLES=2000 for a longer exploratory run.
SETTINGS = settings(max_examples=int(os.environ.get("D3_HYPOTHESIS_EXAMPLES", "80")), deadline=None,
                    derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])

#: The fields of result.json that export reads, as paths into the object.
FIELDS = [(), ("inputs",), ("inputs", "left"), ("timings",), ("timings", "total"), ("timings", "wall"),
          ("files",), ("files", "disp.pfm"), ("files", "disp.pfm", "size"), ("files", "disp.pfm", "sha256")]
#: How every line of export's output starts.
PREFIXES = ("WARNING: ", "failed: ", "skipped ", "wrote ", "Error: ")

#: Any character, lone surrogates included (a non-UTF-8 file name read with surrogateescape).
TEXT = st.text(st.characters(codec=None, exclude_categories=()), max_size=30)
#: Any JSON value: the numbers JSON can hold (huge integers, NaN and infinities included).
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**30), 10**400)
    | st.floats(allow_nan=True, allow_infinity=True) | TEXT,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(TEXT, inner, max_size=4),
    max_leaves=12)

DISP = np.array([[1.5, 300.0], [np.inf, 2.25]], dtype=np.float32)


def write_pair(out: Path, name: str, left: str) -> dict:
    """A pair folder as ``d3stereo run`` leaves it; returns its result.json content."""
    folder = out / name
    folder.mkdir(parents=True)
    write_pfm(folder / "disp.pfm", DISP)
    data = (folder / "disp.pfm").read_bytes()
    result = {"pair": name, "inputs": {"left": left, "right": left, "gt": None},
              "timings": {"total": 1.25, "wall": 2.5},
              "files": {"disp.pfm": {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}}}
    (folder / "result.json").write_text(json.dumps(result))
    return result


def replaced(document: dict, path: tuple, value):
    """``document`` with the field at ``path`` set to ``value`` (made where missing)."""
    if not path:
        return value
    node = document
    for key in path[:-1]:
        if not isinstance(node.get(key), dict):
            node[key] = {}
        node = node[key]
    node[path[-1]] = value
    return document


def snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def check_export(out: Path, sub: Path, *args: str):
    """Run export; assert it ends as the house rules say; return its result."""
    before = snapshot(out)
    result = CliRunner().invoke(main, ["export", str(out), "-o", str(sub), *args])
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code in (0, 1), result.output
    lines = result.output.splitlines()
    assert all(line.startswith(PREFIXES) for line in lines), result.output
    if result.exit_code == 1:
        assert lines[-1].startswith("Error: ") and sum(line.startswith("Error: ") for line in lines) == 1
    assert snapshot(out) == before  # OUT is only read
    return result


@SETTINGS
@given(field=st.sampled_from(FIELDS), value=JSON_VALUES, fmt=st.sampled_from(["kitti", "middeval3"]))
def test_random_json_in_result_json_never_gives_a_traceback(field, value, fmt):
    with tempfile.TemporaryDirectory() as tmp:
        out, sub = Path(tmp) / "out", Path(tmp) / "sub"
        write_pair(out, "middlebury2014-adirondack-Q", "/d/trainingQ/Adirondack/im0.png")
        damaged = write_pair(out, "middlebury2014-teddy-Q", "/d/trainingQ/Teddy/im0.png")
        path = out / "middlebury2014-teddy-Q" / "result.json"
        path.write_text(json.dumps(replaced(damaged, field, value)))
        result = check_export(out, sub, "--format", fmt)
        if result.exit_code == 1:
            lines = result.output.splitlines()
            assert [line for line in lines if line.startswith("failed: ")] == [
                line for line in lines if line.startswith(f"failed: {path}: ")] != []
        # the undamaged pair is exported either way
        written = sorted(p.relative_to(sub).as_posix() for p in sub.rglob("*") if p.is_file())
        expected = ("trainingQ/Adirondack/disp0D3Stereo.pfm" if fmt == "middeval3"
                    else "disp_0/middlebury2014-adirondack-Q_10.png")
        assert expected in written


@SETTINGS
@given(content=st.binary(max_size=200), target=st.sampled_from(["result.json", "disp.pfm"]),
       recorded=st.booleans(), fmt=st.sampled_from(["kitti", "middeval3"]))
def test_random_bytes_in_a_pair_folder_never_give_a_traceback(content, target, recorded, fmt):
    """Random bytes as result.json, or as disp.pfm (with its size and SHA-256 recorded in
    result.json too, as an edit of both files would leave them)."""
    with tempfile.TemporaryDirectory() as tmp:
        out, sub = Path(tmp) / "out", Path(tmp) / "sub"
        write_pair(out, "kitti2015-000000_10", "/k/training/image_2/000000_10.png")
        damaged = write_pair(out, "kitti2015-000001_10", "/k/training/image_2/000001_10.png")
        folder = out / "kitti2015-000001_10"
        (folder / target).write_bytes(content)
        if target == "disp.pfm" and recorded:
            damaged["files"]["disp.pfm"] = {"size": len(content), "sha256": hashlib.sha256(content).hexdigest()}
            (folder / "result.json").write_text(json.dumps(damaged))
        result = check_export(out, sub, "--format", fmt, "--split", "trainingQ")
        written = sorted(p.relative_to(sub).as_posix() for p in sub.rglob("*") if p.is_file())
        assert ("disp_0/000000_10.png" if fmt == "kitti" else "trainingQ/kitti2015-000000_10/disp0D3Stereo.pfm") \
            in written
        if result.exit_code == 1:
            assert result.output.splitlines()[-1] == (
                f"Error: {out}: 1 of 2 pairs not exported (see the failed: lines); fix each as its line says, "
                "then export again")
