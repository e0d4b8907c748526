"""Video in (`probreg run VIDEO --model M`), the configuration file and the progress bars."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from probreg.cli import main
from probreg.config import CONFIG_KEYS, ConfigError, default_config_toml, read_config
from probreg.io import load_clip, read_keypoints_json
from probreg.pipeline import probe_video


def _write_mp4(clip_dir, path, n=None):
    frames = sorted((clip_dir / "frames").glob("*.jpg"))[:n]
    first = cv2.imread(str(frames[0]))
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 50.0, (first.shape[1], first.shape[0]))
    if not vw.isOpened():
        pytest.skip("OpenCV here cannot write mp4")
    for f in frames:
        vw.write(cv2.imread(str(f)))
    vw.release()
    return path


@pytest.fixture(scope="module")
def video(small_clip, tmp_path_factory):
    return _write_mp4(small_clip, tmp_path_factory.mktemp("video") / "race.mp4")


# ----------------------------------------------------------------------------- the configuration file
def test_default_config_round_trips_to_the_defaults(tmp_path):
    p = tmp_path / "probreg.toml"
    p.write_text(default_config_toml())
    values = read_config(p)
    assert values["stature"] == 1.8 and values["walkers"] == 24 and values["camera_side"] == "auto"
    assert values["dist"] is None and values["model"] is None  # [] and "" mean "not given"
    assert {k.dest for k in CONFIG_KEYS} == set(values)


def test_a_config_saved_with_a_byte_order_mark_reads_the_same(tmp_path):
    p = tmp_path / "probreg.toml"
    p.write_bytes(b"\xef\xbb\xbf" + "[priors]\nstature_m = 1.62\n".encode())
    assert read_config(p) == {"stature": 1.62}


@pytest.mark.parametrize("text, needle", [
    ("[priors]\nstature_m = 'tall'\n", "[priors] stature_m must be a number"),
    ("[priors]\nheight = 3\n", "unknown key 'height' in [priors]"),
    ("[nonsense]\nx = 1\n", "unknown section [nonsense]"),
    ("[lens]\ndist = [0.1, 0]\n", "five numbers"),
    ("[lens]\ndist = [nan, 0, 0, 0, 0]\n", "all finite, got [nan, 0, 0, 0, 0]"),
    ("[camera]\nside = 'left'\n", "'auto', 'main' or 'far'"),
    ("[camera]\nshot = 'first'\n", "'longest', 'all' or a shot's number"),
    ("[priors\n", "not valid TOML"),
    ("[priors]\ncamera_height_allowance = -0.1\n", "camera_height_allowance must be a finite number >= 0"),
    ("[camera]\nslow_motion = 0\n", "slow_motion must be a positive factor"),
    ("[sampler]\nseed = -1\n", "[sampler] seed must be a whole number >= 0"),
    ("[detection]\nmin_score = 30\n", "[detection] min_score must be a confidence between 0 and 1"),
])
def test_bad_config_names_file_and_key(tmp_path, text, needle, capsys):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as exc:
        read_config(p)
    assert needle in str(exc.value) and "c.toml" in str(exc.value)
    assert main(["run", "x", "--out", str(tmp_path / "o"), "--config", str(p)]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err


@pytest.mark.parametrize("flag, needle", [
    (["--seed", "-1"], "argument --seed: must be a whole number >= 0, got '-1'"),
    (["--min-score", "30"], "argument --min-score: must be a confidence between 0 and 1, got '30'"),
])
def test_flags_out_of_range_are_named_before_anything_runs(tmp_path, flag, needle, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", str(tmp_path), "--out", str(tmp_path / "o"), *flag])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and needle in err and not (tmp_path / "o").exists()


def test_flags_override_the_config_which_overrides_the_defaults(tmp_path, monkeypatch):
    import probreg.pipeline as pipeline

    seen = {}

    def fake_run_source(source, out, options, **kw):
        seen["options"], seen["kw"] = options, kw
        raise KeyboardInterrupt  # stop before any work

    monkeypatch.setattr(pipeline, "run_source", fake_run_source)
    cfg = tmp_path / "c.toml"
    cfg.write_text("[priors]\nstature_m = 1.62\nstature_sd = 0.03\n[sampler]\ndraws = 7\nwalkers = 30\n"
                   "[lens]\ndist = [-0.1, 0, 0, 0, 0]\n[camera]\nside = 'far'\nshot = '1'\n"
                   "[detection]\nmodel = 'pose.onnx'\n")
    assert main(["run", "clip", "--out", str(tmp_path / "o"), "--config", str(cfg), "--walkers", "40"]) == 130
    o = seen["options"]
    assert o.priors.stature.mean == 1.62 and o.priors.stature.sd == 0.03
    assert o.sampler.n_draws == 7 and o.sampler.n_walkers == 40  # the flag wins
    assert list(o.dist) == [-0.1, 0, 0, 0, 0] and o.camera_side == "far" and o.shot == "1"
    assert seen["kw"]["model"] == Path("pose.onnx")


def test_config_command_writes_the_default_and_never_overwrites(tmp_path, capsys):
    out = tmp_path / "probreg.toml"
    assert main(["config", "--out", str(out)]) == 0
    assert out.read_text() == default_config_toml()
    out.write_text("mine")
    assert main(["config", "--out", str(out)]) == 2
    assert out.read_text() == "mine"
    assert main(["config", "--out", str(out), "--overwrite"]) == 0  # the edited one is moved aside, not lost
    assert out.read_text() == default_config_toml()
    assert [p.read_text() for p in tmp_path.glob("probreg.toml.previous-*")] == ["mine"]
    assert main(["config", "--out", str(out)]) == 0  # the default again: nothing to lose
    assert main(["config"]) == 0 and "[priors]" in capsys.readouterr().out


# ----------------------------------------------------------------------------- video in
def test_probe_video_and_clear_errors(video, tmp_path):
    fps, size, n = probe_video(video)
    assert fps == 50.0 and size == (1920, 1080) and n == 40
    with pytest.raises(ValueError, match="no such video"):
        probe_video(tmp_path / "none.mp4")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video at all")
    with pytest.raises(ValueError, match="cannot open the video|no decodable frames"):
        probe_video(bad)


def test_a_video_needs_a_model(video, tmp_path, capsys):
    assert main(["run", str(video), "--out", str(tmp_path / "o")]) == 2
    assert "--model" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_video_to_result_in_one_command(video, small_clip, tmp_path, monkeypatch, capsys):
    """The video path: decode, detection (here: the clip's own keypoints stand in for a pose model,
    whose decoding tests/detect covers), the pipeline, and the result folder with the detections."""
    import probreg.pipeline as pipeline

    truth = load_clip(small_clip).keypoints_px
    calls = {}

    def fake_detect(clip, model_path, det_model=None, athlete=None, min_score=0.3, progress=None):
        calls["n_frames"], calls["athlete"] = clip.n_frames, athlete
        assert clip.video_path is not None and clip.fps == 50.0
        bar = progress("detection", clip.n_frames) if progress else None
        if bar:
            bar.update(clip.n_frames)
            bar.close()
        return truth

    monkeypatch.setattr(pipeline, "detect_athlete", fake_detect)
    out = tmp_path / "res"
    code = main(["run", str(video), "--out", str(out), "--model", str(tmp_path / "m.onnx"), "--athlete", "900,500",
                 "--walkers", "20", "--max-steps", "600", "--draws", "12", "--dist=-0.12,0,0,0,0"])
    assert code in (0, 3)
    assert calls == {"n_frames": 40, "athlete": [900.0, 500.0]}
    for name in ("angles.csv", "markers.trc", "angles.mot", "gait_cycle.csv", "report.html", "keypoints2d.json",
                 "input_clip.json", "run.json"):
        assert (out / name).exists(), name
    assert np.allclose(read_keypoints_json(out / "keypoints2d.json"), truth, equal_nan=True)
    meta = json.loads((out / "input_clip.json").read_text())
    assert meta["fps"] == 50.0 and meta["n_frames"] == 40 and meta["source"]["video"] == str(video)
    assert video.exists() and video.stat().st_size > 0  # the input is untouched
    err = capsys.readouterr().err
    assert "detection" in err and "sampling" in err and "Traceback" not in err  # progress bars on stderr


def test_detect_athlete_decodes_the_video_with_an_onnx_model(video, tmp_path):
    pytest.importorskip("onnx")
    from tests.detect.test_detect import _constant_model, _yolo_output

    from probreg.pipeline import detect_athlete

    kp = np.column_stack([np.full(17, 320.0), np.linspace(200, 400, 17), np.full(17, 0.9)])
    model = _constant_model(tmp_path / "y.onnx", (1, 3, 640, 640),
                            {"output0": _yolo_output([(320, 300, 60, 220, 0.9, kp)])})
    clip_dir = tmp_path / "clip"
    clip_dir.mkdir()
    (clip_dir / "video.mp4").symlink_to(video)
    (clip_dir / "clip.json").write_text(json.dumps({"fps": 50.0, "image_size": [1920, 1080], "n_frames": 40}))
    h36m = detect_athlete(load_clip(clip_dir), model)
    assert h36m.shape == (40, 17, 3) and np.isfinite(h36m[:, :, 0]).all()
    with pytest.raises(ValueError, match="x,y .* or x0,y0,x1,y1"):
        detect_athlete(load_clip(clip_dir), model, athlete=[1, 2, 3])


def test_the_height_allowance_is_an_option_everywhere_with_one_default(tmp_path, capsys):
    """``--height-allowance`` (CLI), ``[priors] camera_height_allowance`` (config file) and the
    ``height_allowance`` manifest column all default to the model's constant and reach
    RunOptions; a negative value is refused with a message that names the flag."""
    from probreg.batch import DEFAULTS, _run_options as batch_options
    from probreg.cli import _run_options, build_parser
    from probreg.inference.heights import HEIGHT_SYSTEMATIC_SD
    from probreg.pipeline import RunOptions

    assert RunOptions().height_allowance == HEIGHT_SYSTEMATIC_SD
    args = build_parser().parse_args(["run", "clip", "--out", str(tmp_path / "o")])
    assert args.height_allowance == HEIGHT_SYSTEMATIC_SD
    args = build_parser().parse_args(["run", "clip", "--out", str(tmp_path / "o"), "--height-allowance", "0"])
    assert _run_options(args).height_allowance == 0.0
    assert DEFAULTS["height_allowance"] == HEIGHT_SYSTEMATIC_SD
    assert batch_options({**DEFAULTS, "height_allowance": 0.02}).height_allowance == 0.02
    with pytest.raises(ValueError, match="height_allowance"):
        batch_options({**DEFAULTS, "height_allowance": -0.01})
    p = tmp_path / "probreg.toml"
    p.write_text("[priors]\ncamera_height_allowance = 0.0\n")
    assert read_config(p)["height_allowance"] == 0.0
    with pytest.raises(SystemExit) as exc:
        main(["run", "clip", "--out", str(tmp_path / "o"), "--height-allowance", "-1"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--height-allowance" in err and "must be a finite number >= 0" in err
    assert not (tmp_path / "o").exists()


def test_the_slow_motion_factor_is_an_option_everywhere(tmp_path):
    """``--slow-motion`` (CLI), ``[camera] slow_motion`` (config) and the manifest column reach
    RunOptions with one default, real time."""
    from probreg.batch import DEFAULTS, _run_options as batch_options
    from probreg.cli import _run_options, build_parser
    from probreg.pipeline import RunOptions

    assert RunOptions().slow_motion == 1.0 == DEFAULTS["slow_motion"]
    args = build_parser().parse_args(["run", "clip", "--out", str(tmp_path / "o"), "--slow-motion", "4"])
    assert _run_options(args).slow_motion == 4.0
    assert batch_options({**DEFAULTS, "slow_motion": 2.5}).slow_motion == 2.5
    p = tmp_path / "probreg.toml"
    p.write_text("[camera]\nslow_motion = 3\n")
    assert read_config(p)["slow_motion"] == 3.0


@pytest.mark.parametrize("command, needle", [
    (["calibrate", "--dist=nan,0,0,0,0"], "--dist (k1,k2,p1,p2,k3) needs 5 finite comma-separated numbers, got 'nan,0,0,0,0'"),
    (["run", "--dist=0.1,inf,0,0,0"], "--dist (k1,k2,p1,p2,k3) needs 5 finite comma-separated numbers, got '0.1,inf,0,0,0'"),
    (["run", "--athlete", "nan,300"], "needs 2 finite comma-separated numbers, got 'nan,300'"),
    (["calibrate", "--dist=0.1,0"], "--dist (k1,k2,p1,p2,k3) needs 5 finite comma-separated numbers, got '0.1,0'"),
    (["run", "--dist=k1"], "--dist (k1,k2,p1,p2,k3) needs 5 finite comma-separated numbers, got 'k1'"),
])
def test_numbers_that_are_not_finite_are_named_before_anything_runs(small_clip, tmp_path, command, needle, capsys):
    """``nan`` and ``inf`` parse as floats; a lens coefficient or an image point that is one used to
    reach the lane step (calibrate: 0 of 80 frames calibrated, no word why)."""
    out = tmp_path / "o"
    assert main([command[0], str(small_clip), "--out", str(out), *command[1:]]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not out.exists()  # refused before any output
