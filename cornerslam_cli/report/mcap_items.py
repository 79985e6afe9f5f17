"""What the results MCAP's encodings share (report/mcap_out.py writes it, report/mcap_foxglove.py and
report/mcap_ros2.py encode it): its profiles, topics and map frame, a channel as an encoding declares it,
a landmark as the file shows it. Light on purpose: the CLI reads PROFILES for ``--mcap-profile``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

MAP_FRAME = "map"
TOPICS = {
    "pose": "/cornerslam/pose",
    "odom_pose": "/cornerslam/odom_pose",
    "path": "/cornerslam/path",
    "odom_path": "/cornerslam/odom_path",
    "ground_truth_path": "/cornerslam/ground_truth_path",
    "tf": "/cornerslam/tf",
    "odom_tf": "/cornerslam/odom_tf",
    "scan": "/cornerslam/scan",
    "landmarks": "/cornerslam/landmarks",
    "segments": "/cornerslam/segments",
    "grid": "/cornerslam/grid",
}
PROFILES = ("foxglove", "ros2")  # --mcap-profile: the encodings (module docstring)
LANDMARK_DIAMETER = 0.15  # m, the sphere at a landmark
CORNER_ARROW = 0.4  # m, the line (arrow) from a landmark along its corner direction φ
GREEN, ORANGE, GREY = (0.17, 0.63, 0.17, 1.0), (1.0, 0.5, 0.05, 1.0), (0.3, 0.3, 0.3, 0.8)  # r, g, b, a


@dataclass(frozen=True)
class Channel:
    """A topic as an encoding declares it: its schema (name, encoding, data), its messages' encoding and
    the channel's metadata."""

    topic: str
    schema: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    metadata: dict[str, str]


@dataclass(frozen=True)
class LandmarkItem:
    """A landmark of map.csv as the results MCAP shows it: where, its corner direction, its 3σ ellipse
    (k, 2) and its counts."""

    ident: int
    x: float
    y: float
    phi: float
    ellipse: np.ndarray
    n_obs: int
    first_step: int
    last_step: int

    def tip(self, length: float) -> tuple[float, float]:
        """The end of a line ``length`` m long from the landmark along its corner direction."""
        return self.x + length * math.cos(self.phi), self.y + length * math.sin(self.phi)
