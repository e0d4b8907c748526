"""Camera cuts from the frames' colour changes (probreg.lanes.shots): known answers, real frames."""

import numpy as np
import pytest

from probreg.lanes.shots import (
    CUT_MIN_CHANGE,
    ShotSplit,
    colour_histogram,
    find_cuts,
    histogram_change,
    restrict_clip,
    split_shots,
)


def _stadium(shift=0, sky=(200, 150, 90), track=(40, 60, 190), seed=0):
    """A 720p BGR picture: crowd/sky on top, a red track with white lines below, shifted by a pan."""
    rng = np.random.default_rng(seed)
    img = np.zeros((720, 1280 + 200, 3), np.uint8)
    img[:260] = sky
    img[:260] += rng.integers(0, 40, (260, img.shape[1], 1), dtype=np.uint8)  # a textured crowd
    img[260:] = track
    for k in range(6):
        y = 300 + 70 * k
        img[y:y + 4] = 255
    return img[:, shift:shift + 1280].copy()


def test_a_pan_changes_the_colours_little_and_a_cut_a_lot():
    a, panned = colour_histogram(_stadium(0)), colour_histogram(_stadium(40))
    other = colour_histogram(_stadium(0, sky=(60, 140, 60), track=(120, 120, 130), seed=1))
    assert abs(a.sum() - 1) < 1e-12 and a.shape == (512,)
    assert histogram_change(a, panned) < 0.02
    assert histogram_change(a, other) > 3 * CUT_MIN_CHANGE
    assert histogram_change(a, a) == 0.0


def test_histogram_refuses_what_is_not_a_colour_image():
    assert colour_histogram(None) is None
    assert colour_histogram(np.zeros((10, 10), np.uint8)) is None  # grey
    assert colour_histogram(np.zeros((10, 10, 3), np.uint16)) is None  # 16-bit
    assert np.isnan(histogram_change(None, colour_histogram(_stadium())))


def test_cuts_known_answers():
    c = np.full(100, 0.004)
    c[0] = np.nan
    c[[1, 37, 99]] = [0.3, 0.12, 0.2]  # at the very start and end too
    assert find_cuts(c) == [1, 37, 99]
    c[37] = 0.04  # a fast pan, below the floor
    assert find_cuts(c) == [1, 99]
    noisy = np.full(100, 0.06)  # a flickering picture: every frame changes as much
    noisy[50] = 0.09
    assert find_cuts(noisy) == []
    noisy[50] = 0.5  # one frame stands out from a high level: a cut after all
    assert find_cuts(noisy) == [50]
    assert find_cuts(np.full(10, np.nan)) == []


def test_split_shots_picks_the_longest_unless_told():
    c = np.full(200, 0.003)
    c[[60, 150]] = 0.25
    s = split_shots(c, 200)
    assert s.ranges == ((0, 60), (60, 150), (150, 200)) and s.chosen == 1 and s.frames == (60, 150)
    assert s.how == "longest" and s.split and s.change_max == pytest.approx(0.003)
    assert split_shots(c, 200, shot="2").frames == (150, 200)
    assert split_shots(c, 200, shot="all").chosen is None and not split_shots(c, 200, shot="all").split
    one = split_shots(np.full(50, 0.003), 50)
    assert one.cuts == () and one.how == "only" and not one.split and one.frames == (0, 50)
    with pytest.raises(ValueError, match="3 shot"):
        split_shots(c, 200, shot=3)
    with pytest.raises(ValueError, match="longest"):
        split_shots(c, 200, shot="first")
    doc = s.to_dict()
    assert doc["cuts"] == [60, 150] and doc["frames_estimated"] == [60, 150] and doc["chosen"] == 1


def test_restrict_clip_blanks_the_other_shots_and_says_so(small_clip):
    from probreg.io.clip import load_clip

    clip = load_clip(small_clip)
    F = clip.n_frames
    split = ShotSplit(cuts=(10,), ranges=((0, 10), (10, F)), chosen=1, how="longest")
    out = restrict_clip(clip, split)
    assert np.all(np.isnan(out.keypoints_px[:10])) and np.array_equal(out.keypoints_px[10:], clip.keypoints_px[10:], equal_nan=True)
    assert "camera cut at frame 10" in out.notes[-1] and len(out.notes) == len(clip.notes) + 1
    assert np.isfinite(clip.keypoints_px[:10]).any()  # the caller's clip is left alone
    assert restrict_clip(clip, ShotSplit(ranges=((0, F),))) is clip
    with pytest.raises(ValueError, match="only 5 frames"):
        restrict_clip(clip, ShotSplit(cuts=(5,), ranges=((0, 5), (5, F)), chosen=0, how="given"))


def test_no_cut_in_the_independent_validation_clips(shared_data):
    """Continuous shots of another generator (pans, zooms, 25 and 50 fps) are never cut."""
    import cv2

    clips = sorted(p for p in (shared_data / "validation").iterdir() if (p / "frames").is_dir())
    if not clips:
        pytest.skip("no validation clips")
    for clip in clips:
        hists = [colour_histogram(cv2.imread(str(f))) for f in sorted((clip / "frames").iterdir())]
        change = [np.nan] + [histogram_change(a, b) for a, b in zip(hists[:-1], hists[1:])]
        assert find_cuts(change) == [], clip.name
        assert np.nanmax(change) < 0.6 * CUT_MIN_CHANGE, (clip.name, np.nanmax(change))
