"""OpenSim files: ``markers.trc`` (3D markers) and ``angles.mot`` (joint angles with their bands).

Both follow the text layouts OpenSim 4.x reads with its own adapters (``TRCFileAdapter`` for
``.trc``, ``STOFileAdapter``/``TimeSeriesTable`` for ``.mot``), the layouts Pose2Sim and Sports2D
write.

Coordinates
    OpenSim's ground frame has ``Y`` up.  probreg's track frame (``CLIP_FORMAT.md``) has ``x``
    along the straight in the running direction, ``y`` to the infield (the runner's left) and
    ``z`` up.  The markers are written as ``X = x`` (forward), ``Y = z`` (up), ``Z = -y`` (the
    runner's right): a proper rotation, so the model walks forward along ``X`` with its right side
    towards ``+Z``, OpenSim's convention for gait.

Markers
    The 14 markers of Pose2Sim's COCO-17 OpenSim model (``Markers_Coco17.xml``): ``Nose``,
    ``Neck``, ``LShoulder``, ``RShoulder``, ``LElbow``, ``RElbow``, ``LWrist``, ``RWrist``,
    ``LHip``, ``RHip``, ``LKnee``, ``RKnee``, ``LAnkle``, ``RAnkle``, from the Human3.6M joints
    (``Nose`` = ``neck``, the H36M nose/neck point; ``Neck`` = ``thorax``, mid-shoulders).  Frames
    without a 3D pose are written as ``NaN``, which OpenSim reads as missing markers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry import ANGLE_NAMES, JOINT_INDEX
from .clip import ClipFormatError

__all__ = ["TRC_MARKERS", "track_to_opensim", "opensim_to_track", "write_trc", "read_trc", "write_mot",
           "read_mot", "markers_from_joints"]

#: Pose2Sim COCO-17 marker name -> probreg (Human3.6M) joint
TRC_MARKERS = {
    "Nose": "neck", "Neck": "thorax",
    "LShoulder": "l_shoulder", "RShoulder": "r_shoulder", "LElbow": "l_elbow", "RElbow": "r_elbow",
    "LWrist": "l_wrist", "RWrist": "r_wrist", "LHip": "l_hip", "RHip": "r_hip",
    "LKnee": "l_knee", "RKnee": "r_knee", "LAnkle": "l_ankle", "RAnkle": "r_ankle",
}

_TO_OPENSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def track_to_opensim(points):
    """Track-frame points (..., 3) to OpenSim's ground frame (``Y`` up).

    >>> track_to_opensim(np.array([1.0, 2.0, 3.0])).tolist()
    [1.0, 3.0, -2.0]
    """
    return np.asarray(points, float) @ _TO_OPENSIM.T


def opensim_to_track(points):
    """Inverse of :func:`track_to_opensim`.

    >>> opensim_to_track(track_to_opensim(np.array([1.0, 2.0, 3.0]))).tolist()
    [1.0, 2.0, 3.0]
    """
    return np.asarray(points, float) @ _TO_OPENSIM


def markers_from_joints(joints_track_m):
    """(F, 17, 3) track-frame joints -> (F, 14, 3) OpenSim-frame markers in :data:`TRC_MARKERS` order."""
    j = np.asarray(joints_track_m, float)
    if j.ndim != 3 or j.shape[1:] != (17, 3):
        raise ValueError(f"joints must be (frames, 17, 3), got {j.shape}")
    idx = [JOINT_INDEX[v] for v in TRC_MARKERS.values()]
    return track_to_opensim(j[:, idx])


def _num(v):
    return "NaN" if not np.isfinite(v) else f"{v:.6f}"


def write_trc(path, joints_track_m, fps, frames=None):
    """``markers.trc`` of the 3D joints (track frame, metres), in OpenSim's frame (module docstring).

    Parameters
    ----------
    joints_track_m : ndarray (F, 17, 3)
    fps : float
    frames : array of int, optional
        Frame numbers (default 0..F-1); the TRC counts from 1 (``Frame#`` = frame + 1) and its
        ``Time`` is ``frame / fps``.
    """
    m = markers_from_joints(joints_track_m)
    F = len(m)
    frames = np.arange(F) if frames is None else np.asarray(frames, int)
    names = list(TRC_MARKERS)
    path = Path(path)
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{fps:.6g}\t{fps:.6g}\t{F}\t{len(names)}\tm\t{fps:.6g}\t{int(frames[0]) + 1 if F else 1}\t{F}",
        "Frame#\tTime\t" + "\t".join(f"{n}\t\t" for n in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, len(names) + 1)),
        "",
    ]
    for i in range(F):
        vals = "\t".join(_num(v) for v in m[i].ravel())
        lines.append(f"{int(frames[i]) + 1}\t{frames[i] / fps:.6f}\t{vals}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_trc(path):
    """Read a TRC file: ``(marker names, time (F,), markers (F, M, 3) in the file's frame)``.

    Raises
    ------
    ClipFormatError
        When the file is not a TRC (no ``Frame#`` header line) or its rows are malformed.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise ClipFormatError(f"{path}: cannot read ({exc})") from None
    hdr = next((k for k, ln in enumerate(text) if ln.startswith("Frame#")), None)
    if hdr is None:
        raise ClipFormatError(f"{path}: not a TRC file (no 'Frame#' header line)")
    names = [n for n in text[hdr].split("\t")[2:] if n.strip()]
    rows = [ln for ln in text[hdr + 2:] if ln.strip()]
    t, data = [], []
    for k, ln in enumerate(rows):
        cells = ln.split("\t")
        if len(cells) < 2 + 3 * len(names):
            cells += [""] * (2 + 3 * len(names) - len(cells))
        try:
            t.append(float(cells[1]))
            data.append([float(c) if c.strip() else np.nan for c in cells[2:2 + 3 * len(names)]])
        except ValueError as exc:
            raise ClipFormatError(f"{path}: data row {k + 1}: {exc}") from None
    return names, np.array(t), np.array(data, float).reshape(len(rows), len(names), 3)


def write_mot(path, fps, median, lo=None, hi=None, frames=None, in_degrees=True):
    """``angles.mot``: ``time`` and one column per angle (:data:`ANGLE_NAMES`), with its 5 % and
    95 % bounds as ``<angle>_lo`` and ``<angle>_hi`` when given.  Missing values are ``nan``
    (OpenSim's own spelling of a missing value in a storage file)."""
    names = [n for n in ANGLE_NAMES if n in median]
    cols, data = [], []
    for n in names:
        cols.append(n)
        data.append(np.asarray(median[n], float))
        for tag, src in (("lo", lo), ("hi", hi)):
            if src is not None and n in src:
                cols.append(f"{n}_{tag}")
                data.append(np.asarray(src[n], float))
    F = len(data[0]) if data else 0
    frames = np.arange(F) if frames is None else np.asarray(frames)
    path = Path(path)
    lines = [path.name, "version=1", f"nRows={F}", f"nColumns={len(cols) + 1}",
             f"inDegrees={'yes' if in_degrees else 'no'}", "endheader", "time\t" + "\t".join(cols)]
    for i in range(F):
        lines.append(f"{frames[i] / fps:.6f}\t" + "\t".join("nan" if not np.isfinite(d[i]) else f"{d[i]:.4f}"
                                                             for d in data))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_mot(path):
    """Read a ``.mot``/``.sto`` storage file: ``(columns without time, time (F,), data (F, C))``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise ClipFormatError(f"{path}: cannot read ({exc})") from None
    end = next((k for k, ln in enumerate(text) if ln.strip().lower() == "endheader"), None)
    if end is None or end + 1 >= len(text):
        raise ClipFormatError(f"{path}: not an OpenSim storage file (no 'endheader' line)")
    cols = text[end + 1].split("\t")
    if cols[0] != "time":
        raise ClipFormatError(f"{path}: the first column is {cols[0]!r}, not 'time'")
    try:
        arr = np.array([[float(c) for c in ln.split("\t")] for ln in text[end + 2:] if ln.strip()], float)
    except ValueError as exc:
        raise ClipFormatError(f"{path}: {exc}") from None
    arr = arr.reshape(-1, len(cols))
    return cols[1:], arr[:, 0], arr[:, 1:]
