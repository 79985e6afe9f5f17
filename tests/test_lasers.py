"""Laser presets: detection from scan geometry, layering under the user's config, shipped YAML copies."""

import math
import sys
from pathlib import Path

import pytest

from cornerslam_cli.config import load_config
from cornerslam_cli.errors import ConfigError
from cornerslam_cli.lasers import PRESETS, detect_preset, resolve_config

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_logs"


@pytest.mark.parametrize(
    "beams, inc_deg, name",
    [
        (180, 1.0, "sick_lms_1deg"),
        (361, 0.5, "sick_lms_05deg"),
        (682, 360 / 1024, "hokuyo_urg04lx"),
        (1081, 0.25, "hokuyo_270deg"),
        (1081, 0.5, None),
        (100, 1.0, None),
    ],
)
def test_detect_preset_by_beams_and_step(beams, inc_deg, name):
    assert detect_preset(beams, math.radians(inc_deg)) == name


@pytest.mark.parametrize(
    "log, name", [("intel_cut.clf", "sick_lms_1deg"), ("mines_exp3_cut.bag", "hokuyo_urg04lx")]
)
def test_sample_logs_get_their_sensor_preset(log, name):
    cfg = resolve_config(SAMPLES / log, None)
    assert cfg.input.laser_preset == name
    for section, values in PRESETS[name].config.items():
        for key, v in values.items():
            assert getattr(getattr(cfg, section), key) == pytest.approx(v)


def test_user_layers_win_over_the_preset(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("sensor:\n  a: 0.05\n")
    cfg = resolve_config(SAMPLES / "intel_cut.clf", p, ["lines.min_points=9"])
    assert cfg.sensor.a == 0.05  # file over preset
    assert cfg.sensor.b == PRESETS["sick_lms_1deg"].config["sensor"]["b"]  # preset over default
    assert cfg.lines.min_points == 9  # --set over everything


def test_none_and_forced_presets():
    assert resolve_config(SAMPLES / "intel_cut.clf", None, ["input.laser_preset=none"]) == load_config(
        None, ["input.laser_preset=none"]
    )
    forced = resolve_config(SAMPLES / "intel_cut.clf", None, ["input.laser_preset=hokuyo_270deg"])
    assert forced.sensor.model == "piecewise" and forced.input.laser_preset == "hokuyo_270deg"
    with pytest.raises(ConfigError, match="did you mean 'hokuyo_270deg'"):
        resolve_config(SAMPLES / "intel_cut.clf", None, ["input.laser_preset=hokuyo_270"])


def test_shipped_yaml_copies_match_the_built_in_presets():
    sys.path.insert(0, str(ROOT / "configs"))
    from regenerate_default import laser_yaml

    for name in PRESETS:
        assert (ROOT / "configs" / "lasers" / f"{name}.yaml").read_text() == laser_yaml(name)
        cfg = load_config(ROOT / "configs" / "lasers" / f"{name}.yaml")  # usable as --config
        assert cfg.input.laser_preset == "auto"


def test_presets_describe_sensors_not_robots():
    """A preset holds a sensor's noise model and extraction settings; beams that see a robot's body
    and its laser mount belong to that robot's config (configs/mines.yaml for the Mines rover)."""
    for name, preset in PRESETS.items():
        robot = {"skip_beams_start", "skip_beams_end", "laser"} & set(preset.config.get("input", {}))
        assert not robot, (name, robot)


def test_mines_config_through_the_cli(tmp_path, monkeypatch):
    """`config` on the Mines sample: the URG-04LX preset alone keeps every beam; with
    configs/mines.yaml the rover's 70 body beams at each end go and its laser sits 0.145 m ahead.
    A run with it says where the mount came from (the config: the bag has no tf)."""
    import json

    import yaml
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    monkeypatch.chdir(ROOT)
    log = "sample_logs/mines_exp3_cut.bag"
    runner = CliRunner()
    sensor_only = yaml.safe_load(runner.invoke(cli, ["config", log]).stdout)["input"]
    assert sensor_only["laser_preset"] == "hokuyo_urg04lx"
    assert (sensor_only["skip_beams_start"], sensor_only["skip_beams_end"], sensor_only["laser"]["x"]) == (
        0,
        0,
        None,  # not set: the built-in 0, warned by a run
    )
    mines = yaml.safe_load(runner.invoke(cli, ["config", log, "--config", "configs/mines.yaml"]).stdout)[
        "input"
    ]
    assert mines["laser_preset"] == "hokuyo_urg04lx"
    assert (mines["skip_beams_start"], mines["skip_beams_end"], mines["laser"]["x"]) == (70, 70, 0.145)
    out = tmp_path / "run"
    args = ["run", log, "--config", "configs/mines.yaml", "--max-scans", "30", "--out", str(out), "-q"]
    assert runner.invoke(cli, args).exit_code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["input"]["laser_to_base"] == [0.145, 0.0, 0.0]
    assert summary["input"]["laser_to_base_source"] == "config"


def test_a_pinned_preset_another_lasers_scans_do_not_fit_is_warned_about(caplog):
    """A config `cornerslam config` wrote for a SICK log names its preset; run on a Hokuyo log it gave
    the SICK's sensor model and extraction settings without a word (a hostile-user probe)."""
    pinned = ["input.laser_preset=sick_lms_1deg"]
    with caplog.at_level("WARNING"):
        cfg = resolve_config(SAMPLES / "mines_exp3_cut.bag", None, pinned)
    assert cfg.input.laser_preset == "sick_lms_1deg"  # pinned is pinned: warned, not changed
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(said) == 1 and "'hokuyo_urg04lx' fits them" in said[0], said
    assert "682 beams 0.352° apart" in said[0]
    caplog.clear()
    with caplog.at_level("WARNING"):
        resolve_config(SAMPLES / "intel_cut.clf", None, pinned)  # its own laser: nothing to say
    assert not [r for r in caplog.records if r.levelname == "WARNING"]
    # info says so too, as a note (a probe: it showed "preset sick_lms_1deg" beside 682 beams, silent)
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    runner = CliRunner()
    res = runner.invoke(cli, ["info", str(SAMPLES / "mines_exp3_cut.bag"), "--set", pinned[0]])
    assert "note:      input.laser_preset 'sick_lms_1deg' is for 180/181 beams" in res.stdout, res.output
    assert "'hokuyo_urg04lx' fits them" in res.stdout
    res = runner.invoke(cli, ["info", str(SAMPLES / "intel_cut.clf"), "--set", pinned[0]])
    assert "input.laser_preset 'sick_lms_1deg' is for" not in res.stdout


def test_a_pinned_preset_is_not_warned_about_for_its_own_laser_cropped(tmp_path, caplog):
    """A 270° laser's driver publishing 180° of it (fewer beams, the same spacing) is that laser: its
    preset pinned is how such a user gets its sensor model (auto finds none), not a mistake."""
    from cornerslam_cli.simulate import simulate_log

    log = tmp_path / "cropped.mcap"
    simulate_log(log, rate=1.0, beams=721, fov=math.radians(180.0))  # 0.25° apart, as hokuyo_270deg
    with caplog.at_level("WARNING"):
        resolve_config(log, None, ["input.laser_preset=hokuyo_270deg"])
    assert not [r for r in caplog.records if r.levelname == "WARNING"]


def test_a_config_file_over_the_preset_is_warned_of_and_the_default_file_is_not_over_it(tmp_path, caplog):
    """configs/default.yaml listed every key, the sensor model's among them, and a file is layered over
    the laser preset: `--config configs/default.yaml` on a SICK log ran the Hokuyo model while saying the
    SICK preset was used (a probe: 358 → 306 landmarks on aces). Now that file leaves the preset's keys
    commented out, and a file that sets one to another value than the preset's is warned of."""
    import logging

    log = SAMPLES / "intel_cut.clf"  # sick_lms_1deg
    with caplog.at_level(logging.WARNING, logger="cornerslam"):
        assert resolve_config(log, ROOT / "configs" / "default.yaml") == resolve_config(log, None)
    assert "over the laser preset" not in caplog.text
    mine = tmp_path / "mine.yaml"
    mine.write_text("sensor:\n  model: piecewise\n  a: 0.01\nlines:\n  min_points: 6\nekf:\n  alpha1: 0.2\n")
    with caplog.at_level(logging.WARNING, logger="cornerslam"):
        cfg = resolve_config(log, mine)
    assert cfg.sensor.model == "piecewise" and cfg.lines.min_points == 6  # the file's, as before
    assert (
        f"config file '{mine}' sets sensor.model (line 2), lines.min_points (line 5) over the laser preset "
        "'sick_lms_1deg' chosen for this log's scans, and the file's values are used (leave them out of "
        "the file for the preset's, or set input.laser_preset: none)"
    ) in caplog.text  # (sensor.a: the preset's own value, no news)
    caplog.clear()  # a --set of the key wins over the file: only the other is the file's
    with caplog.at_level(logging.WARNING, logger="cornerslam"):
        cfg = resolve_config(log, mine, ["sensor.model=linear", "input.laser_preset=sick_lms_1deg"])
    assert cfg.sensor.model == "linear"
    assert (
        "sets lines.min_points (line 5) over the laser preset 'sick_lms_1deg', and the file's value is"
        in (caplog.text)
    )
