"""cornerslam: natural-corner EKF-SLAM (Yan et al. 2014) on recorded 2D laser logs."""

__version__ = "0.1.0"
