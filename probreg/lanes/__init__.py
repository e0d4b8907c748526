"""Lane lines and their vanishing point (seed paper, Sec. 3.1): the few parallel lane lines of
the straight that a zoomed-in broadcast camera sees are found, measured to sub-pixel accuracy,
followed from frame to frame, and fitted as a pencil through one vanishing point with integer
line indices.  The frames' colour changes and the shots between camera cuts are in
:mod:`probreg.lanes.shots` (the cuts themselves: :mod:`probreg.calibration.cuts`).  Failures are per-frame statuses (:data:`STATUSES`), never exceptions.
"""

from .detection import detect_lanes, merged_lines_note
from .mask import athlete_mask, on_athlete_fraction
from .overlay import draw_lanes
from .shots import ShotSplit, colour_histogram, find_cuts, histogram_change, split_shots
from .tracking import track_lanes
from .types import STATUSES, FrameLanes, LaneDetectorConfig, LaneLine
from .undistort import line_straightness_px, undistort_frame_lanes
from .vanishing import assign_line_indices, lines_through_point, smooth_vanishing_points

__all__ = [
    "LaneDetectorConfig", "LaneLine", "FrameLanes", "STATUSES", "athlete_mask", "on_athlete_fraction",
    "lines_through_point", "assign_line_indices", "smooth_vanishing_points", "track_lanes",
    "undistort_frame_lanes", "line_straightness_px", "draw_lanes", "detect_lanes", "merged_lines_note",
    "ShotSplit", "colour_histogram", "histogram_change", "find_cuts", "split_shots",
]
