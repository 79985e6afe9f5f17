"""Hand-made results (results.py) for the printers' and the consumers' tests."""

from __future__ import annotations

import dataclasses

from cornerslam_cli.results import Accuracy, Ate, Counts, Hashes, RelationError, RunInput, RunSummary, Timing

REL = RelationError(n=3, n_total=4, trans_mean=0.1234, trans_std=0.0456, rot_mean_deg=1.234, rot_std_deg=0.5)
NO_REL = RelationError(n=0, n_total=4)


def ate(rmse: float) -> Ate:
    return Ate(n=501, rmse=rmse, mean=rmse, max=rmse)


def make_summary(
    assoc: str = "pca",
    accuracy: Accuracy | None = None,
    t_match: float = 0.5,
    t_match_max: float = 0.0123,
    t_scan_match: float | None = 2.0,
    **counts: int,
) -> RunSummary:
    """A summary of 500 steps over 502 scans of logs/office.mcap written to out/office_<assoc>;
    ``counts`` replaces counts (every other count is 0)."""
    known = {f.name: 0 for f in dataclasses.fields(Counts) if f.default is dataclasses.MISSING}
    known.update(
        steps=500, scans_in=502, scans_skipped=2, keyframes_skipped=7, landmarks=88, matched_total=2777
    )
    known.update(counts)
    return RunSummary(
        cornerslam_version="0.0.0",
        mode="slam",
        input=RunInput(
            log="logs/office.mcap",
            format="mcap",
            scan_topic="/scan",
            odom_topic="/odom",
            odom_source="odometry",
            laser_to_base=(0.0, 0.0, 0.0),
            laser_to_base_source="default",
        ),
        assoc=assoc,
        counts=Counts(**known),
        timing=Timing(
            t_extract=1.234,
            t_scan_match=t_scan_match,
            t_predict=0.04,
            t_match=t_match,
            t_match_max=t_match_max,
            t_update=0.375,
            t_total=4.5678,
            scans_per_second=118.4,
            wall_time=4.56,
        ),
        final_pose=(1.0, 2.0, 0.5),
        warnings=(),
        accuracy=accuracy,
        hashes=Hashes(input="0" * 64, config="1" * 64, version="0.0.0"),
        config={},
        versions={},
        out_dir=f"out/office_{assoc}",
    )
