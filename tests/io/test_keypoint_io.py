"""Keypoint readers (COCO, OpenPose, CSV, NumPy, TRC) and `probreg import`."""

import json

import cv2
import numpy as np
import pytest

from probreg.cli import main
from probreg.geometry import COCO_NAMES, JOINT_INDEX, JOINT_NAMES, coco_to_h36m
from probreg.io import ClipFormatError, load_clip, read_keypoints
from probreg.io.keypoints import BODY25_TO_COCO


@pytest.fixture
def coco_kp(rng):
    kp = np.concatenate([rng.uniform(100, 900, (5, 17, 2)), rng.uniform(0.6, 1.0, (5, 17, 1))], -1)
    return kp


def test_coco_results_keep_best_person_per_image(tmp_path, coco_kp):
    dets = []
    for i, k in enumerate(coco_kp):
        dets.append({"image_id": 10 + i, "category_id": 1, "keypoints": k.ravel().tolist(), "score": 0.9})
        dets.append({"image_id": 10 + i, "category_id": 1, "keypoints": (k + 50).ravel().tolist(), "score": 0.2})
    p = tmp_path / "res.json"
    p.write_text(json.dumps(dets))
    got = read_keypoints(p)
    assert got.shape == (5, 17, 3)
    assert np.allclose(got, coco_to_h36m(coco_kp), equal_nan=True)


def test_openpose_body25_folder_follows_the_athlete(tmp_path, coco_kp):
    for i, k in enumerate(coco_kp):
        body = np.zeros((25, 3))
        body[BODY25_TO_COCO] = k
        other = body.copy()
        other[:, :2] += 400
        other[:, 2] = 0.99  # a more confident bystander far away
        people = [{"pose_keypoints_2d": body.ravel().tolist()}]
        if i > 0:
            people.append({"pose_keypoints_2d": other.ravel().tolist()})
        (tmp_path / f"clip_{i:012d}_keypoints.json").write_text(json.dumps({"people": people}))
    got = read_keypoints(tmp_path, "openpose")
    assert np.allclose(got[:, :, :2], coco_to_h36m(coco_kp)[:, :, :2], equal_nan=True)


def test_openpose_undetected_joints_are_missing_not_zero(tmp_path):
    body = np.zeros((25, 3))
    body[:, :2] = 100
    body[:, 2] = 0.9
    body[11] = 0  # right ankle not detected
    (tmp_path / "a_keypoints.json").write_text(json.dumps({"people": [{"pose_keypoints_2d": body.ravel().tolist()}]}))
    got = read_keypoints(tmp_path, "openpose")
    assert np.all(np.isnan(got[0, JOINT_INDEX["r_ankle"]]))


def test_csv_with_coco_names(tmp_path, coco_kp):
    header = ["frame"] + [f"{n}_{c}" for n in COCO_NAMES for c in ("x", "y", "score")]
    rows = [[i] + list(k.ravel()) for i, k in enumerate(coco_kp)]
    rows[2][1 + 3 * 16 + 2] = 0.1  # low-score right ankle
    p = tmp_path / "kp.csv"
    p.write_text("\n".join(",".join(map(str, r)) for r in [header] + rows))
    got = read_keypoints(p)
    assert np.allclose(got[0], coco_to_h36m(coco_kp)[0])
    assert np.all(np.isnan(got[2, JOINT_INDEX["r_ankle"]]))


def test_numpy_layouts(tmp_path, coco_kp):
    np.save(tmp_path / "a.npy", coco_kp)
    assert np.allclose(read_keypoints(tmp_path / "a.npy", layout="coco17"), coco_to_h36m(coco_kp))
    assert np.allclose(read_keypoints(tmp_path / "a.npy"), coco_kp)
    np.save(tmp_path / "b.npy", coco_kp[:, :16])
    with pytest.raises(ClipFormatError, match=r"b.npy: expected shape"):
        read_keypoints(tmp_path / "b.npy")


def _trc(path, names, xy):
    n = len(xy)
    lines = ["PathFileType\t4\t(X/Y/Z)\tx.trc",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"50\t50\t{n}\t{len(names)}\tpx\t50\t1\t{n}",
             "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
             "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(len(names)))]
    for f in range(n):
        vals = [str(f + 1), f"{f / 50:.3f}"] + [f"{v:.3f}" for j in range(len(names)) for v in (*xy[f, j], 0.0)]
        lines.append("\t".join(vals))
    path.write_text("\n".join(lines) + "\n")


def test_trc_with_pose2sim_marker_names(tmp_path, coco_kp):
    names = ["Nose", "LEye", "REye", "LEar", "REar", "LShoulder", "RShoulder", "LElbow", "RElbow", "LWrist",
             "RWrist", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle"]
    _trc(tmp_path / "a.trc", names, coco_kp[..., :2])
    got = read_keypoints(tmp_path / "a.trc")
    assert np.allclose(got[..., :2], coco_to_h36m(coco_kp)[..., :2], atol=1e-3)
    flipped = read_keypoints(tmp_path / "a.trc", image_height=1080)
    assert np.allclose(flipped[:, JOINT_INDEX["r_knee"], 1], 1080 - coco_kp[:, 14, 1], atol=1e-3)
    _trc(tmp_path / "b.trc", names[:-1], coco_kp[:, :16, :2])
    with pytest.raises(ClipFormatError, match="r_ankle"):
        read_keypoints(tmp_path / "b.trc")


@pytest.mark.parametrize("content, match", [
    ('[{"image_id": 1, "keypoints": [1, 2, 3]}]', "has 1 keypoints"),
    ("{bad", "malformed JSON"),
])
def test_bad_coco_files(tmp_path, content, match):
    p = tmp_path / "x.json"
    p.write_text(content)
    with pytest.raises(ClipFormatError, match=match):
        read_keypoints(p)


def test_bad_csv_names_line(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("frame,nose_x,nose_y\n0,1,2\n1,abc,3\n")
    with pytest.raises(ClipFormatError, match="line 3"):
        read_keypoints(p)


def test_import_command_builds_a_clip(tmp_path, coco_kp):
    frames = tmp_path / "imgs"
    frames.mkdir()
    for i in range(6):
        cv2.imwrite(str(frames / f"img{i:03d}.png"), np.zeros((72, 128, 3), np.uint8))
    np.save(tmp_path / "kp.npy", coco_kp)
    out = tmp_path / "clip"
    assert main(["import", "--keypoints", str(tmp_path / "kp.npy"), "--layout", "coco17", "--frames", str(frames),
                 "--fps", "50", "--athlete-lane", "4", "--out", str(out)]) == 0
    clip = load_clip(out)
    assert clip.n_frames == 6 and clip.image_size == (128, 72) and clip.athlete_lane == 4
    assert np.all(np.isnan(clip.keypoints_px[5]))  # keypoints for 5 of 6 frames
    assert main(["import", "--keypoints", str(tmp_path / "kp.npy"), "--frames", str(frames),
                 "--out", str(tmp_path / "c2")]) == 2  # no fps
    np.save(tmp_path / "long.npy", np.concatenate([coco_kp, coco_kp]))
    assert main(["import", "--keypoints", str(tmp_path / "long.npy"), "--frames", str(frames), "--fps", "50",
                 "--out", str(tmp_path / "c3")]) == 2  # more keypoint frames than images


def test_import_names_a_bad_frame_rate_and_warns_of_keypoints_without_joints(tmp_path, coco_kp, capsys):
    frames = tmp_path / "imgs"
    frames.mkdir()
    for i in range(6):
        cv2.imwrite(str(frames / f"img{i:03d}.png"), np.zeros((72, 128, 3), np.uint8))
    np.save(tmp_path / "kp.npy", coco_kp)
    args = ["import", "--keypoints", str(tmp_path / "kp.npy"), "--layout", "coco17", "--frames", str(frames)]
    assert main([*args, "--fps", "-5", "--out", str(tmp_path / "c1")]) == 2
    assert "--fps must be a positive frame rate (frames per second), got -5" in capsys.readouterr().err
    np.save(tmp_path / "nan.npy", np.full_like(coco_kp, np.nan))
    assert main(["import", "--keypoints", str(tmp_path / "nan.npy"), "--layout", "coco17", "--frames", str(frames),
                 "--fps", "50", "--out", str(tmp_path / "c2")]) == 0
    assert "no joint in any frame" in capsys.readouterr().out
    assert main([*args, "--fps", "50", "--out", str(tmp_path / "c3")]) == 0
    assert "no joint" not in capsys.readouterr().out


def test_keypoints2d_json_round_trip_and_a_format_its_names_contradict(tmp_path, coco_kp):
    """Both formats come back as written (COCO read into H36M order); a file whose 'joint_names' are
    exactly the other format's order is an error naming the fix (read as declared, every joint would
    be another one), while names spelled otherwise are left alone."""
    from probreg.io.clip import read_keypoints_json, write_keypoints_json

    for fmt, expect in (("h36m17", coco_kp), ("coco17", coco_to_h36m(coco_kp))):
        write_keypoints_json(tmp_path / f"{fmt}.json", coco_kp, fmt=fmt)
        assert np.allclose(read_keypoints_json(tmp_path / f"{fmt}.json"), expect, atol=1e-3, equal_nan=True)
    doc = json.loads((tmp_path / "coco17.json").read_text())
    doc["format"] = "h36m17"  # COCO data declared as H36M
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ClipFormatError, match="'joint_names' are coco17's names; set \"format\": \"coco17\""):
        read_keypoints_json(tmp_path / "bad.json")
    doc["joint_names"] = doc["joint_names"][::-1]  # the other format's names in any order: as wrong
    (tmp_path / "bad2.json").write_text(json.dumps(doc))
    with pytest.raises(ClipFormatError, match="coco17's names"):
        read_keypoints_json(tmp_path / "bad2.json")
    doc["joint_names"] = [n.upper() for n in COCO_NAMES]
    (tmp_path / "other.json").write_text(json.dumps(doc))
    assert read_keypoints_json(tmp_path / "other.json").shape == (5, 17, 3)


def test_joint_columns_named_in_another_order_are_read_by_their_names(tmp_path, coco_kp):
    """A file that lists the format's own joint names in another order (its columns in that order)
    is read by the names: the joints come back where the format has them (before 0.2.0.dev35 the
    names were ignored and every joint was read as another one)."""
    from probreg.io.clip import read_keypoints_json, write_keypoints_json

    for fmt, names, expect in (("h36m17", JOINT_NAMES, coco_kp), ("coco17", COCO_NAMES, coco_to_h36m(coco_kp))):
        write_keypoints_json(tmp_path / "k.json", coco_kp, fmt=fmt)
        doc = json.loads((tmp_path / "k.json").read_text())
        perm = np.random.default_rng(3).permutation(17)
        doc["joint_names"] = [names[j] for j in perm]
        for f in doc["frames"]:
            if f["keypoints"] is not None:
                f["keypoints"] = [f["keypoints"][j] for j in perm]
        (tmp_path / "shuffled.json").write_text(json.dumps(doc))
        assert np.allclose(read_keypoints_json(tmp_path / "shuffled.json"), expect, atol=1e-3, equal_nan=True)


def test_import_refuses_keypoints_normalised_to_the_image_before_writing(tmp_path, coco_kp, capsys):
    """MediaPipe-style landmarks (x, y in [0, 1]) are refused at the import, with the factors that
    make them pixels of the frames found, and no clip folder is left behind."""
    frames = tmp_path / "imgs"
    frames.mkdir()
    for i in range(6):
        cv2.imwrite(str(frames / f"img{i:03d}.png"), np.zeros((72, 128, 3), np.uint8))
    norm = np.array(coco_kp, float)
    norm[..., :2] /= 1000.0  # within [0.1, 0.9]
    np.save(tmp_path / "norm.npy", norm)
    code = main(["import", "--keypoints", str(tmp_path / "norm.npy"), "--layout", "coco17", "--frames", str(frames),
                 "--fps", "50", "--out", str(tmp_path / "clip")])
    err = capsys.readouterr().err
    assert code == 2 and "multiply x by 128 and y by 72" in err and "Traceback" not in err
    assert not (tmp_path / "clip").exists()
