"""Ctrl-C (SIGINT) and kill (SIGTERM) during ``cornerslam run``, in a real subprocess: the previous
complete output directory survives untouched (or there is none), no hidden staging directory is
left behind, and stderr says what happened."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cornerslam_cli.report.ownership import MARKER, mark_output
from cornerslam_cli.simulate import simulate_log

CMD = [sys.executable, "-c", "from cornerslam_cli.cli import main; main()"]


@pytest.fixture(scope="module")
def long_log(tmp_path_factory) -> Path:
    """A simulated lap at 10 Hz (~1,300 scans): a run takes well over the few seconds we wait."""
    path = tmp_path_factory.mktemp("int") / "lap.mcap"
    simulate_log(path, seed=1, rate=10.0, beams=271)
    return path


def staging_dirs(out: Path) -> list[str]:
    return [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]


@pytest.mark.parametrize(
    "sig, previous", [(signal.SIGINT, False), (signal.SIGINT, True), (signal.SIGTERM, True)]
)
def test_interrupted_run_leaves_the_previous_output_or_none(long_log, tmp_path, sig, previous):
    out = tmp_path / "out"
    if previous:
        out.mkdir()
        (out / "summary.json").write_text('{"previous": true}\n')
        mark_output(out, "run")  # a previous cornerslam output: the run may replace it
    proc = subprocess.Popen(
        [*CMD, "run", str(long_log), "--out", str(out), "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 30
    while not staging_dirs(out) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)  # wait until the run is writing its staged output ...
    assert staging_dirs(out), "the run never started writing"
    time.sleep(1.0)  # ... and well into the loop
    assert proc.poll() is None, "the run finished before the signal: make the log longer"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    expected_code, word = (130, "interrupted") if sig == signal.SIGINT else (143, "terminated")
    assert proc.returncode == expected_code, err
    assert err.strip().splitlines()[-1].startswith(f"{word}: no output written"), err
    assert "Traceback" not in err
    assert staging_dirs(out) == []
    if previous:
        assert sorted(p.name for p in out.iterdir()) == [MARKER, "summary.json"]
        assert (out / "summary.json").read_text() == '{"previous": true}\n'
    else:
        assert not out.exists()


@pytest.mark.parametrize(
    ("terminated", "code", "word"), [(True, 143, "terminated"), (False, 130, "interrupted")]
)
def test_a_signal_raised_inside_a_compiled_kernel_still_exits_as_the_signal(terminated, code, word):
    """Numba hands a signal handler's exception back wrapped in SystemErrors ("returned a result with an
    exception set"), as the CI saw once when SIGTERM came during the line fit: it must not read as a bug."""
    import click
    from click.testing import CliRunner

    from cornerslam_cli.cli import _Cli, _Terminated

    def kernel_interrupted():
        try:
            try:
                raise _Terminated if terminated else KeyboardInterrupt
            except KeyboardInterrupt as e:
                raise SystemError("<function _numba_unpickle> returned a result with an exception set") from e
        except SystemError as e:
            raise SystemError(
                "CPUDispatcher(<function second_pass>) returned a result with an exception set"
            ) from e

    group = _Cli()
    group.add_command(click.Command("work", callback=kernel_interrupted))
    res = CliRunner().invoke(group, ["work"])
    assert res.exit_code == code and res.output.startswith(f"{word}: no output written"), res.output
    assert "internal error" not in res.output


@pytest.mark.parametrize(("command", "said"), [("info", ""), ("run", ": no output written")])
def test_a_command_that_writes_no_file_is_not_said_to_have_written_none(command, said):
    """`config`, `info` and `evaluate` only print: "interrupted: no output written (an earlier output
    there, if any, is kept)" had a user look for an output (a probe). They say the word alone."""
    import click
    from click.testing import CliRunner

    from cornerslam_cli.cli import _Cli

    def stopped():
        raise KeyboardInterrupt

    group = _Cli()
    group.add_command(click.Command(command, callback=stopped))
    res = CliRunner().invoke(group, [command])
    assert res.exit_code == 130 and res.output.startswith(f"interrupted{said}"), res.output
    assert len(res.output.splitlines()) == 1


def test_ctrl_c_while_the_command_is_still_importing_exits_130_in_one_line():
    """The console script's entry (cornerslam_cli.entry): a Ctrl-C that lands while the command line's
    modules are imported (here: raised by the import of cornerslam_cli.cli itself, in a fresh
    interpreter) gives exit 130 and the one line a running command gives, not a traceback and exit 1."""
    code = (
        "import sys\n"
        "class Ctrl_c:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'cornerslam_cli.cli':\n"
        "            raise KeyboardInterrupt\n"
        "sys.meta_path.insert(0, Ctrl_c())\n"
        "from cornerslam_cli.entry import main\n"
        "main()\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 130, res.stderr
    assert res.stderr == "interrupted: no output written (an earlier output there, if any, is kept)\n"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_the_interpreter_shuts_down_after_the_command_changes_nothing(sig):
    """Ctrl-C just after a run ended — its output committed, its report printed — killed the process
    without a word while the interpreter shut down (exit 130 after a complete output, whose README says
    "the previous output is kept"), or printed "Exception ignored … KeyboardInterrupt" (a hostile-user
    probe). The command's exit status now stands: here the signal lands from an atexit hook."""
    code = (
        "import atexit, os, signal\n"
        f"atexit.register(lambda: os.kill(os.getpid(), {int(sig)}))\n"
        "from cornerslam_cli.entry import main\n"
        "main()\n"
    )
    res = subprocess.run([sys.executable, "-c", code, "config"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, (res.returncode, res.stderr)
    import dataclasses

    import yaml

    from cornerslam_cli.config import Config

    assert res.stderr == "" and yaml.safe_load(res.stdout).keys() == dataclasses.asdict(Config()).keys()
