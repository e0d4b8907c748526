"""The H36M-17 skeleton: joint order, COCO-17 mapping, limbs, segment lengths, joint angles.

Joint order and angle definitions are those of ``CLIP_FORMAT.md``.  Angles are
returned in degrees (the edge of the library) and computed vectorised over any
leading batch dimensions (frames, posterior draws).
"""

from __future__ import annotations

import numpy as np

__all__ = ["JOINT_NAMES", "JOINT_INDEX", "COCO_NAMES", "BONES", "SEGMENT_BONES", "ANGLE_NAMES", "coco_to_h36m", "segment_lengths", "joint_angles", "bone_lengths"]


JOINT_NAMES = (
    "pelvis", "r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle", "spine",
    "thorax", "neck", "head", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder",
    "r_elbow", "r_wrist",
)

JOINT_INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}

COCO_NAMES = (
    "nose", "l_eye", "r_eye", "l_ear", "r_ear", "l_shoulder", "r_shoulder", "l_elbow",
    "r_elbow", "l_wrist", "r_wrist", "l_hip", "r_hip", "l_knee", "r_knee", "l_ankle",
    "r_ankle",
)

_COCO = {name: i for i, name in enumerate(COCO_NAMES)}

#: Kinematic tree as (parent, child) joint names; the lifting walks it in this order.
BONES = (
    ("pelvis", "r_hip"), ("r_hip", "r_knee"), ("r_knee", "r_ankle"),
    ("pelvis", "l_hip"), ("l_hip", "l_knee"), ("l_knee", "l_ankle"),
    ("pelvis", "spine"), ("spine", "thorax"), ("thorax", "neck"), ("neck", "head"),
    ("thorax", "l_shoulder"), ("l_shoulder", "l_elbow"), ("l_elbow", "l_wrist"),
    ("thorax", "r_shoulder"), ("r_shoulder", "r_elbow"), ("r_elbow", "r_wrist"),
)

#: Named body segments (as used by priors and the posterior) -> the joint pairs that span them.
SEGMENT_BONES = {
    "thigh": (("r_hip", "r_knee"), ("l_hip", "l_knee")),
    "shank": (("r_knee", "r_ankle"), ("l_knee", "l_ankle")),
    "upper_arm": (("r_shoulder", "r_elbow"), ("l_shoulder", "l_elbow")),
    "forearm": (("r_elbow", "r_wrist"), ("l_elbow", "l_wrist")),
    "hip_width": (("r_hip", "l_hip"),),
    "shoulder_width": (("r_shoulder", "l_shoulder"),),
    "trunk": (("pelvis", "thorax"),),
    "neck": (("thorax", "neck"),),
    "head": (("neck", "head"),),
}

ANGLE_NAMES = ("knee_l", "knee_r", "hip_l", "hip_r", "elbow_l", "elbow_r", "trunk_lean")

def _idx(name):
    return JOINT_INDEX[name]


def coco_to_h36m(keypoints):
    """Map COCO-17 keypoints to H36M-17 (``CLIP_FORMAT.md``).

    pelvis = mid-hip, thorax = mid-shoulder, spine = midpoint of pelvis and
    thorax, head = mean of the visible nose and ears, neck = midpoint of thorax
    and head.  Limb joints map one to one.  A derived joint is missing (NaN)
    when any joint it needs is missing; its score is the smallest of its inputs.

    Parameters
    ----------
    keypoints : array_like, shape (..., 17, C)
        COCO order; ``C`` is 2 (x, y) or 3 (x, y, score).  Missing joints are NaN.

    Returns
    -------
    ndarray, shape (..., 17, C)

    Raises
    ------
    ValueError
        If the joint axis does not have 17 entries.

    Examples
    --------
    >>> kp = np.zeros((17, 3)); kp[:, 2] = 1
    >>> kp[11, :2] = [0, 10]; kp[12, :2] = [2, 10]   # hips
    >>> coco_to_h36m(kp)[0].tolist()                  # pelvis
    [1.0, 10.0, 1.0]
    """
    kp = np.asarray(keypoints, dtype=float)
    if kp.ndim < 2 or kp.shape[-2] != 17:
        raise ValueError(f"COCO-17 keypoints need shape (..., 17, C), got {kp.shape}")
    out = np.full(kp.shape, np.nan)

    def mean_of(*names):
        pts = np.stack([kp[..., _COCO[n], :] for n in names], axis=0)
        return np.concatenate([pts[..., :2].mean(axis=0), pts[..., 2:].min(axis=0)], -1)

    for name in ("r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle", "l_shoulder",
                 "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist"):
        out[..., _idx(name), :] = kp[..., _COCO[name], :]
    out[..., _idx("pelvis"), :] = mean_of("l_hip", "r_hip")
    out[..., _idx("thorax"), :] = mean_of("l_shoulder", "r_shoulder")
    pel, tho = out[..., _idx("pelvis"), :], out[..., _idx("thorax"), :]
    out[..., _idx("spine"), :] = _midpoint(pel, tho)
    face = np.stack([kp[..., _COCO[n], :] for n in ("nose", "l_ear", "r_ear")], axis=0)
    seen = ~np.isnan(face[..., 0])
    n_seen = seen.sum(axis=0)
    head_xy = np.where(seen[..., None], face[..., :2], 0.0).sum(axis=0) / np.maximum(n_seen, 1)[..., None]
    head_score = np.where(seen[..., None], face[..., 2:], np.inf).min(axis=0)
    head = np.concatenate([head_xy, head_score], -1)
    out[..., _idx("head"), :] = np.where((n_seen > 0)[..., None], head, np.nan)
    out[..., _idx("neck"), :] = _midpoint(tho, out[..., _idx("head"), :])
    return out


def _midpoint(a, b):
    mid = 0.5 * (a[..., :2] + b[..., :2])
    if a.shape[-1] > 2:
        return np.concatenate([mid, np.minimum(a[..., 2:], b[..., 2:])], -1)
    return mid


def bone_lengths(joints):
    """Length of every bone in :data:`BONES`, shape (..., len(BONES)), in the joints' unit."""
    j = np.asarray(joints, float)
    par = [_idx(p) for p, _ in BONES]
    chi = [_idx(c) for _, c in BONES]
    return np.linalg.norm(j[..., chi, :] - j[..., par, :], axis=-1)


def segment_lengths(joints_m):
    """Named segment lengths (m), averaged over left and right where paired.

    Parameters
    ----------
    joints_m : array_like, shape (..., 17, 3)

    Returns
    -------
    dict of str -> ndarray, shape (...)
    """
    j = np.asarray(joints_m, float)
    out = {}
    for seg, pairs in SEGMENT_BONES.items():
        lens = [np.linalg.norm(j[..., _idx(b), :] - j[..., _idx(a), :], axis=-1) for a, b in pairs]
        out[seg] = np.mean(lens, axis=0)
    return out


def _interior_angle_rad(a, b, c):
    u = a - b
    v = c - b
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.sum(u * v, -1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def joint_angles(joints_track_m, forward=(1.0, 0.0, 0.0)):
    """Joint angles of ``CLIP_FORMAT.md`` in degrees.

    Parameters
    ----------
    joints_track_m : array_like, shape (..., 17, 3)
        Track-frame joints (metres); NaN joints give NaN angles.
    forward : array_like, shape (3,) or (..., 3)
        Horizontal unit running direction ``f`` (default: track ``+x``).

    Returns
    -------
    dict of str -> ndarray, shape (...)
        Keys :data:`ANGLE_NAMES`: knee and elbow flexion (0 = straight), hip
        flexion (thigh against the trunk line in the sagittal plane) and trunk
        lean (forward positive).

    Examples
    --------
    >>> j = np.zeros((17, 3))
    >>> j[JOINT_INDEX["thorax"]] = [0, 0, 0.5]
    >>> j[JOINT_INDEX["r_hip"]] = [0, 0, 0]
    >>> j[JOINT_INDEX["r_knee"]] = [0, 0, -0.4]
    >>> j[JOINT_INDEX["r_ankle"]] = [-0.4, 0, -0.4]
    >>> round(float(joint_angles(j)["knee_r"]), 6)
    90.0
    """
    j = np.asarray(joints_track_m, float)
    f = np.asarray(forward, float)
    f = f / np.linalg.norm(f, axis=-1, keepdims=True)
    z = np.array([0.0, 0.0, 1.0])
    P = lambda name: j[..., _idx(name), :]  # noqa: E731
    out = {}
    for side in ("l", "r"):
        out[f"knee_{side}"] = 180.0 - np.degrees(
            _interior_angle_rad(P(f"{side}_hip"), P(f"{side}_knee"), P(f"{side}_ankle")))
    w = P("thorax") - P("pelvis")
    lean = np.arctan2(np.sum(w * f, -1), np.sum(w * z, -1))
    for side in ("l", "r"):
        v = P(f"{side}_knee") - P(f"{side}_hip")
        out[f"hip_{side}"] = np.degrees(np.arctan2(np.sum(v * f, -1), -np.sum(v * z, -1)) + lean)
    for side in ("l", "r"):
        out[f"elbow_{side}"] = 180.0 - np.degrees(
            _interior_angle_rad(P(f"{side}_shoulder"), P(f"{side}_elbow"), P(f"{side}_wrist")))
    out["trunk_lean"] = np.degrees(lean)
    return {name: out[name] for name in ANGLE_NAMES}
