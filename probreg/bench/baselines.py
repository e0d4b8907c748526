"""Baselines for the comparison tables (stand-ins, not the original methods).

* :func:`planar_knee_angles`: the knee angle measured in the image from 2D
  keypoints, raw or after Sports2D's default 4th-order 6 Hz Butterworth
  filter on the keypoints; what a Sports2D user gets today.
* :func:`generic_camera_lift`: a stand-in for an off-the-shelf monocular 3D
  method that knows no intrinsics.  MeTRAbs, the seed paper's baseline,
  assumes a 55 deg field of view when none is given; this baseline lifts the
  same keypoints with the same limb lengths and the same ray-sphere machinery,
  but under a 55 deg camera looking horizontally and square onto the straight,
  with the athlete's plane fronto-parallel at a weak-perspective depth.  With
  ``track2cam`` (the "+ rotation" variant of the paper) the estimated
  calibration's rotation turns the result into the track frame.  It is *not*
  MeTRAbs: a learned model would bring its own pose prior and its own errors.
"""

from __future__ import annotations

import numpy as np

from ..filtering import butterworth
from ..geometry import JOINT_INDEX, Camera, focal_from_fov, look_at_rotation
from ..lifting import GroundTrack, LiftConfig, lift

__all__ = ["planar_knee_angles", "generic_camera_lift", "GENERIC_FOV_DEG"]


GENERIC_FOV_DEG = 55.0

J = JOINT_INDEX

def planar_knee_angles(keypoints_px, fps=50.0, filtered=False, cutoff_hz=6.0):
    """Knee flexion (deg) measured in the image plane: 180 - the 2D angle hip-knee-ankle.

    Returns
    -------
    dict with ``knee_l``, ``knee_r`` arrays (F,)
    """
    kp = np.asarray(keypoints_px, float)[..., :2].copy()
    if filtered:
        for j in range(kp.shape[1]):
            for c in range(2):
                kp[:, j, c] = butterworth(kp[:, j, c], fps, cutoff_hz, order=4)
    out = {}
    for side in ("l", "r"):
        u = kp[:, J[f"{side}_hip"]] - kp[:, J[f"{side}_knee"]]
        v = kp[:, J[f"{side}_ankle"]] - kp[:, J[f"{side}_knee"]]
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.sum(u * v, -1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))
        out[f"knee_{side}"] = 180.0 - np.degrees(np.arccos(np.clip(c, -1, 1)))
    return out


def generic_camera_lift(keypoints_px, image_size, segments_m, fps=50.0, fov_deg=GENERIC_FOV_DEG,
                        track2cam=None):
    """Pelvis-relative 3D joints (F, 17, 3) from a generic-camera lifting.

    Parameters
    ----------
    keypoints_px : ndarray (F, 17, 3)
    image_size : tuple
    segments_m : dict
        Limb lengths (the same as probreg's, so only the camera differs).
    track2cam : ndarray (F, 3, 3) or (3, 3), optional
        Estimated track-to-camera rotation ("+ rotation" variant): the generic
        camera-frame result is rotated into the track frame with it.

    Returns
    -------
    ndarray, shape (F, 17, 3)
        Joints relative to the pelvis, in the track frame (default orientation
        without ``track2cam``: camera square onto the straight, looking at +y).
    """
    kp = np.asarray(keypoints_px, float)
    F = len(kp)
    w, h = image_size
    f = float(focal_from_fov(fov_deg, w))
    # weak-perspective depth: metric trunk + legs over their pixel lengths
    def seglen(a, b):
        return np.linalg.norm(kp[:, J[a], :2] - kp[:, J[b], :2], axis=-1)
    px = seglen("pelvis", "thorax") + 0.5 * (seglen("r_hip", "r_knee") + seglen("l_hip", "l_knee")
                                            + seglen("r_knee", "r_ankle") + seglen("l_knee", "l_ankle"))
    metres = segments_m["trunk"] + segments_m["thigh"] + segments_m["shank"]
    with np.errstate(invalid="ignore", divide="ignore"):
        depth = f * metres / px
    depth = np.where(np.isfinite(depth), depth, np.nanmedian(depth))
    R0 = look_at_rotation([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])  # horizontal, looking at +y
    cam = Camera(K=[[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], R=R0, C=[0.0, 0.0, 0.0],
                 image_size=(w, h))
    # the athlete's plane: fronto-parallel (y = depth), running along +x
    track = GroundTrack(position_m=np.column_stack([np.zeros(F), depth]),
                        velocity_mps=np.tile([1.0, 0.0], (F, 1)), cov=np.zeros((F, 4, 4)),
                        contacts=np.zeros((F, 2), bool), contact_points_m=np.zeros((0, 4)),
                        log_likelihood=0.0)
    res = lift([cam] * F, kp, fps, segments_m=segments_m, track=track, config=LiftConfig())
    rel = res.joints_track_m - res.joints_track_m[:, J["pelvis"]][:, None]
    if track2cam is None:
        return rel
    # generic world -> generic camera -> (estimated) track frame
    Rt = np.broadcast_to(np.asarray(track2cam, float), (F, 3, 3))
    cam_rel = np.einsum("ij,fkj->fki", R0, rel)
    return np.einsum("fji,fkj->fki", Rt, cam_rel)
