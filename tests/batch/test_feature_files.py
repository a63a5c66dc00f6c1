"""A batch with ``cost.kind: features`` reads each pair's own precomputed ``features.npz``
(a relative path: beside the pair's left image), and the feature files are part of a
pair's fingerprint: a changed npz recomputes that pair only."""

from __future__ import annotations

import json
import os

from click.testing import CliRunner
from tests.helpers import textured_pair
from tests.method.test_features_npz import write_npz

from d3cli.cli import main


def statuses(out):
    return {p["pair"]: p["status"] for p in json.loads((out / "run.json").read_text())["pairs"]}


def run(root, out):
    args = ["run", str(root), "-o", str(out), "--set", "run.backend=cpu", "--set", "cost.kind=features",
            "--set", "features.npz=features.npz", "--set", "pyramid.levels=3"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    return statuses(out)


def test_each_pair_reads_its_own_npz_and_a_changed_npz_recomputes_only_its_pair(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    for name, seed in (("a", 0), ("b", 1)):
        folder = make_pair_folder(root, name, shift=6, size=(48, 96), seed=seed)
        left, right, _ = textured_pair(6, (48, 96), seed=seed)
        write_npz(folder / "features.npz", left, right, 3)
    out = tmp_path / "out"
    assert run(root, out) == {"a": "ok", "b": "ok"}
    assert run(root, out) == {"a": "skipped", "b": "skipped"}
    npz = root / "b" / "features.npz"
    st = npz.stat()
    os.utime(npz, ns=(st.st_atime_ns, st.st_mtime_ns + 2_000_000_000))  # a new version of b's features
    assert run(root, out) == {"a": "skipped", "b": "ok"}
