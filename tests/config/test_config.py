"""load_config: defaults, files, overrides and every kind of mistake, with exact messages."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.config import Config, load_config, read_yaml
from d3cli.errors import ConfigError

DEFAULT_YAML = Path(__file__).resolve().parents[2] / "d3cli" / "presets" / "default.yaml"


def write(tmp_path, text, name="cfg.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_defaults():
    cfg = load_config()
    assert cfg == Config()
    assert cfg.run.method == "d3stereo" and cfg.cost.window == 5


def test_default_yaml_equals_builtin_defaults():
    assert load_config(DEFAULT_YAML) == Config()


def test_default_yaml_lists_every_key():
    data = read_yaml(DEFAULT_YAML)
    expected = Config().to_dict()
    assert list(data) == list(expected)
    for section, keys in expected.items():
        assert list(data[section]) == list(keys), section


def test_file_values(tmp_path):
    path = write(tmp_path, "run:\n  method: sgbm\ncost:\n  window: 7\n  level_windows: [5, 7]\n")
    cfg = load_config(path)
    assert cfg.run.method == "sgbm"
    assert cfg.cost.window == 7 and cfg.cost.level_windows == (5, 7)
    assert cfg.pyramid == Config().pyramid


def test_empty_file_gives_defaults(tmp_path):
    assert load_config(write(tmp_path, "# nothing\n")) == Config()


def test_overrides_win_over_file(tmp_path):
    path = write(tmp_path, "diffusion:\n  tau: 2\n")
    cfg = load_config(path, ["diffusion.tau=3", "refine.fill=false", "aggregation.sigma_color=8"])
    assert cfg.diffusion.tau == 3
    assert cfg.refine.fill is False
    assert cfg.aggregation.sigma_color == 8.0 and isinstance(cfg.aggregation.sigma_color, float)


def test_unknown_section(tmp_path):
    path = write(tmp_path, "foo:\n  a: 1\n")
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value) == (
        f"{path}:1: unknown section 'foo'; valid sections: run, pyramid, cost, features, aggregation, seeds, "
        "diffusion, inheritance, pt, refine, sgbm, peers, camera, road"
    )


def test_unknown_key(tmp_path):
    path = write(tmp_path, "run:\n  metod: sgbm\n")
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value) == f"{path}:2: unknown key 'run.metod'; valid keys of run: method, backend, max_disparity, max_memory_gb, color_range, outputs"


def test_wrong_type(tmp_path):
    path = write(tmp_path, "cost:\n  window: five\n")
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value) == (
        f"{path}:2: cost.window must be an integer, got 'five'; fix the value of cost.window "
        "(see d3cli/presets/default.yaml)"
    )


def test_bool_is_not_an_integer(tmp_path):
    with pytest.raises(ConfigError, match="pyramid.levels must be an integer, got True"):
        load_config(write(tmp_path, "pyramid:\n  levels: true\n"))


def test_out_of_range(tmp_path):
    path = write(tmp_path, "cost:\n  window: 4\n")
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value) == f"{path}:2: cost.window must be an odd integer in [1, 31], got 4; fix the value of cost.window"


def test_duplicate_key_names_line(tmp_path):
    path = write(tmp_path, "run:\n  method: sgbm\n  method: d3stereo\n")
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value) == f"{path}:3: duplicate key 'method' (first at line 2); keep only one"


def test_invalid_yaml_names_line(tmp_path):
    path = write(tmp_path, "run:\n  method: [sgbm\n")
    with pytest.raises(ConfigError, match=rf"^{path}:\d+: not valid YAML \(.*\); fix the syntax$"):
        load_config(path)


def test_non_yaml_binary_file(tmp_path):
    path = tmp_path / "image.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00\x00")
    with pytest.raises(ConfigError, match=rf"^{path}:1: cannot read config file .*; give a readable UTF-8 YAML file$"):
        load_config(path)


def test_top_level_list(tmp_path):
    with pytest.raises(ConfigError, match="the top level must be a mapping of sections, got list"):
        load_config(write(tmp_path, "- a\n- b\n"))


def test_missing_file(tmp_path):
    path = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value) == f"{path}: config file not found; check the path given to -c"


def test_bad_override_forms():
    with pytest.raises(ConfigError) as exc:
        load_config(None, ["nokey"])
    assert str(exc.value) == "--set nokey: expected section.key=value (e.g. diffusion.tau=2); fix the option"
    with pytest.raises(ConfigError) as exc:
        load_config(None, ["pyramid.levels=9"])
    assert str(exc.value) == (
        "--set pyramid.levels=9: pyramid.levels must be an integer in [1, 8], got 9; "
        "fix the value of pyramid.levels"
    )


@pytest.mark.parametrize(
    "args, message",
    [
        (["--set", "run.foo=1"], "Error: --set run.foo=1: unknown key 'run.foo'; valid keys of run: "
                                 "method, backend, max_disparity, max_memory_gb, color_range, outputs"),
        (["--set", "diffusion.tau=abc"], "Error: --set diffusion.tau=abc: diffusion.tau must be an integer, "
                                         "got 'abc'; fix the value of diffusion.tau (see d3cli/presets/default.yaml)"),
    ],
)
def test_cli_config_errors_are_one_line(tmp_path, args, message):
    result = CliRunner().invoke(main, ["run", "-o", str(tmp_path / "out"), *args])
    assert result.exit_code == 1
    assert result.output.strip() == message
    assert "Traceback" not in result.output


def test_cli_config_file_error(tmp_path):
    path = write(tmp_path, "sgbm:\n  mode: fast\n")
    result = CliRunner().invoke(main, ["run", "-c", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert result.output.strip() == (
        f"Error: {path}:2: sgbm.mode must be one of sgbm, hh, 3way, hh4, got 'fast'; fix the value of sgbm.mode"
    )


def test_config_from_environment(tmp_path, monkeypatch):
    from d3cli.cli import config_search

    path = write(tmp_path, "run:\n  method: sgbm\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("D3STEREO_CONFIG", raising=False)
    assert config_search(None) == (None, "built-in defaults")
    monkeypatch.setenv("D3STEREO_CONFIG", str(path))
    assert config_search(None) == (str(path), "$D3STEREO_CONFIG")
    assert config_search("x.yaml") == ("x.yaml", "-c option")


@pytest.mark.parametrize(
    "text, message",
    [
        ("run:\n  method: sgbm\ncost:\n  window: 5\n  window: 7\n",
         "{path}:5: duplicate key 'window' (first at line 4); keep only one"),
        ("run:\n  method: sgbm\ncost:\n  window: [5]\n",
         "{path}:4: cost.window must be an integer, got [5]; fix the value of cost.window (see d3cli/presets/default.yaml)"),
        ("run:\n  method: sgbm\n\ncolour:\n  on: true\n",
         "{path}:4: unknown section 'colour'; valid sections: run, pyramid, cost, features, aggregation, seeds, diffusion, "
         "inheritance, pt, refine, sgbm, peers, camera, road"),
        ("seeds:\n  pkrn_min: 2.0\n  pkrn: 3\n",
         "{path}:3: unknown key 'seeds.pkrn'; valid keys of seeds: pkrn_min, epsilon, lr_tolerance, "
         "pkrn_exclusion, every_level"),
        ("sgbm:\n  uniqueness_ratio: 100\n",
         "{path}:2: sgbm.uniqueness_ratio must be an integer in [0, 99], got 100; "
         "fix the value of sgbm.uniqueness_ratio"),
        ("pyramid: 4\n",
         "{path}:1: section pyramid must be a mapping of keys, got 4; valid keys: levels, ars, band, band_margin, "
             "band_tile, finest_band_tile"),
        ("This is a README, not a config file.\n",
         "{path}:1: the top level must be a mapping of sections, got str; valid sections: run, pyramid, cost, "
         "features, aggregation, seeds, diffusion, inheritance, pt, refine, sgbm, peers, camera, road"),
        ("run:\n\tmethod: sgbm\n",
         "{path}:2: not valid YAML (found character '\\t' that cannot start any token); fix the syntax"),
        ("run:\n  method: sgbm\n\x00\x01binary\n",
         "{path}:3: cannot read config file (a NUL byte: binary data, not YAML); give a readable UTF-8 YAML file"),
    ],
    ids=["duplicate", "wrong-type", "unknown-section", "unknown-key", "out-of-range", "section-not-mapping",
         "not-yaml-prose", "yaml-syntax", "binary"],
)
def test_cli_config_errors_name_file_line_and_key(tmp_path, text, message):
    path = write(tmp_path, text)
    result = CliRunner().invoke(main, ["run", "-c", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    assert result.output.strip() == "Error: " + message.format(path=path)
    assert not (tmp_path / "out").exists()  # nothing is written before the config is valid


def test_line_numbers_of_flow_style_and_nested_keys(tmp_path):
    path = write(tmp_path, "# comment\n\nrun: {method: sgbm, backend: gpu}\n")
    with pytest.raises(ConfigError, match=rf"^{path}:3: run.backend must be one of auto, cpu, cuda, got 'gpu'"):
        load_config(path)


@pytest.mark.parametrize("fit, sgm_p2, equiangular", [("auto", 0.6, True), ("auto", 0.0, False),
                                                      ("parabola", 0.6, False), ("equiangular", 0.0, True)])
def test_subpixel_fit_auto_takes_the_lines_after_the_semi_global_smoothing(fit, sgm_p2, equiangular):
    cfg = load_config(None, [f"refine.subpixel_fit={fit}", f"aggregation.sgm_p2={sgm_p2}"])
    assert cfg.equiangular_subpixel is equiangular


def test_bundled_configs_fit_the_subpixel_as_their_cost_asks():
    """The defaults and kitti.yaml smooth the cost (lines); paper.yaml and road.yaml do not
    (the parabola: the paper's step, and the measured better fit on an RBF cost)."""
    from d3cli.config import bundled_configs

    fits = {name: load_config(path).equiangular_subpixel for name, path in bundled_configs().items()}
    assert fits["default"] and fits["kitti"] and not fits["paper"] and not fits["road"]


def test_unknown_subpixel_fit_is_refused():
    with pytest.raises(ConfigError, match="refine.subpixel_fit.*one of auto, parabola, equiangular"):
        load_config(None, ["refine.subpixel_fit=cubic"])


def _default_yaml_lines() -> dict[tuple[str, str], tuple[str, str]]:
    """``{(section, key): (value text, comment)}`` of configs/default.yaml's key lines."""
    found, section = {}, None
    for line in DEFAULT_YAML.read_text(encoding="utf-8").splitlines():
        if line and not line.startswith((" ", "#")):
            section = line.split(":", 1)[0]
        elif line.startswith("  ") and not line.lstrip().startswith("#"):
            key, _, rest = line.strip().partition(":")
            value, _, comment = rest.partition(" #")
            found[(section, key)] = (value.strip(), comment.strip())
    return found


def test_default_yaml_comments_each_key_with_its_doc_and_value():
    """Each key's line in default.yaml carries its default and, as its comment, the one
    line of meaning declared beside the default (``setting(default, doc, ...)``)."""
    lines = _default_yaml_lines()
    for section in dataclasses.fields(Config):
        for f in dataclasses.fields(section.default_factory):
            value, comment = lines[(section.name, f.name)]
            assert f.metadata["doc"], f"{section.name}.{f.name} has no doc"
            assert comment == f.metadata["doc"], f"{section.name}.{f.name}"
            assert yaml.safe_load(value) == Config().to_dict()[section.name][f.name], f"{section.name}.{f.name}"

