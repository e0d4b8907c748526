"""The speed's stride-to-stride scatter: the along-track error of a poorly fixed pan, in the speed's interval."""

import numpy as np
import pytest

from probreg.geometry import JOINT_INDEX
from probreg.inference import gait_check, speed_scatter

FPS = 50.0
STRIDE = 36.0  # frames: 2 steps of 0.36 s
T = np.arange(200) / FPS


def _pelvis(pan_error_m=0.0, period_s=0.4, seed=0):
    """A runner at 6 m/s whose speed rises and falls by 10 % with every step (two steps a stride),
    with an along-track error of +-``pan_error_m`` held over random stretches near ``period_s`` (a
    pan that the lanes fix poorly)."""
    rng = np.random.default_rng(seed)
    v = 6.0 * (1 + 0.1 * np.sin(2 * np.pi * T / (STRIDE / FPS / 2)))
    x = np.cumsum(v) / FPS
    knots = np.arange(0.0, T[-1] + period_s, period_s)
    x = x + pan_error_m * np.interp(T, knots, rng.uniform(-1, 1, len(knots)))
    j = np.zeros((len(T), 17, 3))
    j[:, :, 0] = x[:, None]
    j[:, :, 1] = -3.0
    return j


def test_a_runner_whose_speed_changes_within_each_stride_has_no_scatter_over_whole_strides():
    """Windows of one stride average the step-by-step rise and fall of the speed away: the known
    answer for a steady runner is a standard error of ~0, while half-stride windows would see it."""
    out = speed_scatter(_pelvis(), FPS, STRIDE)
    assert out["window_frames"] == 36 and out["windows"] == len(T) - 36
    assert out["se_mps"] < 0.02
    assert speed_scatter(_pelvis(), FPS, STRIDE / 4)["sd_mps"] > 0.1  # half a step: the steps show


def test_the_scatter_grows_with_the_pan_error_and_covers_the_error_of_the_mean_speed():
    """With an along-track error of +-0.3 m in stretches of 0.4 s (v02-like: a long lens whose pan
    the lanes barely fix) the clip's mean speed is off by the end points' errors; the standard
    error, from the windows alone, is of that size (over 40 seeds: the 90 % interval it adds holds
    the mean speed's error on at least 80 % of them)."""
    se = [speed_scatter(_pelvis(e), FPS, STRIDE)["se_mps"] for e in (0.1, 0.3, 0.6)]
    assert se[0] < se[1] < se[2]
    held = []
    for seed in range(40):
        j = _pelvis(0.3, seed=seed)
        p = j[:, JOINT_INDEX["pelvis"], 0]
        err = (p[-1] - p[0]) * FPS / (len(p) - 1) - 6.0
        held.append(abs(err) <= 1.645 * speed_scatter(j, FPS, STRIDE)["se_mps"])
    assert np.mean(held) >= 0.8


def test_no_stride_period_or_too_few_frames_give_nan_and_leave_the_interval_as_it_was():
    assert np.isnan(speed_scatter(_pelvis(0.3), FPS, float("nan"))["se_mps"])
    assert np.isnan(speed_scatter(_pelvis(0.3)[:30], FPS, STRIDE)["se_mps"])  # less than a stride
    still = np.zeros((len(T), 17, 3))
    assert np.isnan(speed_scatter(still, FPS, STRIDE)["se_mps"])  # no travel: no direction
    g = {"cadence_spm": {"median": 166.0}, "speed_mps": {"median": 6.0, "lo": 5.6, "hi": 6.5}}
    out = gait_check(g, STRIDE, FPS, scatter=speed_scatter(_pelvis(0.3), FPS, float("nan")))[0]
    assert (out["speed_mps"]["lo"], out["speed_mps"]["hi"]) == (5.6, 6.5)
    out = gait_check(g, STRIDE, FPS, scatter={"se_mps": 0.3})[0]
    assert out["speed_mps"]["lo"] == pytest.approx(6.0 - np.hypot(0.4, 1.645 * 0.3), rel=1e-3)
    assert out["speed_mps"]["hi"] == pytest.approx(6.0 + np.hypot(0.5, 1.645 * 0.3), rel=1e-3)
    assert g["speed_mps"]["lo"] == 5.6  # the caller's summary is not changed
