"""Cross-stride smoothing of a lifted clip's hip, knee and elbow angles (rigid moves of the joints
that give the skeleton the smoothed angles; segment lengths unchanged)."""

from __future__ import annotations

import numpy as np

from ..filtering import periodic_smooth_pair, periodic_smooth_series
from ..geometry import JOINT_INDEX, joint_angles

__all__ = ["smooth_angles_across_strides"]

J = JOINT_INDEX


def _rotate(v, axis, angle):
    """Rodrigues rotation of vectors v (F, 3) about unit axes (F, 3) by angles (F,) (radians)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, -1, keepdims=True) * (1 - c)


def _unit_or(v, fallback):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 1e-9, v / np.maximum(n, 1e-12), fallback)


def smooth_angles_across_strides(joints_track_m, forward, lag, fps, rho=0.0, smooth_cutoff_hz=14.0, pair_min_sd=2.0):
    """Cross-stride smoothing of the hip, knee and elbow angles of a lifted clip.

    Detector noise reaches each lifted angle as a series of its own, new in every
    stride, while the running pattern repeats with small stride-to-stride changes.
    The left and right series of each hip, knee and elbow angle are smoothed together
    with :func:`probreg.filtering.periodic_smooth_pair` (each side tied to itself one
    stride later and to the other side half a stride later; noise level, stride
    variability and asymmetry estimated from the series), and the joints are moved
    rigidly so that the skeleton has exactly the smoothed angles: the whole leg
    turns about the hip in the sagittal plane (hip angle), the shank about the
    knee and the forearm about the elbow in the limb's own plane (flexion).
    Segment lengths are unchanged.

    Parameters
    ----------
    joints_track_m : ndarray (F, 17, 3)
    forward : ndarray (F, 3)
        Running direction per frame (as for :func:`probreg.geometry.skeleton.joint_angles`).
    lag : ndarray (F,)
        Stride lag per frame (:func:`probreg.filtering.stride_lags`).
    fps : float
    rho : float
        Lag-1 correlation of the angle noise.
    pair_min_sd : float or None
        Left and right sides of each angle are smoothed together, tied half a stride apart
        (:func:`probreg.filtering.periodic_smooth_pair`), with their asymmetry sd floored at
        this value (degrees); None smooths each side alone.

    Returns
    -------
    joints : ndarray (F, 17, 3)
    info : dict
        Per angle ``(noise_sd, stride_sd)`` in degrees as estimated by the smoother.
    """
    j = np.array(joints_track_m, float)
    f = np.asarray(forward, float)
    left = np.column_stack([-f[:, 1], f[:, 0], np.zeros(len(f))])
    # the moves below are rigid and each leaves the other angles as they are (the turn about
    # the hip keeps the knee's flexion), so the angles are measured once
    angles = joint_angles(j, forward=f)
    info = {}
    fits = {}
    for base in ("hip", "knee", "elbow"):
        yl, yr = angles[f"{base}_l"], angles[f"{base}_r"]
        if pair_min_sd is None:
            for name, y in ((f"{base}_l", yl), (f"{base}_r", yr)):
                x, inf = periodic_smooth_series(y, lag, fps, rho=rho, smooth_cutoff_hz=smooth_cutoff_hz)
                fits[name], info[name] = x, (inf["noise_sd"], inf["stride_sd"])
            continue
        (xl, xr), inf = periodic_smooth_pair(yl, yr, lag, fps, rho=rho, smooth_cutoff_hz=smooth_cutoff_hz,
                                            min_asym=pair_min_sd)
        for k, (name, x) in enumerate(((f"{base}_l", xl), (f"{base}_r", xr))):
            fits[name], info[name] = x, (inf["noise_sd"][k], inf["stride_sd"][k])

    def smoothed(name):
        x = fits[name]
        d = np.radians(x - angles[name])
        return np.where(np.isfinite(d), d, 0.0), x

    for side in ("l", "r"):
        hip, knee, ankle = (J[f"{side}_{n}"] for n in ("hip", "knee", "ankle"))
        # hip angle: the leg turns about the hip; turning by -d about ``left`` raises the
        # thigh's angle atan2(v.f, -v.z) by d
        d, _ = smoothed(f"hip_{side}")
        for k in (knee, ankle):
            j[:, k] = j[:, hip] + _rotate(j[:, k] - j[:, hip], left, -d)
        # knee flexion (the angle between thigh and shank directions): the shank turns away
        # from the thigh's direction in their common plane
        for (a, b, c), name, default in (((hip, knee, ankle), f"knee_{side}", left),
                                         ((J[f"{side}_shoulder"], J[f"{side}_elbow"], J[f"{side}_wrist"]),
                                          f"elbow_{side}", -left)):
            d, x = smoothed(name)
            u = j[:, b] - j[:, a]
            v = j[:, c] - j[:, b]
            axis = _unit_or(np.cross(u, v), default)
            # flexion is unsigned: a target below zero stays at a straight limb
            d = np.where(np.isfinite(x) & (x < 0), d - np.radians(x), d)
            j[:, c] = j[:, b] + _rotate(v, axis, d)
    return j, info
