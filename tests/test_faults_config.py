"""Config faults at unit level (the CLI cases are in tests/fault_corpus.py): every numeric key has a
range that refuses NaN, ±inf and values past either bound while accepting the bounds; YAML alias
bombs are refused fast and in constant memory; error messages quote a short prefix of any value; a
config read from a pipe is read once."""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import threading
import tracemalloc
import typing

import pytest
from fault_corpus import alias_bomb

from cornerslam_cli.config import Config, config_from, load_config, read_config_file
from cornerslam_cli.errors import ConfigError
from cornerslam_cli.lasers import resolve_config
from cornerslam_cli.ranges import Range, RangeError, field_range, num


def numeric_keys(cls: type = Config, prefix: str = "") -> typing.Iterator[tuple[str, type, Range | None]]:
    """(dotted key, int or float, declared range) of every numeric key of the config, at every depth."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            yield from numeric_keys(tp, f"{prefix}{f.name}.")
        elif tp in (int, float):
            yield f"{prefix}{f.name}", tp, field_range(f)


KEYS = list(numeric_keys())
FLOAT_KEYS = [k for k, tp, _ in KEYS if tp is float]


def test_every_numeric_key_has_a_range():
    assert len(KEYS) > 80
    assert [k for k, _, r in KEYS if r is None] == []


def test_the_defaults_and_shipped_configs_are_inside_the_ranges():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "configs"
    for path in [root / "default.yaml", root / "paper.yaml", *sorted((root / "lasers").glob("*.yaml"))]:
        load_config(path)  # raises if a shipped value is outside its range


@pytest.mark.parametrize("value", ["nan", ".nan", "inf", "-inf", ".inf", "1e999", "-Infinity"])
@pytest.mark.parametrize("key", FLOAT_KEYS)
def test_non_finite_numbers_are_refused_naming_the_key(key, value):
    with pytest.raises(ConfigError) as e:
        load_config(None, [f"{key}={value}"])
    assert f"config key '{key}' = " in str(e.value) and "is not a finite number (allowed: " in str(e.value)


def _outside(r: Range, tp: type) -> list:
    """Values just past each bound (past the integer bound for ints)."""
    if tp is int:
        return [int(math.ceil(r.lo)) - 1, int(math.floor(r.hi)) + 1]
    lo = r.lo if r.lo_open else r.lo - max(abs(r.lo), 1.0) * 1e-6
    hi = r.hi if r.hi_open else r.hi + max(abs(r.hi), 1.0) * 1e-6
    return [lo, hi]


def _inside(r: Range, tp: type) -> list:
    """The bounds, or values just inside an open bound."""
    if tp is int:
        return [int(r.lo), int(r.hi)]
    lo = math.nextafter(r.lo, math.inf) if r.lo_open else r.lo
    hi = math.nextafter(r.hi, -math.inf) if r.hi_open else r.hi
    return [lo, hi]


@pytest.mark.parametrize("key, tp, r", KEYS, ids=[k for k, _, _ in KEYS])
def test_values_past_either_bound_are_refused_and_the_bounds_accepted(key, tp, r):
    for v in _outside(r, tp):
        with pytest.raises(ConfigError) as e:
            load_config(None, [f"{key}={v!r}"])
        assert f"config key '{key}' = " in str(e.value) and f"allowed: {r}" in str(e.value)
    for v in _inside(r, tp):
        if (key, v > 100) == ("scan_match.adapt_min_samples", True) or (key, v < 5) == (
            "scan_match.adapt_window",
            True,
        ):
            continue  # adapt_min_samples ≤ adapt_window (defaults 5, 400): a bound across keys, checked below
        cfg = load_config(None, [f"{key}={v!r}"])
        section = cfg
        for part in key.split("."):
            section = getattr(section, part)
        assert section == v


def test_a_range_refuses_nan_and_bools_also_when_the_section_is_built_directly():
    from cornerslam_cli.filter.params import EkfConfig

    for bad in (math.nan, math.inf, True, "0.1", None):
        with pytest.raises(RangeError, match="alpha1 = "):
            EkfConfig(alpha1=bad)
    with pytest.raises(TypeError):
        num(1.0, ge=0.0)  # an upper bound is required
    with pytest.raises(ValueError):
        num(5.0, ge=0.0, le=1.0)  # a default outside its own range


def test_more_samples_to_learn_from_than_the_window_holds_are_refused():
    with pytest.raises(ConfigError, match="adapt_min_samples = 401 exceeds adapt_window = 400"):
        load_config(None, ["scan_match.adapt_min_samples=401"])
    assert load_config(None, ["scan_match.adapt_min_samples=400"])


def test_keys_of_earlier_versions_are_ignored_with_a_warning():
    import io
    import logging

    stream = io.StringIO()
    handler = logging.StreamHandler(stream)  # on the module's logger: the CLI may stop propagation above it
    logger = logging.getLogger("cornerslam.config")
    logger.addHandler(handler)
    level = logger.level
    logger.setLevel(logging.WARNING)  # a CLI test's -q may have raised the level above it
    try:
        cfg = load_config(None, ["scan_match.retry_angle=0.2", "scan_match.alpha1=0.5"])
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    assert cfg == load_config(None)
    text = stream.getvalue()
    assert "'scan_match.retry_angle' is no longer used" in text and "correlative search" in text
    assert "'scan_match.alpha1' is no longer used" in text and "its own covariance" in text


# ---------------------------------------------------------------------------- YAML
def _peak_mib(fn) -> tuple[float, Exception]:
    """(peak traced MiB, the exception) of ``fn()``, which must raise."""
    tracemalloc.start()
    try:
        fn()
    except Exception as e:  # noqa: BLE001 - returned for the caller's checks
        err = e
    else:
        raise AssertionError("no error")
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return peak / 2**20, err


def test_an_alias_bomb_is_refused_in_constant_memory(tmp_path):
    """9 levels of 9 aliases expand to 387 million scalars (GiBs, minutes): refused on the node graph
    before anything is built — tracing < 5 MiB, which no expansion fits in (memory, not time: a timed
    test flakes on a shared machine) — with a one-line message that quotes no value."""
    p = tmp_path / "bomb.yaml"
    p.write_text(alias_bomb(9, 9))
    mib, err = _peak_mib(lambda: load_config(p))
    assert isinstance(err, ConfigError) and "expands to more than 10,000 YAML nodes" in str(err)
    assert mib < 5.0, mib
    assert len(str(err)) < 250 and "lol" not in str(err)
    # the same bomb in one --set value (flow style)
    levels = ["&a0 [" + ", ".join(["lol"] * 9) + "]"]
    levels += [f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    mib, err = _peak_mib(lambda: load_config(None, ["ekf.alpha1=[" + ", ".join(levels) + "]"]))
    assert isinstance(err, ConfigError) and "--set 'ekf.alpha1=[&a0" in str(err)
    assert mib < 5.0 and len(str(err)) < 250


def test_aliases_below_the_bound_are_fine_and_a_merge_key_may_be_overridden(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text(
        "ekf: &e\n  alpha1: 0.02\n  alpha2: 0.03\nscan_match:\n  <<: *e\n  alpha1: 0.001\n  window: 7\n"
    )
    cfg = load_config(p)  # scan_match.alpha1/alpha2 (keys of earlier versions) are ignored with a warning
    assert (cfg.ekf.alpha1, cfg.ekf.alpha2, cfg.scan_match.window) == (0.02, 0.03, 7)


def test_messages_quote_a_short_prefix_of_any_value(tmp_path):
    huge = "x" * 200_000
    value, key = tmp_path / "value.yaml", tmp_path / "key.yaml"
    value.write_text(f"ekf:\n  alpha1: {huge}\n")
    key.write_text(f"ekf:\n  {huge[:1000]}: 1\n")  # YAML limits a key to 1024 characters
    sources = (
        lambda: load_config(value),
        lambda: load_config(key),
        lambda: load_config(None, [f"ekf.{huge}=1"]),
    )
    for source in sources:
        with pytest.raises(ConfigError) as e:
            source()
        assert "xxx..." in str(e.value) and "x" * 100 not in str(e.value) and len(str(e.value)) < 400
    nested = "[" * 50 + "]" * 50
    with pytest.raises(ConfigError) as e:
        load_config(None, [f"ekf.alpha1={nested}"])
    assert len(str(e.value)) < 200


def test_booleans_follow_yaml_1_1(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("ekf:\n  fuse: off\n  joseph: Yes\ncorners:\n  endpoints: ON\n")
    cfg = load_config(p)
    assert (cfg.ekf.fuse, cfg.ekf.joseph, cfg.corners.endpoints) == (False, True, True)
    for bad in ("ekf.fuse=1", "ekf.fuse='yes'", "ekf.fuse=null"):
        with pytest.raises(ConfigError, match="'ekf.fuse' must be true or false"):
            load_config(None, [bad])


@pytest.mark.parametrize("text, value", [("-.5", -0.5), ("+.25", 0.25), (".5", 0.5), ("-.5e-1", -0.05)])
def test_a_fraction_without_a_leading_zero_is_a_number_whatever_its_sign(tmp_path, text, value):
    """YAML 1.1 reads .5 as a number but -.5 as a string: it was refused as 'must be a number'."""
    p = tmp_path / "c.yaml"
    p.write_text(f"input:\n  laser:\n    x: {text}\n")
    assert load_config(p).input.laser.x == value
    assert load_config(None, [f"input.laser.x={text}"]).input.laser.x == value
    with pytest.raises(ConfigError, match="'ekf.initial_capacity' must be an integer, got '-.5'"):
        load_config(None, ["ekf.initial_capacity=-.5"])


def test_non_utf8_names_the_line_and_a_utf8_bom_is_fine(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_bytes(b"# ok\nekf:\n  alpha1: 0.05  # \xb5m\n")
    with pytest.raises(ConfigError, match=r"'.*c.yaml' is not UTF-8 text \(byte 0xb5 at line 3\)"):
        load_config(p)
    p.write_bytes("\ufeffekf:\n  alpha1: 0.07  # µm\n".encode())
    assert load_config(p).ekf.alpha1 == 0.07


def test_a_config_from_a_pipe_is_read_once(tmp_path):
    """resolve_config layers the file twice (without and with the laser preset): a pipe (``--config
    <(...)``) can be read only once, so the file's mapping is read once and reused."""
    fifo = tmp_path / "config.fifo"
    os.mkfifo(fifo)

    def writer():
        with open(fifo, "w") as f:
            f.write("ekf:\n  alpha1: 0.02\ninput:\n  laser_preset: hokuyo_270deg\n")

    t = threading.Thread(target=writer)
    t.start()
    cfg = resolve_config(None, fifo)
    t.join(5)
    assert cfg.ekf.alpha1 == 0.02 and cfg.input.laser_preset == "hokuyo_270deg"
    assert cfg.sensor.sigma_r_near == 0.03  # the preset's layer applied


def test_config_dash_reads_standard_input_and_its_errors_name_it(sim_log, tmp_path):
    """``--config -`` read a file named '-' (a probe: "cannot read config file '-'"); it is standard input,
    read once for every associator of a compare, and an error in it names '-' with its line."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli
    from cornerslam_cli.results import RunSummary

    out = tmp_path / "cmp"
    args = ["compare", str(sim_log), "--config", "-", "--out", str(out), "-q", "--assoc", "icnn,pca"]
    res = CliRunner().invoke(cli, args, input="scan_match:\n  window: 7\n")
    assert res.exit_code == 0, res.output
    assert [RunSummary.read(out / a).config["scan_match"]["window"] for a in ("icnn", "pca")] == [7, 7]
    res = CliRunner().invoke(cli, ["config", "--config", "-"], input="scan_match:\n  windo: 7\n")
    assert res.exit_code == 2
    assert res.stderr.startswith("error: config file '-' line 2: unknown config key 'scan_match.windo'")


def test_dev_null_is_an_empty_config_and_data_is_not_modified():
    assert load_config("/dev/null") == Config()
    data = read_config_file("/dev/null")
    data["ekf"] = {"alpha1": 0.02}
    before = {"ekf": dict(data["ekf"])}
    cfg = config_from(data, ["ekf.alpha1=0.03", "ekf.alpha2=0.04"])
    assert (cfg.ekf.alpha1, cfg.ekf.alpha2) == (0.03, 0.04) and data == before


@pytest.mark.skipif(not os.environ.get("CORNERSLAM_SLOW"), reason="set CORNERSLAM_SLOW=1 (~2 minutes)")
def test_every_allowed_extreme_runs_to_exit_0_or_2(tmp_path):
    """Each numeric key at both ends of its range (and at 1e-300 … 1e-3 above an excluded zero) on the
    corpus log: a user's extreme but allowed value is a result or one error line, never a crash."""
    from click.testing import CliRunner
    from fault_corpus import build_corpus

    from cornerslam_cli.cli import cli

    log, _ = build_corpus(tmp_path / "corpus")["valid"]
    crashes = []
    for key, tp, r in KEYS:
        tiny = [1e-300, 1e-150, 1e-12, 1e-6, 1e-3] if tp is float and r.lo_open and r.lo == 0 else []
        for v in [*_inside(r, tp), *tiny]:
            out = tmp_path / "out"  # a new directory each time: --out never replaces anything
            res = CliRunner().invoke(cli, ["run", str(log), "--out", str(out), "-q", "--set", f"{key}={v!r}"])
            if res.exit_code not in (0, 2):
                crashes.append((key, v, res.output[-200:]))
            shutil.rmtree(out, ignore_errors=True)
    assert crashes == []
