"""The camera's side of the track: decided by the athlete's motion, known answers both ways."""

from dataclasses import replace

import numpy as np
import pytest

from probreg.calibration import register_clip
from probreg.calibration.side import _ground_track_cue, camera_side_evidence
from probreg.io import load_clip, load_groundtruth


def test_ground_track_cue_reads_the_direction_of_motion(rng):
    t = np.arange(100) / 50.0
    stride = 0.05 * np.sin(2 * np.pi * 1.5 * t)[:, None]
    fwd = np.column_stack([7.0 * t, np.full_like(t, -3.0)]) + stride + rng.normal(0, 0.05, (100, 2))
    assert _ground_track_cue(fwd, 50.0)["llr"] > 20
    back = fwd * [-1, 1]
    assert _ground_track_cue(back, 50.0)["llr"] < -20
    still = np.column_stack([rng.normal(0, 0.05, 100), np.zeros(100)])
    assert abs(_ground_track_cue(still, 50.0)["llr"]) < np.log(20)
    assert _ground_track_cue(np.full((100, 2), np.nan), 50.0)["llr"] == 0.0


def test_no_evidence_and_a_given_side():
    kp = np.full((40, 17, 3), np.nan)
    side = camera_side_evidence(np.full((40, 2), np.nan), kp, 50.0)
    assert side.log_ratio == 0.0 and side.source == "evidence"
    given = camera_side_evidence(np.full((40, 2), np.nan), kp, 50.0, given="far")
    assert given.chosen == "far" and given.source == "given"
    with pytest.raises(ValueError, match="auto, main or far"):
        camera_side_evidence(np.full((40, 2), np.nan), kp, 50.0, given="left")


@pytest.fixture(scope="module")
def infield_clip(tmp_path_factory):
    """A 40-frame rendered clip filmed from across the infield (runner goes right to left)."""
    from probreg.sim import config_from_preset, synthesize, write_clip

    cfg = config_from_preset("run", 11, n_frames=40)
    cfg = replace(cfg, camera=replace(cfg.camera, infield=True, distance_m=70.0, height_m=15.0))
    out = tmp_path_factory.mktemp("infield") / "clip"
    write_clip(synthesize(cfg, seed=11), out, images=True, jobs=1)
    return out


def test_a_camera_across_the_infield_is_placed_on_the_far_side(infield_clip):
    clip = load_clip(infield_clip)
    gt = load_groundtruth(infield_clip)
    assert gt.cameras[0].C[1] > 0  # the generator put it across the infield
    reg = register_clip(clip)
    side = reg.orient(12.0, clip.keypoints_px, fps=clip.fps)
    assert side.chosen == "far" and side.log_ratio > np.log(1000)
    assert side.cues["ground_track"]["llr"] < 0 and side.cues["knee_fold"]["llr"] < 0
    h = float(gt.cameras[0].C[2])
    cams, _ = reg.cameras(h, clip.keypoints_px, clip.athlete_lane)
    err = [np.linalg.norm((c.C - g.C)[1:]) / abs(g.C[1]) for c, g in zip(cams, gt.cameras) if c is not None]
    assert len(err) > 30 and np.median(err) < 0.03  # as well placed as a main-side camera


def test_a_main_side_camera_stays_on_the_main_side(small_clip):
    clip = load_clip(small_clip)
    gt = load_groundtruth(small_clip)
    reg = register_clip(clip)
    side = reg.orient(12.0, clip.keypoints_px, fps=clip.fps)
    assert side.chosen == "main" and side.log_ratio > np.log(1000)
    cams, _ = reg.cameras(float(gt.cameras[0].C[2]), clip.keypoints_px, clip.athlete_lane,
                          dist=gt.cameras[0].dist)
    assert all(c.C[1] < 0 for c in cams if c is not None)


def test_the_user_can_override_the_side(infield_clip):
    clip = load_clip(infield_clip)
    reg = register_clip(clip)
    side = reg.orient(12.0, clip.keypoints_px, fps=clip.fps, given="main")
    assert side.chosen == "main" and side.source == "given"
    assert side.cues["knee_fold"]["llr"] < 0  # the evidence is still reported


def test_a_branch_copy_is_oriented_and_branched_on_its_own(infield_clip):
    """``ClipRegistration.branch_copy``, on which each family branch is built (one copy each, the
    original left for the branch that wins): orienting the copy on a branch leaves the original as
    it was, the frozen lane measurements are shared, and the original oriented afterwards gives
    the copy's cameras."""
    clip = load_clip(infield_clip)
    reg = register_clip(clip)
    forward, sequence = reg.forward_px.copy(), reg.sequence
    dup = reg.branch_copy()
    assert dup.frame_lanes is reg.frame_lanes and dup.sequence is not reg.sequence
    assert dup.orient(12.0, clip.keypoints_px, "wide", fps=clip.fps).chosen == "far"
    assert reg.sequence is sequence and sequence.branch == "narrow" and np.array_equal(reg.forward_px, forward)
    assert not np.array_equal(dup.forward_px, forward) and not getattr(reg, "_oriented", False)
    reg.orient(12.0, clip.keypoints_px, "wide", fps=clip.fps)
    a, b = reg.cameras(12.0, branch="wide")[0], dup.cameras(12.0, branch="wide")[0]
    assert [c is None for c in a] == [c is None for c in b] and sum(c is not None for c in a) > 30
    assert all(np.allclose(x.C, y.C) and np.allclose(x.R, y.R) for x, y in zip(a, b) if x is not None)
