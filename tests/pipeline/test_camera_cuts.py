"""A broadcast clip that cuts between two cameras: the cut is found, one shot is estimated with
its own camera, and taking the clip as one camera (``--shot all``) is flagged, not trusted."""

import json

import numpy as np
import pytest

from probreg.cli import main

FAST_RUN = ["--walkers", "20", "--max-steps", "600", "--draws", "8", "--seed", "1", "--quiet"]
HEIGHTS = (9.0, 11.0)  # the two cameras (m): both in the main stand, 30 m and 40 m from the lane


@pytest.fixture(scope="module")
def two_shots(tmp_path_factory):
    """45 frames from one camera, then a cut to 35 frames from another (frames, keypoints and
    cameras of each shot its own, as a broadcast edit makes them)."""
    from dataclasses import replace

    from probreg.sim import config_from_preset, synthesize, write_clip

    root = tmp_path_factory.mktemp("shots")
    parts = []
    for k, (seed, h, d, n) in enumerate(((11, HEIGHTS[0], 30.0, 45), (13, HEIGHTS[1], 40.0, 35))):
        base = config_from_preset("run", seed, image_size=(1280, 720))
        cfg = replace(base, n_frames=n, camera=replace(base.camera, height_m=h, distance_m=d))
        parts.append(write_clip(synthesize(cfg, seed=seed, preset="run"), root / f"shot{k}", images=True, jobs=1))
    clip = root / "clip"
    (clip / "frames").mkdir(parents=True)
    frames, gt = [], []
    for part in parts:
        for f in sorted((part / "frames").iterdir()):
            (clip / "frames" / f"{len(frames):06d}.jpg").write_bytes(f.read_bytes())
            frames.append(None)
        kp = json.loads((part / "keypoints2d.json").read_text())
        gt.append((kp, np.load(part / "groundtruth" / "joints3d.npy")))
    meta = json.loads((parts[0] / "clip.json").read_text())
    meta.pop("athlete_lane", None)  # the two synthetic athletes run in different lanes
    meta["n_frames"] = len(frames)
    (clip / "clip.json").write_text(json.dumps(meta))
    merged = [dict(fr, frame=i) for i, fr in enumerate(gt[0][0]["frames"] + gt[1][0]["frames"])]
    (clip / "keypoints2d.json").write_text(json.dumps({"format": gt[0][0]["format"], "frames": merged}))
    return clip, np.concatenate([gt[0][1], gt[1][1]])


def _run(clip, out, *extra):
    code = main(["run", str(clip), "--out", str(out), *extra] + FAST_RUN)
    return code, json.loads((out / "run.json").read_text())


def test_the_longest_shot_is_estimated_with_its_own_camera(two_shots, tmp_path):
    from probreg.io import read_angles_csv

    clip, _ = two_shots
    code, run = _run(clip, tmp_path / "res")
    shots = run["shots"]
    assert shots["cuts"] == [45] and shots["ranges"] == [[0, 45], [45, 80]]
    assert shots["chosen"] == 0 and shots["how"] == "longest" and shots["frames_estimated"] == [0, 45]
    assert run["frame_status"][45:] == ["other_shot"] * 35
    assert "other_shot" not in run["frame_status"][:45]
    assert any(n.startswith("camera cut at frame 45: 2 shots") for n in run["input_notes"])
    assert not any(r.startswith("camera cut") for r in run["verdict_reasons"])
    # the camera of the first shot, not a blend of the two
    h = run["height_m"]
    assert h["lo"] <= HEIGHTS[0] <= h["hi"] and h["hi"] < HEIGHTS[1], h
    knee = read_angles_csv(tmp_path / "res" / "angles.csv")["knee_r"][1]
    assert np.isfinite(knee[:45]).mean() > 0.8 and np.all(np.isnan(knee[45:]))


def test_another_shot_can_be_chosen(two_shots, tmp_path):
    clip, _ = two_shots
    code, run = _run(clip, tmp_path / "res", "--shot", "1")
    assert run["shots"]["chosen"] == 1 and run["shots"]["how"] == "given"
    assert run["frame_status"][:45] == ["other_shot"] * 45
    h = run["height_m"]
    assert h["lo"] <= HEIGHTS[1] <= h["hi"] and h["lo"] > HEIGHTS[0], h


def test_the_clip_taken_as_one_camera_is_flagged(two_shots, tmp_path):
    clip, _ = two_shots
    code, run = _run(clip, tmp_path / "res", "--shot", "all")
    assert code == 3 and run["verdict"] == "unreliable"
    assert "camera cut at frame 45 (taken as one camera)" in run["verdict_reasons"]
    assert run["shots"]["chosen"] is None and "other_shot" not in run["frame_status"]


def test_a_shot_the_clip_does_not_have_is_a_clear_error(two_shots, tmp_path, capsys):
    clip, _ = two_shots
    assert main(["run", str(clip), "--out", str(tmp_path / "res"), "--shot", "2"] + FAST_RUN) == 2
    assert "--shot 2: the clip has 2 shot(s) (cuts at frames 45)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["run", str(clip), "--out", str(tmp_path / "res2"), "--shot", "first"])
