"""One assertion per convention stated in shared/CLIP_FORMAT.md."""

import cv2
import numpy as np

from probreg.geometry import (
    JOINT_NAMES,
    STANDARD_TRACK,
    Camera,
    coco_to_h36m,
    joint_angles,
    lane_line_y,
)


def test_track_frame_is_right_handed_z_up():
    # x along the straight, y to the infield, z up: x cross y = z
    assert np.allclose(np.cross([1, 0, 0], [0, 1, 0]), [0, 0, 1])


def test_lane_line_positions():
    assert np.allclose(lane_line_y(np.arange(9)), -1.22 * np.arange(9))
    assert STANDARD_TRACK.lane_width_m == 1.22 and STANDARD_TRACK.line_width_m == 0.05


def test_infield_is_positive_y():
    # bend centres lie in the infield
    assert np.all(STANDARD_TRACK.bend_centers()[:, 1] > 0)


def test_camera_axes_opencv_and_extrinsics_direction():
    cam = Camera.look_at([0, -10, 0.0001], [0, 0, 0], 60.0)
    # the camera looks along +y of the track: X_cam = R (X - C) puts a point ahead at +z
    assert cam.track_to_camera([0, 0, 0])[2] > 0
    # from the stands looking to the infield the running direction (+x) is image right: x right
    assert cam.project([1, 0, 0])[0] > cam.project([0, 0, 0])[0]
    # up in the world is up in the image: y down
    assert cam.project([0, 0, 1])[1] < cam.project([0, 0, 0])[1]


def test_principal_point_at_image_centre_and_pixel_origin():
    cam = Camera.look_at([0, -10, 2], [0, 0, 2], 40.0, image_size=(1920, 1080))
    assert np.allclose(cam.K[:2, 2], [(1920 - 1) / 2, (1080 - 1) / 2])
    assert np.allclose(cam.project([0, 0, 2]), [959.5, 539.5])


def test_distortion_order_matches_opencv():
    cam = Camera.look_at([3, -20, 5], [0, 0, 1], 30.0, dist=[-0.2, 0.05, 0.001, -0.002, 0.01])
    pts = np.array([[1.0, 2.0, 0.5], [-2.0, -1.0, 1.0]])
    rvec, _ = cv2.Rodrigues(cam.R)
    ref, _ = cv2.projectPoints(pts, rvec, -cam.R @ cam.C, cam.K, cam.dist)
    assert np.allclose(cam.project(pts), ref[:, 0], atol=1e-6)


def test_joint_order():
    assert JOINT_NAMES == ("pelvis", "r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle", "spine",
                           "thorax", "neck", "head", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder",
                           "r_elbow", "r_wrist")


def test_coco_mapping_pelvis_thorax_spine():
    kp = np.random.default_rng(0).uniform(0, 100, (17, 3))
    h = coco_to_h36m(kp)
    assert np.allclose(h[0, :2], (kp[11, :2] + kp[12, :2]) / 2)        # pelvis = mid-hip
    assert np.allclose(h[8, :2], (kp[5, :2] + kp[6, :2]) / 2)          # thorax = mid-shoulder
    assert np.allclose(h[7, :2], (h[0, :2] + h[8, :2]) / 2)            # spine = mid pelvis-thorax


def _pose(thigh_fwd_deg=0.0, knee_deg=0.0, lean_deg=0.0):
    j = np.zeros((17, 3))
    lean = np.radians(lean_deg)
    j[8] = [0.5 * np.sin(lean), 0, 0.5 * np.cos(lean)]  # thorax over the pelvis at origin
    for hip, knee, ankle in ((1, 2, 3), (4, 5, 6)):
        t = np.radians(thigh_fwd_deg)
        j[knee] = [0.4 * np.sin(t), 0, -0.4 * np.cos(t)]
        s = t - np.radians(knee_deg)
        j[ankle] = j[knee] + [0.4 * np.sin(s), 0, -0.4 * np.cos(s)]
    for sh, el, wr in ((11, 12, 13), (14, 15, 16)):
        j[sh] = j[8]
        j[el] = j[sh] + [0, 0, -0.3]
        j[wr] = j[el] + [0.25, 0, 0]
    return j


def test_knee_flexion_zero_straight_positive_flexed():
    assert abs(joint_angles(_pose())["knee_r"]) < 1e-9
    assert np.isclose(joint_angles(_pose(knee_deg=30))["knee_l"], 30)


def test_elbow_flexion_definition():
    assert np.isclose(joint_angles(_pose())["elbow_r"], 90)


def test_trunk_lean_forward_positive():
    assert np.isclose(joint_angles(_pose(lean_deg=10))["trunk_lean"], 10)


def test_hip_flexion_is_thigh_against_trunk_line():
    a = joint_angles(_pose(thigh_fwd_deg=20, lean_deg=10))
    assert np.isclose(a["hip_r"], 30)
