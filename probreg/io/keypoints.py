"""Readers of the 2D keypoint files sports scientists already have, one function per format.

All readers return H36M-17 keypoints ``(F, 17, 3)`` ``(x, y, score)`` in image
pixels with NaN for missing joints; joints below ``min_score`` become missing
(never zeros).  Errors name the file and the line or frame.

Formats
-------
``coco``      COCO results JSON (a list of ``{"image_id", "keypoints": [x, y, v] * 17, "score"}``);
              frames are the sorted image ids; the best-scoring person per image is kept.
``openpose``  a folder of OpenPose per-frame JSON files (``*_keypoints.json``), BODY_25 or COCO-18.
``csv``       ``frame,<joint>_x,<joint>_y[,<joint>_score],...`` with COCO-17 or H36M-17 joint names.
``npy``       ``.npy``/``.npz`` array (F, 17, 2|3) in COCO-17 (``--layout coco17``) or H36M-17 order.
``trc``       a Pose2Sim/Sports2D TRC file with 2D pixel coordinates (Z ignored).
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np

from ..geometry import COCO_NAMES, JOINT_NAMES, coco_to_h36m
from .clip import ClipFormatError, _read_json

__all__ = ["read_keypoints", "read_coco_results", "read_openpose_folder", "read_keypoint_csv",
           "read_keypoint_array", "read_trc", "FORMATS", "BODY25_TO_COCO", "COCO18_TO_COCO"]

#: BODY_25 index of each COCO-17 joint (OpenPose's body model).
BODY25_TO_COCO = [0, 16, 15, 18, 17, 5, 2, 6, 3, 7, 4, 12, 9, 13, 10, 14, 11]
#: OpenPose COCO-18 index of each COCO-17 joint (18 adds a neck at index 1).
COCO18_TO_COCO = [0, 15, 14, 17, 16, 5, 2, 6, 3, 7, 4, 11, 8, 12, 9, 13, 10]


def _finish(kp_coco_or_h36m, layout, min_score):
    kp = np.asarray(kp_coco_or_h36m, float)
    if kp.shape[-1] == 2:
        kp = np.concatenate([kp, np.ones(kp.shape[:-1] + (1,))], -1)
    kp[~np.all(np.isfinite(kp), -1)] = np.nan
    kp[kp[..., 2] < min_score] = np.nan  # low confidence = missing, never zeros
    if layout == "coco17":
        kp = coco_to_h36m(kp)
    return kp


def read_coco_results(path, min_score=0.3):
    """COCO keypoint results (list of detections) -> (F, 17, 3) H36M; frames = sorted image ids."""
    doc = _read_json(path)
    if isinstance(doc, dict) and "annotations" in doc:
        doc = doc["annotations"]
    if not isinstance(doc, list):
        raise ClipFormatError(f"{path}: expected a list of COCO detections")
    best = {}
    for k, det in enumerate(doc):
        try:
            img = det["image_id"]
            kps = np.asarray(det["keypoints"], float)
        except (KeyError, TypeError, ValueError):
            raise ClipFormatError(f"{path}: detection {k} lacks 'image_id' or numeric 'keypoints'") from None
        if kps.size != 51:
            raise ClipFormatError(f"{path}: detection {k} (image {img}) has {kps.size // 3} keypoints, "
                                  f"COCO needs 17")
        score = float(det.get("score", np.nanmean(kps[2::3])))
        if img not in best or score > best[img][0]:
            best[img] = (score, kps.reshape(17, 3))
    if not best:
        raise ClipFormatError(f"{path}: no detections")
    ids = sorted(best)
    return _finish(np.stack([best[i][1] for i in ids]), "coco17", min_score)


def read_openpose_folder(folder, min_score=0.3):
    """OpenPose per-frame JSON files -> (F, 17, 3) H36M.

    Per frame the person kept is the one nearest the previous frame's (the
    athlete followed), starting with the most confident; a frame with nobody is missing.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ClipFormatError(f"{folder}: OpenPose folder not found")
    files = sorted(folder.glob("*_keypoints.json")) or sorted(folder.glob("*.json"))
    if not files:
        raise ClipFormatError(f"{folder}: no OpenPose JSON files")
    frames = []
    prev = None
    for i, f in enumerate(files):
        doc = _read_json(f)
        people = doc.get("people", []) if isinstance(doc, dict) else None
        if people is None:
            raise ClipFormatError(f"{f}: expected an object with 'people' (frame {i})")
        cands = []
        for p in people:
            flat = np.asarray(p.get("pose_keypoints_2d", []), float)
            n = flat.size // 3
            if n == 25:
                coco = flat.reshape(25, 3)[BODY25_TO_COCO]
            elif n == 18:
                coco = flat.reshape(18, 3)[COCO18_TO_COCO]
            else:
                raise ClipFormatError(f"{f}: frame {i}: {n} keypoints; expected BODY_25 or COCO-18")
            coco = coco.copy()
            coco[coco[:, 2] <= 0] = np.nan  # OpenPose writes (0, 0, 0) for undetected joints
            cands.append(coco)
        if not cands:
            frames.append(np.full((17, 3), np.nan))
            continue
        if prev is None:
            pick = max(cands, key=lambda c: np.nanmean(c[:, 2]) if np.isfinite(c[:, 2]).any() else -1)
        else:
            pick = min(cands, key=lambda c: np.nanmedian(np.linalg.norm(c[:, :2] - prev[:, :2], axis=1))
                       if np.isfinite(c[:, :2]).any() else np.inf)
        frames.append(pick)
        prev = pick
    return _finish(np.stack(frames), "coco17", min_score)


def _norm_name(name):
    s = re.sub(r"[^a-z0-9]", "", name.lower())
    s = {"rhip": "r_hip", "lhip": "l_hip", "rknee": "r_knee", "lknee": "l_knee", "rankle": "r_ankle",
         "lankle": "l_ankle", "rshoulder": "r_shoulder", "lshoulder": "l_shoulder", "relbow": "r_elbow",
         "lelbow": "l_elbow", "rwrist": "r_wrist", "lwrist": "l_wrist", "reye": "r_eye", "leye": "l_eye",
         "rear": "r_ear", "lear": "l_ear"}.get(s, s)
    for full in set(JOINT_NAMES) | set(COCO_NAMES):
        if s == full.replace("_", "") or s == full:
            return full
        if s.startswith("right") and full == "r_" + s[5:]:
            return full
        if s.startswith("left") and full == "l_" + s[4:]:
            return full
    return s


def _assemble(named, n_frames, path):
    """Named joint tracks -> (F, 17, 3) in H36M or COCO layout (whichever the names cover)."""
    names = set(named)
    if {"nose", "l_eye"} & names or ({"l_hip", "r_hip"} <= names and "pelvis" not in names):
        order, layout = COCO_NAMES, "coco17"
    else:
        order, layout = JOINT_NAMES, "h36m17"
    missing = [n for n in order if n not in named]
    if layout == "coco17":
        # face points are optional (the head is derived from whatever is there)
        hard = [n for n in missing if n not in ("l_eye", "r_eye", "l_ear", "r_ear")]
    else:
        hard = missing
    if hard:
        raise ClipFormatError(f"{path}: no columns/markers for joints {hard}")
    out = np.full((n_frames, 17, 3), np.nan)
    for j, n in enumerate(order):
        if n in named:
            out[:, j] = named[n]
    return out, layout


def read_keypoint_csv(path, min_score=0.3):
    """CSV with ``frame,<joint>_x,<joint>_y[,<joint>_score]`` columns (COCO or H36M names)."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise ClipFormatError(f"{path}: file not found") from None
    if len(rows) < 2:
        raise ClipFormatError(f"{path}: needs a header and at least one row")
    header = [h.strip() for h in rows[0]]
    cols = {}
    for c, h in enumerate(header):
        m = re.match(r"(.+)_(x|y|score|likelihood|conf)$", h)
        if m:
            cols.setdefault(_norm_name(m.group(1)), {})[m.group(2)[0] if m.group(2) in ("x", "y") else "s"] = c
    if not cols:
        raise ClipFormatError(f"{path}: no '<joint>_x'/'<joint>_y' columns in the header")
    data = []
    for ln, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise ClipFormatError(f"{path}: line {ln} has {len(r)} fields, the header {len(header)}")
        try:
            data.append([float(v) if v.strip() not in ("", "nan", "NaN") else np.nan for v in r])
        except ValueError:
            raise ClipFormatError(f"{path}: line {ln} holds a value that is not a number") from None
    data = np.array(data)
    named = {}
    for n, c in cols.items():
        if "x" not in c or "y" not in c:
            raise ClipFormatError(f"{path}: joint {n!r} lacks an x or a y column")
        s = data[:, c["s"]] if "s" in c else np.ones(len(data))
        named[n] = np.stack([data[:, c["x"]], data[:, c["y"]], s], -1)
    kp, layout = _assemble(named, len(data), path)
    return _finish(kp, layout, min_score)


def read_keypoint_array(path, layout="h36m17", min_score=0.3):
    """``.npy``/``.npz`` (F, 17, 2|3) array; ``layout`` is ``h36m17`` or ``coco17``."""
    path = Path(path)
    try:
        arr = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise ClipFormatError(f"{path}: file not found") from None
    except ValueError as exc:
        raise ClipFormatError(f"{path}: not a NumPy array file ({exc})") from None
    if isinstance(arr, np.lib.npyio.NpzFile):
        keys = [k for k in ("keypoints", "keypoints_px", "kp") if k in arr.files] or arr.files[:1]
        arr = arr[keys[0]]
    arr = np.asarray(arr, float)
    if arr.ndim != 3 or arr.shape[1] != 17 or arr.shape[2] not in (2, 3):
        raise ClipFormatError(f"{path}: expected shape (frames, 17, 2|3), got {arr.shape}")
    if layout not in ("h36m17", "coco17"):
        raise ClipFormatError(f"unknown joint layout {layout!r} (h36m17 or coco17)")
    return _finish(arr, layout, min_score)


def read_trc(path, min_score=0.3, image_height=None):
    """TRC marker file with 2D pixel coordinates (Pose2Sim/Sports2D).

    Marker names are matched to COCO/H36M joints (``RHip``, ``LKnee``, ``Nose``, ...).
    Sports2D writes pixel TRCs with ``y`` pointing up; give ``image_height`` to turn
    them back into image rows (``y_image = image_height - y``) when all ``y`` look inverted.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except FileNotFoundError:
        raise ClipFormatError(f"{path}: file not found") from None
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise ClipFormatError(f"{path}: not a TRC file (first line must start with 'PathFileType')")
    names_line = lines[3].split("\t")
    markers = [m.strip() for m in names_line[2:] if m.strip()]
    if not markers:
        raise ClipFormatError(f"{path}: line 4 lists no marker names")
    data = []
    for ln, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        vals = line.split("\t")
        try:
            nums = [float(v) if v.strip() else np.nan for v in vals]
        except ValueError:
            raise ClipFormatError(f"{path}: line {ln} holds a value that is not a number") from None
        if len(nums) < 2 + 3 * len(markers):
            nums += [np.nan] * (2 + 3 * len(markers) - len(nums))
        data.append(nums[: 2 + 3 * len(markers)])
    if not data:
        raise ClipFormatError(f"{path}: no data rows")
    data = np.array(data)
    named = {}
    for k, m in enumerate(markers):
        x, y = data[:, 2 + 3 * k], data[:, 3 + 3 * k]
        if image_height is not None:
            y = image_height - y
        named[_norm_name(m)] = np.stack([x, y, np.ones(len(data))], -1)
    kp, layout = _assemble(named, len(data), path)
    return _finish(kp, layout, min_score)


FORMATS = {
    "coco": read_coco_results,
    "openpose": read_openpose_folder,
    "csv": read_keypoint_csv,
    "npy": read_keypoint_array,
    "trc": read_trc,
}


def read_keypoints(path, fmt=None, **kwargs):
    """Dispatch on ``fmt`` (or guess it from the path): returns (F, 17, 3) H36M keypoints.

    Raises
    ------
    ClipFormatError
        For unknown formats and every malformed input.
    """
    path = Path(path)
    if fmt is None:
        fmt = ("openpose" if path.is_dir() else {".json": "coco", ".csv": "csv", ".npy": "npy", ".npz": "npy",
                                                   ".trc": "trc"}.get(path.suffix.lower()))
    if fmt not in FORMATS:
        raise ClipFormatError(f"{path}: unknown keypoint format {fmt!r}; choose from {sorted(FORMATS)}")
    return FORMATS[fmt](path, **kwargs)
