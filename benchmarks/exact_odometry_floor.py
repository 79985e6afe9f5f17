"""With exact odometry, how much of the error is the front end's learner? A diagnostic, not a default.

    python benchmarks/exact_odometry_floor.py [--data DIR] [--jobs 2] [--logs aces-exact,...]

The radish NAME-exact logs give the reference poses themselves as odometry (odometry ATE 0). The front
end (motion/fusion.py) does not know that: it learns the odometry's noise scale k and bias c (odometer
scale, heading drift) from where the scan matches disagree with it, and any disagreement between the
scans and the reference — the reference's own jitter, a scale the ranges and the reference do not share
(panel_diagnostics.md's scale column) — is put on the odometry. Each exact log is run three ways:

* *default*: as `cornerslam run` does;
* *no bias*: the learnt bias c pinned at 0 after every re-estimate (the noise scales still learnt);
* *trusted*: c at 0 and k at its lower bound ``scan_match.adapt_min`` (the odometry all but exact to the
  fusion) from the first re-estimate on — what a front end that knew its odometry was exact would give.

Both pinned runs use knowledge no run has (that the odometry is exact); they bound how much of the exact
logs' ATE the learner's attribution costs, against what the back end (submaps, loop closures, the graph)
adds. Figures: ATE RMSE of the output and of the scan-matched chain. Deterministic on one machine;
writes docs/results/exact_odometry_floor.md.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

# `cornerslam run` with the fusion's learnt state pinned after every re-estimate (argv: k, c, cli args)
PINNED = """
import sys
import numpy as np
from cornerslam_cli.cli import main
from cornerslam_cli.motion import fusion

pin_k, pin_c = sys.argv[1:3]
learn = fusion.OdometryFusion._learn

def pinned(self):
    learn(self)
    if pin_c == "zero":
        self.c = np.zeros(2)
    if pin_k == "min":
        self.k = self.k_min

fusion.OdometryFusion._learn = pinned
main(sys.argv[3:], prog_name="cornerslam")
"""
MODES = {"default": ("learnt", "learnt"), "no bias": ("learnt", "zero"), "trusted": ("min", "zero")}


def run(log: Path, out: Path, mode: str) -> tuple[float, float]:
    k, c = MODES[mode]
    cmd = [sys.executable, "-c", PINNED, k, c, "run", str(log), "--out", str(out), "-q"]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if res.returncode != 0:
        raise SystemExit(f"{log.name} ({mode}) failed: {res.stderr.strip()}")
    a = json.loads((out / "summary.json").read_text())["accuracy"]
    return a["ate"]["rmse"], a["scan_odom_ate"]["rmse"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--logs", default=",".join(f"{b}-exact" for b in BUILDINGS))
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "exact_odometry_floor.md")
    args = ap.parse_args()
    names = args.logs.split(",")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT)
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        futures = {
            (n, m): pool.submit(run, args.data / "radish" / f"{n}.log", Path(tmp) / f"{n}-{i}", m)
            for n in names
            for i, m in enumerate(MODES)
        }
        res = {key: f.result() for key, f in futures.items()}
    lines = [
        "# Exact odometry: what the front end's learner costs",
        "",
        f"`python benchmarks/exact_odometry_floor.py` (see its docstring), commit {commit.stdout.strip()}. "
        "ATE RMSE (m) of the output and, in brackets, of the scan-matched chain. *No bias*: the learnt "
        "odometry bias pinned at 0; *trusted*: also the odometry's learnt noise scale at its lower bound — "
        "both use the knowledge that the odometry is exact, which no run has: diagnostics, not candidates.",
        "",
        "| log | default | no bias | trusted |",
        "|---|---:|---:|---:|",
        *(
            f"| {n} | " + " | ".join(f"{res[n, m][0]:.3f} ({res[n, m][1]:.3f})" for m in MODES) + " |"
            for n in names
        ),
    ]
    text = "\n".join(lines) + "\n"
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
