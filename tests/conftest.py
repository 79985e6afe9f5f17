"""Shared fixtures: one small simulated log per test session (generated, never shipped)."""

from cornerslam_cli.blas import single_threaded_blas

# As the CLI does (cli.py), before numpy is imported: single-threaded BLAS, so in-process runs here
# compute exactly what `cornerslam run` computes.
single_threaded_blas()

import os  # noqa: E402
import signal  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

from cornerslam_cli.simulate import simulate_log  # noqa: E402

# A suite started in the background by a shell without job control (`pytest … &` in a script) inherits
# SIGINT ignored (POSIX), and so would every run it starts: the Ctrl-C tests (test_interrupt.py,
# test_faults_output.py) then saw their runs finish instead of stop. Python's handler, as a foreground
# start has it (the runs started get SIGINT's default, and install theirs).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def sim_log(tmp_path_factory) -> Path:
    """A short simulated office loop: 2 Hz, 541 beams, with sim.gt.tum beside it."""
    out = tmp_path_factory.mktemp("sim") / "sim.mcap"
    simulate_log(out, seed=7, rate=2.0, beams=541)
    return out


def pytest_xdist_auto_num_workers(config) -> int:
    """``-n auto`` (pyproject.toml): the CPUs this process may run on (a container's or taskset's),
    not the host's cores that psutil would count."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
