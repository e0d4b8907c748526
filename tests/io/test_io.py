import json

import numpy as np
import pytest

from probreg.io import (
    ClipFormatError,
    load_clip,
    read_keypoints_json,
    write_keypoints_json,
)


def _clip(tmp_path, keypoints=None, meta=None):
    d = tmp_path / "clip"
    d.mkdir()
    (d / "clip.json").write_text(json.dumps(meta or {"fps": 50.0, "image_size": [1920, 1080], "n_frames": 3}))
    if keypoints is not None:
        (d / "keypoints2d.json").write_text(keypoints if isinstance(keypoints, str) else json.dumps(keypoints))
    return d


def test_round_trip_with_missing_frames_and_joints(tmp_path, rng):
    kp = rng.uniform(0, 1000, (4, 17, 3))
    kp[..., 2] = rng.uniform(0, 1, (4, 17))  # scores are confidences in [0, 1]
    kp[1] = np.nan
    kp[2, 5] = np.nan
    write_keypoints_json(tmp_path / "k.json", kp)
    back = read_keypoints_json(tmp_path / "k.json")
    assert np.allclose(back, kp, atol=1e-4, equal_nan=True)
    assert json.loads((tmp_path / "k.json").read_text())["frames"][1]["keypoints"] is None


def test_coco_input_is_mapped(tmp_path):
    kps = [[[float(i), 2.0 * i, 0.9] for i in range(17)]]
    d = _clip(tmp_path, {"format": "coco17", "frames": [{"frame": 0, "keypoints": kps[0]}]})
    clip = load_clip(d)
    assert np.allclose(clip.keypoints_px[0, 0, :2], [11.5, 23.0])  # pelvis = mid-hip


def test_low_scores_become_missing(tmp_path):
    kp = [[10.0, 10.0, 0.9]] * 16 + [[5.0, 5.0, 0.1]]
    d = _clip(tmp_path, {"format": "h36m17", "frames": [{"frame": 0, "keypoints": kp}]})
    clip = load_clip(d, min_score=0.3)
    assert np.all(np.isnan(clip.keypoints_px[0, 16])) and np.all(np.isfinite(clip.keypoints_px[0, 15]))
    assert clip.n_frames == 3 and np.all(np.isnan(clip.keypoints_px[1:]))


@pytest.mark.parametrize("content, match", [
    ("{not json", "malformed JSON at line 1"),
    ({"format": "body25", "frames": []}, "unknown keypoint format"),
    ({"format": "h36m17", "frames": [{"frame": 0, "keypoints": [[1, 2, 3]] * 16}]}, "17 joints"),
    ({"format": "h36m17", "frames": [{"frame": 9, "keypoints": None}]}, "beyond"),
    ({"format": "h36m17", "frames": [{"keypoints": None}]}, "lacks 'frame'"),
    ({"format": "h36m17", "frames": [{"frame": 0, "keypoints": [["a", 2, 3]] * 17}]}, "not numbers"),
    # two detections for one frame: an error, not the last one silently kept
    ({"format": "h36m17", "frames": [{"frame": 1, "keypoints": None}, {"frame": 0, "keypoints": None},
                                     {"frame": 1, "keypoints": [[1, 2, 0.9]] * 17}]},
     r"frame 1 is listed twice \(frames\[0\] and frames\[2\]\)"),
])
def test_malformed_keypoints_name_the_file(tmp_path, content, match):
    d = _clip(tmp_path, content)
    with pytest.raises(ClipFormatError, match=match) as exc:
        load_clip(d)
    assert "keypoints2d.json" in str(exc.value)


def test_missing_and_malformed_clip_json(tmp_path):
    with pytest.raises(ClipFormatError, match="not found"):
        load_clip(tmp_path / "nope")
    d = _clip(tmp_path, meta={"fps": 50.0})
    with pytest.raises(ClipFormatError, match="image_size"):
        load_clip(d)


def test_nan_keypoints_are_missing_not_zero(tmp_path):
    kp = [[1.0, 2.0, 0.9]] * 17
    kp[3] = [None, 2.0, 0.9]
    d = _clip(tmp_path, {"format": "h36m17", "frames": [{"frame": 0, "keypoints": kp}]})
    assert np.all(np.isnan(load_clip(d).keypoints_px[0, 3]))
