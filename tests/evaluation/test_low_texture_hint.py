"""A dark, featureless pair is blamed on its scene, not on rectification; a swapped pair
keeps the hint to check the inputs."""

import json

import numpy as np
from click.testing import CliRunner

from d3cli.batch.dispatch import compute_pair
from d3cli.cli import main
from d3cli.config import load_config
from d3cli.evaluation.diagnostics import suspicious_result, texture_share
from tests.helpers import textured_pair, write_png

CHECK_INPUTS = ("is the pair rectified (rows correspond), and is the left image really the left one? "
                "check the inputs before trusting this map")
LOW_TEXTURE = ("the left image has too little texture or contrast for decisive matches ({share} % of its pixels "
               "show texture, below 20 % matching has little to go on): a dark or featureless scene rather than a "
               "wrong pair; trust the map only where matching decided it")


def dark_pair(size=(96, 160), seed=0):
    """A dusk-like pair: a dark, flat scene with nothing but independent sensor noise."""
    rng = np.random.default_rng(seed)
    left, right = (np.clip(np.rint(14 + rng.normal(0, 1, size)), 0, 255).astype(np.uint8) for _ in range(2))
    return left, right


def _decided_warning(result, check):
    decided = 100 * float(np.asarray(result.valid).mean())
    return (f"only {decided:.1f} % of the pixels were decided by matching (the rest is filled; good pairs have "
            f"> 50 %); {check}")


def test_a_dark_featureless_pair_is_blamed_on_the_scene():
    left, right = dark_pair()
    result = compute_pair("sgbm", load_config(None), left, right, max_disparity=16)
    assert texture_share(left) == 0.0
    assert suspicious_result(result, 16, left=left) == [_decided_warning(result, LOW_TEXTURE.format(share="0.0"))]


def test_a_swapped_textured_pair_keeps_the_hint_to_check_the_inputs():
    left, right, _ = textured_pair(6, size=(96, 160))
    assert texture_share(left) > 0.9
    result = compute_pair("sgbm", load_config(None), right, left, max_disparity=16)  # swapped
    assert suspicious_result(result, 16, left=right) == [_decided_warning(result, CHECK_INPUTS)]


def test_contrast_scaled_down_is_low_texture_and_colour_and_16_bit_are_measured_alike():
    left, _, _ = textured_pair(6, size=(96, 160))
    assert texture_share((left / 40 + 10).astype(np.uint8)) < 0.2 < texture_share(left)
    assert texture_share(np.repeat(left[..., None], 3, axis=2)) == texture_share(left)
    assert texture_share(left.astype(np.uint16) * 257) == texture_share(left)
    assert texture_share(left.astype(np.float32) / 255) == texture_share(left)


def test_a_run_records_the_scene_hint_for_a_dark_pair(tmp_path):
    root = tmp_path / "pairs"
    (root / "dusk").mkdir(parents=True)
    left, right = dark_pair()
    write_png(root / "dusk" / "left.png", left)
    write_png(root / "dusk" / "right.png", right)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(root), "-o", str(out), "--method", "sgbm", "--max-disparity", "16"])
    assert result.exit_code == 0, result.output
    warnings = json.loads((out / "dusk" / "result.json").read_text())["warnings"]
    assert [w.split(" %); ", 1)[1] for w in warnings] == [LOW_TEXTURE.format(share="0.0")]


def test_texture_share_takes_any_image():
    """Any size, dtype and content (NaN, inf, tiny, colour) gives a share in [0, 1]."""
    from hypothesis import given, settings, strategies as st
    from hypothesis.extra.numpy import arrays

    kinds = st.sampled_from([np.uint8, np.uint16, np.int16, np.float32, np.float64, np.bool_])
    shapes = st.tuples(st.integers(0, 24), st.integers(0, 24)) | st.tuples(st.integers(0, 12), st.integers(0, 12),
                                                                           st.just(3))

    @settings(max_examples=80, deadline=None, derandomize=True, database=None)
    @given(kinds.flatmap(lambda kind: arrays(kind, shapes)))
    def check(image):
        assert 0.0 <= texture_share(image) <= 1.0

    check()
