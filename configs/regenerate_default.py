"""Rewrite configs/default.yaml and configs/lasers/*.yaml from the built-in defaults and presets
(tests/test_config.py and tests/test_lasers.py check they agree).

    python configs/regenerate_default.py
"""

import argparse
from pathlib import Path

import yaml

from cornerslam_cli.config import Config
from cornerslam_cli.lasers import PRESET_NOTE, PRESETS, dump_for_any_laser

HERE = Path(__file__).resolve().parent
HEADER = """\
# cornerslam default configuration: every key with its built-in default.
# A config file may set any subset of these; --set section.key=value overrides on the command line.
# Angles in radians, lengths in metres. See the docstrings in cornerslam_cli/*/params.py and
# cornerslam_cli/config.py for what each key does, and docs/tuning.md for how to tune them.
"""


def laser_yaml(name: str) -> str:
    p = PRESETS[name]
    head = (
        f"# Laser preset '{name}': {p.description}.\n"
        f"# Chosen automatically for scans of {'/'.join(map(str, p.beams))} beams "
        f"{p.increment_deg:g}° apart\n"
        "# (input.laser_preset: auto); usable as --config, or copy it into your own config.\n"
    )
    return head + yaml.safe_dump(p.config, sort_keys=False)


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__.split("\n\n")[0]).parse_args()  # (--help writes nothing)
    (HERE / "default.yaml").write_text(HEADER + PRESET_NOTE + dump_for_any_laser(Config()))
    (HERE / "lasers").mkdir(exist_ok=True)
    for name in PRESETS:
        (HERE / "lasers" / f"{name}.yaml").write_text(laser_yaml(name))
    print(f"wrote {HERE / 'default.yaml'} and {len(PRESETS)} laser presets")
