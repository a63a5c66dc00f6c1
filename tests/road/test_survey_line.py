"""The terminal line after a ``run --road-report``: potholes by severity, the deepest, the flagged."""

import csv
import json

from click.testing import CliRunner

from d3cli.cli import main
from d3cli.road.outputs import CSV_FIELDS, survey_line


def write_survey(out, rows, frames):
    with (out / "defects.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=CSV_FIELDS, restval="", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    (out / "road_survey.json").write_text(json.dumps({"frames": frames}))


def row(pair, i, kind, depth, severity="", low=False, flags=""):
    return {"pair": pair, "id": i, "kind": kind, "max_depth_mm": depth, "severity": severity,
            "low_confidence": low, "confidence": "low" if low else "ok", "flags": flags}


def test_survey_line_counts_severities_the_deepest_and_the_flagged(tmp_path):
    write_survey(tmp_path, [row("a", 1, "pothole", 30.0, "low"), row("a", 2, "pothole", 62.4, "high"),
                            row("b", 1, "pothole", 20.0, "medium", low=True, flags="weak_match;rematch"),
                            row("b", 2, "bump", 40.0, low=True, flags="specular"),
                            row("b", 3, "pothole", 11.0)], frames=3)
    assert survey_line(tmp_path) == ("road: 3 frames, 4 potholes (low 1, medium 1, high 1, 1 too small to grade), "
                                     "1 bump; deepest 62 mm (a #2); 2 defects flagged (weak match on little texture 1, "
                                     "re-match unreliable 1, wet or specular surface 1)")


def test_survey_line_flags_a_low_confidence_deepest_and_says_when_nothing_was_found(tmp_path):
    write_survey(tmp_path, [row("a", 1, "pothole", 81.0, "high", low=True, flags="specular;noisy")], frames=1)
    assert survey_line(tmp_path) == ("road: 1 frame, 1 pothole (low 0, medium 0, high 1), 0 bumps; deepest 81 mm "
                                     "(a #1, flagged: wet or specular surface; dark or noisy); 1 defect flagged "
                                     "(wet or specular surface 1, dark or noisy 1)")
    # A defects.csv without reason codes (flagged, no flags column): the flag is still said.
    write_survey(tmp_path, [row("a", 1, "pothole", 81.0, "high", low=True)], frames=1)
    assert survey_line(tmp_path).endswith("deepest 81 mm (a #1, flagged: low confidence); 1 defect flagged")
    write_survey(tmp_path, [], frames=2)
    assert survey_line(tmp_path) == "road: 2 frames, no potholes, 0 bumps; none flagged"
    assert survey_line(tmp_path / "nothing") is None
    (tmp_path / "defects.csv").write_text("pair,max_depth_mm\na,deep\n")  # not d3stereo's: no line
    assert survey_line(tmp_path) is None


def test_run_with_road_report_prints_one_road_line(tmp_path):
    runner = CliRunner()
    data = tmp_path / "synth"
    assert runner.invoke(main, ["synth", str(data), "--n", "1", "--seed", "2", "--width", "320",
                                "--height", "192", "-q"]).exit_code == 0
    result = runner.invoke(main, ["run", str(data), "-o", str(tmp_path / "out"), "--method", "sgbm",
                                  "--road-report"])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    road = [line for line in lines if line.startswith("road: ")]
    assert road == [survey_line(tmp_path / "out")] and road[0].startswith("road: 1 frame, ")
    assert lines.index(road[0]) == lines.index(next(x for x in lines if x.startswith("report: "))) - 1
    # Quiet, or without --road-report: no such line.
    for extra in (["--road-report", "-q", "--overwrite"], []):
        result = runner.invoke(main, ["run", str(data), "-o", str(tmp_path / "out2"), "--method", "sgbm", *extra])
        assert result.exit_code == 0, result.output
        assert not any(line.startswith("road: ") for line in result.stdout.splitlines())


def test_survey_line_counts_the_frames_without_a_road_surface(tmp_path):
    write_survey(tmp_path, [], frames=3)
    for pair, road_like in (("a", False), ("b", True), ("c", False)):
        (tmp_path / pair).mkdir()
        (tmp_path / pair / "defects.json").write_text(json.dumps({"road_like": road_like, "defects": []}))
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "defects.json").write_text("[not json")  # damaged: not counted, no failure
    assert survey_line(tmp_path) == ("road: 3 frames (2 without a road surface), no potholes, 0 bumps; "
                                     "none flagged")
