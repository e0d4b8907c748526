"""Bad and unusual input: one test per case of issue 26, plus the cases that already behaved well.

Every user-caused error ends with one line naming the file or option (exit 2, no traceback);
results that are written but unusable exit 3; probreg never deletes what it did not write.
"""

import json
import os
import shutil

import cv2
import numpy as np
import pytest

from probreg.cli import main
from probreg.io import ClipFormatError, load_clip
from probreg.io.results import read_angles_csv
from probreg.io.output import MARKER, OutputRefused, atomic_output_dir, prepare_output

FAST_RUN = ["--walkers", "20", "--max-steps", "300", "--draws", "8", "--seed", "1"]


@pytest.fixture
def clip(small_clip, tmp_path):
    """A private copy of the session's small synthetic clip (40 frames with images)."""
    d = tmp_path / "clip"
    shutil.copytree(small_clip, d)
    return d


def _one_error_line(capsys, *needles):
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("probreg")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def _tree(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------- 1. data loss via --out
def test_run_refuses_out_equal_to_or_inside_the_input_and_leaves_it_intact(clip, capsys):
    before = _tree(clip)
    assert main(["run", str(clip), "--out", str(clip)] + FAST_RUN) == 2
    _one_error_line(capsys, str(clip), "input")
    assert main(["run", str(clip), "--out", str(clip / "result")] + FAST_RUN) == 2
    _one_error_line(capsys, "input")
    assert main(["run", str(clip), "--out", str(clip.parent)] + FAST_RUN) == 2  # would contain the input
    _one_error_line(capsys, "input")
    assert _tree(clip) == before


@pytest.mark.parametrize("command", ["run", "calibrate", "lift"])
def test_out_with_foreign_files_is_refused_before_any_work(clip, tmp_path, capsys, command):
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "notes.txt").write_text("three months of notes")
    extra = ["--cameras", str(clip / "groundtruth" / "cameras.json")] if command == "lift" else []
    assert main([command, str(clip), "--out", str(out)] + extra) == 2
    _one_error_line(capsys, str(out), "not written by probreg", "--overwrite")
    assert (out / "notes.txt").read_text() == "three months of notes"
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_overwrite_moves_foreign_files_aside_never_deletes(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(OutputRefused, match="not written by probreg"):
        prepare_output(out)
    notes = []
    with atomic_output_dir(out, overwrite=True, log=notes.append) as tmp:
        (tmp / "angles.csv").write_text("new")
    assert (out / "angles.csv").read_text() == "new"
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("out.previous-")]
    assert len(aside) == 1 and (aside[0] / "notes.txt").read_text() == "keep me"
    assert notes and str(aside[0]) in notes[0]


def test_a_probreg_result_is_replaced_but_not_when_a_user_added_files(tmp_path):
    out = tmp_path / "res"
    with atomic_output_dir(out) as tmp:
        (tmp / "angles.csv").write_text("first")
        (tmp / "sub").mkdir()
        (tmp / "sub" / "a.txt").write_text("x")
    marker = json.loads((out / MARKER).read_text())
    assert marker["written_by"] == "probreg" and "angles.csv" in marker["files"] and "sub/a.txt" in marker["files"]
    with atomic_output_dir(out) as tmp:  # a re-run replaces our own result
        (tmp / "angles.csv").write_text("second")
    assert (out / "angles.csv").read_text() == "second" and not (out / "sub").exists()
    (out / "my_analysis.ipynb").write_text("user's work")
    with pytest.raises(OutputRefused, match="my_analysis.ipynb"):
        with atomic_output_dir(out) as tmp:
            pass
    assert (out / "my_analysis.ipynb").read_text() == "user's work"
    assert [p.name for p in tmp_path.iterdir()] == ["res"]  # no temporaries left behind


def test_a_clip_folder_with_a_clip_json_is_not_taken_for_a_result(tmp_path):
    """Before: ``clip.json`` made any folder 'ours', so `--out` onto a user's clip deleted it."""
    user_clip = tmp_path / "myclip"
    (user_clip / "frames").mkdir(parents=True)
    (user_clip / "clip.json").write_text('{"fps": 50, "image_size": [64, 48]}')
    (user_clip / "frames" / "000000.jpg").write_bytes(b"jpeg")
    with pytest.raises(OutputRefused):
        prepare_output(user_clip)
    assert (user_clip / "frames" / "000000.jpg").exists()


# ----------------------------------------------------------------------------- 2. frames by number
def test_frames_are_matched_by_number_not_by_listing_position(clip):
    (clip / "frames" / "000005.jpg").unlink()
    shutil.copy(clip / "frames" / "000007.jpg", clip / "frames" / "thumbs.jpg")
    shutil.copy(clip / "frames" / "000007.jpg", clip / "frames" / "000041 (1).jpg")
    c = load_clip(clip)
    assert c.n_frames == 40 and c.frame_paths[5] is None and c.missing_images == [5]
    assert all(c.frame_paths[i].name == f"{i:06d}.jpg" for i in range(40) if i != 5)
    notes = " ".join(c.notes)
    assert "thumbs.jpg" in notes and "000041 (1).jpg" in notes and "missing_image" in notes

    from probreg.calibration import register_clip

    reg = register_clip(c)
    assert reg.frame_lanes[5].status == "missing_image"
    assert reg.frame_lanes[6].status == "ok" and reg.frame_lanes[39].status == "ok"


def test_two_images_with_one_frame_number_are_an_error_naming_both(clip, tmp_path, capsys):
    shutil.copy(clip / "frames" / "000003.jpg", clip / "frames" / "3.png")
    with pytest.raises(ClipFormatError, match=r"000003\.jpg and .*3\.png: both are frame 3"):
        load_clip(clip)
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "both are frame 3")


# ----------------------------------------------------------------------------- 3. scores out of range
def test_scores_out_of_range_are_a_clear_error(clip, tmp_path, capsys):
    doc = json.loads((clip / "keypoints2d.json").read_text())
    for f in doc["frames"]:
        if f["keypoints"]:
            for kp in f["keypoints"]:
                if kp[2] is not None:
                    kp[2] *= 100  # a detector that reports 0-100
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    with pytest.raises(ClipFormatError, match=r"outside \[0, 1\]"):
        load_clip(clip)
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "keypoints2d.json", "score", "[0, 1]")
    assert not (tmp_path / "o").exists()


def test_a_result_without_any_angle_is_a_failure_not_a_success(clip, tmp_path, capsys, monkeypatch):
    """Whatever the cause, a run in which no frame produced an angle says so: verdict
    ``uncalibrated``, exit 3, and the result is still written for inspection."""
    import probreg.pipeline as pipeline

    real = pipeline.angle_bands

    def all_nan(*a, **k):
        return {name: tuple(np.full_like(v, np.nan) for v in bands) for name, bands in real(*a, **k).items()}

    monkeypatch.setattr(pipeline, "angle_bands", all_nan)
    out = tmp_path / "o"
    assert main(["run", str(clip), "--out", str(out), "--dist=-0.1,0,0,0,0"] + FAST_RUN) == 3
    err = capsys.readouterr().err
    assert "uncalibrated" in err and "frames_with_angles 0/40" in err and "Traceback" not in err
    run = json.loads((out / "run.json").read_text())
    assert run["verdict"] == "uncalibrated" and run["verdict_reasons"][0] == "frames_with_angles 0/40"


# ----------------------------------------------------------------------------- 4. absurd coordinates
def test_keypoints_far_outside_the_image_are_missing_with_a_count(clip):
    doc = json.loads((clip / "keypoints2d.json").read_text())
    doc["frames"][3]["keypoints"][2][0] = 1e10
    doc["frames"][9]["keypoints"][5][0] = -40000.0
    doc["frames"][9]["keypoints"][6][1] = 5000.0  # 1080-high image: beyond 2 x 1080
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    c = load_clip(clip)
    assert np.all(np.isnan(c.keypoints_px[3, 2])) and np.all(np.isnan(c.keypoints_px[9, [5, 6]]))
    assert c.keypoints_outside[3] == 1 and c.keypoints_outside[9] == 2 and c.keypoints_outside.sum() == 3
    assert np.isfinite(c.keypoints_px[3, 0, 0])  # the rest of the frame stays
    assert any("more than one image size outside" in n for n in c.notes)


def test_run_end_to_end_with_missing_image_stray_file_and_absurd_keypoint(clip, tmp_path, capsys):
    """The earlier traceback in the report (x = 1e10) and the silent frame shift (missing image)
    in one run: it completes, and run.json says what happened per frame."""
    (clip / "frames" / "000020.jpg").unlink()
    shutil.copy(clip / "frames" / "000007.jpg", clip / "frames" / "Thumbs.jpg")
    half = cv2.imread(str(clip / "frames" / "000030.jpg"))  # one frame of another size: its lines are in other pixels
    cv2.imwrite(str(clip / "frames" / "000030.jpg"), cv2.resize(half, (half.shape[1] // 2, half.shape[0] // 2)))
    (clip / "frames" / "000033.jpg").write_bytes(b"\xff\xd8 a damaged JPEG")  # one frame that does not decode
    doc = json.loads((clip / "keypoints2d.json").read_text())
    doc["frames"][12]["keypoints"][2][0] = 1e10
    for i in (26, 27, 36, 37, 38, 39):  # no athlete: a short gap, and the clip's last four frames
        doc["frames"][i]["keypoints"] = [[None, None, 0.0]] * 17
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    out = tmp_path / "res ü"  # a space and a non-ASCII name on the way
    code = main(["run", str(clip), "--out", str(out), "--dist=-0.1,0,0,0,0"] + FAST_RUN)
    err = capsys.readouterr()
    assert "Traceback" not in err.err
    run = json.loads((out / "run.json").read_text())
    # the short test chain may not have mixed (R-hat / ESS), and 40 frames are under a second
    # (short clip); nothing else may be wrong
    assert code == (3 if run["verdict_reasons"] else 0)
    assert any(r.startswith("short clip (") for r in run["verdict_reasons"])
    assert all(r.startswith(("R-hat", "ESS", "short clip")) for r in run["verdict_reasons"]), run["verdict_reasons"]
    assert run["frame_status"][20] in ("missing_image", "bridged_missing_image")
    assert run["frame_status"][19] == "ok" and run["frame_status"][21] == "ok"
    assert run["keypoints_outside_image"][12] == 1 and sum(run["keypoints_outside_image"]) == 1
    assert any("Thumbs.jpg" in n for n in run["input_notes"])
    assert run["frame_status"][30] in ("bad_image", "bridged_bad_image")  # left out of the lane step, not measured
    assert any(n.startswith("1 frame(s) not") and "frame 30" in n for n in run["input_notes"])
    assert "frame 30" in err.out
    # a damaged image: its own status and note (it had passed as an ordinary frame without lanes)
    assert run["frame_status"][33] in ("bad_image", "bridged_bad_image")
    assert any("1 frame image(s) could not be decoded (first: frame 33)" in n for n in run["input_notes"])
    assert "could not be decoded" in err.out
    report = (out / "report.html").read_text()  # every input note in the report too, where users read
    assert "1 frame image(s) could not be decoded (first: frame 33)" in report and "Thumbs.jpg" in report
    assert any("no detected joint in 6 of 40 frames (first: frame 26)" in n for n in run["input_notes"])
    assert (out / "report.html").exists() and (out / "angles.csv").exists()
    # why a frame has no angles: its keypoints' status, consistent with angles.csv
    kst = run["keypoint_status"]
    assert len(kst) == 40 and kst.count("ok") >= 30
    assert kst[36:] == ["no_detection"] * 4  # nothing after them to bridge from
    assert set(kst[26:28]) <= {"interpolated", "no_detection"}
    frames, knee = read_angles_csv(out / "angles.csv")["knee_r"][:2]
    by_frame = dict(zip(frames.astype(int).tolist(), knee.tolist()))
    for i, st in enumerate(kst):
        if st == "no_detection":
            assert np.isnan(by_frame.get(i, np.nan)), i
        elif st == "ok":
            assert np.isfinite(by_frame[i]), i


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_joints_all_at_one_pixel_give_a_result_without_numpy_warnings(clip, tmp_path, capsys):
    """Degenerate keypoints (every joint of every frame at one pixel: no limb has a length) end with
    a result and a verdict, not with numpy's divide-by-zero warnings on the way; the verdict says the
    legs cannot be read (such a run once came out ``ok`` with knees at 180 deg and zero-width bands)."""
    doc = json.loads((clip / "keypoints2d.json").read_text())
    for f in doc["frames"]:
        f["keypoints"] = [[1000.0, 500.0, 0.9]] * 17
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    code = main(["run", str(clip), "--out", str(tmp_path / "out")] + FAST_RUN)
    err = capsys.readouterr().err
    assert "Warning" not in err and "Traceback" not in err, err
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert code == 3 and run["verdict"] == "unreliable" and (tmp_path / "out" / "angles.csv").exists()
    assert run["diagnostics"]["leg_image_px"] == 0.0
    assert any(r.startswith("legs too short in the image (0.0 px") for r in run["verdict_reasons"]), run


def test_keypoints_of_other_images_are_flagged_and_the_clips_own_are_not(clip, tmp_path, capsys):
    """Keypoints in another image's pixels (a pose model run on a half-size copy of the frames)
    put the skeleton on bare track: they once gave a confident camera and angles under an ``ok``
    verdict (a 12.9 m camera read as 19.8 m).  The clip's own keypoints lie on the athlete."""
    own = tmp_path / "own"
    assert main(["run", str(clip), "--out", str(own)] + FAST_RUN) == 3  # 40 frames: a short clip
    run = json.loads((own / "run.json").read_text())
    assert run["diagnostics"]["keypoints_on_athlete"]["median"] > 0.9
    assert run["diagnostics"]["keypoints_on_athlete"]["frames"] == 40
    assert not any(r.startswith("keypoints off the athlete") for r in run["verdict_reasons"])
    assert run["diagnostics"]["trunk_down_fraction"] == 0.0
    assert not any(r.startswith("skeleton upside down") for r in run["verdict_reasons"])
    assert run["diagnostics"]["merged_far_lines_frames"] == []  # a view whose lanes the blur keeps apart
    doc = json.loads((clip / "keypoints2d.json").read_text())
    for f in doc["frames"]:
        if f["keypoints"]:
            f["keypoints"] = [[x * 0.5, y * 0.5, s] if x is not None else [x, y, s] for x, y, s in f["keypoints"]]
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    half = tmp_path / "half"
    code = main(["run", str(clip), "--out", str(half)] + FAST_RUN)
    err = capsys.readouterr().err
    run = json.loads((half / "run.json").read_text())
    assert code == 3 and run["verdict"] == "unreliable" and (half / "angles.csv").exists()
    assert run["diagnostics"]["keypoints_on_athlete"]["median"] < 0.2
    assert any(r.startswith("keypoints off the athlete (") for r in run["verdict_reasons"]), run
    assert "keypoints off the athlete" in err and "Traceback" not in err


def test_keypoints_with_y_pointing_up_are_flagged_even_with_the_side_given(clip, tmp_path, capsys):
    """Keypoints whose y axis points up (a biomechanics tool's convention) mirror the skeleton in
    the image: with the camera's side given they passed every other check (``ok``)."""
    h = json.loads((clip / "clip.json").read_text())["image_size"][1]
    doc = json.loads((clip / "keypoints2d.json").read_text())
    for f in doc["frames"]:
        if f["keypoints"]:
            f["keypoints"] = [[x, h - 1 - y, s] if y is not None else [x, y, s] for x, y, s in f["keypoints"]]
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    out = tmp_path / "flipped"
    code = main(["run", str(clip), "--out", str(out), "--camera-side", "main"] + FAST_RUN)
    run = json.loads((out / "run.json").read_text())
    assert code == 3 and run["diagnostics"]["trunk_down_fraction"] == 1.0 and (out / "angles.csv").exists()
    assert "skeleton upside down in the image (the trunk points down in 100 % of frames)" in run["verdict_reasons"]
    assert "Traceback" not in capsys.readouterr().err


# ----------------------------------------------------------------------------- 5. metadata
@pytest.mark.parametrize("fps", ["Infinity", "1e-9", "-50", "\"fifty\"", "true"])
def test_fps_outside_the_accepted_range_is_a_clear_error(clip, tmp_path, capsys, fps):
    meta = (clip / "clip.json").read_text()
    doc = json.loads(meta)
    (clip / "clip.json").write_text(json.dumps(doc).replace(f'"fps": {json.dumps(doc["fps"])}', f'"fps": {fps}'))
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "clip.json", "'fps'", "between 1 and 1000")


@pytest.mark.parametrize("width", ["-1.22", "0", "122", "\"wide\"", "NaN"])
def test_an_impossible_lane_width_is_a_clear_error(clip, tmp_path, capsys, width):
    """A sign error or a typo in ``lane_width_m`` once left every frame without a camera and the
    run 'uncalibrated', with nothing naming the cause."""
    doc = json.loads((clip / "clip.json").read_text())
    doc["lane_width_m"] = 0.0
    (clip / "clip.json").write_text(json.dumps(doc).replace('"lane_width_m": 0.0', f'"lane_width_m": {width}'))
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "clip.json", "'lane_width_m'", "between 0.5 and 3")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option", [["--fps", "-3"], ["--stature", "0"], ["--draws", "0"]])
def test_impossible_run_options_are_refused_before_the_work(clip, tmp_path, capsys, option):
    """Each was taken: --fps -3 silently (a clip folder has its own rate), --stature 0 ended
    'uncalibrated' with no posterior, --draws 0 failed after the sampling."""
    assert main(["run", str(clip), "--out", str(tmp_path / "o")] + option) == 2
    _one_error_line(capsys, "must be")
    assert not (tmp_path / "o").exists()


def test_wrong_or_swapped_image_size_is_found(clip, tmp_path, capsys):
    doc = json.loads((clip / "clip.json").read_text())
    doc["image_size"] = doc["image_size"][::-1]
    (clip / "clip.json").write_text(json.dumps(doc))
    with pytest.raises(ClipFormatError, match=r"'image_size' is \[1080, 1920\] but .*000000.jpg is 1920x1080"):
        load_clip(clip)
    assert main(["calibrate", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "image_size")


def test_calibrate_with_no_frame_calibrated_is_a_failure(clip, tmp_path, capsys):
    blank = np.full((1080, 1920, 3), 90, np.uint8)
    for p in (clip / "frames").glob("*.jpg"):
        cv2.imwrite(str(p), blank)
    out = tmp_path / "cal"
    assert main(["calibrate", str(clip), "--out", str(out)]) == 3
    err = capsys.readouterr().err
    assert "calibrated 0/40 frames" in err and "Traceback" not in err
    assert (out / "calibration.json").exists()  # written for inspection


def test_run_with_no_frame_calibrated_writes_an_uncalibrated_result(clip, tmp_path, capsys):
    blank = np.full((1080, 1920, 3), 90, np.uint8)
    for p in (clip / "frames").glob("*.jpg"):
        cv2.imwrite(str(p), blank)
    out = tmp_path / "res"
    assert main(["run", str(clip), "--out", str(out)]) == 3
    err = capsys.readouterr().err
    assert "uncalibrated" in err and "Traceback" not in err
    run = json.loads((out / "run.json").read_text())
    assert run["verdict"] == "uncalibrated"
    assert run["verdict_reasons"][:2] == ["calibrated_frames 0/40", "frames_with_angles 0/40"]
    assert "lanes no_lines 40/40" in run["verdict_reasons"]
    assert run["frame_status"] == ["no_lines"] * 40
    # the whole layout is there, with nothing estimated
    ang = read_angles_csv(out / "angles.csv")
    assert np.all(np.isnan(ang["knee_l"][1])) and len(ang["knee_l"][1]) == 40
    assert np.load(out / "joints3d.npz")["median"].shape == (40, 17, 3)
    assert np.all(np.isnan(np.load(out / "joints3d.npz")["median"]))
    assert all(f["K"] is None for f in json.loads((out / "camera.json").read_text())["frames"])
    report = (out / "report.html").read_text(encoding="utf-8")
    assert "Verdict: uncalibrated" in report
    # each reason with what it means and what to do
    assert "<th>what it means</th>" in report and "frames without the straight&#x27;s lines cannot calibrate" in report


def test_an_uncalibrated_result_says_which_images_did_not_decode(clip, tmp_path, capsys):
    blank = np.full((1080, 1920, 3), 90, np.uint8)
    for p in (clip / "frames").glob("*.jpg"):
        cv2.imwrite(str(p), blank)
    (clip / "frames" / "000005.jpg").write_bytes(b"\xff\xd8 damaged")
    out = tmp_path / "res"
    assert main(["run", str(clip), "--out", str(out)]) == 3
    run = json.loads((out / "run.json").read_text())
    assert run["verdict"] == "uncalibrated" and run["frame_status"][5] == "bad_image"
    assert run["frame_status"].count("no_lines") == 39
    note = "1 frame image(s) could not be decoded (first: frame 5)"
    assert any(note in n for n in run["input_notes"]) and note in (out / "report.html").read_text(encoding="utf-8")


# ----------------------------------------------------------------------------- 6. late checks, leftovers, interrupts
def test_out_that_is_a_file_is_refused_before_the_work(clip, tmp_path, capsys, monkeypatch):
    import probreg.pipeline as pipeline

    def never(*a, **k):
        raise AssertionError("the work started before the output was checked")

    monkeypatch.setattr(pipeline, "register_clip", never)
    f = tmp_path / "result.txt"
    f.write_text("x")
    assert main(["run", str(clip), "--out", str(f)]) == 2
    _one_error_line(capsys, "not a folder")
    assert main(["run", str(clip), "--out", str(f / "sub")]) == 2
    _one_error_line(capsys, "not a folder")
    assert f.read_text() == "x"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root may write into read-only folders")
def test_out_in_a_read_only_folder_is_refused_before_the_work(clip, tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert main(["run", str(clip), "--out", str(ro / "res")]) == 2
        _one_error_line(capsys, "not writable")
    finally:
        ro.chmod(0o755)


def test_stale_temporaries_of_a_dead_run_are_removed_on_the_next_start(tmp_path):
    dead = tmp_path / ".res.tmp-999999999-abc"  # no such process
    dead.mkdir()
    (dead / ".probreg-incomplete").write_text("999999999\n")
    (dead / "angles.csv").write_text("half")
    alive = tmp_path / f".res.tmp-{os.getpid()}-def"  # a run still going on (this process)
    alive.mkdir()
    (alive / ".probreg-incomplete").write_text(f"{os.getpid()}\n")
    foreign = tmp_path / ".res.tmp-1-xyz"  # not ours: no marker
    foreign.mkdir()
    prepare_output(tmp_path / "res")
    assert not dead.exists() and alive.exists() and foreign.exists()


def test_an_interrupted_run_leaves_the_previous_result_intact(clip, tmp_path, capsys, monkeypatch):
    out = tmp_path / "res"
    with atomic_output_dir(out) as tmp:
        (tmp / "angles.csv").write_text("previous result")
    import probreg.pipeline as pipeline

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline.ClipModel, "sample", ctrl_c)
    assert main(["run", str(clip), "--out", str(out)] + FAST_RUN) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "left as it was" in err
    assert (out / "angles.csv").read_text() == "previous result"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".res")] == []


def test_a_failure_inside_the_writer_leaves_the_previous_result(tmp_path):
    out = tmp_path / "res"
    with atomic_output_dir(out) as tmp:
        (tmp / "angles.csv").write_text("previous")
    with pytest.raises(RuntimeError):
        with atomic_output_dir(out) as tmp:
            (tmp / "angles.csv").write_text("half")
            raise RuntimeError("disk full")
    assert (out / "angles.csv").read_text() == "previous"


# ----------------------------------------------------------------------------- already good, kept so
@pytest.mark.parametrize("content, needle", [("{not json", "malformed JSON"), ("[]", "JSON object"),
                                             ('{"fps": 50}', "image_size")])
def test_malformed_clip_json_names_the_file(clip, tmp_path, capsys, content, needle):
    (clip / "clip.json").write_text(content)
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "clip.json", needle)


def test_missing_clip_and_missing_keypoints(clip, tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "not found")
    (clip / "keypoints2d.json").unlink()
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "keypoints2d.json")


def test_debug_shows_the_traceback(tmp_path):
    with pytest.raises(ClipFormatError):
        main(["--debug", "run", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])


def test_an_unknown_camera_side_in_clip_json_is_a_clear_error(clip, tmp_path, capsys):
    doc = json.loads((clip / "clip.json").read_text())
    doc["camera_side"] = "left"
    (clip / "clip.json").write_text(json.dumps(doc))
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "clip.json", "'camera_side' must be auto, main or far")
    assert main(["calibrate", str(clip), "--out", str(tmp_path / "c")]) == 2
    _one_error_line(capsys, "clip.json", "camera_side")


def test_bench_validation_refuses_to_score_old_result_folders(tmp_path):
    """``bench validation --keep-outputs DIR`` never scores (or touches) a result folder that is
    already there: it stops before any run."""
    from probreg.bench.common import BenchReport
    from probreg.bench.validation import _run_sets

    clip = tmp_path / "clips" / "v99_old"
    clip.mkdir(parents=True)
    keep = tmp_path / "keep"
    (keep / "v99_old").mkdir(parents=True)
    (keep / "v99_old" / "angles.csv").write_text("old")
    rep = BenchReport("validation", "t")
    with pytest.raises(ValueError, match="already there"):
        _run_sets(rep, [("validation clips (test)", {}, [clip])], None, keep=keep)
    assert (keep / "v99_old" / "angles.csv").read_text() == "old"
    # nor the work folder of an old true-camera lifting
    old_lift = keep / "v98_old.true_camera" / "lift"
    old_lift.mkdir(parents=True)
    (old_lift / "angles.csv").write_text("old")
    other = tmp_path / "clips" / "v98_old"
    other.mkdir()
    with pytest.raises(ValueError, match="already there"):
        _run_sets(rep, [("validation clips (test)", {}, [other])], None, keep=keep)
    assert (old_lift / "angles.csv").read_text() == "old"


# ----------------------------------------------------------------------------- found by fuzzing (dev19)
@pytest.mark.parametrize("value", [5.5, True])
def test_a_frame_index_that_is_not_a_whole_number_is_a_clear_error(clip, tmp_path, capsys, value):
    doc = json.loads((clip / "keypoints2d.json").read_text())
    doc["frames"][5]["frame"] = value  # int() would have read 5 and 1 (a second frame 1) without a word
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "keypoints2d.json", "frames[5] has a non-integer frame index")


def _lift(clip, tmp_path, cameras, *extra):
    return main(["lift", str(clip), "--cameras", str(cameras), "--out", str(tmp_path / "o"), *extra])


@pytest.mark.parametrize("content, needle", [("[0.45, 0.43]", "expected an object of segment lengths"),
                                             ('{"thigh": 45, "shank": 43}', "'thigh' is 45 m long"),
                                             ('{"segments_m": {"shank": 430}}', "centimetres?"),
                                             ('{"thigh": "45"}', "'thigh' is 45 m long")])
def test_segment_files_that_are_no_lengths_in_metres_are_clear_errors(clip, tmp_path, capsys, content, needle):
    (tmp_path / "seg.json").write_text(content)  # a list used to end in an AttributeError traceback
    assert _lift(clip, tmp_path, clip / "groundtruth" / "cameras.json", "--segments", str(tmp_path / "seg.json")) == 2
    _one_error_line(capsys, "seg.json", needle)
    assert not (tmp_path / "o").exists()


def test_a_camera_below_the_track_is_a_clear_error(clip, tmp_path, capsys):
    doc = json.loads((clip / "groundtruth" / "cameras.json").read_text())
    doc["frames"][3]["C"][2] = -5.0  # used to lift every frame to NaN with exit 0
    (tmp_path / "cams.json").write_text(json.dumps(doc))
    assert _lift(clip, tmp_path, tmp_path / "cams.json") == 2
    _one_error_line(capsys, "cams.json", "frame 3: camera centre at z = -5 m, not above the track")


def test_lift_says_when_the_cameras_give_no_runner(clip, tmp_path, capsys):
    """Cameras that do not fit the clip (here all at one point beside the athlete) lift to legs a
    few centimetres long: said on stderr and in lift.json; the clip's own cameras say nothing."""
    cams = clip / "groundtruth" / "cameras.json"
    assert _lift(clip, tmp_path, cams) == 0
    assert "leg lengths" not in capsys.readouterr().err
    assert json.loads((tmp_path / "o" / "lift.json").read_text())["implausible_segments"] == []
    doc = json.loads(cams.read_text())
    for f in doc["frames"]:
        f["C"] = [0.0, 3.0, 1.0]
    (tmp_path / "cams.json").write_text(json.dumps(doc))
    assert _lift(clip, tmp_path, tmp_path / "cams.json", "--overwrite") == 0
    assert "warning: leg lengths no runner has (thigh 0.0" in capsys.readouterr().err
    odd = json.loads((tmp_path / "o" / "lift.json").read_text())["implausible_segments"]
    assert [s.split()[0] for s in odd] == ["thigh", "shank"]


def test_lift_with_no_frame_lifted_exits_3_with_its_files(clip, tmp_path, capsys):
    doc = json.loads((clip / "keypoints2d.json").read_text())
    for f in doc["frames"]:
        for j in range(1, 7):  # no hip, knee or ankle anywhere: no contact, no ground track
            if f["keypoints"] is not None:
                f["keypoints"][j][2] = 0.0
    (clip / "keypoints2d.json").write_text(json.dumps(doc))
    assert _lift(clip, tmp_path, clip / "groundtruth" / "cameras.json") == 3
    err = capsys.readouterr().err
    assert "Traceback" not in err and "no frame was lifted" in err
    status = json.loads((tmp_path / "o" / "lift.json").read_text())["frame_status"]
    assert len(status) == 40 and "ok" not in status


def test_a_report_file_no_benchmark_wrote_is_refused_before_the_benchmark(tmp_path, capsys, monkeypatch):
    """``probreg bench NAME --reports DIR``: a ``bench_NAME.md`` there that no benchmark wrote is kept
    and the benchmark does not run; a report of its own is replaced."""
    import probreg.bench.validation as bv

    calls = []
    monkeypatch.setattr(bv, "run", lambda args: calls.append(1) or bv.BenchReport("validation", "T"))
    reports = tmp_path / "reports"
    reports.mkdir()
    (reports / "bench_validation.md").write_text("# my own notes\n")
    assert main(["bench", "validation", "--reports", str(reports)]) == 2
    assert "was not written by a probreg benchmark" in capsys.readouterr().err and not calls
    assert (reports / "bench_validation.md").read_text() == "# my own notes\n"
    (reports / "bench_validation.md").unlink()
    for _ in range(2):  # written, then its own report replaced
        assert main(["bench", "validation", "--reports", str(reports)]) == 0
    assert calls == [1, 1] and (reports / "bench_validation.md").read_text().startswith("# T\n\nCommand: `probreg bench")
    assert sorted(p.name for p in reports.iterdir()) == ["bench_validation.md"]
