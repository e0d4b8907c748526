"""Prior predictive checks: the default priors hold every real athlete and broadcast camera."""

import numpy as np

from probreg.inference import ModelPriors


def test_stature_prior_covers_adult_athletes_from_1_50_to_2_10_m(rng):
    p = ModelPriors().stature
    lo, hi = p.interval(0.95)
    assert lo <= 1.50 and hi >= 2.10
    draws = p.sample(rng, 200_000)
    assert 0.93 <= np.mean((draws >= 1.50) & (draws <= 2.10)) <= 0.97
    # athletes spread evenly over the range: the 90 % interval holds 85-95 % of them
    lo90, hi90 = p.interval(0.9)
    truth = rng.uniform(1.50, 2.10, 100_000)
    assert 0.85 <= np.mean((truth >= lo90) & (truth <= hi90)) <= 0.95


def test_camera_height_prior_covers_every_broadcast_position_from_2_to_40_m(rng):
    p = ModelPriors().camera_height
    lo, hi = p.interval(0.95)
    assert lo <= 2.0 and hi >= 40.0
    lo90, hi90 = p.interval(0.9)
    truth = np.exp(rng.uniform(np.log(2.0), np.log(40.0), 100_000))  # rail cameras to the stand roof
    assert 0.85 <= np.mean((truth >= lo90) & (truth <= hi90)) <= 0.95
    draws = p.sample(rng, 200_000)
    assert np.mean(draws < 1.0) < 0.01 and np.mean(draws > 100.0) < 0.01  # no absurd positions


def test_given_values_override_only_what_is_given():
    p = ModelPriors.from_options(stature=1.62)
    assert p.stature.mean == 1.62 and p.stature.sd == 0.02
    assert p.camera_height == ModelPriors().camera_height
    q = ModelPriors.from_options(height=25.0)
    assert q.camera_height.median == 25.0 and q.camera_height.log_sd == 0.05
