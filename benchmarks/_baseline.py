"""Another build of cornerslam beside this one, for side-by-side benchmarks in one run.

    with source_tree("main") as src:          # the package sources of a git revision, in a temp dir
        subprocess.run(..., env=build_env(src))   # python -m cornerslam_cli ... runs *that* build

``build_env(ROOT)`` runs this checkout. The other build is imported from ``PYTHONPATH``, which Python
searches before the editable install's finder, with this environment's packages (numpy, scipy, …).
``python -m`` and ``-c`` would put the working directory before ``PYTHONPATH`` — run from this
repository's root, *both* builds imported this checkout (a side-by-side run once reported two builds
with different outputs as byte-identical) — so the environment sets ``PYTHONSAFEPATH`` (Python ≥ 3.11),
and ``build_env`` checks where ``cornerslam_cli`` is imported from before handing it out.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@contextmanager
def source_tree(rev: str) -> Iterator[Path]:
    """The files of git revision ``rev`` of this repository (``git archive``), removed afterwards."""
    with tempfile.TemporaryDirectory(prefix="cornerslam-baseline-") as tmp:
        archive = Path(tmp) / "src.tar"
        subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), rev], check=True)
        with tarfile.open(archive) as tar:
            tar.extractall(Path(tmp) / "src", filter="data")
        yield Path(tmp) / "src"


def build_env(src: Path) -> dict[str, str]:
    """The environment that makes ``python -m cornerslam_cli`` import the package under ``src``."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(src), *filter(None, [env.get("PYTHONPATH")])])
    env["PYTHONSAFEPATH"] = "1"  # not the working directory first (it may be another build's root)
    where = subprocess.run(
        [sys.executable, "-c", "import cornerslam_cli; print(cornerslam_cli.__file__)"],
        env=env, capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    if Path(where).resolve().parent.parent != Path(src).resolve():
        raise RuntimeError(f"the build under {src} imports cornerslam_cli from {where} instead")
    return env


def revision(rev: str = "HEAD") -> str:
    """Short commit hash of ``rev``; HEAD gets "+changes" when the working tree has uncommitted ones."""
    git = ["git", "-C", str(ROOT)]
    head = subprocess.run([*git, "rev-parse", "--short", rev], capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(
        [*git, "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True
    )
    return head + ("+changes" if rev == "HEAD" and dirty.stdout.strip() else "")


def child_json(code: str, *args: str, what: str):
    """Run ``code`` (a Python program: cornerslam with a hook, its record printed as JSON on its last line
    of stdout) as ``python -c code ARGS`` from this repository's root; its record. A child that fails
    (its own exit code, a failed cornerslam run's included) stops the benchmark with ``what`` and the end of
    its stderr."""
    res = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=ROOT)
    if res.returncode != 0:
        raise SystemExit(f"{what}: {res.stderr.strip()[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])
