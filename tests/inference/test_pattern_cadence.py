"""The published cadence is the 2-D stride pattern's (probreg.inference.gait_check): known answers
on generated runners, whose step frequency the generator sets."""

import numpy as np
import pytest

from probreg.filtering import clean_keypoints, stride_lags
from probreg.inference.gait_check import gait_check, pattern_cadence_interval, pattern_stride_frames
from probreg.sim import config_from_preset, synthesize

CLIPS = [("run", 11, 50.0), ("fast", 12, 50.0), ("jog", 13, 50.0), ("long_step", 14, 25.0), ("high_knee", 15, 25.0),
         ("run", 16, 25.0)]


@pytest.fixture(scope="module")
def cadences():
    out = []
    for preset, seed, fps in CLIPS:
        n = int(5 * fps)  # five seconds
        clip = synthesize(config_from_preset(preset, seed, n_frames=n, fps=fps), seed=seed)
        kp = clean_keypoints(clip.keypoints_px, fps)
        lags = stride_lags(kp, fps)
        true = 60.0 * clip.motion.gait.step_freq_hz
        out.append((preset, fps, true, pattern_cadence_interval(pattern_stride_frames(kp, fps, lags), fps, lags)))
    return out


def test_the_stride_pattern_gives_the_runners_cadence_within_two_percent(cadences):
    for preset, fps, true, (m, lo, hi) in cadences:
        assert m == pytest.approx(true, rel=0.02), (preset, fps)
        assert lo < m < hi and hi - lo < 0.1 * m, (preset, fps)  # an interval of a few per cent


def test_the_cadence_intervals_hold_the_truth(cadences):
    held = [lo <= true <= hi for _, _, true, (_, lo, hi) in cadences]
    assert sum(held) >= len(held) - 1, held


def test_gait_check_publishes_the_pattern_cadence_and_keeps_the_contacts():
    g = {"cadence_spm": {"median": 171.0, "lo": 165.0, "hi": 177.0, "unit": "steps/min"},
         "contact_time_s": {"median": 0.18}}
    lags = np.full(250, 34.0)
    out, status, reasons = gait_check(g, 34.0, 50.0, lags=lags)
    assert status == "ok" and not reasons
    assert out["cadence_spm"]["median"] == pytest.approx(6000 / 34.0)
    assert out["cadence_spm"]["source"] == "stride pattern" and out["cadence_spm"]["unit"] == "steps/min"
    assert out["cadence_contacts_spm"]["median"] == 171.0 and out["cadence_contacts_spm"]["source"] == "contacts"
    # no stride pattern: the contacts' cadence is published as before
    out = gait_check(g, float("nan"), 50.0)[0]
    assert out["cadence_spm"]["median"] == 171.0 and "cadence_contacts_spm" not in out
