"""Deep-feature cost pyramids (docs/design.md, 'Cost volumes'): the cosine cost against a NumPy reference, an
ONNX backbone whose cosine cost equals NCC, and bad models refused in one line.

The ONNX models are generated here with onnx.helper: nothing is downloaded.
"""

from __future__ import annotations

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")
from onnx import TensorProto, helper  # noqa: E402

from d3cli import D3Stereo, load_config  # noqa: E402
from d3cli.config import FeaturesConfig  # noqa: E402
from d3cli.errors import ConfigError  # noqa: E402
from d3cli.kernels import cpu  # noqa: E402
from d3cli.method.features import feature_pyramid, level_of, normalise  # noqa: E402
from d3cli.method.pyramid import build_pyramid  # noqa: E402
from tests.helpers import textured_pair  # noqa: E402
from tests.reference.features import ref_cosine_cost

WINDOW = 5


def ncc_equivalent_model(path, levels: int, *, nan: bool = False, rank3: bool = False, stride3: bool = False):
    """A model whose level-i output holds, per pixel, the 25 pixels of the 5x5 window of
    the level-i image minus their mean: the cosine of two such vectors is their NCC.

    Level images are 2x2 average pools, exactly like the pyramid (odd row/column dropped).
    """
    k = WINDOW * WINDOW
    weight = (np.eye(k, dtype=np.float32) - 1.0 / k).reshape(k, 1, WINDOW, WINDOW)
    nodes, outputs, inits = [], [], [helper.make_tensor("w", TensorProto.FLOAT, weight.shape, weight.ravel())]
    current = "image"
    for level in range(levels):
        if level:
            pooled = f"x{level}"
            kernel = 3 if stride3 and level == 1 else 2
            nodes.append(helper.make_node("AveragePool", [current], [pooled], kernel_shape=[kernel, kernel],
                                          strides=[kernel, kernel]))
            current = pooled
        out = f"f{level}"
        # edge padding: a border window repeats the border pixels (NCC clips it instead)
        inits.append(helper.make_tensor(f"p{level}", TensorProto.INT64, [8], [0, 0, 2, 2, 0, 0, 2, 2]))
        nodes.append(helper.make_node("Pad", [current, f"p{level}"], [f"x{level}_pad"], mode="edge"))
        nodes.append(helper.make_node("Conv", [f"x{level}_pad", "w"], [out if not (nan or rank3) else out + "_c"]))
        if nan:
            inits.append(helper.make_tensor(f"z{level}", TensorProto.FLOAT, [1], [0.0]))
            nodes.append(helper.make_node("Div", [out + "_c", f"z{level}"], [out]))  # 0/0 = NaN, x/0 = inf
        if rank3:
            inits.append(helper.make_tensor(f"s{level}", TensorProto.INT64, [3], [1, k, -1]))
            nodes.append(helper.make_node("Reshape", [out + "_c", f"s{level}"], [out]))
        outputs.append(helper.make_tensor_value_info(out, TensorProto.FLOAT, None))
    graph = helper.make_graph(nodes, "ncc_features",
                              [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, None, None])],
                              outputs, inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return [f"f{level}" for level in range(levels)]


def feature_config(path, outputs, **extra):
    sets = [f"features.model={path}", f"features.outputs=[{', '.join(outputs)}]", "features.scale=1",
            "features.mean=[0]", "features.std=[1]", "cost.kind=features"]
    sets += [f"{k}={v}" for k, v in extra.items()]
    return load_config(overrides=sets)


def test_cosine_cost_volume_matches_the_numpy_reference():
    rng = np.random.default_rng(1)
    fl, nl = normalise(rng.normal(size=(7, 13, 6)).astype(np.float32))
    fr, nr = normalise(rng.normal(size=(7, 13, 6)).astype(np.float32))
    fl[2, 3] = 0.0
    nl[2, 3] = 0.0  # a zero vector: cost 1 like a flat NCC window
    got = cpu.cosine_cost_volume(fl, fr, nl, nr, 5)
    np.testing.assert_allclose(got, ref_cosine_cost(fl, fr, 5), atol=1e-6)
    assert (got[2, 3] == 1).all() and (got[:, 0, 1:] == 1).all()


def test_ncc_equivalent_backbone_gives_the_ncc_cost_inside_the_image(tmp_path):
    left, right, _ = textured_pair(6, (48, 96), seed=2)
    outputs = ncc_equivalent_model(tmp_path / "ncc.onnx", 3)
    cfg = feature_config(tmp_path / "ncc.onnx", outputs)
    shapes = [p.shape for p in build_pyramid(left.astype(np.float32), 3)]
    levels = feature_pyramid(left, right, shapes, cfg.features)
    assert all(level is not None for level in levels)
    for i, level in enumerate(levels):
        grey_l, grey_r = (build_pyramid(img.astype(np.float32), 3)[i] for img in (left, right))
        ncc = cpu.ncc_cost_volume(grey_l, grey_r, 8, WINDOW, 0.0)
        cos = cpu.cosine_cost_volume(level.left, level.right, level.left_norm, level.right_norm, 8)
        r = WINDOW // 2
        inner = (slice(r, shapes[i][0] - r), slice(r + 8, shapes[i][1] - r))  # no window touches a border
        np.testing.assert_allclose(cos[inner], ncc[inner], atol=2e-5)


def test_features_path_matches_the_ncc_path_end_to_end(tmp_path):
    left, right, gt = textured_pair(7, (64, 128), seed=5)
    outputs = ncc_equivalent_model(tmp_path / "ncc.onnx", 4)
    ncc = D3Stereo(load_config()).compute(left, right, max_disparity=24)
    feat = D3Stereo(feature_config(tmp_path / "ncc.onnx", outputs)).compute(left, right, max_disparity=24)
    assert feat.info["feature_levels"] == [1, 2, 3, 4]
    ok = np.isfinite(gt)
    # the model zero-pads at the image border where the NCC path clips its windows: the
    # two costs are the same only where no window touches the border
    r = WINDOW // 2
    ok[:r], ok[-r:], ok[:, -r:] = False, False, False
    epe_ncc = np.abs(ncc.disparity[ok] - gt[ok]).mean()
    epe_feat = np.abs(feat.disparity[ok] - gt[ok]).mean()
    assert epe_feat <= 1.1 * epe_ncc + 0.02, (epe_feat, epe_ncc)


def test_levels_without_a_feature_map_use_ncc(tmp_path):
    left, right, _ = textured_pair(6, (48, 96), seed=3)
    outputs = ncc_equivalent_model(tmp_path / "m.onnx", 3)
    cfg = feature_config(tmp_path / "m.onnx", outputs[1:])  # like VGG: no full-resolution tap
    result = D3Stereo(cfg).compute(left, right, max_disparity=16)
    assert result.info["feature_levels"] == [2, 3]
    assert np.isfinite(result.disparity).all()


def test_stride_must_be_a_power_of_two():
    assert level_of((24, 48), (48, 96)) == 1 and level_of((12, 25), (48, 97)) == 2
    with pytest.raises(ConfigError, match=r"m\.onnx: output 'f' of 16x32 for an image of 48x96 is not at a "
                                          r"power-of-two stride"):
        level_of((16, 32), (48, 96), name="f", model="m.onnx")


@pytest.mark.parametrize("problem, message", [
    ("missing", r"bad\.onnx: the model has no output 'nope'; its outputs are f0, f1; fix features\.outputs"),
    ("nan", r"bad\.onnx: output 'f0' has NaN or inf values"),
    ("rank3", r"bad\.onnx: output 'f0' has shape \(1, 25, \d+\), expected \(1, C, h, w\)"),
    ("stride3", r"bad\.onnx: output 'f1' of \d+x\d+ for an image of 48x96 is not at a power-of-two stride"),
    ("nomodel", r"cost\.kind: features needs features\.model"),
    ("nofile", r"gone\.onnx: features\.model not found"),
])
def test_bad_models_are_one_line_config_errors(tmp_path, problem, message):
    path = tmp_path / "bad.onnx"
    outputs = ncc_equivalent_model(path, 2, nan=problem == "nan", rank3=problem == "rank3",
                                   stride3=problem == "stride3")
    if problem == "missing":
        outputs = ["nope"]
    cfg = FeaturesConfig(model=str(path), outputs=tuple(outputs), scale=1.0, mean=(0.0,), std=(1.0,))
    if problem == "nomodel":
        cfg = FeaturesConfig(outputs=("f0",))
    if problem == "nofile":
        cfg = FeaturesConfig(model=str(tmp_path / "gone.onnx"), outputs=("f0",))
    left, right, _ = textured_pair(6, (48, 96))
    with pytest.raises(ConfigError, match=message) as info:
        feature_pyramid(left, right, [(48, 96), (24, 48)], cfg)
    assert "\n" not in str(info.value)


def test_perspective_transformation_with_features_on_the_road_sample(tmp_path):
    from d3cli.data.layouts import load_ground_truth, load_pair_images, read_pair_folder
    from d3cli.data.samples import __file__ as samples_init
    from pathlib import Path

    pair = read_pair_folder(Path(samples_init).parent / "road")
    left, right = load_pair_images(pair)
    gt, _ = load_ground_truth(pair, left.shape[:2])
    outputs = ncc_equivalent_model(tmp_path / "ncc.onnx", 4)
    repo = Path(__file__).resolve().parents[2]
    results = {}
    for kind in ("ncc", "features"):
        cfg = load_config(repo / "d3cli" / "presets" / "road.yaml", [f"{k}={v}" for k, v in {
            "features.model": tmp_path / "ncc.onnx", "features.outputs": f"[{', '.join(outputs)}]",
            "features.scale": 1, "features.mean": "[0]", "features.std": "[1]", "cost.kind": kind}.items()])
        result = D3Stereo(cfg).compute(left, right, max_disparity=40)
        assert result.info["pt"]["fallback"] is False  # the warped right image's features were matched
        ok = np.isfinite(gt)
        results[kind] = float(np.abs(result.disparity[ok] - gt[ok]).mean())
    assert results["features"] <= 1.1 * results["ncc"] + 0.01, results
