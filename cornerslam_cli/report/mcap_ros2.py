"""The ROS 2 encoding of the results MCAP (``--mcap-profile ros2``): what
``ros2 bag play results.mcap`` publishes to RViz, beside the input bag.

The MCAP ``ros2`` profile (mcap docs, "ROS 2"): each channel's messages in CDR, its schema the ROS 2
``.msg`` definition with its dependencies (``ros2msg``, as rosbag2 writes it), its metadata the
``offered_qos_profiles`` the player offers. Messages are built and serialised with rosbags' typestore,
a dependency we already read logs with. The types are the common ones RViz shows:

- ``/cornerslam/pose``, ``/cornerslam/odom_pose``: geometry_msgs/msg/PoseStamped, one per step;
- ``/cornerslam/path``, ``odom_path``, ``ground_truth_path``: nav_msgs/msg/Path, one each (transient
  local: a subscriber that comes later gets it), each pose at its step's stamp;
- ``/tf``: tf2_msgs/msg/TFMessage, ``map`` → odom per step, and odom → base where the Foxglove profile
  has ``/cornerslam/odom_tf``;
- ``/cornerslam/scan``: sensor_msgs/msg/PointCloud2, x, y, z float32 (RViz draws no other position
  type) in the frame ``cornerslam_scan_origin``, which ``/tf_static`` puts at the first scan's position
  in ``map`` (one message, transient local): points near their frame's origin keep millimetres at UTM
  scale, as the Foxglove cloud's pose does;
- ``/cornerslam/landmarks``: visualization_msgs/msg/MarkerArray, one per landmark: a SPHERE (namespace
  ``landmarks``), its 3σ ellipse as a LINE_STRIP (``landmark_ellipses``) and an ARROW along its corner
  direction (``landmark_directions``), each with map.csv's id;
- ``/cornerslam/segments``: visualization_msgs/msg/MarkerArray, one per step: its segments as one
  LINE_LIST (namespace ``segments``, id = the step), none on a step without;
- ``/cornerslam/grid``: nav_msgs/msg/OccupancyGrid, one (transient local): map.pgm, 100 / 0 / −1.

One profile for every ROS 2 distribution: a player publishes the recorded bytes as they are, so the
layout has to be the subscriber's, and these types' layouts are the same from Humble to Lyrical (rosbags'
type stores: only constants differ, Marker's ARROW_STRIP from Jazzy on, which we do not use; a test
checks it). The definitions embedded are Jazzy's.

QoS: ``offered_qos_profiles`` in rosbag2's numeric YAML (metadata version 8), the form rosbag2 before
Jazzy reads and Jazzy on reads too (it tells the two forms apart per profile). The ``rosbag2`` metadata
record with an empty ``serialized_metadata`` is belt and braces: rosbag2_storage_mcap then takes the
file's metadata version as 8. Paths, grid and the scans' origin are offered transient local, but RViz's
displays subscribe volatile by default: set a Path or Map display's Durability Policy to Transient Local
to get them after they were played, and start RViz before the player for the markers (README).
Line widths are in metres (RViz has no pixel widths).
"""

from __future__ import annotations

import numpy as np

from ..logs.writers.mcap import qos_profile
from .mcap_items import (
    CORNER_ARROW,
    GREEN,
    GREY,
    LANDMARK_DIAMETER,
    MAP_FRAME,
    ORANGE,
    TOPICS,
    Channel,
    LandmarkItem,
)
from .occupancy import Grid

TYPES = {
    "pose": "geometry_msgs/msg/PoseStamped",
    "odom_pose": "geometry_msgs/msg/PoseStamped",
    "path": "nav_msgs/msg/Path",
    "odom_path": "nav_msgs/msg/Path",
    "ground_truth_path": "nav_msgs/msg/Path",
    "tf": "tf2_msgs/msg/TFMessage",
    "odom_tf": "tf2_msgs/msg/TFMessage",
    "scan": "sensor_msgs/msg/PointCloud2",
    "landmarks": "visualization_msgs/msg/MarkerArray",
    "segments": "visualization_msgs/msg/MarkerArray",
    "grid": "nav_msgs/msg/OccupancyGrid",
    "scan_origin": "tf2_msgs/msg/TFMessage",
}
# tf where every ROS tool looks for it
ROS_TOPICS = {**TOPICS, "tf": "/tf", "odom_tf": "/tf", "scan_origin": "/tf_static"}
LATCHED = frozenset({"path", "odom_path", "ground_truth_path", "grid", "scan_origin"})  # transient local
SCAN_FRAME = "cornerslam_scan_origin"  # the scans' frame: at the first scan's position in map
LINE_WIDTH = 0.02  # m, ellipses and segments
ARROW_SCALE = (0.03, 0.08, 0.1)  # m: shaft diameter, head diameter, head length
FLOAT32 = 7  # sensor_msgs/PointField
STORE = "ros2_jazzy"  # rosbags' type store whose definitions are embedded (the module docstring)


class Ros2Encoding:
    """ROS 2 messages in CDR (the module docstring), with Jazzy's definitions."""

    profile = "ros2"
    metadata = {"rosbag2": {"serialized_metadata": ""}}  # (belt and braces: the module docstring)

    def __init__(self):
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores(STORE))
        self.t = self.store.types
        self._defs: dict[str, bytes] = {}  # message definitions by type, generated once
        self._builders = {
            "pose": self._pose_stamped,
            "odom_pose": self._pose_stamped,
            "path": self._path,
            "odom_path": self._path,
            "ground_truth_path": self._path,
            "tf": self._tf,
            "odom_tf": self._tf,
            "scan": self._cloud,
            "landmarks": self._landmark,
            "segments": self._segments,
            "grid": self._grid,
            "scan_origin": self._scan_origin,
        }

    def channel(self, key: str) -> Channel:
        name = TYPES[key]
        if name not in self._defs:
            self._defs[name] = self.store.generate_msgdef(name, ros_version=2)[0].encode()
        meta = {"offered_qos_profiles": qos_profile(key in LATCHED)}
        return Channel(ROS_TOPICS[key], name, "ros2msg", self._defs[name], "cdr", meta)

    def encode(self, ns: int, key: str, item) -> bytes:
        return bytes(self.store.serialize_cdr(self._builders[key](ns, item), TYPES[key]))

    # --- message parts ------------------------------------------------------------------------------
    def _header(self, ns: int, frame: str = MAP_FRAME):
        stamp = self.t["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        return self.t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def _point(self, x: float, y: float):
        return self.t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0)

    def _quat(self, yaw: float):
        half = float(yaw) / 2
        return self.t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(half), w=np.cos(half))

    def _pose(self, x: float, y: float, yaw: float = 0.0):
        return self.t["geometry_msgs/msg/Pose"](position=self._point(x, y), orientation=self._quat(yaw))

    def _color(self, rgba: tuple[float, float, float, float]):
        return self.t["std_msgs/msg/ColorRGBA"](*rgba)

    def _marker(self, ns: int, space: str, ident: int, kind: int, pose, scale, color, points=()):
        """A visualization_msgs/Marker (ADD, forever) with every field of the layout filled."""
        t, empty = self.t, np.empty(0, dtype=np.uint8)
        return t["visualization_msgs/msg/Marker"](
            header=self._header(ns),
            ns=space,
            id=int(ident),
            type=kind,
            action=0,
            pose=pose,
            scale=t["geometry_msgs/msg/Vector3"](*scale),
            color=self._color(color),
            lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
            frame_locked=False,
            points=list(points),
            colors=[],
            texture_resource="",
            texture=t["sensor_msgs/msg/CompressedImage"](header=self._header(0, ""), format="", data=empty),
            uv_coordinates=[],
            text="",
            mesh_resource="",
            mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=empty),
            mesh_use_embedded_materials=False,
        )

    # --- messages ------------------------------------------------------------------------------------
    def _pose_stamped(self, ns: int, pose: np.ndarray, frame: str = MAP_FRAME):
        return self.t["geometry_msgs/msg/PoseStamped"](header=self._header(ns, frame), pose=self._pose(*pose))

    def _path(self, ns: int, item: tuple[np.ndarray, list[int] | None]):
        poses, stamps = item
        stamps = stamps if stamps is not None else [ns] * len(poses)
        stamped = [self._pose_stamped(s, p) for s, p in zip(stamps, poses, strict=True)]
        return self.t["nav_msgs/msg/Path"](header=self._header(ns), poses=stamped)

    def _tf(self, ns: int, item: tuple[str, str, np.ndarray]):
        parent, child, pose = item
        t = self.t
        translation = t["geometry_msgs/msg/Vector3"](x=float(pose[0]), y=float(pose[1]), z=0.0)
        transform = t["geometry_msgs/msg/Transform"](translation=translation, rotation=self._quat(pose[2]))
        stamped = t["geometry_msgs/msg/TransformStamped"](
            header=self._header(ns, parent), child_frame_id=child, transform=transform
        )
        return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])

    def _cloud(self, ns: int, item: tuple[np.ndarray, np.ndarray]):
        """The points (k, 2), float32 relative to their origin, as x, y, z float32 in SCAN_FRAME."""
        xy, _ = item
        xyz = np.zeros((len(xy), 3), dtype="<f4")
        xyz[:, :2] = xy
        field = self.t["sensor_msgs/msg/PointField"]
        fields = [field(name=n, offset=4 * i, datatype=FLOAT32, count=1) for i, n in enumerate("xyz")]
        return self.t["sensor_msgs/msg/PointCloud2"](
            header=self._header(ns, SCAN_FRAME), height=1, width=len(xyz), fields=fields, is_bigendian=False,
            point_step=12, row_step=12 * len(xyz), data=np.frombuffer(xyz.tobytes(), dtype=np.uint8),
            is_dense=True,
        )  # fmt: skip

    def _scan_origin(self, ns: int, origin: np.ndarray):
        """SCAN_FRAME at the scans' origin (2,) in ``map``, for /tf_static."""
        return self._tf(ns, (MAP_FRAME, SCAN_FRAME, (origin[0], origin[1], 0.0)))

    def _landmark(self, ns: int, lm: LandmarkItem):
        marker, none = self.t["visualization_msgs/msg/Marker"], self._pose(0.0, 0.0)
        ring = [self._point(px, py) for px, py in lm.ellipse]
        markers = [
            self._marker(ns, "landmarks", lm.ident, marker.SPHERE, self._pose(lm.x, lm.y),
                         (LANDMARK_DIAMETER,) * 3, GREEN),
            self._marker(ns, "landmark_ellipses", lm.ident, marker.LINE_STRIP, none, (LINE_WIDTH, 0.0, 0.0),
                         GREEN, [*ring, ring[0]] if ring else []),
            self._marker(ns, "landmark_directions", lm.ident, marker.ARROW, none, ARROW_SCALE, ORANGE,
                         [self._point(lm.x, lm.y), self._point(*lm.tip(CORNER_ARROW))]),
        ]  # fmt: skip
        return self.t["visualization_msgs/msg/MarkerArray"](markers=markers)

    def _segments(self, ns: int, item: tuple[int, np.ndarray]):
        step, segs = item
        markers = []
        if len(segs):
            pts = [self._point(*p) for s in segs for p in (s[:2], s[2:])]
            line_list = self.t["visualization_msgs/msg/Marker"].LINE_LIST
            markers.append(
                self._marker(ns, "segments", step, line_list, self._pose(0.0, 0.0), (LINE_WIDTH, 0.0, 0.0),
                             GREY, pts)
            )  # fmt: skip
        return self.t["visualization_msgs/msg/MarkerArray"](markers=markers)

    def _grid(self, ns: int, grid: Grid):
        """map.pgm as nav_msgs/OccupancyGrid: cell (0, 0) at its origin, rows along +y (Grid.nav_values)."""
        values = grid.nav_values()
        rows, cols = grid.cells.shape
        info = self.t["nav_msgs/msg/MapMetaData"](
            map_load_time=self._header(ns).stamp, resolution=float(grid.resolution), width=cols, height=rows,
            origin=self._pose(*grid.origin),
        )  # fmt: skip
        return self.t["nav_msgs/msg/OccupancyGrid"](header=self._header(ns), info=info, data=values.ravel())
