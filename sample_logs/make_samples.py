"""Regenerate the shipped sample logs (run from the repository root; needs ../shared for the real cuts).

    python sample_logs/make_samples.py

* sim_office.mcap (+ .gt.tum, .corners.csv): `cornerslam simulate` seed 1 at 4 Hz, 1,081 beams.
* intel_cut.clf: the first 300 laser scans (with their ODOM lines) of shared/data/real/intel/
  intel-noisy-odom.log, a CARMEN text log, lines copied verbatim.
* mines_exp3_cut.bag: the first 30 s of shared/data/real/mines/exp3.bag (ROS 1), messages copied
  byte for byte with rosbags' writer.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REAL = HERE.parent.parent / "shared" / "data" / "real"


def cut_carmen(src: Path, dst: Path, n_scans: int) -> None:
    out, scans = [], 0
    for line in src.read_text().splitlines(keepends=True):
        if line.startswith(("FLASER", "RLASER", "ROBOTLASER1")):
            if scans == n_scans:
                break
            scans += 1
        out.append(line)
    dst.write_text("".join(out))


def cut_rosbag1(src: Path, dst: Path, seconds: float) -> None:
    from rosbags.rosbag1 import Reader, Writer

    dst.unlink(missing_ok=True)
    with Reader(src) as reader, Writer(dst) as writer:
        conns = {}
        for c in reader.connections:
            conns[c.id] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
        t_end = reader.start_time + int(seconds * 1e9)
        for c, t, raw in reader.messages():
            if t > t_end:
                break
            writer.write(conns[c.id], t, raw)


def main() -> int:
    from cornerslam_cli.simulate import simulate_log

    simulate_log(HERE / "sim_office.mcap", seed=1, rate=4.0, beams=1081)
    if not REAL.is_dir():
        print(f"{REAL} not found: only the simulated sample was regenerated", file=sys.stderr)
        return 1
    cut_carmen(REAL / "intel" / "intel-noisy-odom.log", HERE / "intel_cut.clf", 300)
    cut_rosbag1(REAL / "mines" / "exp3.bag", HERE / "mines_exp3_cut.bag", 30.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
