"""Shared fixtures: one small simulated log per test session (generated, never shipped)."""

from pathlib import Path

import pytest

from cornerslam_cli.simulate import simulate_log


@pytest.fixture(scope="session")
def sim_log(tmp_path_factory) -> Path:
    """A short simulated office loop: 2 Hz, 541 beams, with sim.gt.tum beside it."""
    out = tmp_path_factory.mktemp("sim") / "sim.mcap"
    simulate_log(out, seed=7, rate=2.0, beams=541)
    return out
