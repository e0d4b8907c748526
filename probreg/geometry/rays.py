"""Per-frame cameras stacked as arrays and the viewing rays of pixels (vectorised over frames)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import undistort_normalized

__all__ = ["CameraArrays", "camera_arrays", "camera_centres", "pixel_rays"]


@dataclass(frozen=True)
class CameraArrays:
    """Per-frame cameras as stacked arrays (frames without a camera are NaN, ``valid`` False)."""

    valid: np.ndarray      # (F,)
    C: np.ndarray          # (F, 3)
    R: np.ndarray          # (F, 3, 3)
    focal_px: np.ndarray   # (F,)
    principal_px: np.ndarray  # (F, 2)
    dist: np.ndarray       # (5,) shared by the clip


def camera_arrays(cameras):
    """Stack a list of :class:`~probreg.geometry.camera.Camera` (or None) into :class:`CameraArrays`."""
    F = len(cameras)
    valid = np.array([c is not None for c in cameras], bool)
    C = np.full((F, 3), np.nan)
    R = np.full((F, 3, 3), np.nan)
    f = np.full(F, np.nan)
    pp = np.full((F, 2), np.nan)
    dist = np.zeros(5)
    for i, c in enumerate(cameras):
        if c is not None:
            C[i], R[i], f[i], pp[i] = c.C, c.R, c.focal_px, c.K[:2, 2]
            dist = c.dist
    return CameraArrays(valid, C, R, f, pp, np.asarray(dist, float))


def pixel_rays(cams: CameraArrays, pts_px):
    """Unit rays (track frame) through pixels, vectorised: pts (F, K, 2) -> (F, K, 3)."""
    xy = (pts_px - cams.principal_px[:, None, :]) / cams.focal_px[:, None, None]
    if np.any(cams.dist):
        xy = undistort_normalized(xy, cams.dist)
    d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
    d = np.einsum("fij,fki->fkj", cams.R, d_cam)  # R^T d_cam per frame
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def camera_centres(cameras):
    """Camera centres (F, 3) in the track frame, NaN rows for frames without a camera, from a list
    of :class:`~probreg.geometry.camera.Camera` (or None), a :class:`CameraArrays` or an (F, 3) array.

    >>> camera_centres([None, np.array([1.0, 2.0, 3.0])]).tolist()
    [[nan, nan, nan], [1.0, 2.0, 3.0]]
    """
    if isinstance(cameras, CameraArrays):
        return np.asarray(cameras.C, float)
    if not isinstance(cameras, np.ndarray):
        cameras = np.array([np.full(3, np.nan) if c is None else getattr(c, "C", c) for c in cameras], float)
    return np.asarray(cameras, float).reshape(-1, 3)


def _as_list(cams: CameraArrays):
    """CameraArrays -> list of Camera/None (for functions that take Camera objects)."""
    from .camera import Camera

    out = []
    for i in range(len(cams.valid)):
        if not cams.valid[i]:
            out.append(None)
            continue
        f = cams.focal_px[i]
        K = np.array([[f, 0, cams.principal_px[i, 0]], [0, f, cams.principal_px[i, 1]], [0, 0, 1.0]])
        out.append(Camera(K=K, R=cams.R[i], C=cams.C[i], dist=cams.dist))
    return out
