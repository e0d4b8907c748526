"""Readers and writers: one module per file format, apart from the domain model."""

from .clip import (
    Clip,
    ClipFormatError,
    GroundTruth,
    atomic_output_dir,
    load_clip,
    load_groundtruth,
    read_cameras_json,
    read_keypoints_json,
    write_json,
    write_keypoints_json,
)
from .frames import has_frames, iter_frames, read_frame
from .keypoints import read_keypoints
from .provenance import software_versions
from .results import read_angles_csv, write_angles_csv, write_joints_npz

__all__ = [
    "Clip",
    "ClipFormatError",
    "GroundTruth",
    "atomic_output_dir",
    "load_clip",
    "load_groundtruth",
    "read_cameras_json",
    "read_keypoints_json",
    "write_json",
    "write_keypoints_json",
    "has_frames",
    "iter_frames",
    "read_frame",
    "read_angles_csv",
    "write_angles_csv",
    "write_joints_npz",
    "read_keypoints",
    "software_versions",
]
