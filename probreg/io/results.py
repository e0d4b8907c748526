"""Writers (and readers) of the result layout of ``CLIP_FORMAT.md``: angles.csv, joints3d.npz."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..geometry import ANGLE_NAMES, JOINT_NAMES
from .clip import ClipFormatError

__all__ = ["write_angles_csv", "read_angles_csv", "write_joints_npz", "write_gait_cycle_csv", "read_gait_cycle_csv"]


def write_angles_csv(path, fps, median, lo=None, hi=None, frames=None):
    """Long-format ``frame,time_s,angle,median_deg,lo_deg,hi_deg``.

    Parameters
    ----------
    median, lo, hi : dict of str -> ndarray (F,)
        Per-angle series in degrees (``lo``/``hi``: 5 % / 95 % quantiles; default = median).
        NaN values are written as ``nan`` (frames the pipeline could not estimate).
    """
    lo = median if lo is None else lo
    hi = median if hi is None else hi
    n = len(next(iter(median.values())))
    frames = np.arange(n) if frames is None else np.asarray(frames)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "time_s", "angle", "median_deg", "lo_deg", "hi_deg"])
        for i, fr in enumerate(frames):
            for name in ANGLE_NAMES:
                if name not in median:
                    continue
                w.writerow([int(fr), f"{fr / fps:.4f}", name] +
                           [f"{float(v[name][i]):.3f}" for v in (median, lo, hi)])
    return Path(path)


def read_angles_csv(path):
    """Read ``angles.csv`` into ``{angle: (frames, median, lo, hi)}`` arrays.

    Raises
    ------
    ClipFormatError
        On a missing file or a wrong header.
    """
    path = Path(path)
    if not path.exists():
        raise ClipFormatError(f"{path}: file not found")
    with open(path, encoding="utf-8") as fh:
        r = csv.reader(fh)
        header = next(r, None)
        if header != ["frame", "time_s", "angle", "median_deg", "lo_deg", "hi_deg"]:
            raise ClipFormatError(f"{path}: unexpected header {header}")
        rows = list(r)
    out = {}
    for name in {row[2] for row in rows}:
        sel = [row for row in rows if row[2] == name]
        out[name] = tuple(np.array([float(row[k]) for row in sel]) for k in (0, 3, 4, 5))
    return out


def write_joints_npz(path, median, samples=None, **extra):
    """``joints3d.npz`` with ``median`` (F, 17, 3), ``joint_names`` and optional ``samples`` (S, F, 17, 3).

    Stored uncompressed: the draws' float noise deflates by ~11 % only, at ~0.13 s of the run's
    critical path for 60 draws of 250 frames (``np.load`` reads either)."""
    arrays = {"median": np.asarray(median, float), "joint_names": np.array(JOINT_NAMES)}
    if samples is not None:
        arrays["samples"] = np.asarray(samples, np.float32)
    arrays.update({k: np.asarray(v) for k, v in extra.items()})
    np.savez(path, **arrays)
    return Path(path)


GAIT_CYCLE_HEADER = ["angle", "side", "cycle_pct", "median_deg", "lo_deg", "hi_deg"]


def write_gait_cycle_csv(path, curves):
    """``gait_cycle.csv``: ``angle,side,cycle_pct,median_deg,lo_deg,hi_deg``, one row per angle,
    side (``L``/``R``) and cycle percentage.

    Parameters
    ----------
    curves : dict (angle, side) -> (cycle_pct, median, lo, hi[, n_cycles])
        As :func:`probreg.inference.gait_cycle_bands` returns them.
    """
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(GAIT_CYCLE_HEADER)
        for (angle, side), (pct, med, lo, hi, *_) in curves.items():
            for p, m, a, b in zip(pct, med, lo, hi):
                w.writerow([angle, side, f"{p:.1f}", f"{m:.3f}", f"{a:.3f}", f"{b:.3f}"])
    return Path(path)


def read_gait_cycle_csv(path):
    """Read ``gait_cycle.csv`` into ``{(angle, side): (cycle_pct, median, lo, hi)}`` arrays."""
    rows = {}
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            r = csv.reader(fh)
            header = next(r, None)
            if header != GAIT_CYCLE_HEADER:
                raise ClipFormatError(f"{path}: header {header} is not {GAIT_CYCLE_HEADER}")
            for line in r:
                rows.setdefault((line[0], line[1]), []).append([float(v) for v in line[2:6]])
    except (OSError, ValueError, IndexError) as exc:
        raise ClipFormatError(f"{path}: cannot read gait-cycle curves ({exc})") from None
    return {k: tuple(np.array(v).T) for k, v in rows.items()}
