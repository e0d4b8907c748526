"""The clip's time base: a runner bounces under gravity, so a slow-motion replay (or a wrong
frame rate) shows in the pelvis's motion; known answers, real running capture, the verdict."""

import numpy as np
import pytest

from probreg.geometry import JOINT_INDEX
from probreg.inference import clip_verdict
from probreg.inference.time_base import (BOUNCE_REF_G, MAX_BOUNCE_G, MIN_BOUNCE_AMPLITUDE_M, MIN_BOUNCE_G,
                                         pelvis_bounce_g, stride_frames_any_rate, time_base_check)


def _bounce(n, step_frames, amp_m=0.04, trend=0.0, noise=0.0, seed=0):
    t = np.arange(n)
    rng = np.random.default_rng(seed)
    return 0.95 + amp_m * np.cos(2 * np.pi * t / step_frames + 0.7) + trend * t + rng.normal(0, noise, n)


def test_bounce_is_the_acceleration_amplitude_at_the_step_frequency():
    # 4 cm at 3 steps/s: 0.04 (2 pi 3)^2 / 9.81 = 1.449 g, whatever the trend and moderate noise
    z = _bounce(300, 50 / 3, trend=0.0003, noise=0.01)
    assert pelvis_bounce_g(z, 50 / 3, 50.0) == pytest.approx(0.04 * (2 * np.pi * 3) ** 2 / 9.81, rel=0.05)
    # time slowed by s divides it by s^2: the same frames labelled 4x too slow
    assert pelvis_bounce_g(z, 50 / 3, 12.5) == pytest.approx(pelvis_bounce_g(z, 50 / 3, 50.0) / 16, rel=1e-9)


def test_bounce_needs_two_steps_of_heights():
    z = _bounce(30, 20)
    assert np.isnan(pelvis_bounce_g(z, 20, 50.0))  # 1.5 steps
    z[::2] = np.nan
    assert np.isnan(pelvis_bounce_g(np.r_[z, z], 20, 50.0))  # 30 heights of 60 frames, but 40 needed
    assert np.isnan(pelvis_bounce_g(_bounce(100, 20), float("nan"), 50.0))


@pytest.fixture(scope="module")
def mocap(shared_data):
    import glob

    clips = []
    for f in sorted(glob.glob(str(shared_data / "mocap" / "*.npz"))):
        d = np.load(f)
        clips.append((d["joints3d"][:, JOINT_INDEX["pelvis"], 2], float(d["fps"])))
    if not clips:
        pytest.skip("no mocap clips")
    return clips


def _step_frames(z, fps):
    """The step period (frames) of a pelvis height series: the strongest spectral line in 2-4 steps/s."""
    zz = z - np.polyval(np.polyfit(np.arange(len(z)), z, 2), np.arange(len(z)))
    freqs = np.linspace(2.0, 4.0, 401)
    t = np.arange(len(z)) / fps
    power = [abs(np.sum(zz * np.exp(-2j * np.pi * f * t))) for f in freqs]
    return fps / freqs[int(np.argmax(power))]


def test_real_runners_bounce_near_the_reference_and_a_replay_is_found(mocap):
    for z, fps in mocap:
        step = _step_frames(z, fps)
        g = pelvis_bounce_g(z, step, fps)
        assert 1.0 < g < 1.6 and MIN_BOUNCE_G < g < MAX_BOUNCE_G
        assert time_base_check(None, fps, z, stride_frames=2 * step, speed_mps=3.0)["status"] == "ok"
        # the same capture played as a 4x replay (its file says a quarter of the rate)
        tb = time_base_check(None, fps / 4, z, stride_frames=2 * step, speed_mps=3.0 / 4)
        assert tb["status"] == "slow" and tb["reason"].startswith("slow motion about")
        assert tb["factor"] == pytest.approx(4.0 * np.sqrt(BOUNCE_REF_G / g), rel=1e-6)
        assert 3.4 < tb["factor"] < 4.6
        # and as a recording at half the rate its file states (motion twice too fast)
        assert time_base_check(None, 2 * fps, z, stride_frames=2 * step, speed_mps=6.0)["status"] == "fast"


def test_cadence_alone_and_speed_alone_decide_when_the_bounce_is_unknown():
    tb = time_base_check(None, 50.0, None, stride_frames=140.0, speed_mps=None)  # 43 steps/min
    assert tb["status"] == "slow" and tb["factor"] == pytest.approx(170 / (6000 / 140))
    assert time_base_check(None, 50.0, None, stride_frames=16.0)["status"] == "fast"  # 375 steps/min
    assert time_base_check(None, 50.0, None, stride_frames=35.0, speed_mps=0.9)["status"] == "ok"  # stride rules
    tb = time_base_check(None, 50.0, None, stride_frames=None, speed_mps=0.9)  # no stride: the speed
    assert tb["status"] == "slow" and tb["factor"] is None and "no stride repeats" in tb["reason"]
    assert time_base_check(None, 50.0, None, stride_frames=None, speed_mps=4.0)["status"] == "ok"


def test_with_no_stride_the_slower_of_the_two_speeds_decides():
    """Either speed can be broken (a grazing 6x replay: cast feet at 4.4 m/s, pelvis at 0.2; a
    pelvis at 47 m/s where the feet said 1.2); a stride that repeats leaves both unused."""
    def status(track, pelvis, stride=None):
        return time_base_check(None, 50.0, None, stride_frames=stride, speed_mps=track, pelvis_speed_mps=pelvis)["status"]

    assert status(4.4, 0.2) == status(1.2, 47.0) == status(1.4, None) == status(None, 1.4) == "slow"
    assert status(4.4, 4.0) == status(None, None) == "ok"
    assert status(4.4, 0.2, stride=35.0) == "ok"  # 171 steps/min: the stride rules
    tb = time_base_check(None, 50.0, None, speed_mps=4.4, pelvis_speed_mps=0.2)
    assert tb["speed_mps"] == 4.4 and tb["pelvis_speed_mps"] == 0.2 and "pelvis 0.2 m/s" in tb["reason"]


def test_a_bounce_far_below_a_runners_amplitude_says_nothing_about_time():
    # a pelvis the lifting flattened to 1 mm (0.03 g) at 400 steps/min: the cadence alone says fast
    z = _bounce(250, 17.5, amp_m=0.001)
    tb = time_base_check(None, 50.0, z, stride_frames=15.0 * 2 * 17.5 / 35)
    assert tb["bounce_g"] is None and tb["bounce_amplitude_m"] < MIN_BOUNCE_AMPLITUDE_M
    assert tb["status"] == "fast" and tb["reason"].startswith("fast motion")
    # a grazing 25 fps clip's 1.1 cm swing at 164 steps/min (0.33 g, a 2x replay if it were a
    # runner's bounce, whose real cadence 320 is still a runner's): real time; at 1.6 cm it is a replay
    step = 25.0 * 60 / 164
    flat = _bounce(100, step, amp_m=0.011)
    assert time_base_check(None, 25.0, flat, stride_frames=2 * step)["status"] == "ok"
    assert MIN_BOUNCE_AMPLITUDE_M == 0.015
    slowed = time_base_check(None, 25.0, _bounce(100, step, amp_m=0.016), stride_frames=2 * step)
    assert slowed["status"] == "slow" and slowed["bounce_g"] < MIN_BOUNCE_G


def test_a_stride_beyond_a_runners_window_is_found_at_the_trial_rates():
    t = np.arange(500.0)[:, None, None]
    rng = np.random.default_rng(3)
    kp = np.concatenate([80 * np.sin(2 * np.pi * t / 150 + np.arange(17)[None, :, None] + [0, 1.3])
                         + rng.normal(0, 0.5, (500, 17, 2)), np.ones((500, 17, 1))], -1)
    assert stride_frames_any_rate(kp, 50.0) == pytest.approx(150, abs=2)  # 3 s at 50 fps
    assert stride_frames_any_rate(kp, 50.0, stride_frames=30.0) == 30.0  # one found already is kept
    assert np.isnan(stride_frames_any_rate(kp[:120], 50.0))  # under one stride: nothing repeats


def test_the_verdict_carries_the_time_base_reason():
    slow = time_base_check(None, 50.0, _bounce(250, 70.0), stride_frames=140.0, speed_mps=1.1)
    verdict, reasons = clip_verdict(100, 100, 100, rhat=1.01, ess=900, time_base=slow)
    assert verdict == "unreliable" and reasons == [slow["reason"]]
    real = time_base_check(None, 200.0, _bounce(250, 70.0), stride_frames=140.0, speed_mps=4.4)
    assert real["status"] == "ok" and clip_verdict(100, 100, 100, rhat=1.01, ess=900, time_base=real) == ("ok", [])


def test_a_swing_no_runner_makes_says_nothing_about_time():
    # the amplitude does not change with the time base: metres of swing are a pelvis the lifting missed
    z = _bounce(250, 17.5, amp_m=2.0)
    tb = time_base_check(None, 50.0, z, stride_frames=35.0, speed_mps=4.0)
    assert tb["bounce_g"] is None and tb["bounce_amplitude_m"] == pytest.approx(2.0, rel=0.01)
    assert tb["status"] == "ok"  # the cadence, 171 steps/min, decides
    assert time_base_check(None, 50.0, _bounce(250, 17.5), stride_frames=35.0)["bounce_g"] is not None


def test_strides_shorter_than_a_runners_window_are_found():
    # a 25 fps recording labelled 50 fps: 14 frames a stride (0.28 s), below the 0.45 s window,
    # where the search at the labelled rate finds two strides (28 frames)
    t = np.arange(200.0)[:, None, None]
    rng = np.random.default_rng(5)
    kp = np.concatenate([80 * np.sin(2 * np.pi * t / 14 + np.arange(17)[None, :, None] + [0, 1.3])
                         + rng.normal(0, 0.5, (200, 17, 2)), np.ones((200, 17, 1))], -1)
    assert stride_frames_any_rate(kp, 50.0, stride_frames=28.0) == pytest.approx(14, abs=0.5)
    tb = time_base_check(kp, 50.0, None, stride_frames=28.0)
    assert tb["status"] == "fast" and tb["cadence_spm"] == pytest.approx(6000 / 14, rel=0.03)


def test_repeated_frames_are_counted_against_the_pairs_that_can_repeat():
    from probreg.inference.time_base import repeated_frames

    kp = np.random.default_rng(2).normal(500, 30, (50, 17, 3))
    assert repeated_frames(kp) == (0, 49)
    doubled = np.repeat(kp, 2, axis=0)
    assert repeated_frames(doubled) == (50, 99)
    frozen = kp.copy()
    frozen[10:20] = frozen[10]  # a frozen stretch: 9 repeats
    assert repeated_frames(frozen) == (9, 49)
    gaps = doubled.copy()
    gaps[1::2, 3:] = np.nan  # the copies keep 3 joints: no pair to judge
    assert repeated_frames(gaps) == (0, 0)
    near = doubled.copy()
    near[1::2, :, :2] += 0.02  # re-encoded copies move a hundredth of a pixel: still repeats
    assert repeated_frames(near)[0] == 50


def test_a_stream_that_repeats_its_frames_is_flagged():
    kp = np.random.default_rng(3).normal(500, 30, (100, 17, 3))
    z = _bounce(200, 17.5)
    tb = time_base_check(None, 50.0, z, stride_frames=35.0, speed_mps=4.0, raw_keypoints_px=np.repeat(kp, 2, 0))
    assert tb["status"] == "ok" and tb["repeated_frames"] == 100 and tb["frame_pairs"] == 199
    assert tb["repeats_reason"] == "repeated frames (100 of 199 repeat the one before: 50 fps holds 24.9 fps of motion)"
    verdict, reasons = clip_verdict(100, 100, 100, rhat=1.01, ess=900, time_base=tb)
    assert verdict == "unreliable" and reasons == [tb["repeats_reason"]]
    one = np.repeat(kp, 2, 0)[:110]  # a few repeats (5 of 109) are below the 10 % limit
    tb = time_base_check(None, 50.0, z, stride_frames=35.0, speed_mps=4.0,
                         raw_keypoints_px=np.concatenate([one[:10], kp[10:]]))
    assert tb["repeats_reason"] is None and tb["repeated_frames"] == 5


def test_a_bounce_too_weak_for_a_runners_cadence_says_nothing():
    """0.16 g would be a 2.8x replay, but the stride pattern's 171 steps/min times 2.8 is no runner's
    cadence: the pelvis height came out flat (5 mm, the lifting's), and the clip is taken as real
    time.  The same flat pelvis at a jogger's labelled 85 steps/min is a replay, by its cadence."""
    z = _bounce(250, 17.5, amp_m=0.005)
    tb = time_base_check(None, 50.0, z, stride_frames=35.0)
    assert tb["status"] == "ok" and tb["bounce_g"] is None
    assert tb["bounce_amplitude_m"] == pytest.approx(0.005, rel=0.05)
    slow = time_base_check(None, 50.0, _bounce(250, 35.0, amp_m=0.005), stride_frames=70.0)
    assert slow["status"] == "slow" and slow["bounce_g"] is None
    assert slow["factor"] == pytest.approx(170 / 85.7, rel=0.01)
