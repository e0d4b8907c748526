"""Clip-level registration and the `probreg calibrate` command."""

import json

import numpy as np

from probreg.calibration import register_clip
from probreg.cli import main
from probreg.geometry import Camera
from probreg.io import load_clip, load_groundtruth, read_cameras_json


def test_registration_at_true_height_matches_groundtruth(small_clip):
    clip = load_clip(small_clip)
    gt = load_groundtruth(small_clip)
    reg = register_clip(clip)
    h = gt.cameras[0].C[2]
    cams, info = reg.cameras(h, clip.keypoints_px, clip.athlete_lane, dist=gt.cameras[0].dist)
    got = [(c, g) for c, g in zip(cams, gt.cameras) if c is not None]
    assert len(got) >= 36
    fov_err = np.array([abs(c.fov_deg - g.fov_deg) for c, g in got])
    loc_err = np.array([np.linalg.norm((c.C - g.C)[1:]) for c, g in got])
    dist = np.linalg.norm(gt.cameras[0].C[:2] - gt.joints3d_track_m[0, 0, :2])
    assert np.median(fov_err) < 0.1
    assert np.median(loc_err) < 0.01 * dist          # lateral position incl. the right lane index
    assert len(info["frame_status"]) == clip.n_frames


def test_calibrate_command_writes_format(small_clip, tmp_path):
    gt = load_groundtruth(small_clip)
    out = tmp_path / "cal"
    dist = ",".join(f"{v:.6f}" for v in gt.cameras[0].dist)
    assert main(["calibrate", str(small_clip), "--out", str(out), "--height-m", f"{gt.cameras[0].C[2]:.4f}",
                 f"--dist={dist}"]) == 0
    doc = json.loads((out / "camera.json").read_text())
    assert set(doc["height_m"]) == {"median", "lo", "hi"}
    assert len(doc["frames"]) == 40 and "fov_deg" in doc["frames"][0]
    cams = read_cameras_json(out / "camera.json")
    assert sum(c is not None for c in cams.values()) >= 36
    lanes = json.loads((out / "lanes.json").read_text())
    assert lanes["frames"][0]["status"] == "ok" and len(lanes["frames"][0]["lines"]) >= 3
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["height_source"] == "given"


def test_calibrate_without_height_uses_documented_default(small_clip, tmp_path):
    out = tmp_path / "cal"
    assert main(["calibrate", str(small_clip), "--out", str(out)]) == 0
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["height_source"] == "default" and cal["height_m"] == 12.0


def test_calibrate_bad_input(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    clip = tmp_path / "noframes"
    clip.mkdir()
    (clip / "clip.json").write_text('{"fps": 50, "image_size": [1920, 1080], "n_frames": 3}')
    assert main(["calibrate", str(clip), "--out", str(tmp_path / "o")]) == 2
    assert "no frames" in capsys.readouterr().err
    assert main(["calibrate", str(clip), "--out", str(tmp_path / "o"), "--dist", "1,2"]) == 2


def test_frames_without_lanes_get_a_status_not_a_crash(small_clip, tmp_path):
    import shutil

    import cv2

    clip_dir = tmp_path / "clip"
    shutil.copytree(small_clip, clip_dir)
    for i in (5, 6, 7):  # blank frames: no lanes
        p = clip_dir / "frames" / f"{i:06d}.jpg"
        cv2.imwrite(str(p), np.full((1080, 1920, 3), 90, np.uint8))
    (clip_dir / "frames" / "000009.jpg").write_bytes(b"not a jpeg")
    out = tmp_path / "cal"
    assert main(["calibrate", str(clip_dir), "--out", str(out)]) == 0
    cal = json.loads((out / "calibration.json").read_text())
    assert [cal["frame_status"][i] for i in (5, 6, 7, 9)] == ["no_lines"] * 3 + ["bad_image"]
    cams = json.loads((out / "camera.json").read_text())["frames"]
    assert cams[5]["K"] is None and cams[0]["K"] is not None


def test_slipped_line_identities_are_repaired(small_clip):
    """Followed lines that swap identities with their neighbours half-way through a clip must
    not move the static camera sideways by a lane."""
    from dataclasses import replace

    clip = load_clip(small_clip)
    gt = load_groundtruth(small_clip)
    reg = register_clip(clip)
    h = gt.cameras[0].C[2]
    ref = [ln.track_id for ln in sorted(reg.frame_lanes[19].lines, key=lambda ln: ln.index)]
    slip = {a: b for a, b in zip(ref, ref[1:])}
    for t in range(20, len(reg.frame_lanes)):
        fl = reg.frame_lanes[t]
        lines = tuple(replace(ln, track_id=slip.get(ln.track_id, 1000 + ln.track_id)) for ln in fl.lines)
        reg.frame_lanes[t] = replace(fl, lines=lines)
    cams, _ = reg.cameras(h, clip.keypoints_px, clip.athlete_lane, dist=gt.cameras[0].dist)
    lateral = np.array([abs(c.C[1] - g.C[1]) for c, g in zip(cams, gt.cameras) if c is not None])
    assert len(lateral) >= 36 and np.all(lateral < 0.3)


def test_settling_pass_outvotes_short_runs_off_by_whole_lanes():
    """The second pass of track_offsets: frames whose lateral camera position is off by whole
    lanes from their neighbours' (indices handed on by one bad frame) are moved back."""
    from types import SimpleNamespace

    from probreg.calibration.registration import _settle_offsets

    rng = np.random.default_rng(4)
    lw = 1.22
    true_off = np.full(60, 3)
    y_true = -35.4 + rng.normal(0, 0.08, 60)  # the static camera, with per-frame jitter
    members = [SimpleNamespace(y_m=y + lw * o) for y, o in zip(y_true, true_off)]
    members[30] = None  # a frame without a member
    wrong = true_off.copy()
    wrong[40:44] += 8      # a short run that inherited wrong indices
    wrong[12] -= 1         # one slipped frame
    out = _settle_offsets(wrong, members, lw)
    ok = [t for t in range(60) if members[t] is not None]
    assert np.array_equal(out[ok], true_off[ok])
    assert out[30] == wrong[30]  # frames without a member are left alone


def test_glitch_frames_are_off_the_zoom_path_at_every_height(small_clip):
    """A frame is a glitch only when its family leaves the smooth zoom path whichever height
    is true; a frame that wanders at one (wrong) height only is not singled out."""
    from types import SimpleNamespace

    reg = register_clip(load_clip(small_clip))
    F = 60

    from probreg.calibration.family import SequenceCalibration

    class FakeSequence:
        families = [object()] * F
        focal_at_height = SequenceCalibration.focal_at_height  # the real one, on the fake members

        def members_at_height(self, h):
            f = 2000.0 * (h / 10.0) * np.exp(0.002 * np.arange(F))  # a smooth zoom
            f[[10, 25]] *= 1.3  # bad families: off the path at every height
            if h > 20:
                f[40] *= 1.3  # off the path at high heights only
            else:
                f[50] *= 1.3  # off the path at low heights, and beyond its family's reach above
            out = [SimpleNamespace(focal_px=v) for v in f]
            if h > 20:
                out[50] = None
            if h < 3:
                out[55] = None  # a frame whose branch ends below 3 m, on the path elsewhere
            return out

    reg.sequence = FakeSequence()
    reg._glitches = None
    # frame 50 has no member where it is not off the path: a frame with lanes but no member
    # at a height most frames reach does not vouch for its family; frame 55 is fine above 3 m
    assert reg.glitch_frames() == [10, 25, 50]


def test_zoom_path_follows_a_zoom_to_the_clips_ends():
    """A camera zooming steadily (or a height near the family's turning point, where the
    focal length drifts fast) is on its path in every frame, the clip's first and last
    frames included; a frame 5 % off that path is singled out wherever it lies."""
    from types import SimpleNamespace

    from probreg.calibration.registration import _zoom_outliers

    f = 3000.0 * np.exp(0.01 * np.arange(80)) * (1 + 0.001 * np.sin(np.arange(80)))
    assert _zoom_outliers([SimpleNamespace(focal_px=v) for v in f]) == []
    for bad in (0, 3, 40, 79):
        g = f.copy()
        g[bad] *= 1.05
        assert _zoom_outliers([SimpleNamespace(focal_px=v) for v in g]) == [bad]


def test_distortion_aware_family_recovers_the_camera(distorted_lanes):
    """Lines bent by a wide lens: the family of the distorted lines misses the true camera
    by percents; undistorting with every member's own focal length recovers it."""
    from probreg.calibration import CalibrationFamily, undistorted_members
    from probreg.lanes import line_straightness_px

    dist = np.array([-0.25, 0.03, 0.0, 0.0, 0.0])
    cam = Camera.look_at([30.0, -25.0, 7.0], [45.0, -5.0, 0.5], fov_deg=30.0, dist=dist)
    fl = distorted_lanes(cam)
    assert line_straightness_px(fl) > 0.3  # visibly bent
    fwd = cam.project(np.array([[50.0, -3.0, 0.0]]))[0] - cam.project(np.array([[40.0, -3.0, 0.0]]))[0]
    fam = CalibrationFamily.from_frame_lanes(fl, forward_px=fwd / np.linalg.norm(fwd), lane_width_m=1.22)
    f = np.array([cam.focal_px])
    naive = fam.members(f)
    good = undistorted_members(fl, fam, f, dist, forward_px=fwd / np.linalg.norm(fwd))
    assert good["valid"][0]
    assert abs(naive["height_m"][0] / cam.C[2] - 1) > 0.01
    assert abs(good["height_m"][0] / cam.C[2] - 1) < 0.002
    assert np.allclose(good["R"][0], cam.R, atol=2e-3)
    # the lateral position relative to line index 0 (lane line 1, y = -1.22)
    assert abs(good["y_m"][0] - (cam.C[1] + 1.22)) < 0.02 * abs(cam.C[1])
    # on a whole focal grid: the narrow branch alone gives the same members there, and at
    # focal lengths so long that the lens moves no point by 0.02 px, the bent lines' members
    # are the members
    grid = cam.focal_px * np.geomspace(0.5, 2000.0, 60)
    full = undistorted_members(fl, fam, grid, dist, forward_px=fwd / np.linalg.norm(fwd))
    narrow = undistorted_members(fl, fam, grid, dist, forward_px=fwd / np.linalg.norm(fwd), branch="narrow")
    top = int(np.nanargmax(np.where(full["valid"], full["height_m"], np.nan)))
    both = narrow["valid"][top:] & full["valid"][top:]
    assert both.mean() > 0.9
    assert np.allclose(narrow["height_m"][top:][both], full["height_m"][top:][both])
    assert not narrow["valid"][: max(top - 5, 0)].any()
    far = grid > 200 * cam.focal_px  # the corner moves by < 0.001 px
    plain = fam.members(grid[far])
    assert np.array_equal(full["height_m"][far], plain["height_m"])


def test_a_given_lens_straightens_the_lines_only_near_its_own_focal_length(distorted_lanes):
    """Plumb line: lines bent by a k1 = -0.25 lens at 30 deg, undistorted with that lens at
    a member's own focal length, are straight only near the true focal length; members well
    away from it (their undistorted lines are bent by pixels) are not cameras of this lens."""
    from probreg.calibration import CalibrationFamily, undistorted_members
    from probreg.lanes import line_straightness_px, undistort_frame_lanes

    dist = np.array([-0.25, 0.0, 0.0, 0.0, 0.0])
    cam = Camera.look_at([30.0, -25.0, 7.0], [45.0, -5.0, 0.5], fov_deg=30.0, dist=dist)
    fl = distorted_lanes(cam)
    fwd = cam.project(np.array([[50.0, -3.0, 0.0]]))[0] - cam.project(np.array([[40.0, -3.0, 0.0]]))[0]
    fwd = fwd / np.linalg.norm(fwd)
    fam = CalibrationFamily.from_frame_lanes(fl, forward_px=fwd, lane_width_m=1.22)
    ratios = np.array([0.5, 0.97, 1.0, 1.03])
    m = undistorted_members(fl, fam, cam.focal_px * ratios, dist, forward_px=fwd)
    bend = [line_straightness_px(undistort_frame_lanes(fl, dist, cam.focal_px * r, spacing=False))
            for r in ratios]
    assert bend[0] > 2.0 and max(bend[1:]) < 0.5  # the premise: over-corrected lines bend by pixels
    assert not m["valid"][0]
    assert m["valid"][1:].all()
    assert abs(m["height_m"][2] / cam.C[2] - 1) < 0.002


def test_lanes_followed_in_two_parts_equal_the_lanes_followed_in_one(small_clip, monkeypatch):
    """With a background worker the clip's second part is followed on its own, from a frame the one
    pass detects in full too, two warm-up frames early: every frame's status, lines, identities,
    colour change and family exactly as in one pass, the frames after the seam included (OpenCV's
    phase correlation windows its images in place, which the warm-up replays).  The result must not
    depend on the cores: ``probreg batch`` runs single-core, a ``probreg run`` on two cores splits.
    ``started`` runs once the background work is under way."""
    import probreg.calibration.registration as registration
    from probreg.inference.parallel import fork_call

    clip = load_clip(small_clip)
    one = register_clip(clip)
    monkeypatch.setattr(registration, "SPLIT_MIN_FRAMES", 20)
    calls = []
    two = register_clip(clip, background=fork_call, started=lambda: calls.append(1))
    assert calls == [1]
    mid = int(clip.n_frames * registration.SPLIT_SHARE) // 10 * 10
    assert 0 < mid < clip.n_frames - 2 and sum(fl.ok for fl in one.frame_lanes[mid:]) >= 0.9 * (clip.n_frames - mid)
    assert [fl.frame for fl in two.frame_lanes] == list(range(clip.n_frames))
    assert [fl.status for fl in one.frame_lanes] == [fl.status for fl in two.frame_lanes]
    for i, (a, b) in enumerate(zip(one.frame_lanes, two.frame_lanes)):
        assert [ln.track_id for ln in a.lines] == [ln.track_id for ln in b.lines], i
        for la, lb in zip(a.lines, b.lines):
            assert np.array_equal(la.line, lb.line) and np.array_equal(la.points_px, lb.points_px), i
        assert np.array_equal(a.extra["colour_change"], b.extra["colour_change"], equal_nan=True), i
    f = np.array([2500.0])
    heights = [(x.members(f)["height_m"][0], y.members(f)["height_m"][0])
               for x, y in zip(one.sequence.families, two.sequence.families) if x is not None and y is not None]
    assert len(heights) > 30 and all(x == y or (np.isnan(x) and np.isnan(y)) for x, y in heights)
