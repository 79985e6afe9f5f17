"""How often the front end switches an odometry bias term on and off between re-estimates.

    python benchmarks/bias_switches.py [--data DIR] [--jobs 2] [--out FILE]

The fusion (motion/fusion.py) re-estimates the odometer scale error c_s and the heading drift c_θ at
every keyframe while it has fewer than 2·``adapt_every`` samples, every ``adapt_every`` after, and takes a
term out of the odometry only while it passes its test (3 standard errors from zero; a scale error also
≥ ``SCALE_MIN``). Near that line the test can pass at one re-estimate and fail at the next: the
increments then jump by the term (2–3 cm a metre for a 2–3 % scale error). Each noisy radish log runs
with the default config, with a hook on the fusion's re-estimates recording which terms are taken after each:
the re-estimates, how many times each term switched (on → off or off → on), the share of re-estimates
that held it, and the ATE. Deterministic; writes ``docs/results/bias_switches.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _baseline import child_json, revision  # noqa: E402
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

# One run in a child process: after each re-estimate, whether each bias term is taken.
CHILD = r"""
import json, sys
from cornerslam_cli.cli import main
from cornerslam_cli.motion import fusion

log, out = sys.argv[1], sys.argv[2]
held = []
learn = fusion.OdometryFusion._learn

def recorded(self):
    learn(self)
    held.append([bool(self.c[0] != 0.0), bool(self.c[1] != 0.0)])

fusion.OdometryFusion._learn = recorded
gt = log[: -len(".log")] + ".gt.tum"
if rc := main(["run", log, "--out", out, "-q", "--ground-truth", gt], standalone_mode=False):
    sys.exit(rc)  # (click returns a failed run's exit code here: not a record of a whole run)
print(json.dumps(held))
"""


def one(log: Path, out: Path) -> dict:
    """One run of ``log``: the re-estimates' record of :data:`CHILD` and the run's ATE."""
    held = child_json(CHILD, str(log), str(out), what=log.name)
    summary = json.loads((out / "summary.json").read_text())
    switches = [sum(a[i] != b[i] for a, b in zip(held[:-1], held[1:], strict=True)) for i in range(2)]
    shares = [sum(h[i] for h in held) / max(len(held), 1) for i in range(2)]
    return {
        "log": log.stem,
        "estimates": len(held),
        "switches": switches,
        "shares": shares,
        "ate": summary["accuracy"]["ate"]["rmse"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "bias_switches.md")
    args = ap.parse_args()
    logs = [args.data / "radish" / f"{b}.log" for b in BUILDINGS]
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as ex:
        rows = list(ex.map(lambda log: one(log, Path(tmp) / log.stem), logs))
    lines = [
        "# How often the odometry's bias terms switch on and off",
        "",
        f"`python benchmarks/bias_switches.py` at {revision()} "
        "(see its docstring): each noisy radish log, default config; after each of the fusion's "
        "re-estimates, whether the odometer scale error and the heading drift are taken out. *Switches*: "
        "how many times a term went from taken to not or back; *held*: the share of re-estimates that "
        "took it. Deterministic.",
        "",
        "| log | re-estimates | scale: switches | scale: held | drift: switches | drift: held | ATE (m) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        (s0, s1), (h0, h1) = r["switches"], r["shares"]
        lines.append(
            f"| {r['log']} | {r['estimates']} | {s0} | {100 * h0:.0f} % | {s1} | {100 * h1:.0f} % "
            f"| {r['ate']:.3f} |"
        )
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
