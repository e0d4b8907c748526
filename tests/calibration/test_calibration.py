"""Known-answer tests of the one-DOF calibration family (exact lines from known cameras)."""

import numpy as np
import pytest

from probreg.calibration import (
    AzimuthParameter,
    CalibrationError,
    CalibrationFamily,
    FovParameter,
    HeightParameter,
)
from probreg.geometry import Camera

CASES = {
    # name: (centre, target, fov_deg, roll_deg, branch)
    "typical": ([30, -60, 15], [30, -4, 0], 12.0, 0.0, "narrow"),
    "roll": ([10, -80, 25], [40, -4, 0], 5.0, 2.5, "narrow"),
    "narrow_2deg": ([0, -110, 8], [60, -4, 1], 2.0, -1.0, "narrow"),
    "strong_tilt": ([45, -20, 28], [40, -3, 0], 30.0, 0.5, "wide"),
    "square_vp_at_infinity": ([40, -50, 10], [40, -4, 1], 8.0, 0.0, "narrow"),
    "lines_near_vertical": ([-30, -6, 12], [30, -4, 0], 20.0, 0.0, "narrow"),
    "lines_near_horizontal": ([52, -70, 6], [50, -4, 0], 6.0, 0.0, "narrow"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_true_height_recovers_the_camera(name):
    C, T, fov, roll, branch = CASES[name]
    cam = Camera.look_at(C, T, fov_deg=fov, roll_deg=roll)
    fam = CalibrationFamily.from_camera(cam, line_indices=range(1, 7))
    f = HeightParameter().focal_for(fam, C[2], branch=branch)
    m = fam.member_at_focal(f)
    got = m.camera(cam.image_size, line_offset=1, x_m=C[0])
    assert np.isclose(got.focal_px, cam.focal_px, rtol=1e-7)
    assert np.allclose(got.R, cam.R, atol=1e-7)
    assert np.allclose(got.C, cam.C, atol=1e-5)


def _max_line_distance_px(cam, fam, line_offset):
    """Largest distance (px) between the lines a camera projects and the observed ones."""
    worst = 0.0
    P = cam.projection_matrix
    for line, k in zip(fam.lines, fam.indices):
        y = -1.22 * (k + line_offset)
        xs = np.linspace(0, 80, 200)
        hp = np.column_stack([xs, np.full_like(xs, y), np.zeros_like(xs), np.ones_like(xs)]) @ P.T
        px = hp[hp[:, 2] > 0, :2] / hp[hp[:, 2] > 0, 2:]
        px = px[cam.in_image(px)]
        if len(px):
            worst = max(worst, float(np.max(np.abs(px @ line[:2] + line[2]))))
    return worst


@pytest.mark.parametrize("name", ["typical", "roll", "square_vp_at_infinity", "narrow_2deg"])
def test_every_member_reproduces_the_lines(name):
    C, T, fov, roll, _ = CASES[name]
    cam = Camera.look_at(C, T, fov_deg=fov, roll_deg=roll)
    fam = CalibrationFamily.from_camera(cam, line_indices=range(2, 6))
    for h in (0.5 * C[2], C[2], 1.4 * C[2]):
        try:
            m = fam.member(height_m=h)
        except CalibrationError:
            continue
        other = m.camera(cam.image_size, line_offset=2)
        assert _max_line_distance_px(other, fam, 2) < 0.5
    for fov_deg in (0.7 * fov, 1.3 * fov):
        other = fam.member_at_focal(FovParameter().focal_for(fam, fov_deg)).camera(cam.image_size, line_offset=2)
        assert _max_line_distance_px(other, fam, 2) < 0.5


def test_alternative_parameters_select_the_same_member():
    C, T, fov, roll, _ = CASES["roll"]
    cam = Camera.look_at(C, T, fov_deg=fov, roll_deg=roll)
    fam = CalibrationFamily.from_camera(cam, line_indices=range(0, 5))
    by_height = fam.member(height_m=C[2])
    by_fov = fam.member(fov_deg=fov)
    axis = cam.R[2]
    az = np.degrees(np.arctan2(axis[1], axis[0]))
    by_azimuth = fam.member(azimuth_deg=az)
    for m in (by_fov, by_azimuth):
        assert np.isclose(m.focal_px, by_height.focal_px, rtol=1e-6)
        assert np.isclose(m.height_m, C[2], rtol=1e-6)
    assert np.isclose(AzimuthParameter().values(fam, np.array([by_height.focal_px]),
                                                fam.members([by_height.focal_px]))[0], az)


def test_height_occurs_twice_branches():
    C, T, fov, roll, _ = CASES["typical"]
    cam = Camera.look_at(C, T, fov_deg=fov, roll_deg=roll)
    fam = CalibrationFamily.from_camera(cam, line_indices=range(1, 6))
    narrow = HeightParameter().focal_for(fam, 15.0, "narrow")
    wide = HeightParameter().focal_for(fam, 15.0, "wide")
    assert wide < narrow
    assert np.isclose(fam.member_at_focal(wide).height_m, 15.0)
    with pytest.raises(CalibrationError, match="branch"):
        HeightParameter().focal_for(fam, 15.0, "sideways")


def test_bad_requests_raise_clear_errors():
    cam = Camera.look_at([30, -60, 15], [30, -4, 0], fov_deg=12.0)
    fam = CalibrationFamily.from_camera(cam, line_indices=range(1, 6))
    with pytest.raises(CalibrationError, match="no family member"):
        fam.member(height_m=500.0)
    with pytest.raises(CalibrationError, match="exactly one"):
        fam.member(height_m=10.0, fov_deg=5.0)
    with pytest.raises(CalibrationError, match="field of view"):
        fam.member(fov_deg=200.0)
    with pytest.raises(CalibrationError, match="three"):
        CalibrationFamily([0, 0, 1.0], fam.lines[:2], [0, 1], (1920, 1080))
    with pytest.raises(CalibrationError, match="own lane-line index"):
        CalibrationFamily(fam.vp, fam.lines[:3], [0, 1, 1], (1920, 1080))
    with pytest.raises(CalibrationError, match="finite"):
        CalibrationFamily([np.nan, 0, 1.0], fam.lines[:3], [0, 1, 2], (1920, 1080))


def test_members_vectorised_over_focal_lengths():
    cam = Camera.look_at([30, -60, 15], [30, -4, 0], fov_deg=12.0)
    fam = CalibrationFamily.from_camera(cam, line_indices=range(1, 6))
    f = np.geomspace(2000, 20000, 7)
    m = fam.members(f)
    assert m["R"].shape == (7, 3, 3) and m["height_m"].shape == (7,)
    single = fam.member_at_focal(f[3])
    assert np.isclose(single.height_m, m["height_m"][3]) and np.allclose(single.R, m["R"][3])


def test_null_vector_closed_form_matches_svd():
    """The 2-column least-squares null vector (closed form) is the SVD's, also for one row
    and for nearly rank-one matrices; the misfit ratio is 0 for one row (three lines), as
    documented for ``FamilyMember.residual``."""
    from probreg.calibration.family import _null_vector_2

    rng = np.random.default_rng(3)
    for m in (1, 2, 4, 7):
        M = rng.normal(size=(50, m, 2))
        M[:10] = M[:10, :, :1] * [1.0, -0.3] + 1e-9 * rng.normal(size=(10, m, 2))  # ~rank one
        v, ratio = _null_vector_2(M)
        _, sv, vt = np.linalg.svd(M)
        assert np.allclose(np.abs(np.sum(v * vt[:, -1], -1)), 1.0, atol=1e-9)
        if m == 1:  # one row: an exact null vector (three lines always fit)
            assert np.all(ratio < 1e-15)
        else:
            assert np.allclose(ratio, sv[:, -1] / sv[:, 0], rtol=1e-6, atol=1e-15)


@pytest.mark.parametrize("branch", ["narrow", "wide"])
def test_member_solve_hits_the_requested_height(branch):
    """Noisy lines (no exact camera behind them): the solved member has the requested
    height to 1e-9, on both branches of the family."""
    C, T, fov, roll, _ = CASES["typical"]
    cam = Camera.look_at(C, T, fov_deg=fov, roll_deg=roll)
    exact = CalibrationFamily.from_camera(cam, line_indices=range(1, 7))
    rng = np.random.default_rng(5)
    lines = exact.lines + rng.normal(0, [2e-5, 2e-5, 0.05], exact.lines.shape)
    fam = CalibrationFamily(exact.vp, lines, exact.indices, exact.image_size,
                            sample_points_px=exact.samples, forward_px=exact.forward_px)
    for h in (9.0, 13.0, 15.0):
        f = HeightParameter().focal_for(fam, h, branch=branch)
        assert abs(fam.member_at_focal(f).height_m / h - 1) < 1e-9


def test_a_bracket_that_does_not_hold_is_no_member_not_a_scipy_error():
    """Held-out steep near views died with scipy's "f(a) and f(b) must have different signs":
    the coarse grid saw a crossing that the refinement (members turning invalid) lost."""
    import numpy as np
    import pytest

    from probreg.calibration import CalibrationError, HeightParameter

    class Flaky:
        def focal_range(self):
            f = np.array([100.0, 200.0, 400.0, 800.0])
            return f, {"valid": np.ones(4, bool), "height_m": np.array([10.0, 20.0, 30.0, 40.0])}

        def members(self, fx):
            fx = np.atleast_1d(fx)
            return {"valid": np.zeros(len(fx), bool), "height_m": np.full(len(fx), 10.0)}

    with pytest.raises(CalibrationError, match="does not hold"):
        HeightParameter().focal_for(Flaky(), 25.0)
