import cv2
import numpy as np
import pytest

from probreg.geometry import (
    Camera,
    distort_normalized,
    focal_from_fov,
    fov_from_focal,
    intersect_rays_plane,
    intersect_rays_sphere,
    look_at_rotation,
    rotation_to_pan_tilt_roll,
    undistort_normalized,
)

DIST = np.array([-0.25, 0.08, 0.0015, -0.001, -0.01])


@pytest.fixture
def cam():
    return Camera.look_at([40, -55, 14], [35, -4, 1], fov_deg=12.0, roll_deg=0.7, dist=DIST)


def test_project_matches_opencv(cam, rng):
    pts = np.column_stack([rng.uniform(30, 40, 50), rng.uniform(-8, 0, 50), rng.uniform(0, 2, 50)])
    rvec, _ = cv2.Rodrigues(cam.R)
    ref, _ = cv2.projectPoints(pts, rvec, -cam.R @ cam.C, cam.K, cam.dist)
    assert np.max(np.abs(cam.project(pts) - ref[:, 0])) < 1e-6


def test_undistort_matches_opencv(cam, rng):
    px = rng.uniform([0, 0], [1919, 1079], (200, 2))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(px[:, None], cam.K, cam.dist, P=cam.K, criteria=crit)[:, 0]
    ours = cam.normalized_from_pixels(px) * cam.focal_px + cam.K[:2, 2]
    assert np.max(np.abs(ours - ref)) < 1e-6


def test_distort_undistort_round_trip(rng):
    xy = rng.uniform(-0.4, 0.4, (5, 7, 2))  # batch shape preserved
    back = undistort_normalized(distort_normalized(xy, DIST), DIST)
    assert back.shape == xy.shape
    assert np.max(np.abs(back - xy)) < 1e-12


def test_project_backproject_round_trip(cam, rng):
    pts = np.column_stack([rng.uniform(30, 40, 30), rng.uniform(-8, 0, 30), rng.uniform(0, 2, 30)])
    rays = cam.rays_from_pixels(cam.project(pts))
    assert np.allclose(np.linalg.norm(rays, axis=-1), 1)
    # the ray from C through the pixel passes through the original point
    v = pts - cam.C
    cross = np.linalg.norm(np.cross(rays, v), axis=-1) / np.linalg.norm(v, axis=-1)
    assert np.max(cross) < 1e-9


def test_cast_to_ground_recovers_ground_points(cam):
    g = np.array([[33.0, -3.0, 0.0], [38.0, -6.5, 0.0]])
    assert np.allclose(cam.cast_to_ground(cam.project(g)), g, atol=1e-8)


def test_points_behind_camera_are_nan(cam):
    behind = cam.C - 5 * cam.R[2]
    assert np.all(np.isnan(cam.project(behind)))


def test_fov_focal_round_trip():
    for fov in (2.0, 10.0, 55.0, 120.0):
        assert np.isclose(fov_from_focal(focal_from_fov(fov, 1920), 1920), fov)
    with pytest.raises(ValueError, match="field of view"):
        focal_from_fov(180.0, 1920)
    with pytest.raises(ValueError, match="field of view"):
        focal_from_fov(-1.0, 1920)


def test_pan_tilt_roll_decomposition():
    R = look_at_rotation([0, -30, 10], [5, 0, 0], roll_deg=-1.5)
    pan, tilt, roll = rotation_to_pan_tilt_roll(R)
    assert np.isclose(roll, -1.5)
    assert np.isclose(tilt, np.degrees(np.arctan2(10, np.hypot(5, 30))))
    assert np.isclose(pan, np.degrees(np.arctan2(30, 5)))


def test_ray_plane_batch_and_parallel():
    o = np.zeros((4, 3))
    d = np.array([[0, 0, -1], [1, 0, 0], [0, 0, 1], [0.6, 0, -0.8]])
    p, t = intersect_rays_plane(o, d, [0, 0, 1], -2.0)
    assert np.allclose(p[0], [0, 0, -2]) and np.allclose(p[3], [1.5, 0, -2])
    assert np.all(np.isnan(t[1:3]))  # parallel, and behind the origin


def test_ray_sphere_hits_and_miss():
    o = np.zeros((2, 3))
    d = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    h = intersect_rays_sphere(o, d, [[5.0, 0, 0], [5.0, 0, 0]], [1.0, 1.0])
    assert np.allclose(h.near_m[0], [4, 0, 0]) and np.allclose(h.far_m[0], [6, 0, 0])
    assert h.miss_m[0] == 0
    assert np.isclose(h.miss_m[1], 4.0)  # closest approach 5 m from the centre, radius 1
    assert np.allclose(h.near_m[1], [0, 0, 0])


def test_camera_rejects_bad_input():
    with pytest.raises(ValueError, match="shape"):
        Camera(K=np.eye(2), R=np.eye(3), C=np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        Camera(K=np.eye(3), R=np.eye(3), C=[np.nan, 0, 0])
    with pytest.raises(ValueError, match="rotation"):
        Camera(K=np.eye(3), R=2 * np.eye(3), C=np.zeros(3))
    with pytest.raises(ValueError, match="differ"):
        Camera.look_at([0, 0, 1], [0, 0, 1], 10.0)


def test_dict_round_trip(cam):
    again = Camera.from_dict(cam.to_dict())
    assert np.allclose(again.K, cam.K) and np.allclose(again.R, cam.R) and np.allclose(again.dist, cam.dist)
    with pytest.raises(ValueError, match="lacks key"):
        Camera.from_dict({"K": cam.K.tolist()})
