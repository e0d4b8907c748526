"""``probreg bench on-athlete``: the clip scores of the verdict's keypoints-on-athlete check for a
clip's own keypoints, keypoints of other images and keypoints a detector's bias moves."""

import numpy as np

from probreg.bench.on_athlete import MISMATCHES, _scaled_copy, clip_scores
from probreg.inference.verdict import VerdictThresholds
from probreg.io import load_clip


def test_own_and_biased_keypoints_pass_and_those_of_other_images_do_not(small_clip):
    s = clip_scores(small_clip)
    limit = VerdictThresholds().min_on_athlete
    assert set(s) == {"own", *(m[0] for m in MISMATCHES), "bias 10%", "bias 20%", "neighbour", "trunk down",
                      "trunk down, y up"}
    assert 0.0 <= s["neighbour"] <= 1.0  # measured, not required: a twin in the same kit can pass or not
    assert s["trunk down"] < 0.05 and s["trunk down, y up"] > 0.95
    assert s["own"] > 0.9 and s["bias 10%"] > 2 * limit and s["bias 20%"] > limit
    assert max(s[m[0]] for m in MISMATCHES) < limit / 2, s


def test_a_scaled_copy_shares_the_frames_and_scales_only_the_keypoints(small_clip, tmp_path):
    copy = _scaled_copy(small_clip, tmp_path / "half", 0.5)
    a, b = load_clip(small_clip), load_clip(copy)
    assert (copy / "frames").is_symlink() and b.n_frames == a.n_frames and b.image_size == a.image_size
    assert np.allclose(b.keypoints_px[..., :2], 0.5 * a.keypoints_px[..., :2], atol=1e-3, equal_nan=True)
    assert np.allclose(b.keypoints_px[..., 2], a.keypoints_px[..., 2], atol=1e-3, equal_nan=True)
