"""The feet-slide check: planted feet stand still, unless the camera moves along the track."""

import numpy as np
import pytest

from probreg.geometry import JOINT_INDEX
from probreg.inference import gait_check, stance_slide
from probreg.inference.gait_check import MAX_STANCE_BACKSLIDE

FPS = 50.0
T = np.arange(150) / FPS


def _runner(camera_speed, noise_m=0.0, seed=0):
    """A runner at 5 m/s whose feet are planted ~40 % of the time, in the frame of a camera moving
    along x at ``camera_speed`` (the frame a static-camera reconstruction would give)."""
    rng = np.random.default_rng(seed)
    j = np.zeros((len(T), 17, 3))
    j[:, :, 0] = 5.0 * T[:, None]
    j[:, :, 1] = -3.0
    for name, phase in (("l_ankle", 0.0), ("r_ankle", np.pi)):
        swing = np.maximum(0.0, np.sin(2 * np.pi * 1.5 * T + phase) - 0.3)
        v = 5.0 * swing / swing.mean()  # mean 5 m/s, zero while planted
        j[:, JOINT_INDEX[name], 0] = np.cumsum(v) / FPS
    j[..., 0] -= camera_speed * T[:, None]
    j[..., :2] += rng.normal(0, noise_m, j[..., :2].shape)
    return j


SIDE_CAMERA = np.tile([10.0, -60.0, 12.0], (len(T), 1))


@pytest.mark.parametrize("frac", [0.25, 0.5, 0.75])
def test_a_camera_moving_at_a_share_of_the_runners_speed_makes_planted_feet_run_back(frac):
    """Seen from a camera moving at ``f`` of the runner's speed a planted foot runs back at
    ``f / (1 - f)`` of the runner's apparent speed: the known answer of the measure."""
    out = stance_slide(SIDE_CAMERA, _runner(5.0 * frac), FPS)
    assert out["backslide"] == pytest.approx(-frac / (1 - frac), abs=0.03)
    assert out["speed_mps"] == pytest.approx(5.0 * (1 - frac), rel=0.01)
    assert out["frames"] > 100


def test_a_static_camera_sees_planted_feet_stand_still_even_with_noise():
    assert abs(stance_slide(SIDE_CAMERA, _runner(0.0), FPS)["backslide"]) < 0.01
    noisy = [stance_slide(SIDE_CAMERA, _runner(0.0, noise_m=0.03, seed=s), FPS)["backslide"] for s in range(5)]
    assert all(-MAX_STANCE_BACKSLIDE < b < 0.2 for b in noisy)


def test_frames_seen_along_the_track_are_not_read_and_too_few_give_nan():
    """A camera looking along the straight reads a cast ankle's along-track motion in depth: those
    frames are left out; with too few frames (or none with a camera) there is no measure."""
    ahead = np.tile([300.0, -3.5, 5.0], (len(T), 1))  # far down the straight, on the runner's line
    out = stance_slide(ahead, _runner(2.5), FPS)
    assert np.isnan(out["backslide"]) and out["frames"] < 10
    assert np.isnan(stance_slide([None] * len(T), _runner(0.0), FPS)["backslide"])
    assert np.isnan(stance_slide(SIDE_CAMERA[:8], _runner(0.0)[:8], FPS)["backslide"])
    still = np.zeros((len(T), 17, 3))
    assert np.isnan(stance_slide(SIDE_CAMERA, still, FPS)["backslide"])  # no travel: no direction


def test_sliding_feet_make_every_gait_number_unreliable_the_speed_included():
    g = {"cadence_spm": {"median": 180.0}, "contact_time_s": {"median": 0.15}, "speed_mps": {"median": 5.0},
         "step_length_m": {"median": 1.6}}
    # on a rail at half the speed the ground track moves as the pelvis does in the frame, at 2.5 m/s
    rail = {**g, "speed_mps": {"median": 2.5}, "step_length_m": {"median": 0.8}}
    out, status, reasons = gait_check(rail, 33.3, FPS, slide=stance_slide(SIDE_CAMERA, _runner(2.5), FPS))
    assert status == "unreliable" and len(reasons) == 1
    assert reasons[0].startswith("feet slide back (stance ankles at -1.0")
    # every number but the stride pattern's cadence, which needs neither the camera nor a contact
    assert {k for k, v in out.items() if v["status"] != "unreliable"} == {"cadence_spm"}
    assert out["cadence_spm"]["source"] == "stride pattern" and out["cadence_contacts_spm"]["status"] == "unreliable"
    out, status, reasons = gait_check(g, 33.3, FPS, slide=stance_slide(SIDE_CAMERA, _runner(0.0), FPS))
    assert status == "ok" and not reasons and out["speed_mps"]["status"] == "ok"
    assert gait_check(g, 33.3, FPS, slide={"backslide": float("nan")})[1] == "ok"  # not measured: no verdict


def test_a_ground_track_faster_than_the_pelvis_makes_the_speed_unreliable():
    """The feet move as far as the pelvis over whole strides: a ground track at 3.5 times the
    pelvis's speed (a grazing view's cast feet) is not the athlete's; within 1.25x it is."""
    g = {"cadence_spm": {"median": 180.0}, "contact_time_s": {"median": 0.15}, "speed_mps": {"median": 17.5}}
    slide = stance_slide(SIDE_CAMERA, _runner(0.0), FPS)
    assert slide["speed_mps"] == pytest.approx(5.0, rel=0.02) and slide["backslide"] > -0.1
    out, status, reasons = gait_check(g, 33.3, FPS, slide=slide)
    assert status == "unreliable" and reasons == ["speed 17.5 m/s from the ground track, 5.0 m/s from the pelvis"]
    assert out["speed_mps"]["status"] == out["cadence_contacts_spm"]["status"] == "unreliable"
    for speed, want in ((3.9, "unreliable"), (4.1, "ok"), (6.2, "ok"), (6.3, "unreliable")):
        assert gait_check({**g, "speed_mps": {"median": speed}}, 33.3, FPS, slide=slide)[1] == want, speed
