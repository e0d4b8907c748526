"""Lane-line values: detector settings, one measured line, one frame's pencil of lines.

Per-frame statuses (never exceptions):

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
``missing_image``
    the clip has no image file for this frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["LaneDetectorConfig", "LaneLine", "FrameLanes", "STATUSES"]


#: ``other_shot``: the frame belongs to another camera shot than the one estimated (its lanes are
#: not used; :mod:`probreg.lanes.shots`)
STATUSES = ("ok", "too_few_lines", "no_straight", "no_lines", "bad_image", "missing_image", "other_shot")

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
    #: faint lines: when a frame gives no lane pencil at ``threshold``, it is detected again at
    #: ``max(low_contrast_threshold, low_contrast_snr x`` the response's noise sd ``)`` (lines
    #: 15-25 grey levels above the track; worn paint, haze, a long lens); 0 turns it off
    low_contrast_threshold: int = 12
    low_contrast_snr: float = 6.0
    #: a line whose support scatters by more than this share of the distance to the nearest
    #: other line mixes neighbouring lines and is dropped (:func:`probreg.lanes.detection._drop_mixed`)
    max_rms_gap_frac: float = 0.1


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
