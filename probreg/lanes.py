"""Lane-line detection and the vanishing point of the straight's lanes.

Per frame: a white-line response (morphological top-hat of the per-pixel
minimum over B, G, R: white is bright in every channel, the red track and the
green infield are not) at reduced resolution, ``cv2.HoughLinesP`` segments,
merging of collinear segments, sub-pixel re-measurement of every line at full
resolution (intensity centroids of short perpendicular profiles), rejection
of curved lines (bends), an exhaustive pair search for the vanishing point
that most long lines share (robust to the athlete, kerbs and stray marks),
and a least-squares refinement of the vanishing point in homogeneous
coordinates, so that a vanishing point at infinity (a camera square onto the
straight) is an ordinary case.  Lines are then re-fitted through the
vanishing point, ordered across the track, and given integer indices (a
missing line in the middle is found from the projective spacing fit when at
least four lines are seen).

Failures are per-frame statuses, never exceptions:

``ok``
    a pencil of at least three straight lines.
``too_few_lines``
    fewer than three lines share a vanishing point.
``no_straight``
    line evidence is there but curved (only a bend in view).
``no_lines``
    no line evidence at all.
``bad_image``
    the frame could not be read or is empty.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .camera import cross3, undistort_normalized
from .skeleton import BONES, JOINT_INDEX

__all__ = [
    "LaneDetectorConfig",
    "LaneLine",
    "FrameLanes",
    "STATUSES",
    "detect_lanes",
    "track_lanes",
    "lines_through_point",
    "assign_line_indices",
    "smooth_vanishing_points",
    "undistort_frame_lanes",
    "line_straightness_px",
    "draw_lanes",
    "athlete_mask",
]

STATUSES = ("ok", "too_few_lines", "no_straight", "no_lines", "bad_image")


@dataclass(frozen=True)
class LaneDetectorConfig:
    """Tuning of :func:`detect_lanes` (defaults work for 720p-1080p broadcast frames)."""

    work_width_px: int = 960
    tophat_px: int = 15
    threshold: int = 45
    hough_threshold: int = 50
    hough_theta_deg: float = 0.75
    #: share of the line pixels the Hough transform votes with (a fixed pseudo-random
    #: selection; its threshold scales with it): the transform's time is proportional to
    #: the points and it only seeds the rough lines, which are measured in the full image
    hough_point_fraction: float = 0.5
    min_length_frac: float = 0.08
    max_gap_px: int = 12
    merge_angle_deg: float = 1.0
    merge_dist_px: float = 4.0
    profile_step_px: float = 8.0
    #: how far (px, across the line) the measurement looks for a line's centre around a rough line
    profile_half_px: float = 10.0
    vp_inlier_deg: float = 0.35
    curved_sagitta_px: float = 0.8
    curved_curvature_per_px: float = 3e-5
    min_lines: int = 3
    max_missing_lines: int = 2
    redetect_every: int = 10
    max_segments: int = 80
    #: a line followed from the previous frame is rejected (and the frame fully re-detected)
    #: when its support scatters more than ``max(track_rms_px, track_rms_factor x`` the
    #: previous frame's worst line ``)``: the profiles caught a neighbouring line
    track_rms_px: float = 0.5
    track_rms_factor: float = 3.0


@dataclass(frozen=True)
class LaneLine:
    """One lane line in one frame.

    Attributes
    ----------
    line : ndarray, shape (3,)
        Homogeneous image line ``(a, b, c)`` with ``a**2 + b**2 = 1`` (so ``line @ (x, y, 1)``
        is a signed distance in px), in the (undistorted) pixel coordinates of the frame.
    points_px : ndarray, shape (N, 2)
        Sub-pixel centre points that support the line.
    rms_px : float
        RMS distance of the support points from the line.
    index : int or None
        Integer position across the track in the image order of the pencil
        (set once the pencil is ordered; the calibration decides which end is the infield).
    track_id : int or None
        Identity of the physical line across the frames of a clip (:func:`track_lanes`).
    """

    line: np.ndarray
    points_px: np.ndarray
    rms_px: float
    index: int | None = None
    track_id: int | None = None

    @property
    def endpoints_px(self):
        """The support's extreme points projected onto the line, shape (2, 2)."""
        d = np.array([-self.line[1], self.line[0]])
        t = self.points_px @ d
        foot = self.points_px - np.outer(self.points_px @ self.line[:2] + self.line[2], self.line[:2])
        return foot[[np.argmin(t), np.argmax(t)]]


@dataclass(frozen=True)
class FrameLanes:
    """Lane evidence of one frame.

    Attributes
    ----------
    status : str
        One of :data:`STATUSES`.
    lines : tuple of LaneLine
        Ordered across the track (by ``index``) when ``status == "ok"``.
    vanishing_point : ndarray, shape (3,) or None
        Homogeneous pixel coordinates, unit norm in the scaled frame of ``vp_scale``.
    vp_cov : ndarray, shape (3, 3) or None
        Covariance of the unit homogeneous vector ``vp_unit`` (rank 2).
    spacing_residual_px : float
        With four or more lines: RMS misfit of an equally spaced pencil (NaN otherwise).
    n_curved : int
        Curved line candidates that were rejected.
    image_size : tuple
    undistorted : bool
    """

    status: str
    lines: tuple = ()
    vanishing_point: np.ndarray | None = None
    vp_cov: np.ndarray | None = None
    spacing_residual_px: float = float("nan")
    n_curved: int = 0
    image_size: tuple = (1920, 1080)
    undistorted: bool = False
    frame: int | None = None
    extra: dict = field(default_factory=dict)

    @property
    def ok(self):
        return self.status == "ok"

    @property
    def indices(self):
        return np.array([ln.index for ln in self.lines])

    def vp_px(self):
        """Euclidean vanishing point (NaN when at infinity)."""
        if self.vanishing_point is None:
            return np.full(2, np.nan)
        v = self.vanishing_point
        if abs(v[2]) < 1e-12:
            return np.full(2, np.nan)
        return v[:2] / v[2]

    def to_dict(self):
        return {
            "frame": self.frame, "status": self.status,
            "vanishing_point": None if self.vanishing_point is None else self.vanishing_point.tolist(),
            "vp_cov": None if self.vp_cov is None else self.vp_cov.tolist(),
            "spacing_residual_px": self.spacing_residual_px, "n_curved": self.n_curved,
            "lines": [{"index": ln.index, "line": ln.line.tolist(), "rms_px": ln.rms_px,
                       "endpoints_px": ln.endpoints_px.tolist(), "n_points": len(ln.points_px)}
                      for ln in self.lines],
        }


# --------------------------------------------------------------------------- helpers
def _scale_frame(image_size):
    """Centre and scale that map pixels to O(1) coordinates (conditioning of homogeneous maths)."""
    w, h = image_size
    return np.array([(w - 1) / 2, (h - 1) / 2]), float(np.hypot(w, h)) / 2


def _to_unit(v_px, image_size):
    """Homogeneous pixel point -> unit vector in the scaled frame."""
    c, s = _scale_frame(image_size)
    u = np.array([v_px[0] - c[0] * v_px[2], v_px[1] - c[1] * v_px[2], s * v_px[2]], float)
    return u / np.linalg.norm(u)


def _from_unit(u, image_size):
    c, s = _scale_frame(image_size)
    w = u[2] / s
    return np.array([u[0] + c[0] * w, u[1] + c[1] * w, w])


def _tls_line(mx, my, cxx, cyy, cxy):
    """Unit-normal line through the centroid ``(mx, my)`` along the direction of largest
    spread of the centred scatter matrix ``[[cxx, cxy], [cxy, cyy]]`` (closed form)."""
    ang = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    nx, ny = -np.sin(ang), np.cos(ang)
    return np.array([nx, ny, -(nx * mx + ny * my)])


def _line_from_moments(n, sx, sy, sxx, syy, sxy):
    """Total least-squares line from the point moments (count, sums, sums of products)."""
    mx, my = sx / n, sy / n
    return _tls_line(mx, my, sxx - n * mx * mx, syy - n * my * my, sxy - n * mx * my)


def _moments(points):
    x, y = points[:, 0], points[:, 1]
    return np.array([len(points), x.sum(), y.sum(), x @ x, y @ y, x @ y])


def _fit_line(points):
    """Total least-squares line through points (N, 2): unit-normal homogeneous line."""
    m = np.add.reduce(points, 0) / len(points)
    d = points - m
    return _tls_line(m[0], m[1], d[:, 0] @ d[:, 0], d[:, 1] @ d[:, 1], d[:, 0] @ d[:, 1])


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
    a, b, r = capsules[:, :2], capsules[:, 2:4], capsules[:, 4]
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-12)
    ap = points[:, None, :] - a[None]
    t = np.clip(np.sum(ap * ab[None], axis=-1) / L2, 0.0, 1.0)
    d2 = np.sum((ap - t[..., None] * ab[None]) ** 2, axis=-1)
    return np.any(d2 < (r + reach)[None] ** 2, axis=1)


_TRIPLE_KERNEL = np.ones((1, 3), np.uint8)


def _white_response(gray_min, tophat_px):
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (tophat_px, tophat_px))
    return cv2.morphologyEx(gray_min, cv2.MORPH_TOPHAT, k)


@functools.lru_cache(maxsize=8)
def _vote_selection(shape, fraction):
    """A fixed pseudo-random 0/255 mask selecting ``fraction`` of the pixels (same every call)."""
    rng = np.random.default_rng(20231)
    return np.where(rng.random(shape) < fraction, 255, 0).astype(np.uint8)


def _segments(img_bgr, cfg):
    h, w = img_bgr.shape[:2]
    scale = min(1.0, cfg.work_width_px / w)
    small = cv2.resize(img_bgr, (int(round(w * scale)), int(round(h * scale))),
                       interpolation=cv2.INTER_AREA) if scale < 1 else img_bgr
    # minimum of B, G, R per pixel: an erosion across each interleaved (B, G, R) triple,
    # read at the G positions (one pass, no channel split)
    gmin = np.ascontiguousarray(
        cv2.erode(small.reshape(small.shape[0], -1), _TRIPLE_KERNEL, borderType=cv2.BORDER_REPLICATE)[:, 1::3])
    resp = _white_response(gmin, cfg.tophat_px)
    _, mask = cv2.threshold(resp, cfg.threshold, 255, cv2.THRESH_BINARY)
    # thin wide lines to their ridge (local maximum across rows or across columns): the
    # Hough transform's cost grows with the number of points, its result does not improve
    r = resp
    ridge = np.zeros(r.shape, bool)
    ridge[1:-1, :] = (r[1:-1] >= r[:-2]) & (r[1:-1] > r[2:])
    ridge[:, 1:-1] |= (r[:, 1:-1] >= r[:, :-2]) & (r[:, 1:-1] > r[:, 2:])
    mask = cv2.bitwise_and(mask, mask, mask=ridge.view(np.uint8))
    n_mask = int(np.count_nonzero(mask))
    frac = float(np.clip(cfg.hough_point_fraction, 0.0, 1.0))
    threshold = cfg.hough_threshold
    if frac < 1.0:
        mask = cv2.bitwise_and(mask, _vote_selection(mask.shape, frac))
        threshold = max(2, int(round(threshold * frac)))
    segs = cv2.HoughLinesP(mask, 1, np.radians(cfg.hough_theta_deg), threshold,
                           minLineLength=cfg.min_length_frac * small.shape[1], maxLineGap=cfg.max_gap_px)
    if segs is None:
        return np.zeros((0, 4)), n_mask
    segs = segs.reshape(-1, 4).astype(float) / scale
    if len(segs) > cfg.max_segments:
        keep = np.argsort(-np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]))[:cfg.max_segments]
        segs = segs[keep]
    return segs, n_mask


def _merge_segments(segs, cfg):
    """Greedy clustering of collinear segments; returns a list of endpoint arrays."""
    if len(segs) == 0:
        return []
    lengths = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    order = np.argsort(-lengths)
    clusters = []  # [line, endpoint arrays, moments]
    cos_tol = np.cos(np.radians(cfg.merge_angle_deg))
    for i in order:
        p = segs[i].reshape(2, 2)
        d = (p[1] - p[0]) / max(lengths[i], 1e-9)
        mom = _moments(p)
        placed = False
        for c in clusters:
            line = c[0]
            if abs(d[0] * line[1] - d[1] * line[0]) < cos_tol:  # |d . line direction|
                continue
            if max(abs(p[0] @ line[:2] + line[2]), abs(p[1] @ line[:2] + line[2])) < cfg.merge_dist_px:
                c[1].append(p)
                c[2] = c[2] + mom
                c[0] = _line_from_moments(*c[2])
                placed = True
                break
        if not placed:
            clusters.append([_line_from_moments(*mom), [p], mom])
    return [np.concatenate(c[1]) for c in clusters]


#: BGR weights of the luma (Rec. 601) in which lines are measured: JPEG and broadcast codecs keep
#: luma at full resolution, while the colour channels are subsampled and shifted (the minimum of
#: B, G, R, which finds white lines best, moves a measured centre by ~0.01 px after JPEG)
_LUMA_BGR = np.array([0.114, 0.587, 0.299], np.float32)


def _measure_lines(image_bgr, endpoint_sets, cfg, exclude=None):
    """Sub-pixel centre points along rough lines: luma centroids across the line on the pixel grid.

    Every ``profile_step_px`` along a rough line, the pixels of one image column (a line
    closer to horizontal) or row (closer to vertical) within ``profile_half_px`` of it
    are read without interpolation, and their background-subtracted centroid is the line
    centre there.  The discrete centroid of a blurred line is free of the sub-pixel
    "pixel locking" that interpolated, resampled profiles show (the ~0.5 px-periodic bias
    of a centroid over bilinear samples does not average out along lines whose slope
    barely changes, e.g. a camera square-on to the straight, and it tilts them); the
    centre of a straight band's cross-section in a column lies on its centre line, so the
    points need no correction.  Profiles that reach into the capsules ``exclude``
    (:func:`athlete_mask`) are dropped.  Returns one (N_i, 2) array (or None when too
    little is seen) per line.
    """
    h, w = image_bgr.shape[:2]
    # per line: reading direction, profile half-width and the columns (rows) it crosses;
    # lines alike in both are measured in one batch (one gather, one centroid pass)
    pixels = image_bgr.reshape(-1, 3)  # flat indexing: a 1-D gather is faster than a 2-D one
    plans, groups = [], {}
    for k, endpoints in enumerate(endpoint_sets):
        endpoints = np.asarray(endpoints, float)
        a, b, c = _fit_line(endpoints)
        horizontal = bool(abs(b) >= abs(a))  # normal mostly vertical: read columns
        ax, nrm = (0, b) if horizontal else (1, a)
        lo, hi = endpoints[:, ax].min(), endpoints[:, ax].max()
        major = np.arange(np.ceil(lo), hi, cfg.profile_step_px)
        if len(major) == 0:
            plans.append(None)
            continue
        # the predicted crossing of each column (row), and the pixels around it
        pred = -((a * major if horizontal else b * major) + c) / nrm
        half = int(np.ceil(cfg.profile_half_px / abs(nrm)))
        plans.append((major, np.round(pred).astype(np.int64)))
        groups.setdefault((horizontal, half), []).append(k)
    points, ok_all = [None] * len(plans), [None] * len(plans)
    for (horizontal, half), members in groups.items():
        major = np.concatenate([plans[k][0] for k in members])
        base = np.concatenate([plans[k][1] for k in members])
        offs = np.arange(-half, half + 1)
        minor = base[:, None] + offs[None, :]
        major_i = np.broadcast_to(major.astype(np.int64)[:, None], minor.shape)
        X, Y = (major_i, minor) if horizontal else (minor, major_i)
        inside = (X.min(1) >= 0) & (Y.min(1) >= 0) & (X.max(1) <= w - 1) & (Y.max(1) <= h - 1)
        flat_idx = (np.clip(Y, 0, h - 1) * w + np.clip(X, 0, w - 1)).ravel()
        prof = np.take(pixels, flat_idx, axis=0).reshape(minor.shape + (3,)) @ _LUMA_BGR
        off, ok = _profile_centroids(prof, offs.astype(float), cfg.threshold * 0.6)
        ok &= inside
        ax = 0 if horizontal else 1
        pts = np.empty((len(major), 2))
        pts[:, ax] = major
        pts[:, 1 - ax] = base + off
        if exclude is not None:
            ok &= ~_near_capsules(pts, exclude, cfg.profile_half_px)
        splits = np.cumsum([len(plans[k][0]) for k in members])[:-1]
        for k, p_k, ok_k in zip(members, np.split(pts, splits), np.split(ok, splits)):
            points[k], ok_all[k] = p_k, ok_k
    return [None if plan is None or ok_all[k].sum() < 4 else points[k][ok_all[k]]
            for k, plan in enumerate(plans)]


def _profile_centroids(prof, offs, min_contrast):
    """Background-subtracted centroids of bright lines in profiles (N, M) sampled at ``offs``.

    The background is taken per side of the peak (the two sides may differ: infield and
    track), from the outer two samples.  The centroid runs over the contiguous stretch
    around the peak above 15 % of its contrast (a neighbouring line must not pull it),
    widened by one sample on each side and kept unclipped there, so that cutting the
    blurred flanks at a threshold does not lock the centre to the pixel grid.

    Returns the offsets (N,) and whether each profile saw a line (contrast above
    ``min_contrast``, widened stretch inside the profile).

    >>> prof = np.array([[10, 10, 10, 60, 110, 60, 10, 10.0]])
    >>> off, ok = _profile_centroids(prof, np.arange(8.0) - 4, 20)
    >>> float(off[0]), bool(ok[0])
    (0.0, True)
    """
    n_side = 2
    cols = np.arange(prof.shape[1])[None, :]
    am = np.argmax(prof, axis=1)[:, None]
    left_bg = prof[:, :n_side].mean(1)[:, None]
    right_bg = prof[:, -n_side:].mean(1)[:, None]
    base = np.where(cols < am, left_bg, right_bg)
    top = prof.max(axis=1)[:, None]
    peak = (top - np.minimum(left_bg, right_bg))[:, 0]
    # weights ~ line coverage on both sides: normalise by the contrast on each side
    wts = (prof - base) / np.maximum(top - base, 1e-6) * peak[:, None]
    low = wts <= 0.15 * peak[:, None]
    left = np.where(low & (cols < am), cols, -1).max(1) - 1
    right = np.where(low & (cols > am), cols, prof.shape[1]).min(1) + 1
    wts = np.where((cols > left[:, None]) & (cols < right[:, None]), wts, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        off = (wts * offs).sum(1) / wts.sum(1)
    ok = (peak > min_contrast) & (left >= 0) & (right <= prof.shape[1] - 1) & np.isfinite(off)
    return off, ok


def _median(x):
    """Median of a 1-D array (``np.partition``; avoids ``np.median``'s overhead on small arrays)."""
    n = len(x)
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return 0.5 * float(part[k - 1] + part[k])


def _robust_fit(points, iters=3, min_scale_px=0.1):
    """Line fit that drops points beyond 3.5 robust sd (MAD, at least ``min_scale_px``).

    A clean line's centres scatter by ~0.05 px; where the athlete's legs or shadow
    cross it they move by 0.2-1 px, which a coarser floor would keep.
    """
    line = _fit_line(points)
    keep = np.ones(len(points), bool)
    for _ in range(iters):
        r = np.abs(points @ line[:2] + line[2])
        s = max(1.4826 * _median(r[keep]), min_scale_px)
        new_keep = r < 3.5 * s
        if np.array_equal(new_keep, keep):
            break  # the same points again: the same line
        keep = new_keep
        if keep.sum() < 4:
            break
        line = _fit_line(points[keep])
    return line, keep


def _sagitta(points, line, with_residual=False):
    """Largest deviation of a quadratic fit from the straight line (px): curvature measure.

    With ``with_residual`` also the RMS residual (px) of the quadratic fit: a
    clean curve (a bend's arc) has a small one, clutter a large one.
    """
    n = line[:2]
    d = np.array([-n[1], n[0]])
    t = points @ d
    r = points @ n + line[2]
    if np.ptp(t) < 1e-6:
        return (0.0, 0.0) if with_residual else 0.0
    tt = (t - t.mean()) / (np.ptp(t) / 2)
    V = np.column_stack([tt * tt, tt, np.ones_like(tt)])
    coef = np.linalg.solve(V.T @ V, V.T @ r)  # quadratic least squares (well conditioned: tt in [-1, 1])
    if with_residual:
        return abs(coef[0]), float(np.sqrt(np.mean((V @ coef - r) ** 2)))
    return abs(coef[0])  # quadratic term at the ends of the support


def _scatter_matrices(point_sets, image_size):
    """Per line, the 3x3 scatter ``sum q q^T`` of its points in the scaled frame (``q = ((p - c)/s, 1)``)."""
    c, s = _scale_frame(image_size)
    sizes = [len(p) for p in point_sets]
    pts = np.concatenate(point_sets)
    q = np.column_stack([(pts - c) / s, np.ones(len(pts))])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    outer = (q[:, :, None] * q[:, None, :]).reshape(len(q), 9)
    return np.add.reduceat(outer, starts, axis=0).reshape(len(sizes), 3, 3)


def _pencil_fit(scatter, vp_unit):
    """Geometrically best lines through a point, from the lines' scatter matrices.

    For each line, minimises the sum of squared point-to-line distances over
    the lines through ``vp_unit`` (a generalised 2x2 eigenproblem in the
    pencil's basis; closed form, also for a vanishing point at infinity).
    ``vp_unit`` may also be a stack (K, 3) of points, fitted in one pass.

    Returns
    -------
    lines : ndarray (n, 3), or (K, n, 3)
        Lines in the scaled frame, normalised so that ``hypot(l0, l1) = 1``.
    sq : ndarray (n,), or (K, n)
        Sum of squared distances of each line's points (scaled-frame units).
    """
    V = np.asarray(vp_unit, float)
    single = V.ndim == 1
    V = np.atleast_2d(V)
    V = V / np.sqrt(np.sum(V * V, -1, keepdims=True))
    v0, v1, v2 = V[:, 0], V[:, 1], V[:, 2]
    # orthonormal basis (e1, e2) of the lines through v: e1 = v x axis, e2 = v x e1
    zero = np.zeros_like(v0)
    e1 = np.where((np.abs(v0) < 0.9)[:, None], np.stack([zero, v2, -v1], -1), np.stack([-v2, zero, v0], -1))
    e1 /= np.sqrt(np.sum(e1 * e1, -1, keepdims=True))
    e2 = cross3(V, e1)
    # quadratic forms of the scatter in the basis: a = e1' S e1, b = e2' S e1, cc = e2' S e2
    Se1 = np.einsum("nij,kj->kni", scatter, e1)  # (K, n, 3)
    a = np.einsum("kni,ki->kn", Se1, e1)
    b = np.einsum("kni,ki->kn", Se1, e2)
    cc = np.einsum("ki,nij,kj->kn", e2, scatter, e2)
    # metric of hypot(l0, l1)^2 in the basis
    p = (e1[:, 0] ** 2 + e1[:, 1] ** 2)[:, None]
    q = (e1[:, 0] * e2[:, 0] + e1[:, 1] * e2[:, 1])[:, None]
    r = (e2[:, 0] ** 2 + e2[:, 1] ** 2)[:, None]
    qa = p * r - q * q
    qb = a * r + cc * p - 2 * b * q
    qc = a * cc - b * b
    disc = np.sqrt(np.maximum(qb * qb - 4 * qa * qc, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = np.where(qb + disc > 0, 2 * qc / (qb + disc), 0.0)  # the smaller root
    lam = np.maximum(lam, 0.0)
    x1 = np.stack([-(b - lam * q), a - lam * p], -1)
    x2 = np.stack([cc - lam * r, -(b - lam * q)], -1)
    x = np.where((np.sum(x1**2, -1) >= np.sum(x2**2, -1))[..., None], x1, x2)  # (K, n, 2)
    lines = x[..., 0:1] * e1[:, None, :] + x[..., 1:2] * e2[:, None, :]
    nrm = np.hypot(lines[..., 0], lines[..., 1])
    lines = lines / np.maximum(nrm, 1e-300)[..., None]
    return (lines[0], lam[0]) if single else (lines, lam)


def lines_through_point(point_sets, vp_unit, image_size):
    """Best lines through a common (homogeneous) point, each fitted to its support points.

    Each line minimises the squared perpendicular distances (px) of its
    points among all lines through the point.

    Parameters
    ----------
    point_sets : list of ndarray (N_i, 2)
        Support points (px) of each line.
    vp_unit : ndarray, shape (3,)
        The common point as a unit vector in the scaled frame (see ``FrameLanes``).
    image_size : tuple

    Returns
    -------
    lines : ndarray, shape (n, 3)
        Unit-normal homogeneous lines in pixel coordinates.
    residuals : list of ndarray
        Signed distances (px) of every support point from its line.
    """
    ls, _ = _pencil_fit(_scatter_matrices(point_sets, image_size), vp_unit)
    lines = _lines_from_scaled(ls, image_size)
    return lines, _line_residuals(point_sets, lines)


def _lines_from_scaled(ls, image_size):
    """Lines (n, 3) of the scaled frame in pixel coordinates (the normal keeps its length)."""
    c, s = _scale_frame(image_size)
    return np.stack([ls[:, 0], ls[:, 1], ls[:, 2] * s - ls[:, 0] * c[0] - ls[:, 1] * c[1]], -1)


def _line_residuals(point_sets, lines):
    """Signed distances (px) of each set's points from its unit-normal line: list of arrays."""
    sizes = [len(p) for p in point_sets]
    seg = np.repeat(np.arange(len(sizes)), sizes)
    pts = np.concatenate(point_sets)
    r = np.einsum("ij,ij->i", pts, lines[seg, :2]) + lines[seg, 2]
    return np.split(r, np.cumsum(sizes)[:-1])


def _refine_vp(point_sets, vp_unit0, image_size, iterations=20):
    """Least-squares vanishing point (2 DOF on the sphere) with covariance of the unit vector.

    Minimises the sum of squared point-to-line distances (px) over the
    vanishing point, each line being re-fitted through it (:func:`_pencil_fit`
    on precomputed scatter matrices, so one evaluation costs O(lines)).
    Newton's method on the tangent plane with a central-difference Hessian,
    until the next Newton step's predicted decrease is negligible.  (Nearly
    parallel lines make the cost very flat along the pencil, and not quadratic
    there: a few steps are needed, and a stopping rule that judged the step
    just taken stopped up to one standard deviation short of the minimum.)
    """
    _, s = _scale_frame(image_size)
    S = _scatter_matrices(point_sets, image_size)
    v0 = vp_unit0 / np.linalg.norm(vp_unit0)
    t1 = cross3(v0, [1.0, 0, 0] if abs(v0[0]) < 0.9 else [0, 1.0, 0])
    t1 = t1 / np.linalg.norm(t1)
    t2 = cross3(v0, t1)
    T = np.stack([t1, t2], 1)

    def unit(x):
        u = v0 + T @ x
        return u / np.linalg.norm(u)

    def costs(X):  # (K, 2) tangent-plane offsets -> (K,) costs, in one batched fit
        U = v0 + X @ T.T
        return s * s * np.sum(_pencil_fit(S, U / np.linalg.norm(U, axis=1, keepdims=True))[1], -1)

    def cost(x):
        return float(costs(x[None])[0])

    # central differences: +h e1, +h e2, -h e1, -h e2, the four diagonal points, and
    # the point itself (all evaluated in one batched fit)
    stencil = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0],
                        [1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0], [0.0, 0.0]])

    def grad_hess(x, h, f0=None):
        f = costs(x + h * stencil[:8 if f0 is not None else 9])
        f0 = f[8] if f0 is None else f0
        fp, fm = f[0:2], f[2:4]
        g = (fp - fm) / (2 * h)
        H = np.diag((fp - 2 * f0 + fm) / h**2)
        H[0, 1] = H[1, 0] = (f[4] - f[5] - f[6] + f[7]) / (4 * h * h)
        return f0, g, H

    x = np.zeros(2)
    # the step of the differences: the cost is a difference of nearly equal scatter terms,
    # good to ~1e-8 of itself; with 1e-6 that noise reached the Hessian's flat direction
    # (nearly parallel lines: 44 % off on a frame of a low view), while steps from 1e-5 to
    # 1e-3 agree to 0.1 % there (the cost is quadratic over them)
    h = 1e-4
    f0, g, H = grad_hess(x, h)
    for _ in range(iterations):
        try:
            step = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(step)):
            break
        if -0.5 * (g @ step) < 1e-10 * max(f0, 1e-12):
            break  # converged: the Newton step's predicted decrease is negligible
        # backtracking: never accept a step that increases the cost
        lam = 1.0
        f_new = cost(x + step)
        while lam > 1e-4 and f_new > f0:
            lam *= 0.5
            f_new = cost(x + lam * step)
        if lam <= 1e-4:
            break
        x = x + lam * step
        f0, g, H = grad_hess(x, h, f_new)
        if np.linalg.norm(lam * step) < 1e-10:
            break
    v = unit(x)
    n_pts = sum(len(p) for p in point_sets)
    dof = max(n_pts - 2 - len(point_sets), 1)
    sigma2 = f0 / dof
    try:
        cov_x = 2.0 * sigma2 * np.linalg.inv(H)  # Hessian of the SSR ~ 2 J^T J
    except np.linalg.LinAlgError:
        cov_x = np.full((2, 2), np.nan)
    cov_u = T @ cov_x @ T.T
    return v, cov_u, np.sqrt(sigma2)


def _pencil_basis(vp_unit):
    v = vp_unit / np.linalg.norm(vp_unit)
    e1 = cross3(v, [0.0, 0.0, 1.0]) if abs(v[2]) < 0.99 else cross3(v, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, cross3(v, e1)


def _line_to_scaled(l_px, image_size):
    c, s = _scale_frame(image_size)
    return np.array([l_px[0] * s, l_px[1] * s, l_px[2] + l_px[0] * c[0] + l_px[1] * c[1]])


def _pencil_coordinate(lines_px, vp_unit, image_size):
    """Angle (rad) of each line within the pencil through the vanishing point.

    Lines through ``v`` form a projective line; the angle of a line in the
    basis ``(e1, e2)`` of the plane orthogonal to ``v`` is a coordinate on it.
    The circle of angles is cut at its largest empty gap so that the lines
    seen in the image have increasing, continuous coordinates.
    """
    e1, e2 = _pencil_basis(vp_unit)
    ls = np.array([_line_to_scaled(l, image_size) for l in lines_px])
    ang = np.mod(np.arctan2(ls @ e2, ls @ e1), np.pi)
    sa = np.sort(ang)
    gaps = np.diff(np.concatenate([sa, [sa[0] + np.pi]]))
    cut = sa[(np.argmax(gaps) + 1) % len(sa)]
    return np.where(ang < cut, ang + np.pi, ang)


def assign_line_indices(pencil_coord, max_missing=2):
    """Integer lane-line indices (0 = first in order) for lines sorted by pencil coordinate.

    With three lines the lines are taken as consecutive.  With four or more,
    gap patterns (a missing line in between) are scored by the misfit of a
    1-D projective map from index to pencil coordinate, the image of equally
    spaced lines; a gap must improve the fit clearly to be accepted.

    Returns
    -------
    indices : ndarray of int
    residual : float
        RMS misfit of the chosen fit in pencil-coordinate units (NaN for three lines).
    """
    t = np.asarray(pencil_coord, float)
    n = len(t)
    base = np.arange(n)
    if n < 4:
        return base, float("nan")

    def fit(k):
        A = np.column_stack([k, np.ones(n), -t * k, -t])
        _, _, vt = np.linalg.svd(A)
        a, b, c, d = vt[-1]
        pred = (a * k + b) / (c * k + d)
        return float(np.sqrt(np.mean((pred - t) ** 2)))

    best_k, best_r = base, fit(base.astype(float))
    for extra in range(1, max_missing + 1):
        for gaps in itertools.combinations_with_replacement(range(n - 1), extra):
            inc = np.ones(n - 1)
            for g in gaps:
                inc[g] += 1
            k = np.concatenate([[0], np.cumsum(inc)])
            if k[-1] > 8:
                continue
            r = fit(k)
            if r < 0.3 * best_r:
                best_k, best_r = k.astype(int), r
    return np.asarray(best_k, int), best_r


# --------------------------------------------------------------------------- main entry
def detect_lanes(image_bgr, config: LaneDetectorConfig = LaneDetectorConfig(), frame=None,
                 dist=None, focal_px=None, exclude=None):
    """Detect the lane lines of the straight and their vanishing point in one frame.

    Parameters
    ----------
    image_bgr : ndarray, shape (H, W, 3), uint8, or None
    config : LaneDetectorConfig
    frame : int, optional
        Frame index stored in the result.
    dist : array_like (5,), optional
        Known or hypothesised lens distortion; with ``focal_px`` the support points are
        undistorted before the lines and the vanishing point are fitted.
    focal_px : float, optional
    exclude : ndarray (S, 5), optional
        Image regions whose line evidence is ignored, as capsules (:func:`athlete_mask`).

    Returns
    -------
    FrameLanes
        Never raises for bad image content; see :data:`STATUSES`.
    """
    if image_bgr is None or not hasattr(image_bgr, "shape") or image_bgr.ndim != 3 or image_bgr.size == 0:
        return FrameLanes(status="bad_image", frame=frame)
    h, w = image_bgr.shape[:2]
    size = (w, h)
    segs, n_mask = _segments(image_bgr, config)
    if len(segs) == 0:
        return FrameLanes(status="no_lines", image_size=size, frame=frame, extra={"mask_px": n_mask})
    candidates, (n_curved, curved_len) = _measure_candidates(image_bgr, _merge_segments(segs, config), config,
                                                         exclude=exclude)
    # merge candidates that turned out to be the same line after re-measurement
    candidates = _dedupe(candidates, config)
    fl = FrameLanes(status="no_lines", image_size=size, frame=frame, n_curved=n_curved,
                    extra={"curved_length_px": curved_len})
    if len(candidates) < 2:
        return replace(fl, status="no_straight" if n_curved >= 2 else
                       ("too_few_lines" if candidates or n_curved else "no_lines"))
    if dist is not None and focal_px is not None and np.any(dist):
        candidates = [(_fit_line(p), p, L) for _, p, L in
                      ((c[0], _undistort_px(c[1], dist, focal_px, size), c[2]) for c in candidates)]
        fl = replace(fl, undistorted=True)
    return _pencil_from_candidates(candidates, fl, config)


def _measure_candidates(image_bgr, endpoint_sets, config, distinct=False, exclude=None):
    """Sub-pixel measurement of rough lines (longest first); curved ones are counted, not kept.

    All lines are measured in one batch.  With ``distinct=False`` a cluster lying on an
    already measured line is dropped as a duplicate; ``distinct=True`` (lines known to be
    different, e.g. followed from the previous frame) keeps every one.  Returns the
    candidates ``(line, points, length)`` and ``(number, total length)`` of curved ones.
    """
    candidates, measured = [], []
    n_curved, curved_length = 0, 0.0
    order = sorted(endpoint_sets, key=lambda e: -np.ptp(e, axis=0).max())
    # all profiles in one batch (one remap); duplicates are rare and dropped afterwards
    batch = _measure_lines(image_bgr, order, config, exclude)
    for k, ep in enumerate(order):
        # a cluster lying on an already measured line is a duplicate
        if not distinct and any(np.max(np.abs(ep @ m[:2] + m[2])) < 3.0 for m in measured):
            continue
        pts = batch[k]
        if pts is None or len(pts) < 6:
            continue
        line, keep = _robust_fit(pts)
        pts = pts[keep]
        if len(pts) < 6:
            continue
        length = np.ptp(pts @ np.array([-line[1], line[0]]))
        sag, quad_rms = _sagitta(pts, line, with_residual=True)
        # a bend's arc curves far more than lens distortion bends a lane line
        # (curvature ~ 8 sagitta / length^2: bends >= 4e-5 / px, distorted straight lines <= 2e-5)
        if sag > config.curved_sagitta_px and 8 * sag / length**2 > config.curved_curvature_per_px:
            if quad_rms < 0.35 and length > 150:  # a clean arc is bend evidence; clutter is not
                n_curved += 1
                curved_length += length
            continue
        candidates.append((line, pts, length))
        measured.append(line)
    return candidates, (n_curved, curved_length)


def _image_chord(line, image_size):
    """The two points where a line leaves the image rectangle, shape (2, 2) (None if outside)."""
    w, h = image_size
    a, b, c = line
    pts = []
    if abs(b) > 1e-12:
        for x in (0.0, w - 1.0):
            y = -(a * x + c) / b
            if 0 <= y <= h - 1:
                pts.append((x, y))
    if abs(a) > 1e-12:
        for y in (0.0, h - 1.0):
            x = -(b * y + c) / a
            if 0 <= x <= w - 1:
                pts.append((x, y))
    if len(pts) < 2:
        return None
    pts = np.array(pts)
    d = np.array([-b, a])
    t = pts @ d
    return pts[[np.argmin(t), np.argmax(t)]]


def track_lanes(frames, config: LaneDetectorConfig = LaneDetectorConfig(), keypoints_px=None):
    """Lanes of a frame sequence, following the lines from frame to frame.

    The broadcast camera moves smoothly, so each frame's lines are first
    re-measured around the previous frame's lines (no Hough transform); a full
    :func:`detect_lanes` runs on the first frame, every ``redetect_every``
    frames (to pick up lines entering the view), and whenever following loses
    a line or fails.

    Parameters
    ----------
    frames : iterable of (index, image or None)
    config : LaneDetectorConfig
    keypoints_px : ndarray (F, 17, 2 or 3), optional
        The athlete's 2-D keypoints by frame index: line evidence near the athlete
        (:func:`athlete_mask`) is ignored.

    Returns
    -------
    list of FrameLanes
    """
    out = []
    prev = last_ok = None
    next_id = 0
    prev_small = window = None
    for k, (i, img) in enumerate(frames):
        fl = None
        shift = np.zeros(2)
        small = None
        exclude = (athlete_mask(keypoints_px[i]) if keypoints_px is not None and 0 <= i < len(keypoints_px)
                   else None)
        if img is not None and getattr(img, "ndim", 0) == 3 and img.size:
            # global image motion from the previous frame (phase correlation of a small grey
            # copy): predicts where the lines went when the camera pans or shakes
            scale = 320.0 / img.shape[1]
            step = max(1, img.shape[1] // 640)  # cheap pre-decimation; phase correlation is coarse anyway
            small = cv2.cvtColor(cv2.resize(img[::step, ::step], (320, max(8, int(round(img.shape[0] * scale)))),
                                            interpolation=cv2.INTER_AREA),
                                 cv2.COLOR_BGR2GRAY).astype(np.float32)
            if prev_small is not None and prev_small.shape == small.shape:
                if window is None or window.shape != small.shape:
                    window = cv2.createHanningWindow(small.shape[::-1], cv2.CV_32F)
                (dx, dy), resp = cv2.phaseCorrelate(prev_small, small, window)
                if resp > 0.05:
                    shift = np.array([dx, dy]) / scale
        if prev is not None and prev.ok and small is not None and k % max(config.redetect_every, 1):
            size = (img.shape[1], img.shape[0])
            chords = [c for c in (_image_chord(_translate(ln.line, shift), size) for ln in prev.lines)
                      if c is not None]
            cands, (n_curved, curved_len) = _measure_candidates(img, chords, config, distinct=True,
                                                                exclude=exclude)
            if len(cands) >= max(config.min_lines, len(prev.lines) - 1):
                fl = _pencil_from_candidates(_dedupe(cands, config),
                                             FrameLanes(status="no_lines", image_size=size, frame=i,
                                                        n_curved=n_curved,
                                                        extra={"curved_length_px": curved_len}), config)
                if not fl.ok or len(fl.lines) < len(prev.lines) - 1 or \
                        max(ln.rms_px for ln in fl.lines) > _track_rms_bound(prev, config):
                    fl = None
        if fl is None:
            fl = detect_lanes(img, config, frame=i, exclude=exclude)
        if fl.ok:
            ref = prev if prev is not None else last_ok
            fl, next_id = _assign_track_ids(fl, ref, next_id, shift if ref is prev else np.zeros(2))
            last_ok = fl
        out.append(fl)
        prev = fl if fl.ok else None
        prev_small = small
    return out


def _track_rms_bound(prev, config):
    """Largest support scatter (px) accepted for a line followed from ``prev``.

    When the predicted position is off by a good part of the local line spacing
    (the far end of a low camera's view, where the lines crowd together, after a
    poor global-motion estimate), the intensity profiles jump between neighbouring
    lines and the fit's scatter grows from ~0.1 px to several px.

    >>> from probreg.lanes import LaneDetectorConfig
    >>> prev = FrameLanes(status="ok", lines=(LaneLine(np.array([0.0, 1.0, -5.0]), np.zeros((2, 2)), 0.1),))
    >>> _track_rms_bound(prev, LaneDetectorConfig())
    0.5
    """
    worst = max((ln.rms_px for ln in prev.lines), default=0.0)
    return max(config.track_rms_px, config.track_rms_factor * worst)


def _translate(line, shift):
    """The image line moved by ``shift`` (px)."""
    return np.array([line[0], line[1], line[2] - line[0] * shift[0] - line[1] * shift[1]])


def _assign_track_ids(fl, ref, next_id, shift=(0.0, 0.0)):
    """Give each line of ``fl`` the id of the line of ``ref`` it continues (new ids otherwise).

    Both frames' lines are ordered across the track, so the correspondence is
    an index shift: the shift with the smallest mean distance between matched
    lines wins if that distance is well below the spacing of neighbouring
    lines (the camera moves by less than half a lane between frames).
    """
    ids = [None] * len(fl.lines)
    if ref is not None and ref.ok and len(ref.lines) >= 2:
        # a dozen points per line are plenty to tell which line continues which
        pts = [ln.points_px[:: max(1, len(ln.points_px) // 12)] for ln in fl.lines]
        ref_pts = [r.points_px[:: max(1, len(r.points_px) // 12)] for r in ref.lines]
        spacing = np.median([np.median(np.abs(a @ b.line[:2] + b.line[2]))
                             for a, b in zip(ref_pts[:-1], ref.lines[1:])])
        # the predicted image motion first; no motion when that finds no match (the
        # global-motion estimate can be fooled by the athlete, who stays in the middle
        # of a following camera's view)
        for motion in ([shift, (0.0, 0.0)] if np.any(np.asarray(shift) != 0) else [shift]):
            ref_lines = np.array([_translate(r.line, motion) for r in ref.lines])  # (m, 3)
            D = np.array([np.median(np.abs(p @ ref_lines[:, :2].T + ref_lines[:, 2]), axis=0) for p in pts])
            best, best_cost = None, np.inf
            n, m = D.shape
            for k_shift in range(-(n - 1), m):
                pairs = [(k, k + k_shift) for k in range(n) if 0 <= k + k_shift < m]
                if len(pairs) < min(2, n, m):
                    continue
                cost = float(np.mean([D[k, j] for k, j in pairs]))
                if cost < best_cost:
                    best, best_cost = pairs, cost
            if best is not None and best_cost < 0.35 * spacing:
                for k, j in best:
                    ids[k] = ref.lines[j].track_id
                break
    for k in range(len(ids)):
        if ids[k] is None:
            ids[k] = next_id
            next_id += 1
    lines = tuple(replace(ln, track_id=i) for ln, i in zip(fl.lines, ids))
    return replace(fl, lines=lines), next_id


def _undistort_px(points_px, dist, focal_px, image_size):
    c, _ = _scale_frame(image_size)
    xy = undistort_normalized((points_px - c) / focal_px, dist)
    return xy * focal_px + c


def _dedupe(cands, cfg):
    out = []
    cos_tol = np.cos(np.radians(cfg.merge_angle_deg))
    reach = 2.0 + np.sin(np.radians(cfg.merge_angle_deg)) * 4000.0  # bound for a near-parallel duplicate
    for line, pts, L in sorted(cands, key=lambda c: -c[2]):
        mid = pts[len(pts) // 2]
        for k, (l2, p2, L2) in enumerate(out):
            if abs(line[:2] @ l2[:2]) > cos_tol and abs(mid @ l2[:2] + l2[2]) < reach and \
                    _median(np.abs(pts @ l2[:2] + l2[2])) < 2.0:
                allp = np.concatenate([p2, pts])
                out[k] = (_fit_line(allp), allp, L2 + L)
                break
        else:
            out.append((line, pts, L))
    return out


def _pencil_from_candidates(cands, fl, cfg):
    size = fl.image_size
    mids = np.array([p.mean(0) for _, p, _ in cands])
    lines = np.array([c[0] for c in cands])
    lengths = np.array([L for _, _, L in cands])
    n = len(cands)
    ii, jj = np.triu_indices(n, 1)
    vps = cross3(lines[ii], lines[jj])  # (P, 3) candidate vanishing points
    # angle between every line and the direction from its midpoint to every candidate
    dirs = np.stack([-lines[:, 1], lines[:, 0]], -1)  # (n, 2)
    to_vp = vps[:, None, :2] - mids[None] * vps[:, None, 2:3]  # (P, n, 2)
    nrm = np.linalg.norm(to_vp, axis=-1)
    cosang = np.abs(np.sum(to_vp * dirs[None], -1)) / np.maximum(nrm, 1e-300)
    inlier = (cosang > np.cos(np.radians(cfg.vp_inlier_deg))) | (nrm < 1e-9)
    count = inlier.sum(1)
    score = count * 1e9 + inlier @ lengths  # most lines first, then the longest support
    if len(score) == 0:
        return replace(fl, status="too_few_lines")
    p = int(np.argmax(score))
    best = (vps[p], list(np.flatnonzero(inlier[p])))
    if len(best[1]) < cfg.min_lines:
        status = "no_straight" if fl.n_curved >= 2 and len(best[1]) < 2 else "too_few_lines"
        return replace(fl, status=status)
    vp, inl = best
    if fl.extra.get("curved_length_px", 0.0) > lengths[inl].sum():
        # more curved line evidence than straight: a bend, whose short chords can mimic a pencil
        return replace(fl, status="no_straight")
    sets = [cands[k][1] for k in inl]
    v_unit, cov, sigma = _refine_vp(sets, _to_unit(vp, size), size)
    lines_px, res = lines_through_point(sets, v_unit, size)
    coord = _pencil_coordinate(lines_px, v_unit, size)
    joined = _join_pieces(sets, lines_px, coord)
    if len(joined) < len(sets):
        sets = joined
        if len(sets) < cfg.min_lines:
            return replace(fl, status="too_few_lines")
        v_unit, cov, sigma = _refine_vp(sets, v_unit, size)
        lines_px, res = lines_through_point(sets, v_unit, size)
        coord = _pencil_coordinate(lines_px, v_unit, size)
    order = np.argsort(coord)
    # canonical direction (the sign of the homogeneous vanishing point is arbitrary, so the
    # angular order may run either way): the first line is the one nearer the image top
    # (or, for near-vertical lines, the left edge) where it passes the image centre
    c0 = np.array([(size[0] - 1) / 2, (size[1] - 1) / 2, 1.0])
    nrm = lines_px[:, :2].mean(0)
    nrm = nrm * (1 if (abs(nrm[1]) >= abs(nrm[0]) and nrm[1] > 0) or
                 (abs(nrm[1]) < abs(nrm[0]) and nrm[0] > 0) else -1)
    offs = -(lines_px @ c0) * np.sign(lines_px[:, :2] @ nrm)  # signed position along nrm
    if offs[order[-1]] < offs[order[0]]:
        order = order[::-1]
    idx, spacing = assign_line_indices(coord[order], cfg.max_missing_lines)
    lanes = tuple(LaneLine(line=lines_px[o], points_px=sets[o], rms_px=float(np.sqrt(np.mean(res[o] ** 2))),
                           index=int(k)) for o, k in zip(order, idx))
    spacing_px = (_spacing_residual_px(lanes, coord[order], idx, v_unit, size) if len(lanes) >= 4
                  else float("nan"))
    return replace(fl, status="ok", lines=lanes, vanishing_point=_from_unit(v_unit, size), vp_cov=cov,
                   spacing_residual_px=spacing_px, extra={"vp_unit": v_unit, "vp_sigma_px": sigma})


def _join_pieces(sets, lines_px, coord, max_frac=0.2, max_overlap=0.5):
    """Support-point sets of the pencil with the pieces of one lane line joined.

    A lane line bent by a distorting lens (or partly hidden) can reach the pencil as
    two straight pieces, one after the other along the line.  Their pencil
    coordinates nearly coincide (within ``max_frac`` of the typical spacing of
    neighbouring lines) while distinct lane lines are a whole spacing apart; a kerb
    or a second line close beside a lane line runs alongside it instead, so pieces
    whose extents along the line overlap by more than ``max_overlap`` of the shorter
    one are not joined.

    >>> pts = lambda y0, x0, x1: np.column_stack([np.arange(x0, x1, 10.0), y0 + 0.1 * np.arange(x0, x1, 10.0)])
    >>> sets = [pts(100, 0, 1000), pts(200, 0, 500), pts(200.4, 500, 1000), pts(300, 0, 1000)]
    >>> lines = np.array([[-0.1, 1, -y] for y in (100, 200, 200.4, 300)]) / np.hypot(0.1, 1)
    >>> [len(p) for p in _join_pieces(sets, lines, np.array([0.0, 1.0, 1.004, 2.0]))]
    [100, 100, 100]
    """
    n = len(sets)
    if n < 3:
        return sets
    order = np.argsort(coord)
    gaps = np.diff(np.asarray(coord, float)[order])
    big = gaps[gaps > 0.25 * np.median(gaps)]
    if not len(big):
        return sets
    tol = max_frac * float(np.median(big))
    groups = [[order[0]]]
    for k, g in zip(order[1:], gaps):
        if g < tol and all(_overlap(sets[k], sets[j], lines_px[j]) <= max_overlap for j in groups[-1]):
            groups[-1].append(k)
        else:
            groups.append([k])
    if len(groups) == n:
        return sets
    return [np.concatenate([sets[j] for j in grp]) if len(grp) > 1 else sets[grp[0]] for grp in groups]


def _overlap(pts_a, pts_b, line):
    """Overlap of two point sets' extents along ``line``, as a fraction of the shorter extent."""
    d = np.array([-line[1], line[0]])
    ta, tb = pts_a @ d, pts_b @ d
    inter = min(ta.max(), tb.max()) - max(ta.min(), tb.min())
    shorter = max(min(np.ptp(ta), np.ptp(tb)), 1e-9)
    return max(inter, 0.0) / shorter


def _spacing_residual_px(lanes, coord, idx, vp_unit, image_size):
    """RMS distance (px) of each line's support points from the line that the best
    equally spaced pencil (a 1-D projective map of the indices) predicts."""
    k = np.asarray(idx, float)
    t = np.asarray(coord, float)
    A = np.column_stack([k, np.ones(len(k)), -t * k, -t])
    _, _, vt = np.linalg.svd(A)
    a, b, c, d = vt[-1]
    pred = (a * k + b) / (c * k + d)
    e1, e2 = _pencil_basis(vp_unit)
    ls = np.cos(pred)[:, None] * e1 + np.sin(pred)[:, None] * e2  # predicted lines, scaled frame
    lp = _lines_from_scaled(ls, image_size)
    lp /= np.hypot(lp[:, 0], lp[:, 1])[:, None]
    res = _line_residuals([ln.points_px for ln in lanes], lp)
    return float(np.sqrt(np.mean([np.mean(r**2) for r in res])))


def undistort_frame_lanes(fl: FrameLanes, dist, focal_px, config=LaneDetectorConfig(), spacing=True):
    """Re-fit a frame's lines and vanishing point after undistorting the support points.

    The lines keep their identities (order, ``index``, ``track_id``): the
    support points of each line are undistorted with ``focal_px`` (OpenCV
    coefficients act on normalised coordinates, so the correction in pixels
    depends on the focal length), the vanishing point is re-estimated from
    them and every line is re-fitted through it.  Every support point is
    used: thinning them doubled the focal error of the family at a 10 deg
    field of view.  The temporal smoothing of a frame's distorted vanishing
    point (:func:`smooth_vanishing_points`) is not carried over: the straight
    fits to bent lines depend on which part of each line is seen (a full
    detection and a followed frame see different parts), the smoothing evens
    that out as if it were noise, and the undistortion removes it a second
    time.  On a 30 deg, ``k1 = -0.25`` clip carrying it over left 4 % focal
    errors in the frames of a full detection; re-estimating alone gives
    0.16 % mean and 0.7 % at worst, and no loss on a 10 deg clip.
    ``spacing=False`` keeps the distorted frame's equal-spacing residual
    instead of recomputing it.  ``config`` is kept for backward compatibility
    and not used.

    Examples
    --------
    Lines that a lens bends are straight again after undistortion:

    >>> import numpy as np
    >>> from probreg.camera import distort_normalized
    >>> size, f, dist = (1920, 1080), 1800.0, np.array([-0.3, 0, 0, 0, 0])
    >>> c = np.array([959.5, 539.5])
    >>> vp = np.array([5000.0, -900.0])
    >>> sets = []
    >>> for y0 in (700.0, 820.0, 960.0):
    ...     t = np.linspace(0, 1, 60)[:, None]
    ...     pts = np.array([0.0, y0]) + t * (vp - np.array([0.0, y0])) * 0.35
    ...     sets.append(distort_normalized((pts - c) / f, dist) * f + c)
    >>> lines = tuple(LaneLine(line=_fit_line(p), points_px=p, rms_px=0.0, index=k) for k, p in enumerate(sets))
    >>> fl = FrameLanes(status="ok", lines=lines, vanishing_point=np.array([*vp, 1.0]), image_size=size)
    >>> round(line_straightness_px(fl), 1) > 1.0
    True
    >>> u = undistort_frame_lanes(fl, dist, f)
    >>> line_straightness_px(u) < 1e-3, [ln.index for ln in u.lines]
    (True, [0, 1, 2])
    >>> bool(np.allclose(u.vp_px(), vp, rtol=1e-4))
    True
    """
    if not fl.ok or not len(fl.lines):
        return fl
    size = fl.image_size
    pts = [np.asarray(ln.points_px, float) for ln in fl.lines]
    sizes = [len(p) for p in pts]
    allp = _undistort_px(np.concatenate(pts), dist, focal_px, size)
    sets = np.split(allp, np.cumsum(sizes)[:-1])
    v0 = fl.extra.get("vp_unit") if fl.extra else None
    if v0 is None:
        if fl.vanishing_point is not None:
            v0 = _to_unit(np.asarray(fl.vanishing_point, float), size)
        else:
            v0 = _to_unit(cross3(_fit_line(sets[0]), _fit_line(sets[-1])), size)
    try:
        v_unit, cov, sigma = _refine_vp(sets, np.asarray(v0, float), size)
    except (np.linalg.LinAlgError, ValueError):  # cannot happen for >= 2 distinct lines
        return fl
    lines_px, res = lines_through_point(sets, v_unit, size)
    lanes = tuple(replace(ln, line=l, points_px=p, rms_px=float(np.sqrt(np.mean(r ** 2))))
                  for ln, l, p, r in zip(fl.lines, lines_px, sets, res))
    spacing_px = fl.spacing_residual_px
    if spacing and len(lanes) >= 4 and all(ln.index is not None for ln in lanes):
        coord = _pencil_coordinate(lines_px, v_unit, size)
        spacing_px = _spacing_residual_px(lanes, coord, [ln.index for ln in lanes], v_unit, size)
    extra = dict(fl.extra or {})
    extra.update(vp_unit=v_unit, vp_sigma_px=sigma)
    return replace(fl, lines=lanes, vanishing_point=_from_unit(v_unit, size), vp_cov=cov,
                   spacing_residual_px=spacing_px, undistorted=True, extra=extra)


def line_straightness_px(fl: FrameLanes):
    """RMS distance (px) of the lane support points from their own straight-line fits.

    On an undistorted image a lane line of the straight is straight, so what is
    left is detection noise (~0.05 px on clean renders); a lens distortion that
    is not accounted for bends the lines and raises it.  Evaluated after
    :func:`undistort_frame_lanes` under a hypothesised distortion, it is
    evidence for or against that hypothesis.  NaN for a frame without lines.
    """
    if not fl.ok or not len(fl.lines):
        return float("nan")
    sq, n = 0.0, 0
    for ln in fl.lines:
        p = np.asarray(ln.points_px, float)
        if len(p) < 3:
            continue
        l = _fit_line(p)
        r = p @ l[:2] + l[2]
        sq += float(np.sum(r ** 2))
        n += len(p)
    return float(np.sqrt(sq / n)) if n else float("nan")


def smooth_vanishing_points(frames, process_std=5e-4, min_var=1e-8, gate_chi2=25.0, max_gated_run=5,
                            gate_process_std=5e-5):
    """RTS-smooth the vanishing points of a clip (the broadcast camera moves smoothly).

    The unit vector of each vanishing point (scaled homogeneous frame) is
    smoothed with a constant-velocity Kalman filter and RTS smoother
    (``filterpy``); frames without lanes are bridged.  Each frame's lines are
    then re-fitted through its smoothed vanishing point.

    Parameters
    ----------
    frames : list of FrameLanes
    process_std : float
        Acceleration noise of the unit vector per frame.  A camera that follows
        the runner pans with the stride (the pelvis slows and speeds up within
        each step); a smoother much stiffer than the default (5e-5) lags that
        motion, and the lag turns into a gait-synchronous pan error that makes
        planted feet seem to slide (the posterior's stillness term: its error at
        the true camera height, rms over the suite, was 0.10 of the running speed
        with 5e-5 against 0.06 unsmoothed).  With 5e-4 the vanishing-point error on the
        benchmark suite is 0.16 % (0.23 % unsmoothed, 0.17 % with 5e-5).
    gate_chi2 : float or None
        Innovation gate (squared Mahalanobis distance): a frame whose
        vanishing point is this far from the prediction is treated as an
        outlier and bridged (``extra["vp_gated"]`` is True).  None disables it.
    gate_process_std : float
        Acceleration noise of the stiffer filter pass that decides the gate: a
        filter as loose as ``process_std`` would follow a single wrong frame.
    max_gated_run : int
        After this many consecutive gated frames the next measurement is
        accepted, so a real sudden camera move cannot lock the filter out.

    Returns
    -------
    list of FrameLanes
        Same statuses; ``ok`` frames carry the smoothed vanishing point
        (``extra["vp_raw"]`` keeps the per-frame estimate).
    """
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    ok = [i for i, f in enumerate(frames) if f.ok]
    if len(ok) < 3:
        return list(frames)
    size = frames[ok[0]].image_size
    zs = []
    ref = None
    for f in frames:
        if not f.ok:
            zs.append(None)
            continue
        u = f.extra.get("vp_unit", _to_unit(f.vanishing_point, size))
        if ref is not None and u @ ref < 0:
            u = -u
        ref = u
        zs.append(u)
    def run_filter(q_std, gate, skip=()):
        kf = KalmanFilter(dim_x=6, dim_z=3)
        kf.F = np.kron(np.eye(3), np.array([[1.0, 1.0], [0.0, 1.0]]))
        kf.H = np.kron(np.eye(3), np.array([[1.0, 0.0]]))
        kf.Q = np.kron(np.eye(3), Q_discrete_white_noise(2, dt=1.0, var=q_std**2))
        kf.x = np.zeros(6)
        kf.x[0::2] = zs[ok[0]]
        kf.P = np.eye(6) * 1e-2
        means, covs, gated = [], [], []
        n_updates = run_gated = 0
        for i, (f, z) in enumerate(zip(frames, zs)):
            kf.predict()
            if z is not None and i not in skip:
                R = f.vp_cov + np.eye(3) * min_var if f.vp_cov is not None and np.all(np.isfinite(f.vp_cov)) \
                    else np.eye(3) * 1e-6
                if n_updates >= 3 and gate is not None and run_gated < max_gated_run:
                    y = z - kf.H @ kf.x
                    S = kf.H @ kf.P @ kf.H.T + R
                    d2 = float(y @ np.linalg.lstsq(S, y, rcond=None)[0])
                    if not np.isfinite(d2) or d2 > gate:
                        gated.append(i)
                        run_gated += 1
                        z = None
                if z is not None:
                    kf.update(z, R=R)
                    n_updates += 1
                    run_gated = 0
            means.append(kf.x.copy())
            covs.append(kf.P.copy())
        return kf, means, covs, gated

    # outliers judged against a stiff motion model, the rest smoothed with the looser one
    gated_set = set(run_filter(gate_process_std, gate_chi2)[3]) if gate_chi2 is not None else set()
    kf, means, covs, _ = run_filter(process_std, None, gated_set)
    xs, Ps, _, _ = kf.rts_smoother(np.array(means), np.array(covs))
    out = []
    for i, (f, x, P) in enumerate(zip(frames, xs, Ps)):
        if not f.ok:
            out.append(f)
            continue
        u = x[0::2] / np.linalg.norm(x[0::2])
        lines_px, res = lines_through_point([ln.points_px for ln in f.lines], u, size)
        lanes = tuple(replace(ln, line=l, rms_px=float(np.sqrt(np.mean(r ** 2))))
                      for ln, l, r in zip(f.lines, lines_px, res))
        cov = P[0::2, 0::2]
        out.append(replace(f, lines=lanes, vanishing_point=_from_unit(u, size), vp_cov=cov,
                           extra={**f.extra, "vp_unit": u, "vp_raw": f.vanishing_point,
                                  "vp_gated": i in gated_set}))
    return out


def draw_lanes(image_bgr, fl: FrameLanes, color=(255, 0, 255)):
    """Overlay of the detected lines (with their indices) and the vanishing point (if in view)."""
    img = image_bgr.copy()
    h, w = img.shape[:2]
    for ln in fl.lines:
        a, b, c = ln.line
        if abs(b) > abs(a):
            p0 = (0, -c / b)
            p1 = (w - 1, -(c + a * (w - 1)) / b)
        else:
            p0 = (-c / a, 0)
            p1 = (-(c + b * (h - 1)) / a, h - 1)
        if all(np.isfinite(p0 + p1)) and max(map(abs, p0 + p1)) < 1e6:
            cv2.line(img, tuple(int(round(v)) for v in p0), tuple(int(round(v)) for v in p1), color, 2, cv2.LINE_AA)
        e = ln.endpoints_px
        cv2.putText(img, str(ln.index), tuple(int(v) for v in e[1]), cv2.FONT_HERSHEY_SIMPLEX, 1.0, color, 2)
    vp = fl.vp_px()
    if np.all(np.isfinite(vp)) and -w < vp[0] < 2 * w and -h < vp[1] < 2 * h:
        cv2.circle(img, (int(vp[0]), int(vp[1])), 12, (0, 255, 255), 3)
    label = f"{fl.status}  lines={len(fl.lines)}"
    cv2.putText(img, label, (20, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.2, (0, 255, 255), 2)
    return img
