"""Video files as ``probreg run`` takes them: which paths are videos, what OpenCV reads of them,
and linking an input into a scratch clip folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .clip import ClipFormatError

__all__ = ["VIDEO_SUFFIXES", "is_video", "probe_video", "link_or_copy"]


#: file endings ``probreg run`` takes for a video (anything OpenCV's FFmpeg backend decodes works)
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".m4v", ".mpg", ".mpeg", ".webm", ".mts", ".ts")


def is_video(path):
    """Whether ``path`` is a video file (by its ending) rather than a clip folder."""
    p = Path(path)
    return p.suffix.lower() in VIDEO_SUFFIXES and not p.is_dir()


def probe_video(path, fps=None):
    """``(fps, (width, height), n_frames)`` of a video, read through OpenCV.

    The frame count is decoded when the container does not state it.  ``fps`` overrides a missing
    or wrong rate in the container.

    Raises
    ------
    ClipFormatError
        When the file is missing, cannot be decoded, or states no frame rate and none is given.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise ClipFormatError(f"{path}: no such video file")
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ClipFormatError(f"{path}: cannot open the video (not a video, or a codec OpenCV cannot decode)")
        rate = float(fps) if fps else float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        if n <= 0:
            n = 0
            while cap.grab():
                n += 1
    finally:
        cap.release()
    if n <= 0 or min(size) <= 0:
        raise ClipFormatError(f"{path}: the video has no decodable frames")
    if not (rate > 0 and np.isfinite(rate)):
        raise ClipFormatError(f"{path}: the video states no frame rate; give it with --fps")
    return rate, size, n


def link_or_copy(src, dst):
    """A symbolic link ``dst`` to ``src``, or a copy where the file system has no links."""
    import shutil

    try:
        dst.symlink_to(Path(src).resolve())
    except OSError:  # no symlinks here (some file systems): copy
        if Path(src).is_dir():
            shutil.copytree(src, dst)
        else:
            shutil.copyfile(src, dst)
