"""Geometry and conventions: the camera model (projection, rays, OpenCV lens distortion),
the World Athletics track, and the H36M-17 skeleton with the angle definitions of
``CLIP_FORMAT.md``.  Every other stage builds on these; they import nothing of probreg.
"""

from .camera import (
    Camera,
    RaySphereHits,
    cross3,
    distort_normalized,
    focal_from_fov,
    fov_from_focal,
    intersect_rays_plane,
    intersect_rays_sphere,
    look_at_rotation,
    rotation_to_pan_tilt_roll,
    undistort_normalized,
)
from .rays import CameraArrays, camera_arrays, camera_centres, pixel_rays
from .skeleton import (
    ANGLE_NAMES,
    BONES,
    COCO_NAMES,
    JOINT_INDEX,
    JOINT_NAMES,
    SEGMENT_BONES,
    bone_lengths,
    coco_to_h36m,
    joint_angles,
    segment_lengths,
)
from .track import STANDARD_TRACK, TrackGeometry, lane_center_y, lane_line_y

__all__ = [
    "cross3", "Camera", "RaySphereHits", "distort_normalized", "undistort_normalized",
    "focal_from_fov", "fov_from_focal", "look_at_rotation", "rotation_to_pan_tilt_roll",
    "intersect_rays_plane", "intersect_rays_sphere", "TrackGeometry", "STANDARD_TRACK",
    "lane_line_y", "lane_center_y", "JOINT_NAMES", "JOINT_INDEX", "COCO_NAMES", "BONES",
    "SEGMENT_BONES", "ANGLE_NAMES", "coco_to_h36m", "segment_lengths", "joint_angles",
    "bone_lengths", "CameraArrays", "camera_arrays", "camera_centres", "pixel_rays",
]
