"""A missing features model is named as missing, before the outputs it would list."""

import numpy as np
import pytest

from d3cli.config import load_config
from d3cli.errors import ConfigError
from d3cli.method.features import run_model

pytest.importorskip("onnxruntime")


def test_missing_model_is_named_before_empty_outputs(tmp_path):
    model = tmp_path / "gone.onnx"
    cfg = load_config(None, [f"features.model={model}"]).features
    assert cfg.outputs == ()
    with pytest.raises(ConfigError) as info:
        run_model(np.zeros((8, 8), np.float32), cfg)
    assert str(info.value) == f"{model}: features.model not found; give the path of an ONNX file"
