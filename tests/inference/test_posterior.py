"""Known-answer tests of the Bayesian model and the `probreg run` pipeline (short chains)."""

import json
import shutil
from dataclasses import replace

import cv2
import numpy as np
import pytest

from probreg.calibration import register_clip
from probreg.cli import main
from probreg.filtering import noise_model
from probreg.inference import (
    PARAM_NAMES,
    ClipModel,
    LogNormalPrior,
    ModelPriors,
    NormalPrior,
    SamplerSettings,
)
from probreg.geometry import JOINT_INDEX
from probreg.io import load_clip, load_groundtruth, read_angles_csv
from probreg.io.opensim import read_mot, read_trc
from probreg.io.results import read_gait_cycle_csv
from probreg.pipeline import RunOptions, run_clip

FAST = SamplerSettings(n_walkers=20, burn_in=100, chunk=150, max_steps=600, n_draws=12, seed=1)


@pytest.fixture(scope="module")
def model(small_clip):
    clip = load_clip(small_clip)
    gt = load_groundtruth(small_clip)
    reg = register_clip(clip)
    priors = ModelPriors.from_options(stature=gt.athlete["stature_m"], stature_sd=0.02)
    return ClipModel(reg, clip.keypoints_px, clip.fps, clip.athlete_lane, priors=priors,
                     dist=gt.cameras[0].dist), gt


def test_posterior_covers_the_known_height_and_lengths(model):
    m, gt = model
    sampler, tau = m.sample(FAST)
    chain = sampler.get_chain(flat=True)
    h = np.exp(chain[:, 0])
    h_true = gt.cameras[0].C[2]
    lo, hi = np.percentile(h, [2.5, 97.5])
    assert lo <= h_true <= hi or abs(np.median(h) - h_true) / h_true < 0.05
    L = m.lengths(chain)
    for seg in ("thigh", "shank"):
        assert abs(np.median(L[seg]) - gt.athlete["segments_m"][seg]) < 0.06
    acc = np.mean(sampler.acceptance_fraction)
    assert 0.15 < acc < 0.8
    assert np.all(np.isfinite(tau)) and tau.shape == (len(PARAM_NAMES),)


def test_prior_only_run_recovers_the_prior(model, monkeypatch):
    m, _ = model
    monkeypatch.setattr(m, "log_likelihood", lambda theta: np.zeros(len(np.atleast_2d(theta))))
    m.priors = ModelPriors()  # defaults: stature N(1.80, 0.16), camera height log-normal(9 m, 0.8)
    sampler, _ = m.sample(SamplerSettings(n_walkers=24, burn_in=300, max_steps=1500, seed=2))
    chain = sampler.get_chain(flat=True)
    st = chain[:, 1]
    assert abs(st.mean() - 1.80) < 0.03 and 0.12 < st.std() < 0.20
    logh = chain[:, 0]
    assert abs(np.exp(np.median(logh)) - 9.0) < 1.0 and 0.65 < logh.std() < 0.95


def test_log_prob_is_vectorised_and_rejects_impossible_values(model):
    m, gt = model
    theta = np.tile(np.r_[np.log(gt.cameras[0].C[2]), 1.75, np.ones(7)], (5, 1))
    theta[1, 1] = -1.0      # negative stature
    theta[2, 0] = np.log(1e4)  # height outside the grid
    lp = m.log_prob(theta)
    assert lp.shape == (5,) and np.isfinite(lp[0]) and lp[1] == -np.inf and lp[2] == -np.inf
    assert np.isclose(lp[0], lp[3])


def _member_at(model, i, height_m):
    """Reference: the per-frame search the vectorised one replaced."""
    hh = model.h[i]
    ok = np.isfinite(hh)
    if ok.sum() < 2:
        return None
    hv = hh[ok]
    order = np.argsort(hv)
    hs = hv[order]
    if not hs[0] <= height_m <= hs[-1]:
        return None
    j = int(np.clip(np.searchsorted(hs, height_m), 1, len(hs) - 1))
    a, b = order[j - 1], order[j]
    t = (height_m - hv[a]) / (hv[b] - hv[a]) if hv[b] != hv[a] else 0.0
    idx = np.flatnonzero(ok)
    return idx[a], idx[b], t


def test_members_of_all_frames_at_once_match_the_per_frame_search(model):
    """The vectorised bracket search (cameras_at, _focal_at) gives every frame the grid members and
    weight a per-frame search gives."""
    model, _ = model
    lo, hi = model.height_range
    for h in np.geomspace(max(lo, 0.5) * 0.9, hi * 1.1, 9):
        ia, ib, t, ok = model._brackets(h)
        for i in range(model.F):
            at = _member_at(model, i, h)
            assert ok[i] == (at is not None)
            if at is not None:
                a, b, w = at
                fa = model.logf[i, a] + w * (model.logf[i, b] - model.logf[i, a])
                fb = model.logf[i, ia[i]] + t[i] * (model.logf[i, ib[i]] - model.logf[i, ia[i]])
                assert fa == pytest.approx(fb, abs=1e-12)


def test_noise_model_known_answer(rng):
    n = 4000
    e = np.zeros((n, 17, 2))
    w = rng.standard_normal((n, 17, 2))
    e[0] = w[0]
    for t in range(1, n):
        e[t] = 0.5 * e[t - 1] + np.sqrt(1 - 0.25) * w[t]
    kp = np.concatenate([3.0 * e, np.ones((n, 17, 1))], -1)
    sd, rho = noise_model(kp)
    assert abs(sd - 3.0) < 0.3 and abs(rho - 0.5) < 0.1


def test_priors_validate_and_report_intervals():
    with pytest.raises(ValueError, match="sd"):
        NormalPrior(1.7, 0.0)
    with pytest.raises(ValueError, match="median"):
        LogNormalPrior(-1.0, 0.5)
    p = ModelPriors.from_options(height=20.0)
    assert np.isclose(p.camera_height.centre(), 20.0)


def test_run_pipeline_writes_the_result_layout(small_clip, tmp_path):
    out = tmp_path / "res"
    gt = load_groundtruth(small_clip)
    res = run_clip(small_clip, out, RunOptions(sampler=FAST, dist=tuple(gt.cameras[0].dist)), log=lambda *a: None)
    for name in ("angles.csv", "joints3d.npz", "camera.json", "posterior.nc", "report.html", "gait.json",
                 "markers.trc", "angles.mot", "gait_cycle.csv"):
        assert (out / name).exists(), name
    # the OpenSim files hold the same numbers as the CLIP_FORMAT ones
    names, t, markers = read_trc(out / "markers.trc")
    med3d = np.load(out / "joints3d.npz")["median"]
    shank_trc = np.linalg.norm(markers[:, names.index("RKnee")] - markers[:, names.index("RAnkle")], axis=1)
    shank_npz = np.linalg.norm(med3d[:, JOINT_INDEX["r_knee"]] - med3d[:, JOINT_INDEX["r_ankle"]], axis=1)
    ok = np.isfinite(shank_npz)
    assert ok.mean() > 0.9 and np.max(np.abs(shank_trc[ok] - shank_npz[ok])) < 0.005
    assert np.allclose(t, np.arange(40) / 50.0)
    cols, tm, data = read_mot(out / "angles.mot")
    knee_csv = read_angles_csv(out / "angles.csv")["knee_r"]
    for k, col in enumerate(("knee_r", "knee_r_lo", "knee_r_hi")):
        assert np.allclose(data[:, cols.index(col)], knee_csv[1 + k], atol=1e-3, equal_nan=True)
    cyc = read_gait_cycle_csv(out / "gait_cycle.csv")
    for (angle, side), (pct, m, lo_c, hi_c) in cyc.items():
        assert len(pct) == 101 and pct[0] == 0 and pct[-1] == 100
        fin = np.isfinite(m)
        assert np.all(lo_c[fin] <= m[fin] + 1e-6) and np.all(m[fin] <= hi_c[fin] + 1e-6)
    ang = read_angles_csv(out / "angles.csv")
    frames, med, lo, hi = ang["knee_r"]
    ok = np.isfinite(med)
    assert ok.mean() > 0.9 and np.all(lo[ok] <= med[ok] + 1e-9) and np.all(med[ok] <= hi[ok] + 1e-9)
    assert np.mean(hi[ok] - lo[ok]) > 0.5  # a band, not a line
    npz = np.load(out / "joints3d.npz")
    assert npz["samples"].shape[0] == FAST.n_draws and npz["median"].shape == (40, 17, 3)
    cam = json.loads((out / "camera.json").read_text())
    assert cam["height_m"]["lo"] <= cam["height_m"]["median"] <= cam["height_m"]["hi"]
    run = json.loads((out / "run.json").read_text())
    priors = run["priors"]
    assert set(priors) == {"camera_height", "stature", "running_speed"}
    # the data's angle noise over the bootstrap's, for the angles the cross-stride smoothing ran
    # on: 40 frames are less than the 1.5 strides it needs, so none here (the bands as without)
    assert run["band_noise_ratio"] == {}
    assert priors["running_speed"] == "flat up to 12.5 m/s, half-normal of sd 0.5 m/s beyond"
    # the software that made the result (OpenCV's version changes the lane step's inputs)
    import cv2

    import probreg

    sw = run["software"]
    assert sw["probreg"] == probreg.__version__ and sw["numpy"] == np.__version__
    assert sw["opencv"].split(".")[:3] == cv2.__version__.split(".")[:3]
    # the gait verdict and each gait number's status agree (probreg.inference.gait_check)
    gait = json.loads((out / "gait.json").read_text())
    assert run["gait_verdict"] in ("ok", "unreliable")
    assert (run["gait_verdict"] == "ok") == (not run["gait_verdict_reasons"])
    assert gait["speed_mps"]["status"] == "ok" and gait["cadence_spm"]["status"] == run["gait_verdict"]
    for name, g in gait.items():  # every median inside its interval, none of the non-negative ones below 0
        if g["median"] is not None:
            assert g["lo"] <= g["median"] <= g["hi"], name
            assert name.endswith("_deg") or g["lo"] >= 0, name
    assert "cadence_stride_pattern_spm" in run["diagnostics"]  # NaN here: 40 frames hold no two strides
    terms = run["diagnostics"]["height_terms"]  # do the camera height's terms agree (inference.heights)
    assert {"conflict_nats", "threshold_nats", "temper", "peaks_m", "deficits_nats"} <= set(terms)
    assert (terms["temper"] < 1) == (terms["conflict_nats"] > terms["threshold_nats"])
    import arviz as az

    idata = az.from_netcdf(str(out / "posterior.nc"))
    assert {"chain", "draw"} <= set(idata.posterior.dims) and "height_m" in idata.posterior
    assert "keypoints_px" in idata.observed_data and "sample_stats" in idata.groups()
    assert res.diagnostics["steps"] >= 150
    # the report says what sets the metric scale (here: the default stature prior)
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "Metric scale:" in page
    # and what its angle bands leave out (keypoint bias, the elbows' mirror solution)
    import html

    from probreg.report.html import BANDS_LEAVE_OUT

    assert html.escape(BANDS_LEAVE_OUT) in page and "mirror image in depth" in page


def test_missing_lanes_still_give_a_posterior_with_wider_bands(small_clip, tmp_path):
    clip_dir = tmp_path / "clip"
    shutil.copytree(small_clip, clip_dir)
    blank = np.full((1080, 1920, 3), 90, np.uint8)
    for i in range(14, 27):
        cv2.imwrite(str(clip_dir / "frames" / f"{i:06d}.jpg"), blank)
    out = tmp_path / "res"
    gt = load_groundtruth(small_clip)
    run_clip(clip_dir, out, RunOptions(sampler=FAST, dist=tuple(gt.cameras[0].dist), report=False),
             log=lambda *a: None)
    status = json.loads((out / "run.json").read_text())["frame_status"]
    assert status[20] == "bridged" and status[5] == "ok"
    ang = read_angles_csv(out / "angles.csv")
    _, med, lo, hi = ang["knee_r"]
    assert np.all(np.isfinite(med[14:27]))  # bridged frames still get angles and bands
    # the camera of a bridged frame is uncertain: the athlete's position along the track
    # (one ray through an uncertain pan) scatters more in the middle of the gap.  Each draw's
    # smooth trend (set by its camera height) is removed first.
    x = np.load(out / "joints3d.npz")["samples"][:, :, 0, 0].astype(float)  # pelvis x, (S, F)
    t = np.arange(x.shape[1])
    resid = np.array([xs - np.polyval(np.polyfit(t, xs, 3), t) for xs in x])
    spread = np.std(resid, axis=0)
    assert np.mean(spread[18:23]) > 1.5 * np.median(spread[np.r_[0:12, 29:40]])
def test_run_command_bad_input(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    clip = tmp_path / "c"
    clip.mkdir()
    (clip / "clip.json").write_text('{"fps": 50, "image_size": [1920, 1080], "n_frames": 2}')
    assert main(["run", str(clip), "--out", str(tmp_path / "o")]) == 2
    assert "keypoints2d.json" in capsys.readouterr().err


def test_run_refuses_a_clip_without_detections(small_clip, tmp_path, capsys):
    clip_dir = tmp_path / "clip"
    shutil.copytree(small_clip, clip_dir)
    doc = json.loads((clip_dir / "keypoints2d.json").read_text())
    for f in doc["frames"]:
        f["keypoints"] = None
    (clip_dir / "keypoints2d.json").write_text(json.dumps(doc))
    assert main(["run", str(clip_dir), "--out", str(tmp_path / "o")]) == 2
    assert "detected athlete" in capsys.readouterr().err


def test_propagation_does_not_depend_on_the_number_of_workers(model, monkeypatch):
    """Every draw has its own random stream: forked workers give exactly the serial result,
    and where no process may be started the draws run in this one."""
    import multiprocessing

    m, gt = model
    h = gt.cameras[0].C[2]
    draws = np.column_stack([np.log(np.full(3, h)) + [0.0, 0.02, -0.02], np.full(3, gt.athlete["stature_m"]),
                             np.ones((3, len(PARAM_NAMES) - 2))])
    one = m.propagate(draws, np.random.default_rng(4), workers=1)
    two = m.propagate(draws, np.random.default_rng(4), workers=2)
    assert np.array_equal(one["joints"], two["joints"], equal_nan=True)
    assert np.array_equal(one["joints_point"], two["joints_point"], equal_nan=True)
    for k in one["angles"]:
        assert np.array_equal(one["angles"][k], two["angles"][k], equal_nan=True)
    assert one["gait"].keys() == two["gait"].keys()

    class NoProcesses:
        def Pool(self, n, **kwargs):  # as multiprocessing.Pool (initializer=...)
            raise OSError("no processes here")

    monkeypatch.setattr(multiprocessing, "get_context", lambda method: NoProcesses())
    fallback = m.propagate(draws, np.random.default_rng(4), workers=2)
    assert np.array_equal(one["joints"], fallback["joints"], equal_nan=True)
    # the bootstrap adds noise: the noisy liftings differ from the point liftings
    assert not np.allclose(one["joints"], one["joints_point"], equal_nan=True)


def test_draws_share_noise_copies_as_asked_and_workers_do_not_matter(model):
    """``draws_per_noise_copy``: identical draws that share a re-noised copy lift identically,
    with a copy each they differ; sharing does not make the result depend on the workers."""
    m, gt = model
    h = gt.cameras[0].C[2]
    same = np.tile(np.r_[np.log(h), gt.athlete["stature_m"], np.ones(len(PARAM_NAMES) - 2)], (4, 1))
    assert not np.any(m.gap_distance > 0)  # no bridged frames: no per-draw camera jitter here
    shared = m.propagate(same, np.random.default_rng(5), workers=1, draws_per_noise_copy=2)
    # draws 0 and 2 share copy 0, draws 1 and 3 copy 1 (draw s takes copy s mod 2)
    assert np.array_equal(shared["joints"][0], shared["joints"][2], equal_nan=True)
    assert np.array_equal(shared["joints"][1], shared["joints"][3], equal_nan=True)
    assert not np.allclose(shared["joints"][0], shared["joints"][1], equal_nan=True)
    own = m.propagate(same, np.random.default_rng(5), workers=1, draws_per_noise_copy=1)
    assert not np.allclose(own["joints"][0], own["joints"][2], equal_nan=True)
    two = m.propagate(same, np.random.default_rng(5), workers=2, draws_per_noise_copy=2)
    assert np.array_equal(shared["joints"], two["joints"], equal_nan=True)
    with pytest.raises(ValueError, match="draws_per_noise_copy"):
        m.propagate(same, np.random.default_rng(5), workers=1, draws_per_noise_copy=0)


def test_frame_status_says_how_each_camera_came_about():
    from probreg.lanes import FrameLanes
    from probreg.pipeline import _frame_status

    ok, none = FrameLanes(status="ok"), FrameLanes(status="no_lines")
    cam = object()
    assert _frame_status(ok, cam, False, 0) == "ok"
    assert _frame_status(ok, cam, False, 3) == "bridged_no_member"  # lanes, but no member at this height
    assert _frame_status(ok, cam, True, 3) == "bridged_inconsistent"
    assert _frame_status(none, cam, False, 2) == "bridged"
    assert _frame_status(none, None, False, 0) == "no_lines"
    assert _frame_status(ok, None, False, 0) == "no_member"
    assert _frame_status(ok, None, True, 0) == "inconsistent"  # off the zoom path at the clip's end


def test_with_a_known_lens_frames_are_judged_on_the_undistorted_families(tmp_path):
    """A 30 deg, k1 = -0.25 lens: the straight fits to bent lines depend on which part of each
    line a frame sees, so a full detection (every 10th frame) and the followed frames give
    slightly different distorted families, and the bent lines' zoom path singles out a
    correct frame.  The model judges its frames on its own, undistorted families: none is
    singled out, every frame keeps its own camera."""
    from probreg.bench.distortion import make_clip
    from probreg.calibration import register_clip

    clip = load_clip(make_clip("wide_k25", tmp_path / "wide", n_frames=60))
    gt = load_groundtruth(clip.path)
    reg = register_clip(clip)
    assert reg.glitch_frames()  # the bent lines' families do single out frames
    m = ClipModel(reg, clip.keypoints_px, clip.fps, clip.athlete_lane, dist=gt.cameras[0].dist)
    assert not m.inconsistent.any() and m.valid.all()
    h = float(gt.cameras[0].C[2])
    f = m._focal_at(h)
    true_f = np.array([c.focal_px for c in gt.cameras])
    assert np.max(np.abs(f / true_f - 1)) < 0.01
    # the undistorted families are built on forked workers; where no process may be started,
    # in this one, with exactly the same result
    import multiprocessing

    class NoProcesses:
        def Pool(self, n, **kwargs):  # as multiprocessing.Pool (initializer=...)
            raise OSError("no processes here")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(multiprocessing, "get_context", lambda method: NoProcesses())
        serial = ClipModel(reg, clip.keypoints_px, clip.fps, clip.athlete_lane, dist=gt.cameras[0].dist)
    for key in ("h", "logf", "y", "R"):
        assert np.array_equal(getattr(m, key), getattr(serial, key), equal_nan=True)


def test_angle_bands_scale_the_bootstrap_and_add_the_curvature_term():
    """Known answers: a straight angle curve gets the family's scale times the bootstrap
    deviations; a parabola with no bootstrap spread gets the curvature term alone; a number
    for ``inflation`` gives the scaled bootstrap band without that term."""
    from probreg.inference import BAND_CURVATURE_S2, BAND_SCALE, angle_bands

    fps, F = 50.0, 100
    t = np.arange(F) / fps
    line = 30.0 + 10.0 * t
    offsets = np.linspace(-1.0, 1.0, 101)[:, None]  # bootstrap draws: 5th/95th percentile -0.9/+0.9
    point = {"knee_l": np.tile(line, (5, 1)), "trunk_lean": np.tile(line, (5, 1))}
    noisy = {"knee_l": line + offsets, "trunk_lean": line + offsets}
    med, lo, hi = angle_bands(point, noisy, fps=fps)["knee_l"]
    assert np.allclose(med, line)
    assert np.allclose(hi - med, BAND_SCALE["knee"] * 0.9) and np.allclose(med - lo, BAND_SCALE["knee"] * 0.9)
    _, lo_t, hi_t = angle_bands(point, noisy, fps=fps)["trunk_lean"]
    assert np.allclose(hi_t - lo_t, 2 * BAND_SCALE["trunk_lean"] * 0.9)
    # a parabola of curvature 2000 deg/s^2, every draw alike: the band is the bias term alone
    par = 1000.0 * (t - 1.0) ** 2
    same = {"knee_l": np.tile(par, (5, 1))}
    med, lo, hi = angle_bands(same, same, fps=fps)["knee_l"]
    assert np.allclose(hi - med, BAND_CURVATURE_S2 * 2000.0) and np.allclose(med - lo, BAND_CURVATURE_S2 * 2000.0)
    # inflation: the raw bootstrap band scaled, no curvature term (and without fps none either)
    _, lo1, hi1 = angle_bands(same, same, fps=fps, inflation=1.0)["knee_l"]
    assert np.allclose(lo1, par) and np.allclose(hi1, par)
    _, lo0, hi0 = angle_bands(same, same)["knee_l"]
    assert np.allclose(hi0, par)


def test_noise_ratio_scales_the_bootstrap_part_of_the_band():
    """Known answers: data 4x noisier than the bootstrap doubles the bootstrap part of the band
    (square root of the ratio), 4x less noisy halves it, a ratio beyond the clipping range acts
    as its end, an angle without a ratio keeps its band, ``inflation`` ignores the ratio; the
    ratio itself is the medians' quotient over the draws (NaN draws left out)."""
    from probreg.inference import BAND_SCALE, angle_bands, bootstrap_noise_ratio
    from probreg.inference.bands import NOISE_RATIO_RANGE

    fps, F = 50.0, 100
    line = 30.0 + 10.0 * np.arange(F) / fps
    offsets = np.linspace(-1.0, 1.0, 101)[:, None]  # 5th/95th percentile -0.9/+0.9
    point = {k: np.tile(line, (5, 1)) for k in ("knee_l", "knee_r", "hip_l")}
    noisy = {k: line + offsets for k in point}
    base = BAND_SCALE["knee"] * 0.9
    bands = angle_bands(point, noisy, fps=fps, noise_ratio={"knee_l": 4.0, "knee_r": 0.25})
    assert np.allclose(bands["knee_l"][2] - line, 2.0 * base) and np.allclose(line - bands["knee_l"][1], 2.0 * base)
    assert np.allclose(bands["knee_r"][2] - line, 0.5 * base)
    assert np.allclose(bands["hip_l"][2] - line, BAND_SCALE["hip"] * 0.9)  # no ratio: unchanged
    far = angle_bands(point, noisy, fps=fps, noise_ratio={"knee_l": 100.0})["knee_l"]
    assert np.allclose(far[2] - line, np.sqrt(NOISE_RATIO_RANGE[1]) * base)
    raw = angle_bands(point, noisy, fps=fps, inflation=1.0, noise_ratio={"knee_l": 4.0})["knee_l"]
    assert np.allclose(raw[2] - line, 0.9)
    r = bootstrap_noise_ratio({"knee_l": np.array([3.0, 3.0, 9.0]), "hip_l": np.array([2.0])},
                              {"knee_l": np.array([1.0, 1.5, np.nan, 1.5])})
    assert r == {"knee_l": pytest.approx(2.0)}


def test_bands_below_the_reference_frame_rate_widen_by_the_rate_factor():
    """Known answers: the same bootstrap draws on a straight angle curve at 25 fps give a band
    (25/50 fps) ** -BAND_RATE_POWER = 1.248 times the 50 fps band; 60 fps keeps the 50 fps band;
    ``inflation`` ignores the rate; the gait-cycle bands carry the same factor."""
    from probreg.inference import BAND_SCALE, angle_bands, gait_cycle_bands
    from probreg.inference.bands import BAND_RATE_POWER, frame_rate_factor

    assert frame_rate_factor(25.0) == pytest.approx(2.0 ** BAND_RATE_POWER) == pytest.approx(1.248, abs=1e-3)
    F = 100
    line = 30.0 + 0.2 * np.arange(F)  # straight per frame at any rate: no curvature term
    offsets = np.linspace(-1.0, 1.0, 101)[:, None]  # 5th/95th percentile -0.9/+0.9
    point, noisy = {"knee_l": np.tile(line, (5, 1))}, {"knee_l": line + offsets}
    half = {fps: angle_bands(point, noisy, fps=fps)["knee_l"][2] - line for fps in (25.0, 50.0, 60.0)}
    assert np.allclose(half[50.0], BAND_SCALE["knee"] * 0.9) and np.allclose(half[60.0], half[50.0])
    assert np.allclose(half[25.0], 1.248 * half[50.0], rtol=1e-3)
    assert np.allclose(angle_bands(point, noisy, fps=25.0, inflation=1.0)["knee_l"][2] - line, 0.9)
    contacts = np.zeros((F, 2), bool)
    for a in range(5, F, 30):
        contacts[a:a + 10, 0] = True
        contacts[a + 15:a + 25, 1] = True
    cyc = {fps: gait_cycle_bands(point, noisy, contacts, fps=fps)[("knee", "L")] for fps in (25.0, 50.0)}
    w = {fps: np.nanmean(c[3] - c[1]) for fps, c in cyc.items()}
    assert w[50.0] > 0 and w[25.0] == pytest.approx(1.248 * w[50.0], rel=1e-3)


def test_gait_intervals_carry_the_step_timing_uncertainty(model):
    """Contacts are fixed for the point liftings (every camera hypothesis scored on the same
    steps), so their step timing is the same in every draw; the bootstrap liftings detect the
    contacts anew on re-noised keypoints, so the reported intervals of cadence and contact
    time are not of zero width."""
    from probreg.inference import gait_intervals

    m, gt = model
    h = gt.cameras[0].C[2]
    S = 12
    draws = np.column_stack([np.log(np.full(S, h)), np.full(S, gt.athlete["stature_m"]),
                             np.ones((S, len(PARAM_NAMES) - 2))])
    prop = m.propagate(draws, np.random.default_rng(7), workers=1)
    point, noisy = prop["gait_point"], prop["gait"]
    assert point.keys() == noisy.keys()
    assert np.ptp(point["contact_time_s"]) == 0 and np.ptp(point["cadence_spm"]) == 0
    timing = [k for k in ("contact_time_s", "cadence_spm") if np.ptp(noisy[k][np.isfinite(noisy[k])]) > 0]
    assert timing
    g = gait_intervals(point, noisy, inflation=1.0)
    for k in timing:
        med, lo, hi = g[k]
        assert lo < hi and lo <= med <= hi and med == np.nanmedian(point[k])


def test_planted_feet_slide_at_wrong_camera_heights(tmp_path):
    """A foot in early stance stands still; family members at a wrong height disagree from
    frame to frame on where it is, so it seems to slide.  The slide changes sign at about
    the true height, and the likelihood term built on it peaks there.  Three clips: with legs
    that leave their plane (0.2.0.dev24) one of them crosses 14.6 % high (4.1 % before), the
    others at 2.2 and 5.8 %."""
    from probreg.sim import config_from_preset, synthesize, write_clip

    crossings, peaks, above = [], [], []  # above: the slide 15 % above the true height
    for seed in (5, 6, 7):
        clip = synthesize(config_from_preset("run", seed, n_frames=150), seed=seed, preset="run")
        write_clip(clip, tmp_path / f"c{seed}", images=True, jobs=1)
        c = load_clip(tmp_path / f"c{seed}")
        h_true = float(load_groundtruth(tmp_path / f"c{seed}").cameras[0].C[2])
        model = ClipModel(register_clip(c), c.keypoints_px, c.fps, c.athlete_lane)
        assert len(model._stance_windows()) >= 6
        lg = np.log(model.grid / h_true)
        ok = np.isfinite(model.slide_median) & (np.abs(lg) < np.log(1.25))
        slide = model.slide_median[ok]
        assert np.all(np.diff(slide) < 0)  # the slide falls steadily with height here
        crossings.append(np.interp(0.0, -slide, lg[ok]))
        assert np.interp(np.log(0.85), lg[ok], slide) > 0.2
        above.append(np.interp(np.log(1.15), lg[ok], slide))
        peaks.append(lg[np.argmax(model.ll_still)])
    crossings, peaks = np.abs(crossings), np.abs(peaks)
    assert np.all(np.array(above) < 0) and np.median(above) < -0.2  # one clip, crossing at +14.6 %: -0.01
    assert np.all(crossings < np.log(1.2)) and np.median(crossings) < np.log(1.1)
    assert np.all(peaks < np.log(1.2)) and np.median(peaks) < np.log(1.1)


def test_member_sensitivity_is_small_for_a_broadcast_camera_and_grows_at_the_family_top(model):
    """At the true height of the broadcast clip a 1 % height change moves the focal length by
    about 1 %; towards the top of the family (where both branches meet) by far more."""
    m, gt = model
    h = gt.cameras[0].C[2]
    assert 0.5 < m.member_sensitivity(h) < 3.0
    top = float(np.nanmedian(np.nanmax(m.h[m.valid], axis=1)))  # each frame's highest member
    assert top > 1.5 * h
    assert m.member_sensitivity(0.995 * top) > 5.0
    assert np.isnan(m.member_sensitivity(10 * top))  # no frame has a member there


def test_line_identities_are_settled_away_from_the_family_top(model):
    """The lines' frame-to-frame identities (and the athlete's lane) are settled at the reference
    height only where its members are well conditioned.  A reference height on the family's
    fold (where a first pass can land on a steep view) used to settle them there: on this clip
    the camera then sat one lane (1.24 m) off at the true height, and some frames a lane apart."""
    import copy

    m, gt = copy.deepcopy(model[0]), model[1]
    h = gt.cameras[0].C[2]
    true_y = np.array([c.C[1] for c in gt.cameras])
    top = float(np.nanmedian(np.nanmax(m.h[m.valid], axis=1)))
    for f in (0.99, 0.995):
        m.h_ref = f * top
        assert not m.member_sensitivity(m.h_ref) <= 2.0  # hypersensitive there
        m._fix_offsets(final=True)
        assert m.member_sensitivity(m._identity_h) <= 2.0
        cams = m.cameras_at(h)
        y = cams.C[cams.valid, 1]
        assert np.all(np.abs(np.diff(y)) < 0.5 * 1.22)
        assert abs(np.median(y - true_y[cams.valid])) < 0.3


def test_no_noise_copies_are_made_without_a_known_noise_level(model, monkeypatch):
    """Keypoints whose noise level is unknown (or zero) are not re-noised: the pipeline then
    starts no noise copies at all, as propagate adds no noise."""
    m, _ = model
    assert m.bootstraps_noise(True) == (np.isfinite(m.noise_sd) and m.noise_sd > 0)
    assert not m.bootstraps_noise(False)
    for level in (float("nan"), 0.0):
        monkeypatch.setattr(m, "noise_sd", level)
        assert not m.bootstraps_noise(True)


def test_a_clip_without_a_finite_posterior_at_any_height_is_uncalibrated(small_clip, tmp_path, monkeypatch):
    """A grazing view whose few calibrated frames give no usable term at any height (held-out-like
    tuning clip t8013) sent NaN walkers into emcee ("At least one parameter value was NaN"); now
    the model says it cannot calibrate, and ``probreg run`` writes an ``uncalibrated`` result."""
    from probreg.inference.model import NoCalibrationError

    clip = load_clip(small_clip)
    original = ClipModel._precompute

    def no_term_anywhere(self):
        original(self)
        self.ll_static[:] = -np.inf  # no height gives one camera for the clip

    monkeypatch.setattr(ClipModel, "_precompute", no_term_anywhere)
    with pytest.raises(NoCalibrationError, match="finite posterior") as info:
        ClipModel(register_clip(clip), clip.keypoints_px, clip.fps, clip.athlete_lane)
    assert info.value.reason == "no_finite_posterior"  # the verdict reads the reason, not the message
    res = run_clip(small_clip, tmp_path / "out", RunOptions(sampler=FAST, report=False))
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert run["verdict"] == "uncalibrated" and res is not None
    assert any("finite posterior" in r for r in run["verdict_reasons"])


def test_limb_term_does_not_tilt_towards_low_cameras():
    """The limb lengths measured at a height scale with it, and so does their standard error;
    normalised by its standard error in metres the term added -log(h) per observed segment
    (five of them: h^-5), which pulled prior-dominated heights ~3 % low (tuning clips of the
    held-out distribution, seeds 8010-8017).  Normalised in the image's terms, an exact scale
    family -- every height explaining the limbs equally well -- scores every height alike."""
    from probreg.inference.model import OBSERVED_SEGMENTS, SEGMENTS
    from probreg.inference.priors import SEGMENT_PROPORTIONS

    m = object.__new__(ClipModel)
    m.grid = np.geomspace(5.0, 40.0, 12)
    G = len(m.grid)
    m.ll_track, m.ll_static, m.ll_still, m.ll_limbs = np.zeros(G), np.zeros(G), np.zeros(G), np.zeros(G)
    m.track_weight, m.lens = 0.2, None
    m.height_systematic_sd, m._precompute_id = 0.015, 1
    m.priors, m.speed_grid = ModelPriors(), np.full(G, np.nan)  # no track: no speed, no penalty
    per_m = {"thigh": 0.045, "shank": 0.044, "upper_arm": 0.033, "forearm": 0.026, "trunk": 0.05}
    m.seg_obs = {s: per_m[s] * m.grid for s in OBSERVED_SEGMENTS}
    m.seg_se = {s: 0.03 * m.seg_obs[s] for s in OBSERVED_SEGMENTS}
    thetas = []
    for h in m.grid[[1, 5, 10]]:  # grid heights: no interpolation
        stature = per_m["thigh"] * h / SEGMENT_PROPORTIONS["thigh"]
        props = [per_m[s] * h / (stature * SEGMENT_PROPORTIONS[s]) if s in per_m else 1.0 for s in SEGMENTS]
        thetas.append(np.r_[np.log(h), stature, props])
    ll = m.log_likelihood(np.array(thetas))
    assert np.all(np.isfinite(ll)) and np.ptp(ll) < 1e-6


def test_a_height_spike_is_widened_to_the_systematic_allowance():
    """Near the family's fold the height-only terms make a spike a few tenths of a percent wide;
    marginalised over the systematic allowance, a height one allowance away scores half a
    nat-squared below the peak (a Gaussian of that sd), and without the allowance it is
    excluded.  The limb terms are left out (no segment observed)."""
    from probreg.inference.model import OBSERVED_SEGMENTS

    m = object.__new__(ClipModel)
    m.grid = np.geomspace(5.0, 40.0, 4000)
    G = len(m.grid)
    m.ll_track, m.ll_still, m.ll_limbs = np.zeros(G), np.zeros(G), np.zeros(G)
    m.ll_static = -0.5 * (np.log(m.grid / 20.0) / 0.001) ** 2
    m.track_weight, m.lens, m._precompute_id = 0.2, None, 1
    m.priors, m.speed_grid = ModelPriors(), np.full(G, np.nan)
    m.seg_obs = {s: np.full(G, np.nan) for s in OBSERVED_SEGMENTS}
    m.seg_se = dict(m.seg_obs)
    theta = np.array([np.r_[np.log(20.0 * f), 1.8, np.ones(7)] for f in (1.0, np.exp(0.015), np.exp(-0.03))])
    m.height_systematic_sd = 0.015
    ll = m.log_likelihood(theta)
    assert ll[1] - ll[0] == pytest.approx(-0.5, abs=0.02)
    assert ll[2] - ll[0] == pytest.approx(-2.0, abs=0.05)
    m.height_systematic_sd, m._precompute_id = 0.0, 2
    ll = m.log_likelihood(theta)
    assert ll[1] - ll[0] < -100


def test_limbs_keep_their_length_only_under_the_true_camera(distorted_lanes):
    """Known answer for the limb-consistency term: a steep camera close to the track, lanes
    straight from the true cameras.  Cast onto the sagittal plane, the limbs' per-frame lengths
    spread least at (about) the true height and clearly more 15 % below it, where the lanes'
    own terms hardly tell the heights apart; the term's maximum is within 3 % of the truth."""
    from probreg.calibration.registration import register_frames
    from probreg.sim import config_from_preset, synthesize

    syn = synthesize(config_from_preset("steep_near", 5, n_frames=60), seed=5, preset="steep_near")
    cams = [c.with_(dist=np.zeros(5)) for c in syn.cameras]
    kp = syn.keypoints_px.copy()
    kp[..., :2] = np.stack([c.project(j) for c, j in zip(cams, syn.motion.joints_track_m)])  # exact, undistorted
    lanes = [replace(distorted_lanes(c), frame=i) for i, c in enumerate(cams)]
    fwd = cams[0].project(np.array([[60.0, -3.0, 0.0]]))[0] - cams[0].project(np.array([[50.0, -3.0, 0.0]]))[0]
    reg = register_frames(lanes, cams[0].image_size, fwd / np.linalg.norm(fwd))
    m = ClipModel(reg, kp, syn.config.fps, syn.config.athlete_lane, branch="wide")  # the camera's branch
    h_true = float(cams[0].C[2])
    assert m.grid[0] < 0.85 * h_true and h_true < m.grid[-1]
    ok = np.isfinite(m.seg_spread["thigh"])
    at = lambda h: np.interp(np.log(h), np.log(m.grid[ok]), m.seg_spread["thigh"][ok])  # noqa: E731
    assert at(0.85 * h_true) > 1.5 * at(h_true)
    best = m.grid[int(np.argmax(m.ll_limbs))]
    assert abs(best / h_true - 1) < 0.03


def test_running_speed_prior_is_flat_for_human_speeds_and_walls_off_the_rest(model):
    """The model's ground track at each grid height gives the athlete's speed; at the true height
    it is the true speed, and the prior only penalises heights that make the athlete run faster
    than a human can (above 12.5 m/s)."""
    m, gt = model
    v_true = gt.athlete["gait"]["speed_mps"]
    h_true = float(gt.cameras[0].C[2])
    ok = np.isfinite(m.speed_grid)
    assert ok.sum() > 10
    v_at_truth = np.interp(np.log(h_true), np.log(m.grid[ok]), m.speed_grid[ok])
    assert abs(v_at_truth - v_true) / v_true < 0.1
    term = m.priors.running_speed_logpdf(m.speed_grid)
    assert np.all(term[ok & (m.speed_grid <= 12.5)] == 0.0)
    assert np.all(term[m.speed_grid > 13.5] < -2.0)
    # the term is part of the height likelihood: a wall below the true speed moves the best height
    x, ll = m._height_terms()
    slow = replace(m.priors, max_speed_mps=0.5 * v_true)
    m_priors, m.priors = m.priors, slow
    try:
        m._height_cache = (None,)
        x2, ll2 = m._height_terms()
    finally:
        m.priors, m._height_cache = m_priors, (None,)
    best, best_slow = x[np.nanargmax(ll)], x2[np.nanargmax(ll2)]
    v_best_slow = np.interp(best_slow, np.log(m.grid[ok]), m.speed_grid[ok])
    assert best_slow != best and v_best_slow < 0.75 * v_true


def test_noise_copies_made_ahead_in_part_give_the_same_propagation(model):
    """The copies made while the sampler runs may stop at any point: the propagation makes the
    missing ones from the same seeds, so the result does not depend on how many were ready."""
    m, gt = model
    h = gt.cameras[0].C[2]
    draws = np.tile(np.r_[np.log(h), gt.athlete["stature_m"], np.ones(len(PARAM_NAMES) - 2)], (4, 1))
    draws[:, 0] += np.linspace(-0.05, 0.05, 4)
    seeds = m.noise_copy_seeds(np.random.default_rng(9), 2)
    full = m.bootstrap_copies(seeds)
    calls = []
    part = m.bootstrap_copies(seeds, stop=lambda: calls.append(1) or len(calls) > 1)  # stops after one copy
    assert part[0] is not None and part[1] is None
    assert np.array_equal(part[0], full[0], equal_nan=True)
    a = m.propagate(draws, np.random.default_rng(5), workers=1, noise_copies=full)
    b = m.propagate(draws, np.random.default_rng(5), workers=2, noise_copies=part, noise_copy_seeds=seeds)
    for key in ("joints", "joints_point"):
        assert np.array_equal(a[key], b[key], equal_nan=True)
    with pytest.raises(ValueError, match="noise_copy_seeds"):
        m.propagate(draws, np.random.default_rng(5), workers=1, noise_copies=part)
    # made ahead in a forked process and stopped at once: every copy is then made by the workers
    finish = m.bootstrap_copies_ahead(np.random.default_rng(9), 2)
    copies, s2 = finish()
    assert np.array_equal(s2, seeds) and len(copies) == 2
    c = m.propagate(draws, np.random.default_rng(5), workers=1, noise_copies=copies, noise_copy_seeds=s2)
    assert np.array_equal(a["joints"], c["joints"], equal_nan=True)


@pytest.mark.parametrize("noise_px", [0.0, 6.0])
def test_limb_lengths_seen_at_the_true_camera_are_unbiased(noise_px):
    """The limbs' observations (cast into the sagittal plane at a height hypothesis) are the
    median over the frames, with the length that noise adds removed: at the true camera they
    give the true lengths whatever the keypoint noise.  (The 60th percentile used until
    0.2.0.dev40 lies a quarter of the lengths' spread above it: +1-2 % with a detector's noise,
    and the stature and camera height followed.)"""
    from probreg.geometry import camera_arrays
    from probreg.inference.model import OBSERVED_SEGMENTS
    from probreg.lifting import fit_ground_track
    from probreg.sim import config_from_preset, synthesize

    clip = synthesize(config_from_preset("run", 5, n_frames=150), seed=5, preset="run")
    rng = np.random.default_rng(0)
    kp = clip.joints2d_px[..., :2] + rng.normal(0.0, noise_px, clip.joints2d_px[..., :2].shape)
    cams = camera_arrays(clip.cameras)
    m = object.__new__(ClipModel)
    m.kp, m.F, m.noise_sd = kp, len(kp), noise_px
    m.seg_obs, m.seg_se, m.seg_spread, m.seg_measured = ({s: np.full(1, np.nan) for s in OBSERVED_SEGMENTS}
                                                         for _ in range(4))
    m._segment_stats(0, cams, fit_ground_track(cams, clip.joints2d_px[..., :2], clip.config.fps))
    true = clip.motion.anthropometry.segments_m()
    err = {s: m.seg_obs[s][0] / true[s] - 1 for s in ("thigh", "shank", "upper_arm", "trunk")}
    assert abs(np.mean(list(err.values()))) < 0.006, err
    assert all(abs(e) < 0.02 for e in err.values()), err
