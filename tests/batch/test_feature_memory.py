"""The memory check counts the feature channels of ``cost.kind: features``.

Per level i both views hold float32 (H / 2^i, W / 2^i, C_i + 1) (vectors and norms),
counted twice (the raw maps and the normalised copies).
"""

from __future__ import annotations

import numpy as np
import pytest

from d3cli import load_config
from d3cli.batch.resources import check_memory, estimate_peak_bytes
from d3cli.errors import InputError
from d3cli.method.features import DEFAULT_CHANNELS, feature_channels

H, W, DMAX = 96, 160, 31


def features_bytes(channels):
    return 2 * sum(2 * (H >> i) * (W >> i) * (c + 1) * 4 for i, c in enumerate(channels))


def extra(cfg):
    ncc = load_config(overrides=["cost.kind=ncc"])
    return estimate_peak_bytes((H, W), DMAX, cfg, method="d3stereo") - estimate_peak_bytes((H, W), DMAX, ncc,
                                                                                           method="d3stereo")


def test_npz_channels_come_from_the_headers(tmp_path):
    path = tmp_path / "f.npz"
    arrays = {f"{view}_{i}": np.zeros((H >> i, W >> i, c), np.float32)
              for i, c in enumerate((16, 64, 256)) for view in ("left", "right")}
    np.savez(path, **arrays)
    cfg = load_config(overrides=["cost.kind=features", f"features.npz={path}"])
    assert feature_channels(cfg.features, 4) == [16, 64, 256, 0]  # level 4 has no map: NCC
    assert extra(cfg) == features_bytes([16, 64, 256, 0])
    # compressed archives have the same headers
    np.savez_compressed(path, **arrays)
    assert extra(cfg) == features_bytes([16, 64, 256, 0])


def test_unreadable_npz_counts_the_upper_bound(tmp_path):
    cfg = load_config(overrides=["cost.kind=features", "features.npz=relative/to/each/pair.npz"])
    assert feature_channels(cfg.features, 4) == [DEFAULT_CHANNELS] * 4
    assert extra(cfg) == features_bytes([DEFAULT_CHANNELS] * 4)


def test_ncc_counts_no_features():
    cfg = load_config(overrides=["features.outputs=[a, b]", "features.model=none.onnx"])  # kind ncc: unused
    assert extra(cfg) == 0


def test_model_channels_come_from_its_output_shapes(tmp_path):
    onnx = pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from onnx import TensorProto, helper

    w7 = np.ones((7, 1, 1, 1), np.float32)
    w5 = np.ones((5, 7, 1, 1), np.float32)
    graph = helper.make_graph(
        [helper.make_node("Conv", ["image", "w7"], ["s1"]),
         helper.make_node("AveragePool", ["s1"], ["p"], kernel_shape=[2, 2], strides=[2, 2]),
         helper.make_node("Conv", ["p", "w5"], ["s2"]),
         helper.make_node("Conv", ["image", "wd"], ["dyn"])],  # channels: a graph input's dimension
        "taps", [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, None, None]),
                 helper.make_tensor_value_info("wd", TensorProto.FLOAT, ["c", 1, 1, 1])],
        [helper.make_tensor_value_info("s1", TensorProto.FLOAT, [1, 7, "h", "w"]),
         helper.make_tensor_value_info("s2", TensorProto.FLOAT, [1, 5, "h2", "w2"]),
         helper.make_tensor_value_info("dyn", TensorProto.FLOAT, None)],
        [helper.make_tensor("w7", TensorProto.FLOAT, w7.shape, w7.ravel()),
         helper.make_tensor("w5", TensorProto.FLOAT, w5.shape, w5.ravel())])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(tmp_path / "taps.onnx"))
    cfg = load_config(overrides=["cost.kind=features", f"features.model={tmp_path / 'taps.onnx'}",
                                 "features.outputs=[s1, s2, dyn]"])
    assert feature_channels(cfg.features, 4) == [7, 5, DEFAULT_CHANNELS, 0]
    assert extra(cfg) == features_bytes([7, 5, DEFAULT_CHANNELS, 0])


def test_feature_channels_can_make_the_memory_check_refuse_a_pair(tmp_path):
    path = tmp_path / "f.npz"
    np.savez(path, left_0=np.zeros((H, W, 512), np.float32), right_0=np.zeros((H, W, 512), np.float32))
    ncc = load_config(overrides=["cost.kind=ncc"])
    feats = load_config(overrides=["cost.kind=features", f"features.npz={path}"])
    limit_gb = (estimate_peak_bytes((H, W), DMAX, ncc, method="d3stereo") + features_bytes([512]) / 2) / 1e9
    ncc = load_config(overrides=["cost.kind=ncc", f"run.max_memory_gb={limit_gb}"])
    feats = load_config(overrides=["cost.kind=features", f"features.npz={path}", f"run.max_memory_gb={limit_gb}"])
    check_memory((H, W), DMAX, ncc, method="d3stereo")
    with pytest.raises(InputError):
        check_memory((H, W), DMAX, feats, method="d3stereo")
