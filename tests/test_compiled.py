"""The first run's note: which kernels have no cached compilation yet (features/jit.py, compiled.py)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

import cornerslam_cli
from cornerslam_cli import compiled
from cornerslam_cli.cli import cli
from cornerslam_cli.features import jit

PACKAGE = Path(cornerslam_cli.__file__).resolve().parent


def test_the_list_of_kernel_modules_is_every_module_with_kernels():
    using = {
        "cornerslam_cli." + ".".join(f.relative_to(PACKAGE).with_suffix("").parts)
        for f in PACKAGE.rglob("*.py")
        if re.search(r"^from \.+(features\.)?jit import kernel", f.read_text(), re.M)
    }
    assert using == set(compiled.KERNEL_MODULES)


def test_a_kernel_counts_as_uncached_until_its_first_call(tmp_path, monkeypatch):
    """A kernel in a fresh module has an empty cache; its first call compiles and caches it."""
    (tmp_path / "fresh_kernels.py").write_text(
        "from cornerslam_cli.features.jit import kernel\n\n\n@kernel\ndef twice(x):\n    return 2 * x\n"
    )
    monkeypatch.setattr(jit, "_CACHED", [])
    spec = importlib.util.spec_from_file_location("fresh_kernels", tmp_path / "fresh_kernels.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert jit.uncached() == 1
    assert module.twice(3) == 6
    assert jit.uncached() == 0


def test_run_says_it_compiles_when_the_caches_are_empty_and_not_when_quiet(tmp_path, monkeypatch):
    monkeypatch.setattr(jit, "uncached", lambda: 7)
    log = Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf"
    args = [
        "run",
        str(log),
        "--out",
        str(tmp_path / "o"),
        "--max-scans",
        "20",
        "--set",
        "submaps.enabled=false",
    ]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    assert "compiling 7 numerical kernels for this machine before the first step" in res.stderr
    # and the report says its wall time holds that (a new user read a first run's 97 s as its speed)
    note = "(the wall time includes compiling the numerical kernels: once, later runs use the cache)"
    assert note in res.stdout.splitlines()
    res = CliRunner().invoke(cli, [*args[:3], str(tmp_path / "q"), *args[4:], "-q"])
    assert res.exit_code == 0 and "compiling" not in res.stderr and res.stdout == ""
    monkeypatch.setattr(jit, "uncached", lambda: 0)
    res = CliRunner().invoke(cli, [*args[:3], str(tmp_path / "c"), *args[4:]])
    assert res.exit_code == 0 and "compiling" not in res.stderr + res.stdout


@pytest.mark.parametrize("command", ["run", "compare"])
def test_a_bad_logs_error_comes_alone_even_when_the_caches_are_empty(tmp_path, monkeypatch, command):
    """The note is said after the log's checks: a log without the odometry topic asked for gives its
    one line and exit 2, not a minute's promise first."""
    monkeypatch.setattr(jit, "uncached", lambda: 7)
    log = Path(__file__).resolve().parents[1] / "sample_logs" / "sim_office.mcap"
    res = CliRunner().invoke(cli, [command, str(log), "--out", str(tmp_path / "o"), "--odom-topic", "/nope"])
    assert res.exit_code == 2, res.output
    assert "compiling" not in res.stderr and "has no topic '/nope'" in res.stderr
