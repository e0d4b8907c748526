"""The gait intervals' per-number factors apply to the numbers gait.json publishes."""

import numpy as np

from probreg.analysis import GAIT_FIELDS
from probreg.inference.bands import GAIT_BAND_SCALE, GAIT_NUMBER_FACTORS, gait_intervals


def test_every_factor_names_a_published_gait_number():
    # a factor under a name gait.json does not have would silently not apply
    assert set(GAIT_NUMBER_FACTORS) <= set(GAIT_FIELDS)
    assert all(0.5 <= f <= 2.0 for f in GAIT_NUMBER_FACTORS.values())


def test_default_interval_is_scale_times_factor_and_inflation_overrides():
    rng = np.random.default_rng(0)
    point = {n: np.full(40, 1.0) for n in GAIT_NUMBER_FACTORS}
    noisy = {n: 1.0 + 0.1 * rng.standard_normal(40) for n in GAIT_NUMBER_FACTORS}
    raw = gait_intervals(point, noisy, inflation=1.0)
    scaled = gait_intervals(point, noisy)
    for n, f in GAIT_NUMBER_FACTORS.items():
        med, lo, hi = scaled[n]
        _, rlo, rhi = raw[n]
        assert np.isclose(hi - med, GAIT_BAND_SCALE * f * (rhi - med))
        assert np.isclose(med - max(lo, 0.0), min(GAIT_BAND_SCALE * f * (med - rlo), med))
    # a number without a factor gets the common scale alone
    other = gait_intervals({"x_deg": np.full(40, 1.0)}, {"x_deg": noisy["speed_mps"]})["x_deg"]
    _, _, rhi = gait_intervals({"x_deg": np.full(40, 1.0)}, {"x_deg": noisy["speed_mps"]}, inflation=1.0)["x_deg"]
    assert np.isclose(other[2] - 1.0, GAIT_BAND_SCALE * (rhi - 1.0))
