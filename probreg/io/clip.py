"""Reading and writing the clip folder of ``CLIP_FORMAT.md``.

The domain model (:class:`Clip`) is plain arrays; this module only knows the
files.  The pipeline never reads ``groundtruth/``: only benchmarks and tests
call :func:`load_groundtruth`.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..geometry import COCO_NAMES, JOINT_NAMES, Camera, coco_to_h36m
from .output import atomic_output_dir

__all__ = [
    "ClipFormatError",
    "Clip",
    "GroundTruth",
    "load_clip",
    "with_slow_motion",
    "load_groundtruth",
    "read_keypoints_json",
    "read_segments_json",
    "write_keypoints_json",
    "written_by_detect",
    "read_cameras_json",
    "write_json",
    "atomic_output_dir",
    "athlete_frames",
    "MIN_ATHLETE_FRAMES",
    "MIN_ATHLETE_JOINTS",
]

#: a frame has a detected athlete with at least this many joints, and a clip (or the shot of it
#: that is estimated) needs at least this many such frames
MIN_ATHLETE_JOINTS = 8
MIN_ATHLETE_FRAMES = 10


def with_slow_motion(clip, factor):
    """``clip`` in real time: a slow-motion replay recorded at ``factor`` times the frame rate it is
    played at (``clip.json``'s ``fps``) has ``fps * factor`` frames per second of real time; the
    clip's notes say so.  ``factor`` 1 returns ``clip`` itself.

    >>> c = Clip(Path("c"), 50.0, (1920, 1080), None, [], 1, 1.22, {})
    >>> with_slow_motion(c, 4).fps, with_slow_motion(c, 4).notes[-1]
    (200.0, 'slow motion 4x: 50 fps played, 200 fps of real time')
    >>> with_slow_motion(c, 0)
    Traceback (most recent call last):
    ...
    ValueError: slow motion must be a positive factor (4 for a replay at a quarter of real speed), got 0
    """
    try:
        f = float(factor)
    except (TypeError, ValueError):
        f = float("nan")
    if not (np.isfinite(f) and f > 0):
        raise ValueError(f"slow motion must be a positive factor (4 for a replay at a quarter of real speed), "
                         f"got {factor}")
    if f == 1.0:
        return clip
    fps = clip.fps * f
    if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise ValueError(f"slow motion {f:g}x makes {clip.fps:g} fps into {fps:g} fps of real time, outside "
                         f"{FPS_RANGE[0]:g}-{FPS_RANGE[1]:g}")
    return replace(clip, fps=fps, notes=(*clip.notes, f"slow motion {f:g}x: {clip.fps:g} fps played, {fps:g} fps of "
                                         "real time"))


def athlete_frames(keypoints_px):
    """Frames of ``keypoints_px`` (F, J, 2 or 3) in which at least :data:`MIN_ATHLETE_JOINTS`
    joints were detected.

    >>> kp = np.full((3, 17, 3), np.nan); kp[0] = 1.0; kp[1, :8] = 1.0; kp[2, :7] = 1.0
    >>> athlete_frames(kp)
    2
    """
    return int(np.sum(np.isfinite(np.asarray(keypoints_px, float)[..., 0]).sum(axis=1) >= MIN_ATHLETE_JOINTS))


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
    frame_paths : list of Path or None
        One entry per frame, matched by the number in the file name (``frames/000041.jpg`` is
        frame 41); ``None`` where the image is missing.  Empty when the clip has only
        keypoints or a video.
    athlete_lane : int or None
    lane_width_m : float
    meta : dict
        Everything in ``clip.json``.
    notes : tuple of str
        Warnings about the input that did not stop the load (stray files ignored, missing
        images, keypoints far outside the image treated as missing).
    keypoints_outside : ndarray of int, shape (F,) or None
        Per frame, how many joints lay more than one image size outside the image and were
        treated as missing.
    """

    path: Path
    fps: float
    image_size: tuple
    keypoints_px: np.ndarray | None
    frame_paths: list
    athlete_lane: int | None
    lane_width_m: float
    meta: dict
    notes: tuple = ()
    keypoints_outside: np.ndarray | None = None

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

    @property
    def missing_images(self):
        """Frames of an image-folder clip whose image file is missing."""
        return [i for i, p in enumerate(self.frame_paths) if p is None]

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
    """A JSON document of the clip or of the user (UTF-8, with or without the byte-order mark
    some Windows editors put first), or a :class:`ClipFormatError` that names the file."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise ClipFormatError(f"{path}: file not found") from None
    except json.JSONDecodeError as exc:
        raise ClipFormatError(f"{path}: malformed JSON at line {exc.lineno}, column {exc.colno}: "
                              f"{exc.msg}") from None
    except UnicodeDecodeError as exc:
        raise ClipFormatError(f"{path}: not UTF-8 text ({exc.reason})") from None


def check_pixel_coordinates(keypoints, image_size, where):
    """Raise :class:`ClipFormatError` when every keypoint of ``keypoints`` (F, 17, 2+) lies within
    [0, 1]: coordinates normalised to the image (MediaPipe's), not the frames' pixels; the message
    gives the factors that turn them into pixels."""
    xy = np.asarray(keypoints, float)[..., :2]
    xy = xy[np.isfinite(xy).all(axis=-1)]
    w, h = image_size
    if len(xy) >= 8 and min(w, h) > 8 and np.all((xy >= -0.05) & (xy <= 1.05)):
        raise ClipFormatError(f"{where}: every keypoint lies within [0, 1] (coordinates normalised to the image, "
                              f"as MediaPipe gives them?); CLIP_FORMAT wants pixels of the {w}x{h} frames: "
                              f"multiply x by {w} and y by {h}")


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
        On malformed JSON, an unknown format, wrong joint counts, bad or repeated frame
        indices, or scores outside [0, 1].
    """
    path = Path(path)
    doc = _read_json(path)
    if not isinstance(doc, dict) or "frames" not in doc:
        raise ClipFormatError(f"{path}: expected an object with 'format' and 'frames'")
    fmt = doc.get("format", "h36m17")
    if fmt not in ("h36m17", "coco17"):
        raise ClipFormatError(f"{path}: unknown keypoint format {fmt!r} (h36m17 or coco17)")
    order = _joint_order(path, fmt, doc.get("joint_names"))
    frames = doc["frames"]
    if not isinstance(frames, list):
        raise ClipFormatError(f"{path}: 'frames' must be a list")
    idx, first = [], {}
    for k, entry in enumerate(frames):
        if not isinstance(entry, dict) or "frame" not in entry:
            raise ClipFormatError(f"{path}: frames[{k}] lacks 'frame'")
        v = entry["frame"]
        try:
            fi = int(v)
            if isinstance(v, bool) or fi != v:  # 5.5 or true: not a frame number (int() would take them)
                raise ValueError
        except (TypeError, ValueError):
            raise ClipFormatError(f"{path}: frames[{k}] has a non-integer frame index {v!r}") from None
        if fi < 0:
            raise ClipFormatError(f"{path}: frames[{k}] has a negative frame index {fi}")
        if fi in first:  # two detections for one frame: which one is the athlete is not ours to guess
            raise ClipFormatError(f"{path}: frame {fi} is listed twice (frames[{first[fi]}] and frames[{k}]); "
                                  f"give one entry per frame")
        first[fi] = k
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
    if order is not None:  # columns named in another order: put each joint where the format has it
        out = out[:, order]
    scores = out[..., 2]
    with np.errstate(invalid="ignore"):
        bad_score = np.isfinite(scores) & ((scores < 0) | (scores > 1 + 1e-6))
    if np.any(bad_score):
        fi, ji = np.argwhere(bad_score)[0]
        raise ClipFormatError(f"{path}: frame {fi}, joint {ji}: score {scores[fi, ji]:g} outside [0, 1] "
                              f"({int(bad_score.sum())} scores out of range); scores are detector "
                              f"confidences from 0 to 1: rescale them (e.g. divide 0-100 scores by 100)")
    if fmt == "coco17":
        out = coco_to_h36m(out)
    # a joint with any NaN coordinate is missing as a whole
    bad = np.any(~np.isfinite(out), axis=-1)
    out[bad] = np.nan
    return out


def _joint_order(path, fmt, names):
    """Where each of ``fmt``'s joints is among the optional ``joint_names`` of a keypoints file:
    ``None`` when they are absent, spelled otherwise (not checked) or in the format's own order;
    the index array that puts the joints in the format's order when they are the format's names in
    another order.  Names in the other format's order contradict ``format`` (every joint would be
    read as another one): a :class:`ClipFormatError`.

    >>> names = list(JOINT_NAMES)
    >>> _joint_order("k.json", "h36m17", names) is None, _joint_order("k.json", "h36m17", None) is None
    (True, True)
    >>> _joint_order("k.json", "h36m17", names[::-1])[:3].tolist()  # pelvis is the last column, ...
    [16, 15, 14]
    >>> _joint_order("k.json", "h36m17", list(COCO_NAMES))
    Traceback (most recent call last):
    probreg.io.clip.ClipFormatError: k.json: 'format' says h36m17 but 'joint_names' are coco17's names; set "format": "coco17" (or fix the names)
    """
    if not isinstance(names, list):
        return None
    given = sorted(map(str, names))
    own = list(JOINT_NAMES if fmt == "h36m17" else COCO_NAMES)
    other, other_names = ("coco17", COCO_NAMES) if fmt == "h36m17" else ("h36m17", JOINT_NAMES)
    if given == sorted(other_names) != sorted(own):
        raise ClipFormatError(f"{path}: 'format' says {fmt} but 'joint_names' are {other}'s names; "
                              f"set \"format\": \"{other}\" (or fix the names)")
    if names == own or given != sorted(own):
        return None
    return np.array([names.index(n) for n in own])


def write_keypoints_json(path, keypoints_px, fmt="h36m17", written_by=None):
    """Write ``(F, 17, 3)`` keypoints; an all-NaN frame is written as ``null``.  ``written_by``
    (e.g. ``"probreg detect"``), when given, is stored as a key of that name (readers ignore it)."""
    kp = np.asarray(keypoints_px, float)
    frames = []
    for i, k in enumerate(kp):
        if np.all(np.isnan(k)):
            frames.append({"frame": i, "keypoints": None})
        else:
            frames.append({"frame": i, "keypoints": [[None if not np.isfinite(v) else round(float(v), 4)
                                                      for v in row] for row in k]})
    names = list(JOINT_NAMES if fmt == "h36m17" else COCO_NAMES)
    write_json(path, {"format": fmt, "joint_names": names, "frames": frames,
                      **({"written_by": written_by} if written_by else {})})


def written_by_detect(path):
    """Whether ``path`` is a keypoints file ``probreg detect`` wrote (it may replace it)."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and str(doc.get("written_by", "")).startswith("probreg detect")


#: frame rates a clip may have (frames per second)
FPS_RANGE = (1.0, 1000.0)

#: accepted ``lane_width_m`` (m): World Athletics lanes are 1.22 m wide (1.25 m on older tracks); the
#: range only stops a typo or a sign error, which would otherwise leave every frame without a camera
LANE_WIDTH_RANGE_M = (0.5, 3.0)
#: image file endings read as frames
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
_FRAME_NAME = re.compile(r"\d+")


def _index_frames(frame_dir: Path):
    """``{frame number: path}`` of ``frames/`` by the number in each file name, and notes.

    Raises
    ------
    ClipFormatError
        If two files carry the same frame number.
    """
    found, ignored = {}, []
    for p in sorted(frame_dir.iterdir()):
        if not (p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and _FRAME_NAME.fullmatch(p.stem)):
            if not p.name.startswith("."):
                ignored.append(p.name)
            continue
        k = int(p.stem)
        if k in found:
            raise ClipFormatError(f"{found[k]} and {p}: both are frame {k}; keep one of them")
        found[k] = p
    notes = []
    if ignored:
        notes.append(f"{frame_dir}: ignored {len(ignored)} file(s) that are not frames "
                     f"(name must be the frame number, e.g. 000041.jpg): {', '.join(ignored[:5])}"
                     + (" ..." if len(ignored) > 5 else ""))
    return found, notes


def _check_number(meta, key, path, lo, hi, what):
    v = meta.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise ClipFormatError(f"{path}: '{key}' must be {what} between {lo:g} and {hi:g}, got {v!r}")
    return v


def _video_length_notes(count, video, n):
    """A note when the video's container says it holds ``count`` frames, fewer or more than the
    clip's ``n`` (``clip.json``'s ``n_frames``, else the keypoints'): the frames past the video's
    end have no image; frames past the clip's end are not read.  Nothing without a count (0).

    >>> _video_length_notes(20, "v.mp4", 40)
    ['v.mp4: 20 frames, the clip 40 (clip.json n_frames or the keypoints): frames 20 to 39 have no image (status bad_image)']
    >>> _video_length_notes(0, "v.mp4", 40), _video_length_notes(40, "v.mp4", 40)
    ([], [])
    """
    if count <= 0 or count == n:
        return []
    if count < n:
        return [f"{video}: {count} frames, the clip {n} (clip.json n_frames or the keypoints): frames {count} to "
                f"{n - 1} have no image (status bad_image)"]
    return [f"{video}: {count} frames, the clip {n} (clip.json n_frames or the keypoints): the last {count - n} "
            f"are not read"]


def _actual_image_size(frame_paths, video):
    """``((W, H), source path, frame count)`` of the video (its container's count, 0 when it gives
    none) or of the first readable frame (count None), or None."""
    import cv2

    if video is not None:
        cap = cv2.VideoCapture(str(video))
        try:
            if cap.isOpened():
                w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
                count = max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), 0)
                return ((w, h), video, count) if w > 0 and h > 0 else None
        finally:
            cap.release()
        return None
    for p in frame_paths:
        if p is None:
            continue
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is not None:
            return (img.shape[1], img.shape[0]), p, None


def load_clip(path, min_score=0.0):
    """Load a clip folder and check it against ``CLIP_FORMAT.md``.

    Frames are matched to keypoints by the number in the image's file name, never by their
    position in a listing: a missing image leaves its frame without an image (status
    ``missing_image`` downstream), a file that is not named by a frame number is ignored with
    a note, and two files with one number are an error.  Keypoints more than one image size
    outside the image (absurd coordinates) are treated as missing, with a note and a count
    per frame (:attr:`Clip.keypoints_outside`).  Frames without any detected joint are counted in a
    note (the run's ``keypoint_status`` says which).

    Parameters
    ----------
    path : path-like
    min_score : float
        Joints with a lower detection score become missing (NaN).

    Raises
    ------
    ClipFormatError
        If the folder, ``clip.json`` or ``keypoints2d.json`` is missing or malformed; if
        ``fps`` is not within :data:`FPS_RANGE` or ``lane_width_m`` within
        :data:`LANE_WIDTH_RANGE_M`; if ``image_size`` disagrees with the frames;
        if keypoint scores lie outside [0, 1]; if two images carry one frame number.
    ValueError
        If ``min_score`` is not a confidence in [0, 1] (above 1 it would drop every keypoint).
    """
    if not 0 <= min_score <= 1:
        raise ValueError(f"min_score must be a confidence between 0 and 1, got {min_score}")
    path = Path(path)
    if not path.is_dir():
        raise ClipFormatError(f"{path}: clip folder not found")
    cj = path / "clip.json"
    meta = _read_json(cj)
    if not isinstance(meta, dict):
        raise ClipFormatError(f"{cj}: expected a JSON object")
    if "fps" not in meta or "image_size" not in meta:
        raise ClipFormatError(f"{cj}: needs 'fps' and 'image_size': [W, H]")
    fps = float(_check_number(meta, "fps", cj, *FPS_RANGE, "a frame rate (frames per second)"))
    size = meta["image_size"]
    if (not isinstance(size, list) or len(size) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 100_000 for v in size)):
        raise ClipFormatError(f"{cj}: 'image_size' must be [width, height] in whole pixels, got {size!r}")
    w, h = size
    lane = meta.get("athlete_lane")
    if lane is not None and (not isinstance(lane, int) or not 1 <= lane <= 9):
        raise ClipFormatError(f"{cj}: athlete_lane must be a lane number 1..9")
    if meta.get("lane_width_m") is not None:
        _check_number(meta, "lane_width_m", cj, *LANE_WIDTH_RANGE_M,
                      "the lane width in metres (1.22 on a standard track)")
    if meta.get("n_frames") is not None:
        _check_number(meta, "n_frames", cj, 1, 10_000_000, "a whole number of frames")
        if meta["n_frames"] != int(meta["n_frames"]):
            raise ClipFormatError(f"{cj}: 'n_frames' must be a whole number, got {meta['n_frames']!r}")
    notes = []
    frame_dir = path / "frames"
    found = {}
    if frame_dir.is_dir():
        found, notes_f = _index_frames(frame_dir)
        notes += notes_f
    n_meta = int(meta["n_frames"]) if meta.get("n_frames") is not None else None
    n = n_meta or ((max(found) + 1) if found else None)
    if n_meta is not None and found and max(found) >= n_meta:
        beyond = sorted(k for k in found if k >= n_meta)
        notes.append(f"{frame_dir}: {len(beyond)} image(s) beyond the clip's {n_meta} frames ignored "
                     f"(first: {found[beyond[0]].name})")
    kp = None
    outside = None
    if (path / "keypoints2d.json").exists():
        kp = read_keypoints_json(path / "keypoints2d.json", n_frames=n)
        x, y = kp[..., 0], kp[..., 1]
        check_pixel_coordinates(kp, (w, h), path / "keypoints2d.json")
        # absurd coordinates (far outside the image) are not detections: treat them as missing
        with np.errstate(invalid="ignore"):
            far = (x < -w) | (x > 2 * w) | (y < -h) | (y > 2 * h)
        if np.any(far):
            outside = far.sum(axis=1).astype(int)
            fi, ji = np.argwhere(far)[0]
            notes.append(f"{path / 'keypoints2d.json'}: {int(far.sum())} joint(s) in {int(np.sum(outside > 0))} "
                         f"frame(s) lie more than one image size outside the {w}x{h} image (first: frame "
                         f"{fi}, {JOINT_NAMES[ji]} at ({x[fi, ji]:.4g}, {y[fi, ji]:.4g})); treated as missing")
            kp[far] = np.nan
        if min_score > 0:
            kp[kp[..., 2] < min_score] = np.nan
        n = len(kp)
        empty = np.flatnonzero(np.all(np.isnan(kp[..., :2]).reshape(n, -1), axis=1))
        if len(empty):
            notes.append(f"{path / 'keypoints2d.json'}: no detected joint in {len(empty)} of {n} frames (first: "
                         f"frame {empty[0]}); their angles are NaN unless a short gap is bridged "
                         f"(run.json: keypoint_status)")
    frame_paths = [found.get(i) for i in range(n)] if found and n else []
    missing = [i for i, p in enumerate(frame_paths) if p is None]
    if missing:
        notes.append(f"{frame_dir}: no image for {len(missing)} of {n} frames (first: frame {missing[0]}); "
                     f"their status is missing_image")
    video = path / "video.mp4"
    actual = _actual_image_size(frame_paths, video if (not frame_paths and video.exists()) else None)
    if actual is not None and actual[2] is not None and n:
        notes += _video_length_notes(actual[2], video, n)
    if actual is not None and tuple(actual[0]) != (w, h):
        (aw, ah), src, _ = actual
        raise ClipFormatError(f"{cj}: 'image_size' is [{w}, {h}] but {src} is {aw}x{ah} pixels "
                              f"(expected [width, height] of the frames)")
    return Clip(path=path, fps=fps, image_size=(w, h), keypoints_px=kp, frame_paths=frame_paths,
                athlete_lane=lane, lane_width_m=float(meta.get("lane_width_m", 1.22)), meta=meta,
                notes=tuple(notes), keypoints_outside=outside)


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
            out[fi] = cam = Camera.from_dict(entry, image_size=image_size)
        except (ValueError, TypeError) as exc:
            raise ClipFormatError(f"{path}: frame {fi}: {exc}") from None
        if not cam.C[2] > 0:  # the rays would never come down onto the track
            raise ClipFormatError(f"{path}: frame {fi}: camera centre at z = {cam.C[2]:g} m, not above the track "
                                  f"(the track frame's z points up from the track at z = 0; CLIP_FORMAT)")
    return out


#: user-given segment lengths above this (m) are taken for a unit error: no human segment
#: (thigh, trunk, shoulder width, ...) is longer, and lengths in centimetres all are
MAX_GIVEN_SEGMENT_M = 1.5


def read_segments_json(path):
    """Segment lengths (m) a user gives in a JSON file: ``{"thigh": 0.45, ...}`` or an
    ``athlete.json`` with them under ``"segments_m"``.  Raises :class:`ClipFormatError` for a
    file that is not such an object, or a length above :data:`MAX_GIVEN_SEGMENT_M` (centimetres
    for metres); the names and values are checked by the lifting (:func:`probreg.lifting.lift`)."""
    path = Path(path)
    doc = _read_json(path)
    seg = doc.get("segments_m", doc) if isinstance(doc, dict) else doc
    if not isinstance(seg, dict):
        raise ClipFormatError(f"{path}: expected an object of segment lengths in metres, e.g. "
                              f'{{"thigh": 0.45, "shank": 0.43}} (or an athlete.json with "segments_m")')
    for name, v in seg.items():
        try:
            x = float("nan") if isinstance(v, bool) else float(v)
        except (TypeError, ValueError):
            continue  # not a number: the lifting names it
        if x > MAX_GIVEN_SEGMENT_M:
            raise ClipFormatError(f"{path}: segment {name!r} is {x:g} m long; lengths are in metres (no human "
                                  f"segment exceeds {MAX_GIVEN_SEGMENT_M:g} m: centimetres?)")
    return seg


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
