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
    # a score limit no confidence can reach would drop every keypoint: an error, not an empty clip
    for bad in (2.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="min_score must be a confidence between 0 and 1"):
            load_clip(d, min_score=bad)


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


def test_a_byte_order_mark_is_read_past(tmp_path):
    """JSON saved by an editor that writes UTF-8 with a byte-order mark first (Notepad,
    PowerShell) reads as the same document, for the clip and for keypoints given apart."""
    from probreg.io.keypoints import read_coco_results

    kp = [[float(i), 2.0 * i, 0.9] for i in range(17)]
    plain = _clip(tmp_path, {"format": "h36m17", "frames": [{"frame": 1, "keypoints": kp}]})
    marked = tmp_path / "marked"
    marked.mkdir()
    for name in ("clip.json", "keypoints2d.json"):
        (marked / name).write_bytes(b"\xef\xbb\xbf" + (plain / name).read_bytes())
    a, b = load_clip(plain), load_clip(marked)
    assert (a.fps, a.image_size, a.n_frames) == (b.fps, b.image_size, b.n_frames) == (50.0, (1920, 1080), 3)
    assert np.array_equal(a.keypoints_px, b.keypoints_px, equal_nan=True)
    assert np.allclose(b.keypoints_px[1, 5, :2], [5.0, 10.0]) and np.isnan(b.keypoints_px[0]).all()
    coco = [{"image_id": 0, "category_id": 1, "score": 0.9, "keypoints": [v for i in range(17) for v in (i, i, 0.9)]}]
    (tmp_path / "coco.json").write_bytes(b"\xef\xbb\xbf" + json.dumps(coco).encode())
    assert np.allclose(read_coco_results(tmp_path / "coco.json")[0, 1, :2], [12.0, 12.0])  # r_hip = COCO 12
    # a mark inside the text is still not JSON
    (marked / "clip.json").write_bytes(b'{"fps": 50.0, \xef\xbb\xbf"image_size": [1920, 1080]}')
    with pytest.raises(ClipFormatError, match="malformed JSON"):
        load_clip(marked)


def test_keypoints_normalised_to_the_image_are_a_clear_error(tmp_path):
    """x, y in [0, 1] (MediaPipe's normalised landmarks) are not pixels: the error says how to
    turn them into the frames' pixels; a small athlete's pixel coordinates pass."""
    kp = [[0.40 + 0.01 * i, 0.30 + 0.02 * i, 0.9] for i in range(17)]
    d = _clip(tmp_path, {"format": "h36m17", "frames": [{"frame": 0, "keypoints": kp}]})
    with pytest.raises(ClipFormatError, match=r"within \[0, 1\].*multiply x by 1920 and y by 1080") as exc:
        load_clip(d)
    assert "keypoints2d.json" in str(exc.value)
    (d / "keypoints2d.json").write_text(json.dumps(
        {"format": "h36m17", "frames": [{"frame": 0, "keypoints": [[x * 1920, y * 1080, c] for x, y, c in kp]}]}))
    assert np.allclose(load_clip(d).keypoints_px[0, 3, :2], [0.43 * 1920, 0.36 * 1080])


def test_nan_keypoints_are_missing_not_zero(tmp_path):
    kp = [[1.0, 2.0, 0.9]] * 17
    kp[3] = [None, 2.0, 0.9]
    d = _clip(tmp_path, {"format": "h36m17", "frames": [{"frame": 0, "keypoints": kp}]})
    assert np.all(np.isnan(load_clip(d).keypoints_px[0, 3]))


def test_a_video_shorter_or_longer_than_the_clip_is_named_in_the_notes(tmp_path):
    """A video.mp4 of 5 frames in a clip of 8 (clip.json n_frames): frames 5 to 7 have no image, said
    at load time (before 0.2.0.dev35 only the lane step's 'could not be decoded' told of it); a clip
    of 3 frames leaves the video's last 2 unread; a clip of 5 says nothing."""
    import cv2

    d = _clip(tmp_path, meta={"fps": 25.0, "image_size": [64, 48], "n_frames": 8})
    writer = cv2.VideoWriter(str(d / "video.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 25, (64, 48))
    if not writer.isOpened():
        pytest.skip("this OpenCV cannot write mp4v")
    for k in range(5):
        writer.write(np.full((48, 64, 3), 40 * k, np.uint8))
    writer.release()
    notes = [n for n in load_clip(d).notes if "video.mp4" in n]
    assert len(notes) == 1 and "5 frames, the clip 8" in notes[0] and "frames 5 to 7 have no image" in notes[0]
    for n_frames, expect in ((3, "the last 2 are not read"), (5, None)):
        (d / "clip.json").write_text(json.dumps({"fps": 25.0, "image_size": [64, 48], "n_frames": n_frames}))
        notes = [n for n in load_clip(d).notes if "video.mp4" in n]
        assert (notes == []) if expect is None else (len(notes) == 1 and expect in notes[0])
