"""A broken pair folder inside a dataset fails alone."""

import json

from click.testing import CliRunner

from d3cli.cli import main


def test_broken_pair_folder_is_recorded_failed_and_the_others_run(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    make_pair_folder(root, "a", shift=4)
    make_pair_folder(root, "c", shift=6, seed=1)
    broken = make_pair_folder(root, "b", shift=5, seed=2)
    (broken / "right.png").unlink()
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(root), "-o", str(out), "--method", "sgbm"])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert [line for line in result.output.splitlines() if line.startswith("Error:")] == [
        f"Error: 1 of 3 pairs failed (see {out / 'run.json'})"]
    run = json.loads((out / "run.json").read_text())
    status = {p["pair"]: p["status"] for p in run["pairs"]}
    assert status == {"a": "ok", "b": "failed", "c": "ok"}
    (failed,) = run["failed"]
    assert "found left.png but no right image" in failed["error"]
    assert (out / "a" / "disp.pfm").is_file() and (out / "c" / "disp.pfm").is_file()
