"""Keeping the athlete out of the lane evidence: capsules around the 2D skeleton."""

from __future__ import annotations

import numpy as np

from ..geometry import BONES, JOINT_INDEX

__all__ = ["athlete_mask", "on_athlete_fraction"]


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


#: the skeleton's bones as joint index pairs (the points :func:`on_athlete_fraction` looks at)
_BONE_INDEX = np.array([(JOINT_INDEX[a], JOINT_INDEX[b]) for a, b in BONES])


def on_athlete_fraction(image, keypoints_px, bone_points=8, ring_points=128, ring_margin=0.35,
                        min_distance=8.0):
    """Whether one frame's 2-D keypoints lie on a person in its image: the share of points along
    the skeleton's bones whose colour is unlike every colour around the skeleton.

    Keypoints found on the frames themselves put most points of their bones on the athlete's
    body, whose kit, skin and shoes differ from the track, the lines and the grass around it.
    Keypoints that belong to other images (a pose model run on a resized or cropped copy, another
    clip, coordinates in the wrong unit) put their bones on whatever lies there, which looks like
    its surroundings.  The surroundings are sampled on an ellipse around the skeleton's box,
    ``ring_margin`` of its extent outside it; a bone point is *unlike* them when its colour is
    farther from every ring colour than 90 % of the ring's points are from their nearest other ring
    point (and at least ``min_distance`` grey levels, BGR Euclidean).  So on plain surroundings
    about a tenth of the points of a skeleton that lies on no person count as unlike; on the
    validation clips and on probreg's own, 0.97-1.0 of those of the clip's own keypoints do, and
    0.0-0.18 once the keypoints are scaled by 0.5-2 about the image corner
    (``docs/method.md``, "Keypoints that belong to other images").

    Parameters
    ----------
    image : ndarray (H, W, 3) uint8 or None
    keypoints_px : array_like (17, 2 or 3)
        H36M-17 keypoints of the frame, NaN where missing.

    Returns
    -------
    float
        In [0, 1]; a bone point off the image is not counted as unlike (it lies on nothing the
        image shows), so an athlete half out of the frame scores at most a half there.  NaN when
        the frame has no image or fewer than 8 joints, or too little of the ring lies inside it.

    >>> img = np.full((200, 200, 3), (40, 60, 160), np.uint8)  # a red track
    >>> kp = np.full((17, 2), np.nan)
    >>> kp[_BONE_INDEX[:, 0]] = [100, 60]; kp[_BONE_INDEX[:, 1]] = [100, 140]  # every bone on x = 100
    >>> img[50:150, 95:106] = (200, 180, 20)  # a body in a blue kit along them
    >>> on_athlete_fraction(img, kp), on_athlete_fraction(img, kp + [40, 0])
    (1.0, 0.0)
    """
    if image is None or getattr(image, "ndim", 0) != 3 or image.size == 0:
        return float("nan")
    kp = np.asarray(keypoints_px, float)[:, :2]
    seen = np.isfinite(kp).all(axis=1)
    bones = _BONE_INDEX[seen[_BONE_INDEX].all(axis=1)]
    if seen.sum() < 8 or len(bones) == 0:
        return float("nan")
    t = (np.arange(bone_points) + 0.5) / bone_points
    a, b = kp[bones[:, 0]], kp[bones[:, 1]]
    body = (a[:, None] + (b - a)[:, None] * t[None, :, None]).reshape(-1, 2)
    lo, hi = kp[seen].min(axis=0), kp[seen].max(axis=0)
    half = (hi - lo) / 2 + ring_margin * float(np.max(hi - lo))
    th = np.linspace(0.0, 2 * np.pi, ring_points, endpoint=False)
    ring = (lo + hi) / 2 + half * np.column_stack([np.cos(th), np.sin(th)])
    h, w = image.shape[:2]

    def colours(points):
        p = np.round(points).astype(np.int64)
        keep = (p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h)
        return image[p[keep, 1], p[keep, 0]].astype(np.float64)

    n_body = len(body)
    body, ring = colours(body), colours(ring)
    if len(body) == 0:
        return 0.0  # the whole skeleton lies off the image: on nothing it shows
    if len(ring) < ring_points // 8:
        return float("nan")
    # squared colour distances through one matrix product each (0.2 ms a 1080p frame in all)
    r2 = np.einsum("ij,ij->i", ring, ring)
    d_ring = r2[:, None] + r2[None] - 2.0 * (ring @ ring.T)
    np.fill_diagonal(d_ring, np.inf)
    nearest = np.sort(d_ring.min(axis=1))
    tau2 = max(float(nearest[int(round(0.9 * (len(nearest) - 1)))]), min_distance**2)  # the 90th percentile
    d_body = (np.einsum("ij,ij->i", body, body)[:, None] + r2[None] - 2.0 * (body @ ring.T)).min(axis=1)
    return float(np.sum(d_body > tau2) / n_body)  # a point off the image lies on nothing it shows


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
