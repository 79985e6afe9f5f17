"""Config loading: defaults, YAML, overrides, and the exit-2 errors that name the key."""

from pathlib import Path

import pytest

from cornerslam_cli.config import Config, dump_config, load_config
from cornerslam_cli.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_default_yaml_mirrors_the_built_in_defaults():
    assert load_config(ROOT / "configs" / "default.yaml") == Config()


@pytest.mark.parametrize("name", ["default.yaml", "paper.yaml"])
def test_shipped_configs_load(name):
    cfg = load_config(ROOT / "configs" / name)
    assert cfg.association.method in ("icnn", "jcbb", "pca")


def test_paper_config_has_the_papers_parameters():
    cfg = load_config(ROOT / "configs" / "paper.yaml")
    assert cfg.association.pca.group_size == 3
    assert cfg.sensor.model == "piecewise"
    assert cfg.sensor.sigma_r_near == pytest.approx(0.03)


def test_yaml_then_override_wins(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("association:\n  alpha: 0.01\n  pca:\n    group_size: 4\n")
    cfg = load_config(p, ["association.pca.group_size=6"])
    assert cfg.association.alpha == 0.01
    assert cfg.association.pca.group_size == 6
    assert cfg.association.method == "pca"


def test_exponent_without_a_dot_is_a_number(tmp_path):
    # YAML 1.1 (PyYAML) reads 1e-6 as a string; as a float key it means the number
    assert load_config(None, ["ekf.alpha1=1e-6"]).ekf.alpha1 == 1e-6
    p = tmp_path / "c.yaml"
    p.write_text("ekf:\n  alpha2: 2E-3\n")
    assert load_config(p).ekf.alpha2 == 0.002
    with pytest.raises(ConfigError, match="must be an integer"):
        load_config(None, ["lines.min_points=1e2"])


def test_int_is_accepted_for_float():
    cfg = load_config(None, ["sensor.sigma_r_near=1"])
    assert isinstance(cfg.sensor.sigma_r_near, float) and cfg.sensor.sigma_r_near == 1.0


@pytest.mark.parametrize(
    "override, fragment",
    [
        ("association.pca.grup_size=5", "did you mean 'group_size'"),
        ("asociation.alpha=0.1", "did you mean 'association'"),
        ("association.alpha=abc", "'association.alpha' must be a number"),
        ("lines.min_points=2.5", "'lines.min_points' must be an integer"),
        ("corners.drop_occluded=3", "'corners.drop_occluded' must be true or false"),
        ("sensor.model=linaer", "did you mean 'linear'"),
        ("association=3", "'association' must be a mapping"),
        ("noequals", "is not key=value"),
    ],
)
def test_bad_keys_and_types_name_the_key(override, fragment):
    with pytest.raises(ConfigError) as e:
        load_config(None, [override])
    assert fragment in str(e.value)


def test_bad_yaml_names_the_file_and_line(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("association:\n  alpha: [0.1\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert "bad.yaml" in str(e.value) and "not valid YAML" in str(e.value)


def test_missing_and_non_mapping_files(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "nope.yaml")
    p = tmp_path / "list.yaml"
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must contain a mapping"):
        load_config(p)


def test_dump_round_trips(tmp_path):
    cfg = load_config(None, ["association.method=jcbb", "keyframes.linear_update=0.2"])
    p = tmp_path / "dump.yaml"
    p.write_text(dump_config(cfg))
    assert load_config(p) == cfg


# ---------------------------------------------------------------------------- sections left empty
def test_a_null_section_is_an_empty_one(tmp_path):
    """`ekf:` with every key commented out (YAML: null) means the defaults — or the laser preset's
    values, which it must not wipe — at any depth (it was "must be a mapping, got None")."""
    from cornerslam_cli.lasers import PRESETS, resolve_config

    p = tmp_path / "c.yaml"
    p.write_text("ekf:\n#  alpha1: 0.1\nsensor:\nassociation:\n  alpha: 0.01\n  jcbb: ~\n")
    cfg = load_config(p)
    assert cfg.ekf == Config().ekf and cfg.association.jcbb == Config().association.jcbb
    assert cfg.association.alpha == 0.01
    preset = PRESETS["sick_lms_1deg"].config
    assert preset["sensor"]["model"] == "linear"  # the preset sets the section the file leaves empty
    assert load_config(p, base=preset).sensor == load_config(None, base=preset).sensor
    cfg = resolve_config(None, p, ["input.laser_preset=sick_lms_1deg"])
    assert cfg.sensor.model == "linear" and cfg.association.alpha == 0.01


@pytest.mark.parametrize(
    ("text", "key", "got"),
    [
        ("ekf: 5\n", "ekf", "5"),
        ("ekf: [1, 2]\n", "ekf", "[1, 2]"),
        ("input:\n  laser: x\n", "input.laser", "'x'"),
    ],
)
def test_a_section_given_as_a_scalar_or_list_is_refused_naming_the_file_and_key(tmp_path, text, key, got):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value).startswith(
        f"config file '{p}': section '{key}' must be a mapping of its keys, got {got}"
    )
