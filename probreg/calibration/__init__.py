"""Partial sports field registration (seed paper, Sec. 3.2): one vanishing point and the equal
1.22 m lane spacing fix the camera up to one degree of freedom per frame
(:class:`CalibrationFamily`); a static camera ties the frames together, so one scalar (the
camera height) selects a member in every frame (:func:`register_clip`).
"""

from .family import (
    PARAMETERS,
    AzimuthParameter,
    CalibrationError,
    CalibrationFamily,
    FamilyMember,
    FamilyParameter,
    FovParameter,
    HeightParameter,
    SequenceCalibration,
)
from .registration import (
    ANKLE_HEIGHT_M,
    DEFAULT_HEIGHT_M,
    ClipRegistration,
    athlete_ground_track,
    lane_anchor_shift,
    register_clip,
    register_frames,
    undistorted_members,
)
from .side import SIDES, CameraSide, camera_side_evidence

__all__ = [
    "SIDES", "CameraSide", "camera_side_evidence",
    "FamilyMember", "CalibrationFamily", "FamilyParameter", "HeightParameter", "FovParameter",
    "AzimuthParameter", "PARAMETERS", "SequenceCalibration", "CalibrationError",
    "DEFAULT_HEIGHT_M", "ANKLE_HEIGHT_M", "ClipRegistration", "athlete_ground_track",
    "lane_anchor_shift", "register_frames", "register_clip", "undistorted_members",
]
