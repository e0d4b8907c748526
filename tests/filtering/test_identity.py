"""Left/right labels of the legs repaired from the motion: injected swaps found again, right labels left
alone, an outlier does not pull them over."""

import numpy as np
import pytest

from probreg.filtering import clean_keypoints, noise_model, relabel_left_right
from probreg.filtering.identity import LEFT_RIGHT_PAIRS
from probreg.geometry import JOINT_INDEX as J
from probreg.sim import Anthropometry, gait_for_style, simulate_runner

LEGS = [(J[r], J[l]) for r, l in LEFT_RIGHT_PAIRS[:3]]
ARMS = [(J[r], J[l]) for r, l in LEFT_RIGHT_PAIRS[3:]]


def _side_view(joints, f=2000.0, dist=25.0):
    """A static side-on pinhole view of a runner (the camera pans with the athlete): (F, 17, 3)."""
    x, y, z = joints[..., 0], joints[..., 1], joints[..., 2]
    depth = dist - y
    u = 960 + f * (x - joints[:, :1, 0]) / depth
    v = 540 - f * (z - 1.0) / depth
    return np.stack([u, v, np.ones_like(u)], -1)


def _swap_runs(rng, F, start_p=0.05, lo=2, hi=10):
    """A mask of frames swapped in runs of ``lo``-``hi`` frames, as a detector does near crossings."""
    mask, t = np.zeros(F, bool), 0
    while t < F:
        if rng.random() < start_p:
            n = int(rng.integers(lo, hi + 1))
            mask[t:t + n] = True
            t += n
        else:
            t += 1
    return mask


def _exchange(kp, mask, pairs):
    out = kp.copy()
    for r, l in pairs:
        out[mask, r], out[mask, l] = kp[mask, l], kp[mask, r]
    return out


@pytest.fixture(scope="module")
def runner():
    rng = np.random.default_rng(21)
    m = simulate_runner(Anthropometry.from_stature(1.78), gait_for_style("run"), 250, 50.0, rng=rng)
    truth = _side_view(m.joints_track_m)
    noisy = truth.copy()
    noisy[..., :2] += rng.normal(0, 3.0, truth.shape[:2] + (2,))
    return truth, noisy


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_swapped_runs_of_legs_are_found_again(runner, seed):
    _, noisy = runner
    rng = np.random.default_rng(seed)
    legs, arms = _swap_runs(rng, len(noisy)), _swap_runs(rng, len(noisy))
    assert 0.1 < legs.mean() < 0.5 and 0.1 < arms.mean() < 0.5
    bad = _exchange(_exchange(noisy, legs, LEGS), arms, ARMS)
    fixed, exchanged = relabel_left_right(bad, noise_px=3.0)
    # every swapped frame of the legs is found and nothing else is touched; the arms are left as
    # the detector labelled them (their tracks overlap too much to tell them apart)
    assert np.array_equal(exchanged[:, :3], np.repeat(legs[:, None], 3, 1))
    assert not exchanged[:, 3:].any()
    np.testing.assert_array_equal(fixed, _exchange(noisy, arms, ARMS))


def test_right_labels_are_left_alone_and_a_second_pass_changes_nothing(runner):
    truth, noisy = runner
    for kp, sd in ((truth, 0.0), (noisy, 3.0)):
        same, exchanged = relabel_left_right(kp, noise_px=sd)
        assert not exchanged.any() and np.array_equal(same, kp)
    bad = _exchange(noisy, _swap_runs(np.random.default_rng(4), len(noisy)), LEGS)
    once, _ = relabel_left_right(bad, noise_px=3.0)
    twice, again = relabel_left_right(once, noise_px=3.0)
    assert not again.any() and np.array_equal(once, twice)


def test_missing_frames_do_not_cut_the_legs_tracks(runner):
    _, noisy = runner
    legs = _swap_runs(np.random.default_rng(5), len(noisy))
    bad = _exchange(noisy, legs, LEGS)
    gone = np.zeros(len(noisy), bool)
    gone[[30, 31, 77, 140, 141, 142, 200]] = True
    bad[gone] = np.nan
    # a missing knee alone: the frame's other joints still carry it
    bad[100, J["r_knee"]] = np.nan
    _, exchanged = relabel_left_right(bad, noise_px=3.0)
    seen = ~gone
    np.testing.assert_array_equal(exchanged[seen, 0], legs[seen])
    assert not exchanged[gone].any()  # nothing to relabel there


def test_a_swapped_runner_lifts_as_the_right_one_after_cleaning(runner):
    """The knee angle of the side view: the swapped clip's is wrong by tens of degrees, the
    cleaned one's (which relabels first) equals that of the clip without swaps."""
    truth, noisy = runner
    bad = _exchange(noisy, _swap_runs(np.random.default_rng(6), len(noisy)), LEGS)

    def knee(kp, side):
        h, k, a = (kp[:, J[f"{side}_{n}"], :2] for n in ("hip", "knee", "ankle"))
        u, v = h - k, a - k
        c = np.sum(u * v, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)
        return 180 - np.degrees(np.arccos(np.clip(c, -1, 1)))

    clean_good, clean_bad = clean_keypoints(noisy, 50.0), clean_keypoints(bad, 50.0)
    err = {name: np.mean(np.abs(knee(kp, "r") - knee(truth, "r"))) for name, kp in
           (("swapped", bad), ("cleaned swapped", clean_bad), ("cleaned", clean_good))}
    assert err["swapped"] > 15
    assert err["cleaned swapped"] == pytest.approx(err["cleaned"], abs=1e-9)
    assert noise_model(bad)[0] == pytest.approx(noise_model(noisy)[0], rel=1e-9)  # the trunk's noise only
    # relabelled beforehand (as a run's clip model does), the cleaning need not do it again
    again = clean_keypoints(relabel_left_right(bad, noise_model(bad)[0])[0], 50.0, relabel=False)
    np.testing.assert_array_equal(again, clean_bad)
    assert not np.array_equal(clean_keypoints(bad, 50.0, relabel=False), clean_bad)


def test_bad_shapes_are_refused_and_short_clips_pass_through():
    with pytest.raises(ValueError, match="shape"):
        relabel_left_right(np.zeros((10, 16, 3)), 1.0)
    kp = np.arange(2 * 17 * 3, dtype=float).reshape(2, 17, 3)
    out, exchanged = relabel_left_right(kp, float("nan"))
    assert np.array_equal(out, kp) and exchanged.shape == (2, 6) and not exchanged.any()


def test_an_outlier_does_not_pull_the_labels_over(runner):
    """A detector outlier (one joint, one frame, far off) costs the same under either labelling:
    it must not make the legs' labels change for the frames after it."""
    _, noisy = runner
    legs = _swap_runs(np.random.default_rng(8), len(noisy))
    bad = _exchange(noisy, legs, LEGS)
    for t, j in ((23, J["l_ankle"]), (120, J["r_knee"]), (121, J["r_knee"])):
        bad[t, j, :2] += [60.0, -45.0]  # 25 noise sd
    _, exchanged = relabel_left_right(bad, noise_px=3.0)
    np.testing.assert_array_equal(exchanged[:, 0], legs)
