"""Config loading: defaults, YAML, overrides, and the exit-2 errors that name the key."""

from pathlib import Path

import pytest

from cornerslam_cli.config import Config, dump_config, load_config, set_leaves
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
        ("association.pca.grup_size=5", "did you mean 'association.pca.group_size'"),
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


@pytest.mark.parametrize(
    "override, hint",
    [
        ("refine=true", "(did you mean 'graph.refine'?)"),  # was 'lines', the closest top-level name
        ("association.group_size=5", "(did you mean 'association.pca.group_size'?)"),  # inside the section
        ("enabled=false", "(did you mean 'scan_match.enabled' or 'submaps.enabled' or 'loops.enabled'?)"),
        ("lnes.min_points=3", "(did you mean 'lines'?)"),  # no key further down is named so: the closest
        ("graph.group_size=3", "(valid keys: kernel, "),  # (one in another section is not looked for)
    ],
)
def test_an_unknown_key_suggests_a_key_further_down_of_that_name(override, hint):
    """`--set refine=true` suggested 'lines' (difflib over the top-level names): a key further down
    whose last part is the name given is the likelier meaning."""
    with pytest.raises(ConfigError) as e:
        load_config(None, [override])
    assert hint in str(e.value), str(e.value)


@pytest.mark.parametrize(
    "text, line, fragment",
    [
        ("ekf:\n  alpha1: -3\n", 2, "config key 'ekf.alpha1' = -3.0 is out of range"),
        (
            "association:\n  alpha: 0.01\n\nscan_match:\n  window: abc\n",
            5,
            "'scan_match.window' must be an integer",
        ),
        ("ekf:\n  alhpa1: 0.1\n", 2, "unknown config key 'ekf.alhpa1'"),
        # keys YAML reads as null or a boolean (the line was lost: the key looked up as written)
        ("ekf:\n  alpha1: 0.1\nnull: 3\n", 3, "unknown config key 'None'"),
        ("ekf:\n  alpha1: 0.1\n  true: 3\n", 3, "unknown config key 'ekf.True'"),
        # keys a YAML merge key (<<) brings in: where they are written (they had no place)
        ("<<: {association: {alpha: 5}}\n", 1, "'association.alpha' = 5.0 is out of range"),
        ("association:\n  <<: {alfa: 0.5}\n", 2, "unknown config key 'association.alfa'"),
        ("ekf: &b {alpha1: 0.1}\nassociation:\n  <<: [*b]\n", 1, "unknown config key 'association.alpha1'"),
        ("association:\n  <<: {alpha: 0.01}\n  alpha: 7\n", 3, "'association.alpha' = 7.0"),  # its own wins
        # a date (it was named datetime.date(2024, 1, 1), with no line)
        ("ekf:\n  alpha1: 0.1\n  2024-01-01: 3\n", 3, "unknown config key 'ekf.2024-01-01'"),
        ("lines:\n  min_points: 6\nassociation: 3\n", 3, "'association' must be a mapping"),
    ],
)
def test_a_bad_value_in_a_file_is_reported_at_its_file_and_line(tmp_path, text, line, fragment):
    p = tmp_path / "mine.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value).startswith(f"config file '{p}' line {line}: ")
    assert fragment in str(e.value)


def test_a_bad_value_given_with_set_names_the_set_even_over_a_file(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("scan_match:\n  window: 12\n")
    with pytest.raises(ConfigError) as e:
        load_config(p, ["association.alpha=0.01", "scan_match.window=ab"])
    assert str(e.value).startswith("--set 'scan_match.window=ab': config key 'scan_match.window' must be an")
    with pytest.raises(ConfigError) as e:  # a section replaced by a scalar
        load_config(None, ["ekf=3"])
    assert str(e.value).startswith("--set 'ekf=3': config key 'ekf' must be a mapping")
    # a key the file sets and --set does not: the file's line, though --set set a sibling
    p.write_text("scan_match:\n  window: 12\n  gate: -1\n")
    with pytest.raises(ConfigError) as e:
        load_config(p, ["scan_match.window=20"])
    assert str(e.value).startswith(f"config file '{p}' line 3: config key 'scan_match.gate'")


def test_a_set_whose_value_starts_a_yaml_comment_says_so():
    """`--set input.scan_topic=#x`: YAML reads a comment, no value (before: "must be a string, got
    None"); quoted, it is the text."""
    with pytest.raises(ConfigError) as e:
        load_config(None, ["input.scan_topic=#x"])
    assert str(e.value) == (
        "--set 'input.scan_topic=#x': '#' starts a YAML comment, so the value would be empty "
        "(quote it if it is the value: --set \"input.scan_topic='#x'\")"
    )
    assert load_config(None, ["input.scan_topic='#x'"]).input.scan_topic == "#x"


def test_a_bad_value_from_neither_a_file_nor_set_is_reported_as_it_was():
    # a laser preset's layer is ours, not the user's: no place to point at (a bad one is a bug)
    with pytest.raises(ConfigError) as e:
        load_config(None, [], base={"ekf": {"alpha1": -1}})
    assert str(e.value).startswith("config key 'ekf.alpha1' = -1.0 is out of range")


def test_a_check_across_a_sections_keys_names_one_place_or_none(tmp_path):
    # scan_match's adapt_min_samples must not exceed adapt_window: which key is wrong is not known, so
    # the error names where the section's keys were given only when that is one place
    p = tmp_path / "mine.yaml"
    p.write_text("scan_match:\n  adapt_min_samples: 1000\n")
    check = "config section 'scan_match': adapt_min_samples"

    def error(path, sets):
        with pytest.raises(ConfigError) as e:
            load_config(path, sets)
        return str(e.value)

    assert error(p, []).startswith(f"config file '{p}' line 1: {check}")
    assert error(None, ["scan_match.adapt_window=1"]).startswith(
        f"--set 'scan_match.adapt_window=1': {check}"
    )
    assert error(None, ["scan_match={adapt_window: 1}"]).startswith(
        f"--set 'scan_match={{adapt_window: 1}}': {check}"
    )
    # an unrelated --set in the section is not the place: the file's value or another --set may be
    assert error(p, ["scan_match.window=10"]).startswith(check)
    assert error(None, ["scan_match.adapt_window=1", "scan_match.window=3"]).startswith(check)


def test_a_key_holding_a_quote_is_located_at_its_set(tmp_path):
    p = tmp_path / "mine.yaml"
    p.write_text("ekf:\n  alpha1: 0.1\n")
    with pytest.raises(ConfigError) as e:
        load_config(p, ["ekf'x=1"])
    assert str(e.value).startswith("--set 'ekf'x=1': unknown config key 'ekf'x'")


@pytest.mark.parametrize(
    "text", ["/\U0001f600", "caf\u00e9", "a'b\"c\\d", "a\nb\tc", "a\x7fb\x85\ufeff", "\udcff", "yes", "1:30"]
)
def test_yaml_quoted_reads_back_as_the_text(text):
    from cornerslam_cli.config import parse_override, yaml_quoted

    assert parse_override(f"input.scan_topic={yaml_quoted(text)}") == (["input", "scan_topic"], text)


def test_a_bad_laser_preset_is_located(tmp_path):
    from cornerslam_cli.lasers import resolve_config

    p = tmp_path / "mine.yaml"
    p.write_text("ekf:\n  alpha1: 0.1\ninput:\n  laser_preset: nope\n")
    with pytest.raises(ConfigError) as e:
        resolve_config(None, p)
    assert str(e.value).startswith(f"config file '{p}' line 4: config key 'input.laser_preset' = 'nope'")
    with pytest.raises(ConfigError) as e:
        resolve_config(None, p, ["input.laser_preset=foo"])
    assert str(e.value).startswith("--set 'input.laser_preset=foo': config key 'input.laser_preset' = 'foo'")


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
    ("text", "key", "got", "line"),
    [
        ("ekf: 5\n", "ekf", "5", 1),
        ("ekf: [1, 2]\n", "ekf", "[1, 2]", 1),
        ("input:\n  laser: x\n", "input.laser", "'x'", 2),
    ],
)
def test_a_section_given_as_a_scalar_or_list_is_refused_naming_the_file_and_key(
    tmp_path, text, key, got, line
):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value).startswith(
        f"config file '{p}' line {line}: section '{key}' must be a mapping of its keys, got {got}"
    )


# ---------------------------------------------------------------------------- YAML 1.1 base-60 and octal
SIXTY = ("a base-60 number", "write the number itself, in seconds for a time")


def octal(decimal: str) -> tuple[str, str]:
    return "an octal number", f"write it without leading zeros ({decimal})"


@pytest.mark.parametrize(
    ("line", "key", "text", "read_as", "what"),
    [
        ("ekf:\n  alpha1: 1:30\n", "ekf.alpha1", "1:30", "90", SIXTY),
        ("keyframes:\n  max_interval: 1:02:03\n", "keyframes.max_interval", "1:02:03", "3723", SIXTY),
        ("input:\n  scan_time_offset: -1:30.5\n", "input.scan_time_offset", "-1:30.5", "-90.5", SIXTY),
        ("input:\n  odom_frame: 2:15\n", "input.odom_frame", "2:15", "135", SIXTY),  # a string key too
        ("loops:\n  min_gap: [1:30]\n", "loops.min_gap[0]", "1:30", "90", SIXTY),
        ("scan_match:\n  window: 010\n", "scan_match.window", "010", "8", octal("10")),
        ("submaps:\n  max_steps: 0300\n", "submaps.max_steps", "0300", "192", octal("300")),
        ("input:\n  laser:\n    x: -0_10\n", "input.laser.x", "-0_10", "-8", octal("-10")),  # a float key
        ("input:\n  odom_frame: 017\n", "input.odom_frame", "017", "15", octal("17")),  # a string key
        ("loops:\n  min_gap: [00]\n", "loops.min_gap[0]", "00", "0", octal("0")),
    ],
)
def test_a_number_yaml_reads_unlike_it_looks_is_refused_naming_the_file_key_and_text(
    tmp_path, line, key, text, read_as, what
):
    """YAML 1.1 (PyYAML) reads `1:30` as 90 (a time written as minutes:seconds) and an integer with a
    leading zero as octal (`window: 010` became 8, `--set submaps.max_steps=0300` 192), silently. Both
    refused, in a file and in --set (010 may mean 8 or 10: not read either way)."""
    kind, fix = what
    p = tmp_path / "c.yaml"
    p.write_text("# a config\n" + line)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == (
        f"config file '{p}' line {line.count(chr(10)) + 1}: config key '{key}' = {text} is {kind} "
        f"to YAML 1.1, read as {read_as} ({fix}, or quote it ('{text}') if it is text)"
    )
    dotted = key.split("[")[0]
    with pytest.raises(ConfigError) as e:
        load_config(None, [f"{dotted}={text}"])  # --set likewise, naming the --set as other errors do
    assert str(e.value).startswith(f"--set '{dotted}={text}': config key '{dotted}' = {text} is {kind}")


@pytest.mark.parametrize(
    ("setting", "want"),
    [
        ("input.laser.x=0x10", 16.0),  # hex is not ambiguous: read as YAML 1.1 reads it
        ("scan_match.window=0x10", 16),
        ("input.laser.x=00.5", 0.5),  # a float with a leading zero is decimal to YAML 1.1 too
        ("input.laser.x=010.5", 10.5),
        ("input.laser.x=+09.5", 9.5),
        ("input.laser.x=0e0", 0.0),
        ("input.laser.x=0", 0.0),
        ("input.laser.x='010'", "refused"),  # text where a number is expected
    ],
)
def test_numbers_with_a_leading_zero_that_yaml_reads_as_written(setting, want):
    key = setting.split("=")[0]
    if want == "refused":
        with pytest.raises(ConfigError, match="must be a number"):
            load_config(None, [setting])
        return
    cfg = load_config(None, [setting]).to_dict()
    got = cfg[key.split(".")[0]]
    for k in key.split(".")[1:]:
        got = got[k]
    assert got == want and type(got) is type(want)


@pytest.mark.parametrize(
    ("setting", "kind"), [("scan_match.window=08", "an integer"), ("input.laser.x=09", "a number")]
)
def test_a_leading_zero_yaml_reads_as_text_says_to_drop_it(setting, kind):
    """08 and 09 have no octal digits: YAML 1.1 reads them as text, refused where a number is expected,
    with the same advice as 010."""
    key, text = setting.split("=")
    with pytest.raises(ConfigError) as e:
        load_config(None, [setting])
    assert str(e.value).endswith(
        f"config key '{key}' must be {kind}, got '{text}' (write it without leading zeros ({text[1:]}))"
    )


def test_base_60_text_quoted_is_text_and_every_other_scalar_reads_as_safe_load_reads_it(tmp_path):
    import yaml

    from cornerslam_cli.config import read_config_file

    p = tmp_path / "c.yaml"
    p.write_text("input:\n  odom_frame: '1:30'\n")
    assert load_config(p).input.odom_frame == "1:30"
    assert load_config(None, ["input.odom_frame='1:30'"]).input.odom_frame == "1:30"
    # a colon that YAML 1.1 does not read as a number stays text, as does a leading zero that it does not
    # read as octal (0, a float, 08); every other form is untouched
    text = (
        "a: [0:30, 1:60, 12:5a, 0x1F, 0o17, 0, 0_, 00.5, 017.5, 08, 0b101, 1_000, +12, 1e3, 1.5e3, 1.5, "
        ".5, -.5, "
        ".inf, -.Inf, .nan, yes, off, ~, null, 2001-12-14, '2001-12-14 21:59:43.10', 2001-12-14 21:59:43.10, "
        "'1:30', \"1:30\", a:b, 'x', 190, -3]\n"
    )
    p.write_text(text)
    mine, theirs = read_config_file(p)["a"], yaml.safe_load(text)["a"]
    assert [type(v) for v in mine] == [type(v) for v in theirs]
    assert [repr(v) for v in mine] == [repr(v) for v in theirs]


def test_shipped_configs_read_exactly_as_yaml_safe_load_reads_them():
    import yaml

    from cornerslam_cli.config import read_config_file

    paths = sorted((ROOT / "configs").rglob("*.yaml"))
    assert len(paths) >= 7
    for p in paths:  # (a section of comments only, default.yaml's sensor, is read as an empty one)
        mine, theirs = read_config_file(p), yaml.safe_load(p.read_text())
        theirs = {k: {} if v is None else v for k, v in theirs.items()}
        assert mine == theirs and repr(mine) == repr(theirs), p


def test_a_runs_summary_json_gives_the_config_that_run_used(tmp_path):
    import json

    cfg = Config().to_dict()
    cfg["scan_match"]["window"] = 7
    summary = {"cornerslam_version": "0", "mode": "submaps", "counts": {"steps": 3}, "config": cfg}
    p = tmp_path / "summary.json"
    p.write_text(json.dumps(summary, indent=1))
    assert load_config(p).scan_match.window == 7
    cfg["ekf"]["alpha1"] = -3.0  # a bad value in it is named at its line, as the run's summary
    p.write_text(json.dumps(summary, indent=1))
    with pytest.raises(
        ConfigError,
        match=r"summary\.json' \(the config section of a run's summary\.json\) line \d+: "
        r"config key 'ekf.alpha1'",
    ):
        load_config(p)


def test_an_unknown_associator_in_a_config_file_names_the_file_and_line(tmp_path):
    """`association.method: jbcc` in --config FILE: the error said only "unknown associator 'jbcc'",
    naming neither the file nor the key (as a bad input.laser_preset in it does)."""
    from cornerslam_cli.lasers import resolve_config

    p = tmp_path / "mine.yaml"
    p.write_text("ekf:\n  alpha1: 0.1\nassociation:\n  method: jbcc\n")
    with pytest.raises(ConfigError) as e:
        resolve_config(None, p)
    assert str(e.value) == (
        f"config file '{p}' line 4: config key 'association.method' = 'jbcc' is not an associator "
        "(did you mean 'jcbb'? Choices: icnn, jcbb, pca)"
    )
    with pytest.raises(ConfigError) as e:
        resolve_config(None, p, ["association.method=pcaa"])
    assert str(e.value).startswith("--set 'association.method=pcaa': config key 'association.method'")


def test_a_set_of_a_mapping_merges_into_the_section_as_the_file_does(tmp_path):
    """`--set 'scan_match={enabled: false}'` replaced the whole section: the config file's (and the
    laser preset's) other scan_match keys went back to the defaults, silently (`--set 'sensor={}'`
    undid the preset's sensor model). It sets the keys it names, as the file does over the preset,
    and an error in a key it does not name is not blamed on it."""
    p = tmp_path / "mine.yaml"
    p.write_text("scan_match:\n  window: 7\n")
    cfg = load_config(p, ["scan_match={enabled: false}"])
    assert cfg.scan_match.window == 7 and cfg.scan_match.enabled is False
    assert load_config(None, ["sensor={}"], base={"sensor": {"model": "linear"}}).sensor.model == "linear"
    p.write_text("scan_match:\n  window: 0\n")
    with pytest.raises(ConfigError) as e:
        load_config(p, ["scan_match={enabled: false}"])
    assert str(e.value).startswith(f"config file '{p}' line 2: config key 'scan_match.window' = 0")
    with pytest.raises(ConfigError) as e:
        load_config(p, ["scan_match={window: 0}"])
    assert str(e.value).startswith("--set 'scan_match={window: 0}': config key 'scan_match.window' = 0")


def test_a_check_across_the_keys_a_set_of_a_mapping_names_is_located_at_it():
    """--set 'scan_match={adapt_min_samples: 50, adapt_window: 10}' breaks a check across the two keys it
    sets: the error names that --set, as before 14090b8 (which split a mapping into its keys, each
    counted as a place of its own, so two keys of one --set were "several places": no place named)."""
    text = "scan_match={adapt_min_samples: 50, adapt_window: 10}"
    with pytest.raises(ConfigError) as e:
        load_config(None, [text])
    assert str(e.value).startswith(f"--set '{text}': config section 'scan_match': adapt_min_samples = 50")
    with pytest.raises(ConfigError) as e:  # two --sets: either may be the mistake, neither is named
        load_config(None, ["scan_match.adapt_min_samples=50", "scan_match.adapt_window=10"])
    assert str(e.value).startswith("config section 'scan_match'")


def test_a_key_given_twice_in_a_set_mapping_is_named():
    """As in a file (it was taken as a string: "'grid' must be a mapping, got '{…}'")."""
    with pytest.raises(ConfigError) as e:
        load_config(None, ["grid={resolution: 0.1, resolution: 0.2}"])
    head = "--set 'grid={resolution: 0.1, resolution: 0.2}': key 'resolution' is given twice"
    assert str(e.value).startswith(head)
    assert load_config(None, ["input.scan_topic=a: b: c"]).input.scan_topic == "a: b: c"  # not YAML: text


@pytest.mark.parametrize(
    "mapping, key",
    [
        ("{1: 3}", "ekf.1"),
        ("{null: 3}", "ekf.None"),
        ("{1.5: 3}", "ekf.1.5"),
        ("{2024-01-01: 3}", "ekf.2024-01-01"),
    ],
)
def test_a_set_mapping_key_yaml_reads_as_no_string_is_an_unknown_key(mapping, key):
    """``--set 'ekf={1: 3}'`` was an internal error (its leaves' dotted names joined the key as a number)."""
    text = f"ekf={mapping}"
    assert [leaf for _, leaf, _ in set_leaves([text])] == [key]
    with pytest.raises(ConfigError) as e:
        load_config(None, [text])
    assert str(e.value).startswith(f"--set '{text}': unknown config key '{key}'")


@pytest.mark.parametrize(
    ("value", "hint"), [("1e7", "10000000"), ("300.0", "300"), ("3.5", None), ("ab", None), ("yes", None)]
)
def test_an_integer_key_given_a_float_says_the_whole_number_to_write(value, hint):
    """`--set grid.max_cells=1e7` said "must be an integer, got '1e7'", as if the user had typed a word
    (YAML 1.1 reads 1e7 as text; a probe): a whole number written as a float is named as one."""
    with pytest.raises(ConfigError) as e:
        load_config(None, [f"grid.max_cells={value}"])
    assert "config key 'grid.max_cells' must be an integer" in e.value.msg
    assert e.value.hint == (f"write it as a whole number: {hint}" if hint else None)


def test_a_dotted_key_in_a_file_is_told_to_nest(tmp_path):
    """`scan_match.window: 5` in a file (the --set form) was an unknown key "did you mean 'scan_match'?"."""
    p = tmp_path / "c.yaml"
    p.write_text("association.pca.group_size: 4\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert "unknown config key 'association.pca.group_size'" in e.value.msg
    assert e.value.hint == "in a file, nest it: 'group_size:' indented under 'pca:' under 'association:'"
