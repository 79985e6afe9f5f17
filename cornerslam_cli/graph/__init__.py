"""The global level of the two-level SLAM: closed submaps (submap.py), loop closing between them
(loops.py) and the pose graph joining them (posegraph.py, on GTSAM)."""
