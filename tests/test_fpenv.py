"""fpenv: the BLAS kernels and numpy SIMD level a run used, as summary.json records them."""

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from cornerslam_cli import fpenv
from cornerslam_cli.cli import cli

openblas = pytest.mark.skipif(
    not fpenv.blas_kernels() or platform.machine() not in ("x86_64", "AMD64"),
    reason="numpy/scipy not on OpenBLAS, or not x86-64 (OPENBLAS_CORETYPE names differ)",
)


def describe_in(env: dict[str, str]) -> dict:
    """fpenv.describe() of a fresh interpreter started with ``env`` added (kernels are chosen at load)."""
    code = "import json; from cornerslam_cli import fpenv; print(json.dumps(fpenv.describe()))"
    out = subprocess.run(
        [sys.executable, "-c", code], env={**os.environ, **env}, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)


def test_summary_records_the_kernels_of_the_run(sim_log, tmp_path):
    res = CliRunner().invoke(cli, ["run", str(sim_log), "--out", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 0, res.output
    versions = json.loads((tmp_path / "out" / "summary.json").read_text())["versions"]
    assert versions["blas"] == fpenv.describe()["blas"] and versions["blas"]
    assert versions["numpy_simd"] == fpenv.numpy_simd()


@openblas
def test_blas_kernel_is_the_one_openblas_coretype_selects():
    # Nehalem's kernels (SSE4.2) run on every x86-64 CPU since 2008; the default here is another set
    # unless the CPU is a Nehalem, so the name must follow the variable, not the CPU
    got = describe_in({"OPENBLAS_CORETYPE": "Nehalem"})["blas"]
    assert got.split("; ") and all(k.endswith(" Nehalem") for k in got.split("; ")), got
    assert all(k.startswith("OpenBLAS ") for k in got.split("; "))


def test_numpy_simd_follows_npy_disable_cpu_features():
    used = fpenv.simd_targets()
    if not used:
        pytest.skip("numpy dispatches to no SIMD target above its baseline on this CPU")
    assert describe_in({})["numpy_simd"] == " ".join(used)
    capped = describe_in({"NPY_DISABLE_CPU_FEATURES": used[-1]})["numpy_simd"]
    assert capped == (" ".join(used[:-1]) or f"baseline {fpenv.simd_baseline()}")
    none = describe_in({"NPY_DISABLE_CPU_FEATURES": " ".join(used)})["numpy_simd"]
    assert none == f"baseline {fpenv.simd_baseline()}"


def first_scans(src: Path, n: int, dst: Path) -> Path:
    """The CARMEN log ``src`` up to its ``n``-th FLASER line."""
    out, seen = [], 0
    for line in src.read_text().splitlines(keepends=True):
        out.append(line)
        seen += line.startswith("FLASER ")
        if seen == n:
            break
    dst.write_text("".join(out))
    return dst


@openblas
def test_run_is_byte_identical_under_two_blas_kernel_sets(tmp_path):
    """The same log under the Sandybridge and the Haswell OpenBLAS kernels: the same trajectory, to the
    last printed digit. Real laser ranges are quantised (1 cm here), so the scan matcher meets exactly
    equidistant map points; when the last bit decided between them this log parted at step 27."""
    envs = {core: {"OPENBLAS_CORETYPE": core} for core in ("Sandybridge", "Haswell")}
    for core, env in envs.items():
        if not describe_in(env)["blas"].endswith(core):
            pytest.skip(f"this CPU cannot run OpenBLAS's {core} kernels")
    log = first_scans(
        Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf", 60, tmp_path / "i.clf"
    )
    outs = []
    for core, env in envs.items():
        out = tmp_path / core
        cmd = [sys.executable, "-m", "cornerslam_cli", "run", str(log), "--out", str(out), "-q"]
        res = subprocess.run(cmd, env={**os.environ, **env}, capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
        assert json.loads((out / "summary.json").read_text())["versions"]["blas"].endswith(core)
        outs.append((out / "trajectory.csv").read_bytes())
    assert outs[0] == outs[1]
