"""Progress and verbosity (issue 17 item 8): the ETA from recent steps, ``compare``'s progress after
extraction, what ``-v`` and ``-vv`` add to the default output."""

import io
import logging
import re
import signal
import subprocess
import sys
import time

from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.options import setup_logging
from cornerslam_cli.report import progress as progress_module
from cornerslam_cli.report.progress import Progress


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_eta_follows_the_recent_step_cost_not_the_average():
    """Steps cost 1 s, then 3 s as the map grows: the ETA is what is left at 3 s a step (the
    average since the start would promise less than half of it)."""
    clock = FakeClock()
    p = Progress("log", True, clock)
    total = 300
    for done in range(1, 151):
        clock.t += 1.0 if done <= 100 else 3.0
        p(done, total)
    assert p.eta(total) == " 450s"  # 150 steps left × 3 s; the whole-run average says 250 s
    for done in range(151, 231):  # faster again (40 s): the ETA follows once the window is past
        clock.t += 0.5
        p(done, total)
    assert p.eta(total) == "  35s"  # 70 steps left × 0.5 s


def test_eta_restarts_with_a_new_unit():
    clock = FakeClock()
    p = Progress("log", True, clock)
    for done in range(1, 11):
        clock.t += 1.0
        p(done, 10)
    p(0, 40, "filter steps")
    assert p.eta(40) == "?"  # no rate for filter steps yet; extraction's is not theirs
    clock.t += 2.0
    p(10, 40, "filter steps")
    assert p.eta(40) == "   6s"


def test_compare_shows_progress_after_extraction(sim_log, tmp_path, monkeypatch):
    monkeypatch.setattr(progress_module, "SHOW_AFTER", 0.0)
    monkeypatch.setattr(progress_module, "EVERY_LOG", 0.0)
    res = CliRunner().invoke(
        cli,
        ["compare", str(sim_log), "--assoc", "icnn,pca", "--out", str(tmp_path / "c"), "--max-scans", "20"],
    )
    assert res.exit_code == 0, res.output
    lines = [line for line in res.stderr.splitlines() if "(compare)" in line]
    assert any(" scans " in line for line in lines)  # extraction
    filter_lines = [line for line in lines if "filter steps" in line]
    n = re.search(r"(\d+)/(\d+) filter steps", filter_lines[-1]).groups()
    assert n[0] == n[1] and int(n[1]) == 2 * 20  # both associators' steps, to the end
    assert len(filter_lines) >= 20  # after every step when run one after another
    # which associator runs (a probe: on a long log nothing said which was slow), the rate not restarted
    doing = [re.search(r"filter steps \((\w+)\)", line)[1] for line in filter_lines]
    assert doing == sorted(doing) and set(doing) == {"icnn", "pca"}


def test_a_run_says_what_it_does_after_its_last_step(sim_log, tmp_path, monkeypatch):
    """After the last scan the bar stood at its count while the run closed loops, smoothed, wrote the
    map and drew the figures: on a long log seconds without a sign (a new-user walkthrough). Each stage
    is said as it begins."""
    monkeypatch.setattr(progress_module, "SHOW_AFTER", 0.0)
    args = ["run", str(sim_log), "--out", str(tmp_path / "r"), "--max-scans", "20", "--plot"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    said = [
        re.search(r"finishing: (.*?) +\d+s$", line)[1]
        for line in res.stderr.splitlines()
        if "finishing" in line
    ]
    assert said == ["the last loop closing and the smoothing", "the map and the tables", "the figures"]


def test_what_runs_now_is_shown_without_restarting_the_rate():
    clock = FakeClock()
    p = Progress("log", True, clock)
    for done, doing in ((0, "icnn"), (10, "icnn"), (20, "pca")):
        p(done, 40, "filter steps", doing)
        clock.t += 1.0
    assert p.eta(40) == "   2s"  # 20 left at 10 a second: the rate spans both


def test_verbose_prints_more_than_the_default(sim_log, tmp_path):
    def stderr(*flags):
        out = tmp_path / f"run{len(flags)}{''.join(flags)}"
        res = CliRunner().invoke(cli, ["run", str(sim_log), "--out", str(out), "--max-scans", "12", *flags])
        assert res.exit_code == 0, res.output
        return res.stderr.splitlines()

    default, v, vv = stderr(), stderr("-v"), stderr("-vv")
    assert not [line for line in default if line.startswith(("INFO", "DEBUG"))]
    info = [line for line in v if line.startswith("INFO:")]
    assert any("laser mount" in line and "sim.mcap" in line for line in info)  # what is read
    assert any(re.search(r"filter pca: \d+ steps, \d+ landmarks", line) for line in info)  # stage totals
    assert not [line for line in v if line.startswith("DEBUG")]
    steps = [line for line in vv if re.match(r"DEBUG: step \d+ \(pca\): \d+ corners", line)]
    assert len(steps) == 12  # every filter step


def test_a_warning_on_a_terminal_clears_the_status_line_first(monkeypatch):
    """On a terminal the status line ends without a newline: a warning logged while it was drawn was
    written after it, on its line ("… 907/910 scans    16s eta    0sWARNING: skipped …"). The line is
    cleared first; the next update draws it again below the warning."""

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    setup_logging(0, False)
    clock = FakeClock()
    p = Progress("log", True, clock)
    clock.t = 3.0
    p(5, 10)
    logging.getLogger("cornerslam.test").warning("a warning")
    clock.t = 4.0
    p(6, 10)
    p.close()
    lines = err.getvalue().split("\n")
    assert lines[0].endswith("\r\033[KWARNING: a warning"), lines
    assert lines[0].split("\r\033[K")[-2].startswith("log [") and "6/10 scans" in lines[1], lines
    assert lines[2:] == [""], lines


def test_a_batch_workers_warning_on_a_terminal_clears_the_status_line_first(monkeypatch):
    """batch --jobs runs its combinations in spawned workers, which have no status line of their own:
    their warnings were written after the parent's line ('… 2 remaining     0s eta    ?WARNING: ground
    truth …'), as run's were before 73415fb."""
    from cornerslam_cli import batch, workers

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(workers, "exit_with_parent", lambda: None)
    monkeypatch.setattr(workers, "stopped_by_parent", lambda: None)
    setup_logging(0, False)  # a spawned worker's basicConfig: the same handler and format
    batch._init_worker(logging.WARNING)
    logging.getLogger("cornerslam.test").warning("a warning")
    assert err.getvalue() == "\r\033[KWARNING: a warning\n"


CALLBACK_WORKER = """
import ctypes, sys, time
from cornerslam_cli import workers
workers.stopped_by_parent()
libc = ctypes.CDLL(None)
CMP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
def slow(a, b):  # Python called back from C, as llvmlite calls Numba's object cache
    time.sleep(0.05)
    return 0
items = (ctypes.c_int * 20)()
try:
    print("ready", flush=True)
    libc.qsort(items, 20, ctypes.sizeof(ctypes.c_int), CMP(slow))
    time.sleep(30)
except SystemExit:
    print("unwound", flush=True)
    raise
"""


def test_a_sigterm_that_lands_in_a_callback_from_c_still_ends_the_worker_quietly():
    """A batch worker's SIGTERM raised SystemExit inside llvmlite's callback (Numba compiling on a fresh
    checkout): C dropped it with a printed traceback, and the worker ran on. It is sent again after
    the callback: the worker unwinds, exits 143, and prints no traceback."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CALLBACK_WORKER], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.5)  # inside qsort's callbacks (20 items: some 60 comparisons of 50 ms)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert "unwound" in out
