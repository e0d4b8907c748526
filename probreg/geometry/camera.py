"""Pinhole camera with OpenCV lens distortion: projection, rays and ray casting.

Conventions (``CLIP_FORMAT.md``): OpenCV camera axes (x right, y down,
z forward); ``R`` maps track to camera, ``X_cam = R @ (X_track - C)``; ``K``
has square pixels and no skew; pixel ``(0, 0)`` is the centre of the top-left
pixel; distortion ``[k1, k2, p1, p2, k3]`` acts on normalised coordinates.

Every function is vectorised over leading batch dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["cross3", "Camera", "RaySphereHits", "distort_normalized", "undistort_normalized", "focal_from_fov", "fov_from_focal", "look_at_rotation", "rotation_to_pan_tilt_roll", "intersect_rays_plane", "intersect_rays_sphere"]


_NO_DIST = np.zeros(5)

def cross3(a, b):
    """Cross product of 3-vectors (broadcasting over leading axes).

    Same result as ``np.cross`` for ``(..., 3)`` arrays, without its axis
    handling overhead (which dominates for the small arrays of per-frame code).

    >>> cross3([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    array([0., 0., 1.])
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


def focal_from_fov(fov_deg, width_px):
    """Focal length (px) of a pinhole camera with horizontal field of view ``fov_deg``.

    Parameters
    ----------
    fov_deg : float or array_like
        Horizontal field of view in degrees, in the open interval (0, 180).
    width_px : float
        Image width in pixels.

    Raises
    ------
    ValueError
        If a field of view is outside (0, 180) degrees.

    Examples
    --------
    >>> round(float(focal_from_fov(90.0, 1920)), 6)
    960.0
    """
    fov_deg = np.asarray(fov_deg, dtype=float)
    if np.any(~np.isfinite(fov_deg)) or np.any((fov_deg <= 0) | (fov_deg >= 180)):
        raise ValueError(f"field of view must lie in (0, 180) degrees, got {fov_deg}")
    return 0.5 * width_px / np.tan(np.radians(fov_deg) / 2)


def fov_from_focal(focal_px, width_px):
    """Horizontal field of view (degrees) of a pinhole camera; inverse of :func:`focal_from_fov`.

    >>> round(float(fov_from_focal(960.0, 1920)), 6)
    90.0
    """
    focal_px = np.asarray(focal_px, dtype=float)
    return np.degrees(2 * np.arctan(0.5 * width_px / focal_px))


def distort_normalized(xy, dist):
    """Apply OpenCV's lens distortion to normalised image coordinates.

    Parameters
    ----------
    xy : array_like, shape (..., 2)
        Ideal (undistorted) normalised coordinates ``(X/Z, Y/Z)``.
    dist : array_like, shape (5,)
        ``[k1, k2, p1, p2, k3]``.

    Returns
    -------
    ndarray, shape (..., 2)
        Distorted normalised coordinates.
    """
    xy = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=float)
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def undistort_normalized(xy_distorted, dist, iterations=20):
    """Invert :func:`distort_normalized` by Newton iterations.

    OpenCV's ``undistortPoints`` uses a fixed-point iteration; Newton with the
    analytic Jacobian converges to the same point (to machine precision) in a
    few steps and is vectorised over any batch shape.

    Parameters
    ----------
    xy_distorted : array_like, shape (..., 2)
        Distorted normalised coordinates.
    dist : array_like, shape (5,)
        ``[k1, k2, p1, p2, k3]``.
    iterations : int
        Maximum number of Newton steps.

    Returns
    -------
    ndarray, shape (..., 2)
    """
    xy_distorted = np.asarray(xy_distorted, dtype=float)
    dist = np.asarray(dist, dtype=float)
    if not np.any(dist):
        return xy_distorted.copy()
    k1, k2, p1, p2, k3 = dist
    xy = xy_distorted.copy()
    for _ in range(iterations):
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
        fx = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - xy_distorted[..., 0]
        fy = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - xy_distorted[..., 1]
        j11 = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
        j12 = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
        j21 = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
        j22 = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
        det = j11 * j22 - j12 * j21
        dx = (j22 * fx - j12 * fy) / det
        dy = (-j21 * fx + j11 * fy) / det
        xy[..., 0] -= dx
        xy[..., 1] -= dy
        if np.nanmax(np.abs(dx) + np.abs(dy), initial=0.0) < 1e-14:  # ~1e-10 px at f = 10^4 px
            break
    return xy


def look_at_rotation(center_track_m, target_track_m, roll_deg=0.0):
    """Track-to-camera rotation of a camera at ``center`` looking at ``target``.

    The camera's x axis stays horizontal (no roll) unless ``roll_deg`` is given;
    positive roll turns the image clockwise about the optical axis.

    Parameters
    ----------
    center_track_m, target_track_m : array_like, shape (3,)
        Camera centre and a point on the optical axis, track frame, metres.
    roll_deg : float
        Rotation about the optical axis.

    Returns
    -------
    ndarray, shape (3, 3)
        ``R`` with rows = camera axes expressed in the track frame.

    Raises
    ------
    ValueError
        If the target coincides with the centre or lies straight below/above it.

    Examples
    --------
    >>> R = look_at_rotation([0, -50, 10], [0, 0, 0])
    >>> np.allclose(R @ R.T, np.eye(3))
    True
    """
    forward = np.asarray(target_track_m, float) - np.asarray(center_track_m, float)
    norm = np.linalg.norm(forward)
    if not np.isfinite(norm) or norm < 1e-12:
        raise ValueError("look-at target must differ from the camera centre")
    forward = forward / norm
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look-at direction is vertical; camera heading is undefined")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    if roll_deg:
        a = np.radians(roll_deg)
        c, s = np.cos(a), np.sin(a)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R
    return R


def rotation_to_pan_tilt_roll(track2cam):
    """Decompose ``R`` into pan (heading of the optical axis, deg, from +x towards +y),
    tilt (deg below the horizon, positive looking down) and roll (deg).

    >>> R = look_at_rotation([0, -10, 10], [0, 0, 0], roll_deg=2.0)
    >>> [round(float(a), 6) for a in rotation_to_pan_tilt_roll(R)]
    [90.0, 45.0, 2.0]
    """
    R = np.asarray(track2cam, float)
    forward = R[..., 2, :]
    pan = np.degrees(np.arctan2(forward[..., 1], forward[..., 0]))
    tilt = np.degrees(np.arcsin(np.clip(-forward[..., 2], -1, 1)))
    # roll: angle of the camera x axis against the horizontal right vector
    right0 = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right0 /= np.linalg.norm(right0, axis=-1, keepdims=True)
    down0 = np.cross(forward, right0)
    x_axis = R[..., 0, :]
    roll = np.degrees(np.arctan2(-np.sum(x_axis * down0, -1), np.sum(x_axis * right0, -1)))
    return pan, tilt, roll


@dataclass(frozen=True)
class RaySphereHits:
    """Both intersections of rays with spheres.

    Attributes
    ----------
    near_m, far_m : ndarray, shape (..., 3)
        Intersection points (track frame) with the smaller/larger ray parameter.
        Where the ray misses, both equal the ray point closest to the sphere.
    miss_m : ndarray, shape (...)
        Distance by which the ray misses the sphere surface (0 when it hits).
    """

    near_m: np.ndarray
    far_m: np.ndarray
    miss_m: np.ndarray


def intersect_rays_plane(origins_m, dirs, plane_normal, plane_offset_m):
    """Intersect rays ``o + t d`` with planes ``n . X = offset``.

    Parameters
    ----------
    origins_m : array_like, shape (..., 3)
    dirs : array_like, shape (..., 3)
    plane_normal : array_like, shape (..., 3)
    plane_offset_m : array_like, shape (...)

    Returns
    -------
    points_m : ndarray, shape (..., 3)
        NaN where the ray is parallel to the plane or the hit lies behind the origin.
    t : ndarray, shape (...)
        Ray parameter (NaN as above).

    Examples
    --------
    >>> p, t = intersect_rays_plane([0, 0, 10], [0, 0.6, -0.8], [0, 0, 1], 0.0)
    >>> p.round(6).tolist(), float(t)
    ([0.0, 7.5, 0.0], 12.5)
    """
    o = np.asarray(origins_m, float)
    d = np.asarray(dirs, float)
    n = np.asarray(plane_normal, float)
    denom = np.sum(d * n, axis=-1)
    num = np.asarray(plane_offset_m, float) - np.sum(o * n, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / denom
    t = np.where((np.abs(denom) > 1e-12) & (t > 0), t, np.nan)
    return o + t[..., None] * d, t


def intersect_rays_sphere(origins_m, dirs, centers_m, radii_m):
    """Intersect rays with spheres; both solutions plus the miss distance.

    Parameters
    ----------
    origins_m : array_like, shape (..., 3)
    dirs : array_like, shape (..., 3)
        Unit directions.
    centers_m : array_like, shape (..., 3)
    radii_m : array_like, shape (...)

    Returns
    -------
    RaySphereHits

    Examples
    --------
    >>> h = intersect_rays_sphere([0, 0, 0], [1, 0, 0], [5, 0, 0], 1.0)
    >>> h.near_m.tolist(), h.far_m.tolist(), float(h.miss_m)
    ([4.0, 0.0, 0.0], [6.0, 0.0, 0.0], 0.0)
    """
    o = np.asarray(origins_m, float)
    d = np.asarray(dirs, float)
    c = np.asarray(centers_m, float)
    r = np.asarray(radii_m, float)
    oc = c - o
    t_mid = np.sum(oc * d, axis=-1)
    closest_sq = np.sum(oc * oc, axis=-1) - t_mid**2
    half_sq = r**2 - closest_sq
    half = np.sqrt(np.clip(half_sq, 0, None))
    miss = np.where(half_sq < 0, np.sqrt(np.clip(closest_sq, 0, None)) - r, 0.0)
    near = o + (t_mid - half)[..., None] * d
    far = o + (t_mid + half)[..., None] * d
    return RaySphereHits(near_m=near, far_m=far, miss_m=miss)


def _as_matrix(value, shape, name):
    arr = np.array(value, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Camera:
    """A calibrated pinhole camera in the track frame.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Intrinsics ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` in pixels.
    R : array_like, shape (3, 3)
        Rotation track -> camera (``X_cam = R @ (X_track - C)``).
    C : array_like, shape (3,)
        Camera centre, track frame, metres.
    dist : array_like, shape (5,)
        OpenCV distortion ``[k1, k2, p1, p2, k3]``.
    image_size : tuple of int
        ``(width_px, height_px)``.

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values, a non-orthonormal ``R`` or a
        non-positive focal length.

    Examples
    --------
    >>> cam = Camera.look_at([30, -60, 12], [30, -4, 1], fov_deg=10.0)
    >>> px = cam.project([30, -4, 1])
    >>> np.allclose(px, [959.5, 539.5])
    True
    """

    K: np.ndarray
    R: np.ndarray
    C: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: _NO_DIST.copy())
    image_size: tuple = (1920, 1080)

    def __post_init__(self):
        object.__setattr__(self, "K", _as_matrix(self.K, (3, 3), "K"))
        object.__setattr__(self, "R", _as_matrix(self.R, (3, 3), "R"))
        object.__setattr__(self, "C", _as_matrix(self.C, (3,), "C"))
        object.__setattr__(self, "dist", _as_matrix(self.dist, (5,), "dist"))
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ValueError(f"image_size must be positive, got {self.image_size}")
        object.__setattr__(self, "image_size", (w, h))
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0:
            raise ValueError("focal length must be positive")
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-6) or np.linalg.det(self.R) < 0:
            raise ValueError("R must be a proper rotation matrix")

    # -- constructors -----------------------------------------------------
    @classmethod
    def look_at(cls, center_track_m, target_track_m, fov_deg, image_size=(1920, 1080),
                roll_deg=0.0, dist=None):
        """Camera at ``center_track_m`` aimed at ``target_track_m`` with horizontal FOV ``fov_deg``,
        principal point at the image centre ``((W - 1) / 2, (H - 1) / 2)``."""
        w, h = image_size
        f = float(focal_from_fov(fov_deg, w))
        K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
        R = look_at_rotation(center_track_m, target_track_m, roll_deg)
        return cls(K=K, R=R, C=np.asarray(center_track_m, float),
                   dist=_NO_DIST if dist is None else dist, image_size=image_size)

    @classmethod
    def from_dict(cls, d, image_size=(1920, 1080)):
        """Build from a ``cameras.json`` / ``camera.json`` frame entry (CLIP_FORMAT)."""
        try:
            return cls(K=d["K"], R=d["R"], C=d["C"], dist=d.get("dist", _NO_DIST),
                       image_size=tuple(d.get("image_size", image_size)))
        except KeyError as exc:
            raise ValueError(f"camera entry lacks key {exc}") from None

    def to_dict(self):
        """JSON-ready dict in the CLIP_FORMAT layout (plus ``fov_deg``)."""
        return {"K": self.K.tolist(), "R": self.R.tolist(), "C": self.C.tolist(),
                "dist": self.dist.tolist(), "fov_deg": self.fov_deg}

    def with_(self, **changes):
        """Copy with some fields replaced."""
        return replace(self, **changes)

    # -- properties -------------------------------------------------------
    @property
    def focal_px(self):
        return float(self.K[0, 0])

    @property
    def fov_deg(self):
        """Horizontal field of view in degrees."""
        return float(fov_from_focal(self.focal_px, self.image_size[0]))

    @property
    def principal_point_px(self):
        return self.K[:2, 2].copy()

    @property
    def has_distortion(self):
        return bool(np.any(self.dist))

    @property
    def projection_matrix(self):
        """3x4 matrix ``K [R | -R C]`` (ignores distortion)."""
        return self.K @ np.hstack([self.R, (-self.R @ self.C)[:, None]])

    # -- projection -------------------------------------------------------
    def track_to_camera(self, points_track_m):
        """Points in camera coordinates, shape (..., 3)."""
        p = np.asarray(points_track_m, float)
        return (p - self.C) @ self.R.T

    def project(self, points_track_m, return_depth=False):
        """Project track-frame points to (distorted) pixels.

        Parameters
        ----------
        points_track_m : array_like, shape (..., 3)
        return_depth : bool
            Also return the camera-frame depth ``Z`` (negative = behind).

        Returns
        -------
        pts_px : ndarray, shape (..., 2)
            NaN for points at or behind the camera plane.
        depth_m : ndarray, shape (...), only if ``return_depth``
        """
        pc = self.track_to_camera(points_track_m)
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = pc[..., :2] / np.where(z > 1e-9, z, np.nan)[..., None]
        if self.has_distortion:
            xy = distort_normalized(xy, self.dist)
        px = xy * self.K[0, 0] + self.K[:2, 2]
        return (px, z) if return_depth else px

    def normalized_from_pixels(self, pts_px):
        """Undistorted normalised coordinates of pixels, shape (..., 2)."""
        xy = (np.asarray(pts_px, float) - self.K[:2, 2]) / self.K[0, 0]
        if self.has_distortion:
            xy = undistort_normalized(xy, self.dist)
        return xy

    def rays_from_pixels(self, pts_px):
        """Unit viewing rays (track frame) through pixels.

        Parameters
        ----------
        pts_px : array_like, shape (..., 2)

        Returns
        -------
        ndarray, shape (..., 3)
            Unit directions; every ray starts at ``C``.

        Examples
        --------
        >>> cam = Camera.look_at([0, -50, 10], [0, 0, 0], fov_deg=20.0)
        >>> ray = cam.rays_from_pixels(cam.project([1.0, 2.0, 0.5]))
        >>> p, _ = intersect_rays_plane(cam.C, ray, [0, 0, 1], 0.5)
        >>> np.allclose(p, [1.0, 2.0, 0.5])
        True
        """
        xy = self.normalized_from_pixels(pts_px)
        d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        d = d_cam @ self.R  # R.T @ d_cam for each ray
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def cast_to_ground(self, pts_px, height_m=0.0):
        """Intersect pixel rays with the horizontal plane ``z = height_m``; NaN above the horizon."""
        rays = self.rays_from_pixels(pts_px)
        pts, _ = intersect_rays_plane(self.C, rays, [0.0, 0.0, 1.0], height_m)
        return pts

    def in_image(self, pts_px, margin_px=0.0):
        """Boolean mask of pixels inside the image (with an optional margin)."""
        p = np.asarray(pts_px, float)
        w, h = self.image_size
        return ((p[..., 0] >= -0.5 - margin_px) & (p[..., 0] <= w - 0.5 + margin_px)
                & (p[..., 1] >= -0.5 - margin_px) & (p[..., 1] <= h - 0.5 + margin_px))
