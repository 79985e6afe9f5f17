"""Motion front end: scan matching that refines wheel odometry before the filter's prediction."""

from .icp import MatchResult, ScanMatcher
from .params import ScanMatchConfig

__all__ = ["MatchResult", "ScanMatchConfig", "ScanMatcher"]
