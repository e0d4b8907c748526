"""Reading and writing the clip folder of ``CLIP_FORMAT.md``.

The domain model (:class:`Clip`) is plain arrays; this module only knows the
files.  The pipeline never reads ``groundtruth/``: only benchmarks and tests
call :func:`load_groundtruth`.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry import JOINT_NAMES, Camera, coco_to_h36m

__all__ = [
    "ClipFormatError",
    "Clip",
    "GroundTruth",
    "load_clip",
    "load_groundtruth",
    "read_keypoints_json",
    "write_keypoints_json",
    "read_cameras_json",
    "write_json",
    "atomic_output_dir",
]


class ClipFormatError(ValueError):
    """A clip folder or one of its files does not follow ``CLIP_FORMAT.md``."""


@dataclass(frozen=True)
class Clip:
    """An input clip.

    Attributes
    ----------
    path : Path
    fps : float
    image_size : tuple of int
        ``(width_px, height_px)``.
    keypoints_px : ndarray, shape (F, 17, 3) or None
        H36M-17 ``(x, y, score)``; missing joints and frames without a
        detection are NaN.
    frame_paths : list of Path
        One image per frame (may be empty when the clip has only keypoints or a video).
    athlete_lane : int or None
    lane_width_m : float
    meta : dict
        Everything in ``clip.json``.
    """

    path: Path
    fps: float
    image_size: tuple
    keypoints_px: np.ndarray | None
    frame_paths: list
    athlete_lane: int | None
    lane_width_m: float
    meta: dict

    @property
    def n_frames(self):
        if self.keypoints_px is not None:
            return len(self.keypoints_px)
        if self.frame_paths:
            return len(self.frame_paths)
        return int(self.meta.get("n_frames", 0))

    @property
    def video_path(self):
        p = self.path / "video.mp4"
        return p if p.exists() else None

    def times_s(self):
        return np.arange(self.n_frames) / self.fps


@dataclass(frozen=True)
class GroundTruth:
    """Ground truth of a synthetic clip (benchmarks and tests only)."""

    cameras: list
    joints3d_track_m: np.ndarray
    joints2d_px: np.ndarray
    contacts: np.ndarray
    athlete: dict


def _read_json(path: Path):
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise ClipFormatError(f"{path}: file not found") from None
    except json.JSONDecodeError as exc:
        raise ClipFormatError(f"{path}: malformed JSON at line {exc.lineno}, column {exc.colno}: "
                              f"{exc.msg}") from None
    except UnicodeDecodeError as exc:
        raise ClipFormatError(f"{path}: not UTF-8 text ({exc.reason})") from None


def write_json(path, obj):
    """Write JSON (UTF-8, indented) with NaN/inf written as ``null``."""

    def clean(o):
        if isinstance(o, float):
            return o if math.isfinite(o) else None
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, np.ndarray):
            return clean(o.tolist())
        if isinstance(o, np.generic):
            return clean(o.item())
        return o

    Path(path).write_text(json.dumps(clean(obj), indent=1), encoding="utf-8")


def read_keypoints_json(path, n_frames=None):
    """Read ``keypoints2d.json`` into H36M-17 ``(F, 17, 3)`` with NaN for missing.

    Parameters
    ----------
    path : path-like
    n_frames : int, optional
        Number of frames of the clip; frames absent from the file are missing.

    Returns
    -------
    ndarray, shape (F, 17, 3)

    Raises
    ------
    ClipFormatError
        On malformed JSON, an unknown format, wrong joint counts or bad frame indices.
    """
    path = Path(path)
    doc = _read_json(path)
    if not isinstance(doc, dict) or "frames" not in doc:
        raise ClipFormatError(f"{path}: expected an object with 'format' and 'frames'")
    fmt = doc.get("format", "h36m17")
    if fmt not in ("h36m17", "coco17"):
        raise ClipFormatError(f"{path}: unknown keypoint format {fmt!r} (h36m17 or coco17)")
    frames = doc["frames"]
    if not isinstance(frames, list):
        raise ClipFormatError(f"{path}: 'frames' must be a list")
    idx = []
    for k, entry in enumerate(frames):
        if not isinstance(entry, dict) or "frame" not in entry:
            raise ClipFormatError(f"{path}: frames[{k}] lacks 'frame'")
        try:
            fi = int(entry["frame"])
        except (TypeError, ValueError):
            raise ClipFormatError(f"{path}: frames[{k}] has a non-integer frame index") from None
        if fi < 0:
            raise ClipFormatError(f"{path}: frames[{k}] has a negative frame index {fi}")
        idx.append(fi)
    total = n_frames if n_frames is not None else (max(idx) + 1 if idx else 0)
    if idx and max(idx) >= total:
        raise ClipFormatError(f"{path}: frame {max(idx)} beyond the clip's {total} frames")
    out = np.full((total, 17, 3), np.nan)
    for k, (fi, entry) in enumerate(zip(idx, frames)):
        kp = entry.get("keypoints")
        if kp is None:
            continue
        try:
            arr = np.array([[np.nan if v is None else v for v in row] for row in kp], dtype=float)
        except (TypeError, ValueError):
            raise ClipFormatError(f"{path}: frame {fi}: keypoints are not numbers") from None
        if arr.ndim != 2 or arr.shape[0] != 17 or arr.shape[1] not in (2, 3):
            raise ClipFormatError(f"{path}: frame {fi}: expected 17 joints of [x, y, score], "
                                  f"got shape {arr.shape}")
        if arr.shape[1] == 2:
            arr = np.concatenate([arr, np.ones((17, 1))], axis=1)
        out[fi] = arr
    if fmt == "coco17":
        out = coco_to_h36m(out)
    # a joint with any NaN coordinate is missing as a whole
    bad = np.any(~np.isfinite(out), axis=-1)
    out[bad] = np.nan
    return out


def write_keypoints_json(path, keypoints_px, fmt="h36m17"):
    """Write ``(F, 17, 3)`` keypoints; an all-NaN frame is written as ``null``."""
    kp = np.asarray(keypoints_px, float)
    frames = []
    for i, k in enumerate(kp):
        if np.all(np.isnan(k)):
            frames.append({"frame": i, "keypoints": None})
        else:
            frames.append({"frame": i, "keypoints": [[None if not np.isfinite(v) else round(float(v), 4)
                                                      for v in row] for row in k]})
    write_json(path, {"format": fmt, "joint_names": list(JOINT_NAMES), "frames": frames})


def load_clip(path, min_score=0.0):
    """Load a clip folder.

    Parameters
    ----------
    path : path-like
    min_score : float
        Joints with a lower detection score become missing (NaN).

    Raises
    ------
    ClipFormatError
        If the folder, ``clip.json`` or ``keypoints2d.json`` is missing or malformed.
    """
    path = Path(path)
    if not path.is_dir():
        raise ClipFormatError(f"{path}: clip folder not found")
    meta = _read_json(path / "clip.json")
    if not isinstance(meta, dict):
        raise ClipFormatError(f"{path / 'clip.json'}: expected a JSON object")
    try:
        fps = float(meta["fps"])
        w, h = (int(v) for v in meta["image_size"])
    except (KeyError, TypeError, ValueError):
        raise ClipFormatError(f"{path / 'clip.json'}: needs 'fps' and 'image_size': [W, H]") from None
    if not (fps > 0 and w > 0 and h > 0):
        raise ClipFormatError(f"{path / 'clip.json'}: fps and image size must be positive")
    lane = meta.get("athlete_lane")
    if lane is not None and (not isinstance(lane, int) or not 1 <= lane <= 9):
        raise ClipFormatError(f"{path / 'clip.json'}: athlete_lane must be a lane number 1..9")
    frame_dir = path / "frames"
    frame_paths = sorted(p for p in frame_dir.glob("*") if p.suffix.lower() in (".jpg", ".jpeg", ".png")) \
        if frame_dir.is_dir() else []
    n = meta.get("n_frames") or (len(frame_paths) or None)
    kp = None
    if (path / "keypoints2d.json").exists():
        kp = read_keypoints_json(path / "keypoints2d.json", n_frames=n)
        if min_score > 0:
            kp[kp[..., 2] < min_score] = np.nan
    return Clip(path=path, fps=fps, image_size=(w, h), keypoints_px=kp, frame_paths=frame_paths,
                athlete_lane=lane, lane_width_m=float(meta.get("lane_width_m", 1.22)), meta=meta)


def read_cameras_json(path, image_size=(1920, 1080)):
    """Per-frame cameras from ``cameras.json`` / ``camera.json``; ``None`` for a frame without one.

    Returns
    -------
    dict of int -> Camera or None
    """
    path = Path(path)
    doc = _read_json(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("frames"), list):
        raise ClipFormatError(f"{path}: expected an object with a 'frames' list")
    out = {}
    for k, entry in enumerate(doc["frames"]):
        try:
            fi = int(entry["frame"])
        except (KeyError, TypeError, ValueError):
            raise ClipFormatError(f"{path}: frames[{k}] lacks an integer 'frame'") from None
        if entry.get("K") is None:
            out[fi] = None
            continue
        try:
            out[fi] = Camera.from_dict(entry, image_size=image_size)
        except (ValueError, TypeError) as exc:
            raise ClipFormatError(f"{path}: frame {fi}: {exc}") from None
    return out


def load_groundtruth(path):
    """Ground truth of a synthetic clip (never used by the pipeline)."""
    path = Path(path)
    gt = path / "groundtruth"
    meta = _read_json(path / "clip.json")
    size = tuple(meta.get("image_size", (1920, 1080)))
    cams = read_cameras_json(gt / "cameras.json", image_size=size)
    try:
        j3 = np.load(gt / "joints3d.npy")
        j2 = np.load(gt / "joints2d.npy")
        contacts = np.load(gt / "contacts.npy")
    except FileNotFoundError as exc:
        raise ClipFormatError(f"{exc.filename}: file not found") from None
    return GroundTruth(cameras=[cams[i] for i in sorted(cams)], joints3d_track_m=j3,
                       joints2d_px=j2, contacts=contacts, athlete=_read_json(gt / "athlete.json"))


class atomic_output_dir:
    """Context manager: build an output folder under a temporary name, rename on success.

    A failure leaves no folder that looks complete.  An existing target is
    replaced only when it is empty, was written by probreg (has ``clip.json``
    or ``.probreg``), or ``overwrite`` is set.

    Raises
    ------
    FileExistsError
        If the target holds foreign files and ``overwrite`` is not set.
    PermissionError, OSError
        If the parent folder cannot be written.
    """

    def __init__(self, target, overwrite=False):
        self.target = Path(target)
        self.overwrite = overwrite
        self.tmp = None

    def __enter__(self):
        t = self.target
        if t.exists():
            if not t.is_dir():
                raise FileExistsError(f"{t}: exists and is not a folder")
            ours = (t / "clip.json").exists() or (t / ".probreg").exists()
            if any(t.iterdir()) and not (ours or self.overwrite):
                raise FileExistsError(f"{t}: folder is not empty and was not written by probreg "
                                      f"(use --overwrite to replace it)")
        parent = t.parent if str(t.parent) else Path(".")
        parent.mkdir(parents=True, exist_ok=True)
        if not os.access(parent, os.W_OK):
            raise PermissionError(f"{parent}: output folder is not writable")
        try:
            self.tmp = Path(tempfile.mkdtemp(prefix=f".{t.name}.tmp-", dir=parent))
        except OSError as exc:
            raise PermissionError(f"{parent}: cannot create the output folder there ({exc.strerror})") from None
        os.chmod(self.tmp, 0o755)
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return False
        (self.tmp / ".probreg").write_text("written by probreg\n")
        if self.target.exists():
            old = self.target.with_name(self.target.name + ".old-" + self.tmp.name[-8:])
            os.replace(self.target, old)
            os.replace(self.tmp, self.target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(self.tmp, self.target)
        return False
