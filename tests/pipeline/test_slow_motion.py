"""A slow-motion replay: its file states the rate it is played at, not the rate it was recorded
at.  Run as it is labelled, the clip is flagged (the runner bounces at a quarter of gravity);
given its slow-down, it runs in real time and its cadence is the runner's."""

import json

import numpy as np
import pytest

from probreg.cli import main

FAST_RUN = ["--walkers", "20", "--max-steps", "600", "--draws", "8", "--seed", "1", "--quiet"]
CAPTURE_FPS, PLAYED_FPS = 100.0, 50.0  # a 2x replay


@pytest.fixture(scope="module")
def replay(tmp_path_factory):
    """140 frames recorded at 100 fps (1.4 s: two strides), labelled 50 fps as the replay plays."""
    from dataclasses import replace

    from probreg.sim import config_from_preset, synthesize, write_clip

    base = config_from_preset("run", 21, image_size=(1280, 720))
    clip = write_clip(synthesize(replace(base, n_frames=140, fps=CAPTURE_FPS), seed=21, preset="run"),
                      tmp_path_factory.mktemp("replay") / "clip", images=True, jobs=1)
    meta = json.loads((clip / "clip.json").read_text())
    meta["fps"] = PLAYED_FPS
    (clip / "clip.json").write_text(json.dumps(meta))
    athlete = json.loads((clip / "groundtruth" / "athlete.json").read_text())
    return clip, 60.0 * athlete["gait"]["step_freq_hz"]


def _run(clip, out, *extra):
    code = main(["run", str(clip), "--out", str(out), *extra] + FAST_RUN)
    return code, json.loads((out / "run.json").read_text()), json.loads((out / "gait.json").read_text())


@pytest.fixture(scope="module")
def as_labelled(replay, tmp_path_factory):
    out = tmp_path_factory.mktemp("labelled") / "res"
    return (out, *_run(replay[0], out))


def test_a_replay_run_as_labelled_is_flagged_with_its_slow_down(replay, as_labelled):
    clip, cadence_true = replay
    out, code, run, gait = as_labelled
    tb = run["time_base"]
    assert code == 3 and run["verdict"] == "unreliable"
    assert tb["status"] == "slow" and tb["fps"] == PLAYED_FPS and tb["slow_motion"] == 1.0
    assert 1.5 < tb["factor"] < 2.7  # the true slow-down is 2
    assert tb["cadence_spm"] == pytest.approx(cadence_true / 2, rel=0.05)
    assert any(r.startswith("slow motion about") for r in run["verdict_reasons"])
    assert run["gait_verdict"] == "unreliable" and tb["reason"] in run["gait_verdict_reasons"]
    # the published cadence is the stride pattern's, half the runner's at the played rate, and the
    # time base marks it (and every other rate, time and speed) unreliable; a step length is not a rate
    assert gait["cadence_spm"]["source"] == "stride pattern"
    assert gait["cadence_spm"]["median"] == pytest.approx(cadence_true / 2, rel=0.05)
    assert gait["cadence_spm"]["status"] == gait["speed_mps"]["status"] == "unreliable"
    report = (out / "report.html").read_text()
    assert "Time base: 50 fps taken as real time" in report and "--slow-motion N" in report


def test_given_its_slow_down_the_replay_runs_in_real_time(replay, tmp_path):
    import csv

    clip, cadence_true = replay
    code, run, gait = _run(clip, tmp_path / "given", "--slow-motion", "2")
    tb = run["time_base"]
    assert tb["status"] == "ok" and tb["reason"] is None and tb["fps"] == CAPTURE_FPS and tb["slow_motion"] == 2.0
    assert 0.7 < tb["factor"] < 1.35 and not any("motion" in r for r in run["verdict_reasons"])
    assert tb["cadence_spm"] == pytest.approx(cadence_true, rel=0.05)
    assert any(n.startswith("slow motion 2x: 50 fps played, 100 fps") for n in run["input_notes"])
    with open(tmp_path / "given" / "angles.csv", encoding="utf-8") as fh:
        rows = [(int(r["frame"]), float(r["time_s"])) for r in csv.DictReader(fh)]
    assert all(t == pytest.approx(f / CAPTURE_FPS, abs=1e-4) for f, t in rows)  # the files' time is real time
    assert "slow motion" not in json.dumps(gait)
    assert gait["cadence_spm"]["median"] == pytest.approx(cadence_true, rel=0.03)  # the stride pattern's
    assert gait["cadence_spm"]["status"] == "ok" and gait["cadence_spm"]["source"] == "stride pattern"


def test_the_replay_benchmark_scores_a_result_against_the_truth(replay, as_labelled):
    from probreg.bench.replays import score_replay

    clip, cadence_true = replay
    s = score_replay(clip, as_labelled[0])
    assert s["status"] == "slow" and s["cadence_true_spm"] == pytest.approx(cadence_true)
    assert s["pattern_cadence_spm"] == pytest.approx(cadence_true / 2, rel=0.05)
    assert 0 < s["knee_deg"] < 15 and s["verdict"] == "unreliable"


def test_lift_takes_the_slow_down_too(replay, tmp_path):
    import csv

    clip, _ = replay
    out = tmp_path / "lifted"
    assert main(["lift", str(clip), "--cameras", str(clip / "groundtruth" / "cameras.json"), "--segments",
                 str(clip / "groundtruth" / "athlete.json"), "--out", str(out), "--slow-motion", "2"]) == 0
    with open(out / "angles.csv", encoding="utf-8") as fh:
        rows = [(int(r["frame"]), float(r["time_s"])) for r in csv.DictReader(fh)]
    assert rows and all(t == pytest.approx(f / CAPTURE_FPS, abs=1e-4) for f, t in rows)
    assert main(["lift", str(clip), "--cameras", str(clip / "groundtruth" / "cameras.json"), "--out",
                 str(tmp_path / "bad"), "--slow-motion", "-1"]) == 2


def test_a_stream_that_repeats_its_frames_is_flagged(replay, tmp_path):
    """The replay's frames given twice each (as 25 fps content is carried in a 50 fps stream):
    the clip's keypoints repeat every other frame, and the verdict says so."""
    import shutil

    clip, _ = replay
    dup = tmp_path / "doubled"
    (dup / "frames").mkdir(parents=True)
    frames = sorted((clip / "frames").iterdir())[:70]
    for i, f in enumerate(frames):
        for k in (0, 1):
            shutil.copy(f, dup / "frames" / f"{2 * i + k:06d}.jpg")
    kp = json.loads((clip / "keypoints2d.json").read_text())
    kp["frames"] = [dict(fr, frame=2 * i + k) for i, fr in enumerate(kp["frames"][:70]) for k in (0, 1)]
    (dup / "keypoints2d.json").write_text(json.dumps(kp))
    meta = json.loads((clip / "clip.json").read_text())
    (dup / "clip.json").write_text(json.dumps({**meta, "fps": 2 * CAPTURE_FPS, "n_frames": 140}))
    code, run, _ = _run(dup, tmp_path / "res")
    tb = run["time_base"]
    assert code == 3 and tb["repeated_frames"] >= 65 and tb["frame_pairs"] <= 139
    assert any(r.startswith("repeated frames (") for r in run["verdict_reasons"])


def test_a_kept_output_note_of_someone_else_is_never_overwritten(tmp_path):
    from probreg.bench.cuts import _run_kept

    (tmp_path / "x.bench.json").write_text('{"mine": 1}')
    with pytest.raises(FileExistsError, match="not a note of this benchmark"):
        _run_kept(tmp_path / "clip", tmp_path / "x", ())
    assert (tmp_path / "x.bench.json").read_text() == '{"mine": 1}'
