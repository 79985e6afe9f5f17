"""Rewrite configs/default.yaml from the built-in defaults (tests/test_config.py checks they agree).

    python configs/regenerate_default.py
"""

from pathlib import Path

from cornerslam_cli.config import Config, dump_config

HEADER = """\
# cornerslam default configuration: every key with its built-in default.
# A config file may set any subset of these; --set section.key=value overrides on the command line.
# Angles in radians, lengths in metres. See the docstrings in cornerslam_cli/*/params.py and
# cornerslam_cli/config.py for what each key does.
"""

if __name__ == "__main__":
    out = Path(__file__).with_name("default.yaml")
    out.write_text(HEADER + dump_config(Config()))
    print(f"wrote {out}")
