"""Log writers for test fixtures and ``cornerslam simulate``: MCAP, ROS 1 bag, ROS 2 bag, CARMEN,
one module each (``mcap.py``, ``rosbag.py``, ``carmen.py``) over the ROS messages of ``ros.py`` and
the shared :class:`RawScan` of ``base.py``.

Every writer takes full-beam scans (:class:`RawScan`, inf/NaN allowed = no return) and odometry
samples (:class:`~cornerslam_cli.types.OdomSample`) as iterables sorted by stamp (generators are
fine: writing streams), merges them by stamp (odometry first on ties) and uses the stamp as both
header stamp and log time. ROS messages are serialized with rosbags' typestores.

The three ROS writers take the options they share (topics, frames, how odometry is written) as
keyword arguments, the fields of :class:`RosTopics`.
"""

from .base import RawScan
from .carmen import write_carmen
from .mcap import write_mcap
from .ros import LASERSCAN, ODOMETRY, TFMESSAGE, JsonSerializer, RosSerializer, RosTopics, serializer
from .rosbag import write_rosbag1, write_rosbag2

__all__ = [
    "LASERSCAN",
    "ODOMETRY",
    "TFMESSAGE",
    "JsonSerializer",
    "RawScan",
    "RosSerializer",
    "RosTopics",
    "serializer",
    "write_carmen",
    "write_mcap",
    "write_rosbag1",
    "write_rosbag2",
]
