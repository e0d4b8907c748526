"""Keeping the athlete out of the lane evidence: capsules around the 2D skeleton."""

from __future__ import annotations

import numpy as np

from ..geometry import BONES, JOINT_INDEX

__all__ = ["athlete_mask"]


#: Joint pairs whose 2-D segments outline the athlete for :func:`athlete_mask`: the skeleton's
#: bones plus the hip-shoulder sides and diagonals that span the torso.
_MASK_BONES = tuple((JOINT_INDEX[a], JOINT_INDEX[b]) for a, b in BONES + (
    ("r_hip", "r_shoulder"), ("l_hip", "l_shoulder"), ("r_hip", "l_shoulder"), ("l_hip", "r_shoulder")))

def athlete_mask(keypoints_px, radius_frac=0.12, margin_px=4.0):
    """The athlete's outline in one frame as capsules around the 2-D skeleton's bones.

    Lane lines are measured from perpendicular intensity profiles; where the athlete's
    body crosses or touches a line (a leg in front of a far line, the shirt beside it)
    the profile's centre and background are pulled.  The shift is small enough to pass
    the robust line fit yet follows the gait, so the camera's pan would follow the
    stride.  Support points near the athlete are therefore dropped.

    Parameters
    ----------
    keypoints_px : array_like, shape (17, 2 or 3)
        H36M-17 keypoints of the frame (NaN where missing).
    radius_frac : float
        Capsule radius as a fraction of the skeleton's extent (head to lowest ankle);
        a body's limbs are at most ~8 % of stature thick.
    margin_px : float
        Added to the radius (keypoint error, anti-aliasing).

    Returns
    -------
    ndarray, shape (S, 5) or None
        Capsules ``(x0, y0, x1, y1, radius)``; None when fewer than four joints are seen.

    >>> kp = np.full((17, 2), np.nan); kp[[0, 1, 2, 3]] = [[50, 0], [50, 10], [50, 50], [50, 100]]
    >>> athlete_mask(kp)[:, 4].round(1)  # extent 100 px: radius 12 + 4 px
    array([16., 16., 16.])
    """
    kp = np.asarray(keypoints_px, float)[:, :2]
    seen = np.isfinite(kp).all(axis=1)
    if seen.sum() < 4:
        return None
    extent = float(np.ptp(kp[seen], axis=0).max())
    caps = [(*kp[a], *kp[b]) for a, b in _MASK_BONES if seen[a] and seen[b]]
    if not caps:
        return None
    caps = np.array(caps, float)
    return np.column_stack([caps, np.full(len(caps), radius_frac * extent + margin_px)])


def _near_capsules(points, capsules, reach):
    """(N,) bool: points within ``radius + reach`` of any capsule (S, 5)."""
    if capsules is None or len(capsules) == 0 or len(points) == 0:
        return np.zeros(len(points), bool)
    out = np.zeros(len(points), bool)
    # only points inside the capsules' common bounding box can be near one (most are far away)
    grow = float(np.max(capsules[:, 4])) + reach
    lo = np.minimum(capsules[:, :2], capsules[:, 2:4]).min(axis=0) - grow
    hi = np.maximum(capsules[:, :2], capsules[:, 2:4]).max(axis=0) + grow
    inside = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
    if len(inside) == 0:
        return out
    points = points[inside]
    a, b, r = capsules[:, :2], capsules[:, 2:4], capsules[:, 4]
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-12)
    ap = points[:, None, :] - a[None]
    t = np.clip(np.sum(ap * ab[None], axis=-1) / L2, 0.0, 1.0)
    d2 = np.sum((ap - t[..., None] * ab[None]) ** 2, axis=-1)
    out[inside] = np.any(d2 < (r + reach)[None] ** 2, axis=1)
    return out
