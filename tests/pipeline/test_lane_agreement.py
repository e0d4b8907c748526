"""A static camera explains every frame's lanes: a clip whose lanes mostly do not fit the camera
found says so in its verdict (``lanes_agree_frames``), with the per-frame statuses behind it."""

import json
import re

import pytest

from probreg.cli import main

FAST_RUN = ["--walkers", "20", "--max-steps", "300", "--draws", "8", "--seed", "1", "--quiet"]


@pytest.fixture(scope="module")
def cut_clip(tmp_path_factory):
    """60 frames of one run in which the broadcast cuts, for frames 20-39, to a second camera
    low and close (4 m up, 15 m away, instead of ~13 m and ~49 m) and back: no static camera
    explains the lanes of both, and the frames of one are bridged over lanes that do not admit
    the camera of the other.  (A low grazing tuning clip used to trigger this through its lanes'
    fits jumping between neighbouring lines; its lines are now measured right.)"""
    from dataclasses import replace

    from probreg.sim import config_from_preset, synthesize, write_clip

    root = tmp_path_factory.mktemp("cut")
    cfg = config_from_preset("run", 3, n_frames=60, image_size=(1280, 720))
    other = replace(cfg, camera=replace(cfg.camera, height_m=4.0, distance_m=15.0))
    write_clip(synthesize(cfg, seed=3, preset="run"), root / "cut", images=True, jobs=1)
    write_clip(synthesize(other, seed=3, preset="run"), root / "other", images=True, jobs=1)
    frames = sorted((root / "cut" / "frames").iterdir())
    for f in frames[20:40]:
        f.write_bytes((root / "other" / "frames" / f.name).read_bytes())
    return root / "cut"


def test_lanes_that_do_not_fit_the_camera_make_the_clip_unreliable(cut_clip, tmp_path):
    # taken as one camera (--shot all; by default the cuts at 20 and 40 are found and one shot
    # is estimated: tests/pipeline/test_camera_cuts.py), the lanes of the two cameras disagree
    out = tmp_path / "res"
    code = main(["run", str(cut_clip), "--out", str(out), "--shot", "all"] + FAST_RUN)
    run = json.loads((out / "run.json").read_text())
    assert code == 3 and run["verdict"] == "unreliable"
    assert run["shots"]["cuts"] == [20, 40]
    assert "camera cut at frames 20, 40 (taken as one camera)" in run["verdict_reasons"]
    found = [r for r in run["verdict_reasons"] if r.startswith("lanes_agree_frames")]
    assert len(found) == 1, run["verdict_reasons"]
    n, m = map(int, re.match(r"lanes_agree_frames (\d+)/(\d+)$", found[0]).groups())
    # the reason's numbers are the per-frame statuses: "ok" frames among those with a camera
    # and lanes of their own (the others bridged over lanes that do not fit)
    st = run["frame_status"]
    assert n == st.count("ok") and m == n + st.count("bridged_no_member") + st.count("bridged_inconsistent")
    assert n < 0.8 * m
