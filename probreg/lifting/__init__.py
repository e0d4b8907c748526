"""Ray-cast lifting of a 2D skeleton with known cameras (seed paper, Sec. 3.3): feet in contact
are cast onto the ground, a Kalman/RTS smoother turns the contacts into the ground track and
the sagittal plane (:func:`fit_ground_track`), the pelvis ray meets that plane, and each limb
joint is found on a sphere of limb-length radius around its parent, with the two solutions
chosen over the clip by Viterbi (:func:`lift`).
"""

from .raycast import (
    ANTHROPOMETRIC_RATIOS,
    LiftConfig,
    LiftResult,
    estimate_segments,
    implausible_segments,
    lift,
    lift_many,
    smooth_angles_across_strides,
)
from .trajectory import (
    GroundTrack,
    TrackConfig,
    camera_track_config,
    cast_ankles,
    detect_contacts,
    fit_ground_track,
    fit_ground_tracks,
    gate_contacts_by_height,
    sagittal_ankle_height,
    sagittal_ankle_points,
)

__all__ = [
    "LiftConfig", "LiftResult", "estimate_segments", "implausible_segments", "lift", "lift_many",
    "smooth_angles_across_strides",
    "ANTHROPOMETRIC_RATIOS", "GroundTrack", "TrackConfig", "camera_track_config", "cast_ankles", "detect_contacts",
    "fit_ground_track", "fit_ground_tracks", "sagittal_ankle_points", "sagittal_ankle_height",
    "gate_contacts_by_height",
]
