"""A clip folder from what a user already has: a video or a folder of images, plus 2D keypoints
from another tool (``probreg import``)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from .clip import ClipFormatError, atomic_output_dir, check_pixel_coordinates, write_json, write_keypoints_json
from .keypoints import read_keypoints
from .output import prepare_output

__all__ = ["import_clip"]

_IMAGES = (".jpg", ".jpeg", ".png")


def import_clip(out, keypoints, video=None, frames=None, fps=None, fmt=None, layout="h36m17",
                trc_image_height=None, min_score=0.3, athlete_lane=None, overwrite=False, log=print):
    """Write the clip folder ``out``: ``clip.json``, ``keypoints2d.json`` (H36M-17) and the frames
    (``video.mp4``, or ``frames/000000.jpg ...`` numbered in the images' name order).

    Keypoints shorter than the video are padded with missing frames (a note says so).

    Raises
    ------
    ClipFormatError
        Not exactly one of ``video`` / ``frames``, an unreadable video or image, no frame rate,
        more keypoint frames than images, or keypoints :func:`read_keypoints` cannot read.
    """
    inputs = [p for p in (keypoints, video, frames) if p is not None]
    prepare_output(out, inputs, overwrite)
    kwargs = {"min_score": min_score}
    if fmt == "npy" or (fmt is None and str(keypoints).endswith((".npy", ".npz"))):
        kwargs["layout"] = layout
    if trc_image_height is not None:
        kwargs["image_height"] = trc_image_height
    kp = read_keypoints(keypoints, fmt, **kwargs)
    if (video is None) == (frames is None):
        raise ClipFormatError("give exactly one of --video FILE or --frames DIR")
    if fps is not None and not (np.isfinite(fps) and fps > 0):  # not "unknown": the user gave one
        raise ClipFormatError(f"--fps must be a positive frame rate (frames per second), got {fps:g}")
    if not np.isfinite(np.asarray(kp, float)[..., :2]).any():
        log(f"warning: {keypoints}: no joint in any frame; 'probreg run' will refuse the clip")
    import cv2

    images = None
    if video is not None:
        cap = cv2.VideoCapture(str(video))
        if not cap.isOpened():
            raise ClipFormatError(f"{video}: cannot open the video")
        n_src = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        fps = fps or cap.get(cv2.CAP_PROP_FPS)
        cap.release()
    else:
        images = sorted(p for p in Path(frames).glob("*") if p.suffix.lower() in _IMAGES)
        if not images:
            raise ClipFormatError(f"{frames}: no .jpg/.png frames")
        img = cv2.imread(str(images[0]))
        if img is None:
            raise ClipFormatError(f"{images[0]}: cannot read the image")
        size = (img.shape[1], img.shape[0])
        n_src = len(images)
        if not fps:
            raise ClipFormatError("--fps is required with --frames (a folder of images has no frame rate)")
    if not fps or fps <= 0:
        raise ClipFormatError("the frame rate is unknown: give --fps")
    check_pixel_coordinates(kp, size, keypoints)
    if len(kp) > n_src:
        raise ClipFormatError(f"{keypoints}: {len(kp)} frames of keypoints but the video has only {n_src}")
    if len(kp) < n_src:
        log(f"note: keypoints cover {len(kp)} of {n_src} frames; the rest are marked missing")
        kp = np.concatenate([kp, np.full((n_src - len(kp), 17, 3), np.nan)])
    with atomic_output_dir(out, overwrite=overwrite, inputs=inputs, log=log) as tmp:
        if images is not None:
            (tmp / "frames").mkdir()
            for i, p in enumerate(images):
                shutil.copyfile(p, tmp / "frames" / f"{i:06d}{p.suffix.lower()}")
        else:
            shutil.copyfile(video, tmp / "video.mp4")
        meta = {"fps": float(fps), "image_size": list(size), "n_frames": n_src,
                "source": {"keypoints": str(keypoints), "format": fmt}}
        if athlete_lane is not None:
            meta["athlete_lane"] = athlete_lane
        write_json(tmp / "clip.json", meta)
        write_keypoints_json(tmp / "keypoints2d.json", kp)
    return Path(out), n_src
