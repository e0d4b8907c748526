import numpy as np
import pytest

from probreg.geometry import (
    ANGLE_NAMES,
    BONES,
    JOINT_INDEX,
    bone_lengths,
    coco_to_h36m,
    joint_angles,
    segment_lengths,
)


def test_coco_head_uses_visible_face_points_and_missing_propagates():
    kp = np.zeros((2, 17, 3))
    kp[..., 2] = 0.9
    kp[:, 0, :2] = [10, 0]   # nose
    kp[:, 3, :2] = [0, 0]    # l_ear
    kp[:, 4, :2] = [20, 0]   # r_ear
    kp[1, 3:5] = np.nan      # ears missing in frame 1
    kp[1, 11] = np.nan       # left hip missing
    h = coco_to_h36m(kp)
    assert np.allclose(h[0, JOINT_INDEX["head"], :2], [10, 0])
    assert np.allclose(h[1, JOINT_INDEX["head"], :2], [10, 0])  # nose alone
    assert np.all(np.isnan(h[1, JOINT_INDEX["pelvis"]]))
    assert np.all(np.isnan(h[1, JOINT_INDEX["spine"]]))


def test_coco_rejects_wrong_joint_count():
    with pytest.raises(ValueError, match="17"):
        coco_to_h36m(np.zeros((18, 3)))


def test_angles_vectorised_and_nan_safe(rng):
    j = rng.normal(size=(3, 5, 17, 3))
    j[0, 0, JOINT_INDEX["r_knee"]] = np.nan
    a = joint_angles(j)
    assert set(a) == set(ANGLE_NAMES)
    assert a["knee_r"].shape == (3, 5)
    assert np.isnan(a["knee_r"][0, 0]) and np.isfinite(a["knee_l"][0, 0])
    assert np.all((a["knee_l"] >= 0) & (a["knee_l"] <= 180))


def test_angles_invariant_to_translation_and_heading_when_forward_rotates(rng):
    j = rng.normal(size=(17, 3))
    c, s = np.cos(0.7), np.sin(0.7)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    a0 = joint_angles(j)
    a1 = joint_angles(j @ Rz.T + [5, -2, 0], forward=Rz @ [1, 0, 0])
    for k in ANGLE_NAMES:
        assert np.isclose(a0[k], a1[k])


def test_segment_and_bone_lengths():
    j = np.zeros((17, 3))
    j[JOINT_INDEX["r_knee"]] = [0, 0, -0.4]
    j[JOINT_INDEX["l_knee"]] = [0, 0, -0.44]
    seg = segment_lengths(j)
    assert np.isclose(seg["thigh"], 0.42)
    assert bone_lengths(j).shape == (len(BONES),)
