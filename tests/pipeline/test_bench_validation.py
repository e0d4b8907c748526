"""``bench validation``'s lifting floor: the knee error of ``probreg lift`` given the clip's true
cameras and limb lengths."""

import shutil

import numpy as np
import pytest

from probreg.bench.validation import _true_camera_knee
from probreg.io.clip import write_keypoints_json


def test_true_camera_floor_is_zero_for_exact_keypoints_and_not_for_noisy(small_clip, tmp_path):
    noisy = _true_camera_knee(small_clip, tmp_path / "noisy")
    exact = tmp_path / "exact"
    shutil.copytree(small_clip, exact)
    truth = np.load(exact / "groundtruth" / "joints2d.npy")
    if truth.shape[-1] == 2:
        truth = np.concatenate([truth, np.ones(truth.shape[:-1] + (1,))], axis=-1)
    write_keypoints_json(exact / "keypoints2d.json", truth)
    floor = _true_camera_knee(exact, tmp_path / "exact_work")
    # the lifting with the true cameras and exact 2D is nearly exact: ray casting, no smoothing
    # needed; what is left (0.5 deg on this clip) is the limb plane's pull along the rays on legs
    # that leave their plane, as generated legs do since 0.2.0.dev24 (docs/method.md)
    assert floor < 1.0
    # the clip's simulated detector noise costs degrees even with the true cameras
    assert 1.0 < noisy < 8.0
    # a clip without a usable lifting gives NaN, not an exception
    broken = tmp_path / "broken"
    shutil.copytree(small_clip, broken)
    (broken / "keypoints2d.json").write_text("{")
    assert np.isnan(_true_camera_knee(broken, tmp_path / "broken_work"))


def test_other_angles_table_scores_every_clip_and_averages_the_unflagged():
    """Hips, elbows and the trunk lean are reported next to the knee: a clip whose hips fail under an
    ``ok`` verdict (the ground track run backwards of 0.2.0.dev20) shows in the unflagged mean."""
    from probreg.bench.validation import other_angle_rows

    def score(hip, verdict):
        return {"hip_deg": hip, "hip_coverage": 0.9, "elbow_deg": 3.0, "elbow_coverage": 1.0,
                "trunk_lean_deg": 1.0, "verdict": verdict}

    rows = other_angle_rows({"a": score(2.0, "ok"), "b": score(48.0, "ok"), "c": score(9.0, "unreliable"),
                             "d": {"failed": True}})
    assert [r[0] for r in rows[:-1]] == ["a", "b", "c"]
    assert rows[1][1:] == [48.0, 90.0, 3.0, 100.0, 1.0, "ok"]
    assert rows[-1][0] == "**mean, 2 unflagged**" and rows[-1][1] == 25.0 and rows[-1][2] == 90.0


def test_reseed_with_the_same_seed_reproduces_every_number(small_clip, tmp_path):
    """``bench validation --reseed``: a second run of every clip; with the first run's own seed it must
    reproduce every score exactly (a run is a function of its inputs and its seed), and a result
    folder already in ``--keep-outputs`` is refused, not scored as new."""
    import pytest

    from probreg.bench.common import BenchReport
    from probreg.bench.validation import _run_sets

    rep = BenchReport("validation", "test")
    keep = tmp_path / "keep"
    _run_sets(rep, [("test set (one clip)", {}, [small_clip])], None, keep, reseed=0)
    text = "\n".join(rep.sections)
    assert "### Seed stability on the test set" in text
    assert "verdicts that changed: **0 of 1**" in text
    row = [ln for ln in text.splitlines() if ln.startswith("| **largest change**")][0]
    assert row.split("|")[2:8:2] == [" 0.00 ", " 0.00 ", " 0.00 "]
    assert (keep / "seed0" / small_clip.name / "run.json").exists()
    with pytest.raises(ValueError, match="already there"):
        _run_sets(BenchReport("validation", "again"), [("test set", {}, [small_clip])], None, keep, reseed=0)


def test_jittered_copy_moves_only_the_keypoints_and_the_same_way_each_time(small_clip, tmp_path):
    """``--jitter-px``: the copy links everything but the keypoints, which move by noise of the given
    size (the same noise for the clip every time); missing joints stay missing."""
    from probreg.bench.validation import jittered_clip
    from probreg.io.clip import read_keypoints_json

    a = jittered_clip(small_clip, tmp_path / "a", 0.05)
    b = jittered_clip(small_clip, tmp_path / "b", 0.05)
    k0, ka, kb = (read_keypoints_json(p / "keypoints2d.json") for p in (small_clip, a, b))
    d = (ka - k0)[..., :2]
    ok = np.isfinite(d)
    assert np.array_equal(np.isnan(ka), np.isnan(k0)) and np.array_equal(ka, kb, equal_nan=True)
    assert 0.04 < float(np.std(d[ok])) < 0.06 and np.array_equal(ka[..., 2], k0[..., 2], equal_nan=True)
    assert (a / "frames").resolve() == (small_clip / "frames").resolve()
    assert (a / "clip.json").read_text() == (small_clip / "clip.json").read_text()


def test_a_shared_folder_given_is_the_one_used_or_an_error(tmp_path, monkeypatch, capsys):
    """``--shared`` names the data a benchmark scores on: a folder that is not there is an error
    (before, another ``shared/data`` found beside the checkout was used in its place without a
    word), and the ``shared`` folder itself stands for its ``data``."""
    from probreg.bench.common import find_shared_data
    from probreg.cli import main

    with pytest.raises(ValueError, match="no such folder"):
        find_shared_data(tmp_path / "nowhere")
    (tmp_path / "shared" / "data" / "validation").mkdir(parents=True)
    assert find_shared_data(tmp_path / "shared") == (tmp_path / "shared" / "data").resolve()
    assert find_shared_data(tmp_path / "shared" / "data") == (tmp_path / "shared" / "data").resolve()
    # the environment's folder is not taken when one is given
    monkeypatch.setenv("PROBREG_SHARED_DATA", str(tmp_path / "shared" / "data"))
    with pytest.raises(ValueError):
        find_shared_data(tmp_path / "nowhere")
    assert find_shared_data() == (tmp_path / "shared" / "data").resolve()
    code = main(["bench", "validation", "--set", "validation", "--shared", str(tmp_path / "nowhere"),
                 "--reports", str(tmp_path / "reports")])
    err = capsys.readouterr().err
    assert code == 2 and "no such folder" in err and "Traceback" not in err
    assert not (tmp_path / "reports").exists()
