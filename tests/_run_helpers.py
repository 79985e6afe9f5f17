"""Running ``cornerslam run`` in-process for the tests of a run's outputs."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from cornerslam_cli.cli import cli


def run_cli(log: Path, out: Path, *sets: str) -> dict:
    """``cornerslam run LOG --out OUT -q --set …`` through click; its summary.json (exit 0 asserted)."""
    args = ["run", str(log), "--out", str(out), "-q"]
    for s in sets:
        args += ["--set", s]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text())
