"""Lens-distortion sensitivity study (`probreg sensitivity`)."""

import json

import numpy as np
import pytest

from probreg.cli import main
from probreg.inference import SamplerSettings
from probreg.io import load_groundtruth, read_angles_csv
from probreg.pipeline import RunOptions
from probreg.sensitivity import corner_shift_px, distortion_study, parse_k1_list

FAST = SamplerSettings(n_walkers=20, burn_in=100, chunk=150, max_steps=600, n_draws=12, seed=1)


def test_study_compares_hypotheses_with_the_reference(small_clip, tmp_path):
    gt = load_groundtruth(small_clip)
    true = np.asarray(gt.cameras[0].dist, float)
    k_true = float(true[0])
    out = tmp_path / "sens"
    study = distortion_study(small_clip, out, [0.0, 0.3], RunOptions(sampler=FAST, dist=tuple(true), report=False),
                             log=lambda *a: None)
    # the nominal k1 (that of --dist) is the reference and is added to the runs
    assert np.isclose(study.reference_k1, k_true)
    assert [r["k1"] for r in study.rows] == sorted([0.0, 0.3, k_true])
    ref = study.row(k_true)
    for a in ref["angles"].values():
        assert a["mean_abs_change_deg"] == 0.0 and a["max_abs_change_deg"] == 0.0
    # every hypothesis is a complete result folder; its knee medians differ from the reference's
    # by exactly what the table says
    r = study.row(0.3)
    med = read_angles_csv(out / "k1_+0.300" / "angles.csv")["knee_r"][1]
    med_ref = read_angles_csv(out / f"k1_{k_true:+.3f}" / "angles.csv")["knee_r"][1]
    ok = np.isfinite(med) & np.isfinite(med_ref)
    assert np.isclose(np.mean(np.abs(med - med_ref)[ok]), r["angles"]["knee_r"]["mean_abs_change_deg"], atol=1e-3)
    assert r["angles"]["knee_r"]["mean_abs_change_deg"] > 0
    # the clip's lens is barrel (k1 < 0): undistorting with the true k1 leaves straighter lines than
    # a strong pincushion hypothesis, and the corner shifts carry the sign of k1
    assert ref["lane_straightness_px"] < r["lane_straightness_px"]
    assert ref["corner_shift_px"] < 0 < r["corner_shift_px"]
    doc = json.loads((out / "sensitivity.json").read_text())
    assert len(doc["rows"]) == 3 and (out / "sensitivity.csv").read_text().count("\n") == 4
    assert "Straightest lane lines under" in (out / "sensitivity.md").read_text()
    # the plumb-line check on a fine grid finds the barrel lens
    assert study.plumb_line["best_k1"] < -0.03


def test_plumb_line_curve_is_straightest_at_the_true_k1(distorted_lanes):
    from probreg.geometry import Camera
    from probreg.sensitivity import lane_straightness_curve

    cam = Camera.look_at([30.0, -25.0, 7.0], [45.0, -5.0, 0.5], fov_deg=30.0, dist=[-0.2, 0, 0, 0, 0])
    grid = np.round(np.arange(-0.4, 0.21, 0.05), 3)
    curve = lane_straightness_curve([distorted_lanes(cam)], [cam.focal_px], grid)
    assert grid[np.argmin(curve)] == -0.2 and curve.min() < 1e-3 < 0.1 < curve.max()


def test_corner_shift_known_answer():
    # r = 1101.6 / 1000 at the corner of a 1920x1080 frame: shift = f r^3 k1
    r = np.hypot(959.5, 539.5) / 1000.0
    assert np.isclose(corner_shift_px([0.05, 0, 0, 0, 0], 1000.0, (1920, 1080)), 1000.0 * r**3 * 0.05)
    assert np.isclose(corner_shift_px([0, 0.1, 0, 0, 0], 1000.0, (1920, 1080)), 1000.0 * r**5 * 0.1)


@pytest.mark.parametrize("text", ["", "1.5", "nan", "0.1,x"])
def test_bad_k1_lists_are_refused(text):
    with pytest.raises(ValueError, match="--k1"):
        parse_k1_list(text)


def test_sensitivity_command_bad_input(tmp_path, capsys):
    assert main(["sensitivity", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    cap = capsys.readouterr()
    assert "clip folder not found" in cap.err and "k1 =" not in cap.out  # refused before the first run
    assert not (tmp_path / "o").exists() and not list(tmp_path.glob(".o.tmp-*"))
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "clip.json").write_text('{"fps": "fast", "image_size": [640, 360]}')
    assert main(["sensitivity", str(bad), "--out", str(tmp_path / "o")]) == 2
    cap = capsys.readouterr()
    assert "clip.json" in cap.err and "'fps'" in cap.err and "k1 =" not in cap.out and not (tmp_path / "o").exists()
    assert main(["sensitivity", str(tmp_path), "--out", str(tmp_path / "o"), "--k1=0,abc"]) == 2
    assert "--k1" in capsys.readouterr().err
