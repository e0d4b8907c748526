import numpy as np
import pytest

from probreg.analysis import cycle_curves, gait_cycles
from probreg.geometry import JOINT_INDEX, bone_lengths, joint_angles
from probreg.sim import (
    STYLES,
    Anthropometry,
    GaitParams,
    gait_for_style,
    simulate_runner,
)


@pytest.fixture(scope="module", params=sorted(STYLES))
def motion(request):
    rng = np.random.default_rng(3)
    a = Anthropometry.from_stature(1.62 + 0.05 * len(request.param) % 0.35, rng=rng)
    return simulate_runner(a, gait_for_style(request.param, rng=rng), 300, 50.0, rng=rng,
                           start_x_m=10.0, lane_y_m=-3.05, start_phase=0.3)


def test_segment_lengths_constant(motion):
    assert np.max(np.ptp(bone_lengths(motion.joints_track_m), axis=0)) < 1e-3


def test_stance_foot_does_not_slide(motion):
    cp = motion.contact_points_track_m
    for side in (0, 1):
        for a, b in gait_cycles(motion.contacts[:, side]):
            run = cp[a:b, side]
            run = run[np.all(np.isfinite(run), axis=1)]
            assert np.max(np.linalg.norm(run - run[0], axis=1)) < 0.02


def test_contacts_match_foot_heights(motion):
    j = motion.joints_track_m
    h = motion.anthropometry.ankle_height_m
    for side, ankle in ((0, "l_ankle"), (1, "r_ankle")):
        z = j[:, JOINT_INDEX[ankle], 2]
        c = motion.contacts[:, side]
        assert np.all(z[c] < h + 0.12)        # foot flat or heel rising on the ball
        assert np.all(z[c] >= h - 1e-9)
        assert np.all(z[~c] > 0.03)           # swing foot clears the ground
    # contact points of stance feet lie on the ground
    cp = motion.contact_points_track_m
    assert np.allclose(cp[np.isfinite(cp[..., 2])][:, 2], 0)


def test_speed_and_cadence(motion):
    g = motion.gait
    pel = motion.joints_track_m[:, 0]
    speed = (pel[-1, 0] - pel[0, 0]) / (motion.times_s[-1] - motion.times_s[0])
    assert abs(speed - g.speed_mps) / g.speed_mps < 0.05
    steps = np.diff(sorted(t for t, _, _ in motion.touchdowns))
    assert abs(np.mean(steps) * g.step_freq_hz - 1) < 0.02
    # stride-to-stride variability: step times vary by about step_time_cv
    assert 0.3 * g.step_time_cv < np.std(steps) * g.step_freq_hz < 2.5 * g.step_time_cv


def test_strides_vary_with_rng_and_repeat_without():
    a = Anthropometry.from_stature(1.75)
    g = gait_for_style("run")
    fps = 20 * g.step_freq_hz  # a stride is exactly 40 frames
    fixed = simulate_runner(a, g, 400, fps)
    assert np.allclose(np.diff(sorted(t for t, _, _ in fixed.touchdowns)), 1 / g.step_freq_hz)
    knee = joint_angles(fixed.joints_track_m)["knee_r"]
    assert np.max(np.abs(knee[40:] - knee[:-40])) < 1e-6
    varied = simulate_runner(a, g, 400, fps, rng=np.random.default_rng(5))
    knee = joint_angles(varied.joints_track_m)["knee_r"]
    sd = np.std(knee[40:] - knee[:-40]) / np.sqrt(2)
    assert 1.0 < sd < 8.0  # deg: a few degrees from stride to stride, as in real running


def test_angles_physiological(motion):
    a = joint_angles(motion.joints_track_m)
    for side in "lr":
        assert 0 <= a[f"knee_{side}"].min() and a[f"knee_{side}"].max() < 150
        assert -45 < a[f"hip_{side}"].min() and a[f"hip_{side}"].max() < 110
        assert 20 < a[f"elbow_{side}"].min() and a[f"elbow_{side}"].max() < 150
    assert 0 < a["trunk_lean"].min() and a["trunk_lean"].max() < 20


def test_flight_phase_exists(motion):
    assert np.any(~motion.contacts.any(axis=1))
    assert not np.any(motion.contacts.all(axis=1))  # running: never double support


def test_bad_parameters():
    with pytest.raises(ValueError, match="stature"):
        Anthropometry.from_stature(-1.7)
    with pytest.raises(ValueError, match="style"):
        gait_for_style("moonwalk")
    with pytest.raises(ValueError, match="walking"):
        GaitParams(speed_mps=2.0, step_freq_hz=2.0, contact_time_s=0.49)


def test_knee_curve_close_to_real_mocap(shared_data):
    """The synthetic knee-flexion cycle at the real clips' speed stays within 10 deg MAD of the real mean."""
    from probreg.bench.realism import mocap_knee_cycles, synthetic_knee_cycles

    curves, speeds = [], []
    for p in sorted((shared_data / "mocap").glob("*.npz")):
        c, v, _ = mocap_knee_cycles(p)
        curves.append(c)
        speeds.append(v)
    real = np.concatenate(curves).mean(0)
    syn, _ = synthetic_knee_cycles("jog", speed_mps=float(np.mean(speeds)))
    assert np.mean(np.abs(syn.mean(0) - real)) < 10.0
    assert cycle_curves(np.zeros(10), np.zeros(10, bool)).shape == (0, 101)


def test_stance_ankle_motion_known_answer():
    """A hand-made clip: the ankle rolls 2 cm forward over the first 15 % of each 21-frame
    contact, then creeps at 5 % of the running speed; the measures return exactly that."""
    from probreg.bench.realism import stance_ankle_motion

    fps, v, F = 100.0, 4.0, 120
    X = np.zeros((F, 17, 3))
    X[:, JOINT_INDEX["pelvis"], 0] = v * np.arange(F) / fps
    contacts = np.zeros((F, 2), bool)
    for side, a in ((0, 10), (1, 60)):
        b = a + 21
        contacts[a:b, side] = True
        s = np.linspace(0, 1, b - a)
        j = JOINT_INDEX["l_ankle" if side == 0 else "r_ankle"]
        X[a:b, j, 0] = np.where(s < 0.15, 0.02 * s / 0.15, 0.02 + 0.05 * v * (s - 0.15) * (b - a - 1) / fps)
        X[a:b, j, 2] = 0.07
    r = stance_ankle_motion(X, contacts, fps, window=(0.2, 0.45))
    assert len(r["slide"]) == 2
    np.testing.assert_allclose(r["early_travel_cm"], 2.0, atol=1e-9)
    np.testing.assert_allclose(r["slide"], 0.05, atol=1e-9)
    np.testing.assert_allclose(r["rise_cm"], 0.0, atol=1e-9)


def test_real_midstance_ankle_slide_within_model_sd(shared_data):
    """The planted-feet term assumes the mid-stance ankle still (sd STILLNESS_SYS_SD); real
    runners' ankles (CMU mocap) slide there by a median of ~0.02 of the running speed."""
    from probreg.bench.realism import stance_ankle_motion
    from probreg.inference import STILLNESS_SYS_SD

    slides, early = [], []
    for p in sorted((shared_data / "mocap").glob("*.npz")):
        d = np.load(p)
        r = stance_ankle_motion(d["joints3d"], d["contact"], float(d["fps"]))
        slides.append(r["slide"])
        early.append(r["early_travel_cm"])
    slides = np.concatenate(slides)
    assert len(slides) >= 15
    assert abs(np.median(slides)) < 0.5 * STILLNESS_SYS_SD
    # early stance is not still in real running: that is why the window skips it
    assert np.median(np.concatenate(early)) > 0.5


def test_legs_leave_their_plane_by_the_given_offsets():
    """Knee and ankle sit medially by the gait's offsets where the segment hangs vertical (no
    stride-periodic part here), the segment lengths and the planted foot are kept."""
    from dataclasses import replace

    from probreg.bench.realism import leg_medial_offsets

    g = replace(gait_for_style("run"), knee_medial_m=0.03, ankle_medial_m=0.015, leg_medial_swing_m=0.0)
    a = Anthropometry.from_stature(1.8)
    m = simulate_runner(a, g, 200, 50.0)
    X = m.joints_track_m
    for side, medial in (("l", -1.0), ("r", 1.0)):
        hip, knee, ankle = (X[:, JOINT_INDEX[f"{side}_{n}"]] for n in ("hip", "knee", "ankle"))
        vertical = np.abs(knee[:, 0] - hip[:, 0]) < 0.01 * a.thigh_m  # thigh hanging straight down
        assert vertical.any()
        np.testing.assert_allclose(medial * (knee - hip)[vertical, 1], 0.03, atol=3e-4)
        np.testing.assert_allclose(np.linalg.norm(knee - hip, axis=-1), a.thigh_m, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(ankle - knee, axis=-1), a.shank_m, atol=1e-9)
    o = leg_medial_offsets(X)  # means over the stride: below the vertical segment's offset
    assert np.all((o[:, 0] > 2.0) & (o[:, 0] < 3.0) & (o[:, 2] > 0.5) & (o[:, 2] < 1.5))
    for side, name in ((0, "l_ankle"), (1, "r_ankle")):  # the stance ankle does not slide sideways
        y = X[:, JOINT_INDEX[name], 1]
        c = m.contacts[:, side]
        for s, e in gait_cycles(c):
            stance = y[s:e][c[s:e]]
            assert np.ptp(stance) < 1e-9
    # without offsets the legs swing in their plane, as up to 0.2.0.dev23
    flat = simulate_runner(a, replace(g, knee_medial_m=0.0, ankle_medial_m=0.0), 200, 50.0).joints_track_m
    assert np.max(np.abs(flat[:, JOINT_INDEX["l_knee"], 1] - flat[:, JOINT_INDEX["l_hip"], 1])) < 1e-9
