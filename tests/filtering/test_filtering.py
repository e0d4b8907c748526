"""Keypoint cleaning: noise model, cross-stride smoothing."""

import numpy as np
import pytest

from probreg.filtering import (
    clean_keypoints,
    leg_length_px,
    noise_model,
    periodic_smooth,
    periodic_smooth_series,
    stride_lags,
    stride_period_frames,
)
from probreg.geometry import JOINT_INDEX as J
from probreg.sim import Anthropometry, gait_for_style, simulate_runner


def _side_view(joints, f=2000.0, dist=25.0):
    """A static side-on pinhole view (x right, z up) of a runner: (F, 17, 3) keypoints."""
    x, y, z = joints[..., 0], joints[..., 1], joints[..., 2]
    depth = dist - y
    u = 960 + f * (x - joints[:, :1, 0]) / depth  # the camera pans with the athlete
    v = 540 - f * (z - 1.0) / depth
    return np.stack([u, v, np.ones_like(u)], -1)


def _ar1(rng, shape, sd, rho):
    e = rng.standard_normal(shape)
    out = np.empty(shape)
    out[0] = e[0]
    for t in range(1, shape[0]):
        out[t] = rho * out[t - 1] + np.sqrt(1 - rho**2) * e[t]
    return sd * out


def _knee2d(kp, side="r"):
    h, k, a = (kp[:, J[f"{side}_{n}"], :2] for n in ("hip", "knee", "ankle"))
    u, v = h - k, a - k
    c = np.sum(u * v, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)
    return 180 - np.degrees(np.arccos(np.clip(c, -1, 1)))


@pytest.fixture(scope="module")
def runner_views():
    rng = np.random.default_rng(11)
    g = gait_for_style("run")
    m = simulate_runner(Anthropometry.from_stature(1.78), g, 300, 50.0, rng=rng)
    truth = _side_view(m.joints_track_m)
    noisy = truth.copy()
    noisy[..., :2] += _ar1(rng, truth.shape[:2] + (2,), 4.0, 0.5)
    return m, truth, noisy


def test_noise_model_recovers_ar1_noise(runner_views):
    _, truth, noisy = runner_views
    sd, rho = noise_model(noisy)
    assert abs(sd - 4.0) < 0.8 and abs(rho - 0.5) < 0.2


def test_stride_period_known_answer(runner_views):
    m, truth, _ = runner_views
    rel = truth[..., :2] - truth[:, :1, :2]
    T = stride_period_frames(rel / 300.0, 50.0)
    assert abs(T - 50.0 * 2 / m.gait.step_freq_hz) < 1.0


def test_stride_period_is_not_a_multiple():
    # a stride of 31.05 frames: lag 62 lies nearer to two periods than 31 to one, and with
    # noise the two-stride lag often matched better (the fast_a clip of the suite); the
    # period must still come out as one stride
    rng = np.random.default_rng(0)
    F, T = 250, 31.05
    ph = 2 * np.pi * np.arange(F) / T
    for _ in range(10):
        rel = np.stack([np.sin(ph + k) + 0.4 * np.sin(2 * ph + 2 * k) for k in range(34)], 1).reshape(F, 17, 2)
        rel = rel + rng.normal(0, 0.15, rel.shape)
        assert abs(stride_period_frames(rel, 50.0) - T) < 0.5


def test_periodic_smoothing_beats_low_pass_and_keeps_stride_differences(runner_views):
    m, truth, noisy = runner_views
    sm = periodic_smooth(noisy, 50.0)
    assert sm is not None
    low = clean_keypoints(noisy, 50.0, cutoff_hz=7.0)
    err = lambda kp: np.sqrt(np.mean((_knee2d(kp) - _knee2d(truth)) ** 2))  # noqa: E731
    assert err(sm) < 0.85 * err(low) and err(sm) < 0.6 * err(noisy)
    # the truth varies from stride to stride; the estimate follows it rather than
    # collapsing onto one average stride
    T = int(round(50.0 * 2 / m.gait.step_freq_hz))
    d_true = _knee2d(truth)[T:] - _knee2d(truth)[:-T]
    d_est = _knee2d(sm)[T:] - _knee2d(sm)[:-T]
    assert np.corrcoef(d_true, d_est)[0, 1] > 0.3
    # "auto" cleaning uses it for noisy running clips
    auto = clean_keypoints(noisy, 50.0)
    assert np.allclose(auto[..., :2], sm[..., :2], equal_nan=True)


def test_noise_floor_follows_the_athletes_image_size(runner_views):
    # 1.2 px of noise is below the 1.5 px floor: clean for an athlete whose legs are 218 px long
    # in the image (0.55 %), but 2.6 % of a 47 px leg (a wide 720p view), as noisy as the benchmark
    # suite's clips: that one is smoothed, and its 2D knee angle gets closer to the truth
    m, _, _ = runner_views
    rng = np.random.default_rng(5)
    err = lambda kp, truth: np.sqrt(np.nanmean((_knee2d(kp) - _knee2d(truth)) ** 2))  # noqa: E731
    for f, leg, smoothed in ((1500.0, 47.0, True), (7000.0, 218.0, False)):
        truth = _side_view(m.joints_track_m, f=f)
        noisy = truth.copy()
        noisy[..., :2] += _ar1(rng, truth.shape[:2] + (2,), 1.2, 0.3)
        assert abs(leg_length_px(noisy) - leg) < 0.1 * leg and noise_model(noisy)[0] < 1.5
        out = clean_keypoints(noisy, 50.0)
        assert (not np.allclose(out[..., :2], noisy[..., :2])) == smoothed
        if smoothed:
            assert err(out, truth) < 0.7 * err(noisy, truth)
            # with the pixel floor alone (as up to 0.2.0.dev2) it was left as it came
            alone = clean_keypoints(noisy, 50.0, noise_floor_leg_frac=None)
            assert np.allclose(alone[..., :2], noisy[..., :2])


def test_periodic_smoothing_declines_without_repeating_strides():
    rng = np.random.default_rng(2)
    walk = np.cumsum(rng.normal(0, 3.0, (200, 17, 2)), axis=0) + 500
    kp = np.concatenate([walk, np.ones((200, 17, 1))], -1)
    assert periodic_smooth(kp, 50.0) is None
    short = np.concatenate([rng.normal(500, 3.0, (15, 17, 2)), np.ones((15, 17, 1))], -1)
    assert periodic_smooth(short, 50.0) is None
    out = clean_keypoints(kp, 50.0)  # falls back to the low-pass, never fails
    assert out.shape == kp.shape and np.isfinite(out).all()


def test_noise_model_is_not_fooled_by_sampling_noise_of_one_ratio():
    """250 frames: the multi-lag fit stays near the truth where a two-lag ratio wanders."""
    errs = []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        e = _ar1(rng, (250, 17, 2), 5.0, 0.5)
        sd, rho = noise_model(np.concatenate([e, np.ones((250, 17, 1))], -1))
        errs.append((abs(sd - 5.0), abs(rho - 0.5)))
    errs = np.array(errs)
    assert errs[:, 0].max() < 1.0 and errs[:, 1].max() < 0.2


def test_periodic_smoothing_rejects_outliers_without_cutting_fast_turns(runner_views):
    m, truth, noisy = runner_views
    rng = np.random.default_rng(5)
    wild = noisy.copy()
    hits = rng.random(wild.shape[:2]) < 0.01
    wild[..., :2] += hits[..., None] * rng.choice([-1, 1], wild.shape[:2] + (2,)) * 80.0  # 20 sigma
    err = lambda kp, j: np.sqrt(np.nanmean(np.sum((kp[:, j, :2] - truth[:, j, :2]) ** 2, -1)))  # noqa: E731
    clean = periodic_smooth(noisy, 50.0)
    robust = periodic_smooth(wild, 50.0)
    ankle = J["r_ankle"]
    # outliers cost little: the fit down-weights them itself
    assert err(robust, ankle) < 1.15 * err(clean, ankle)
    assert err(robust, ankle) < err(wild, ankle) * 0.7


def test_periodic_series_smoothing_known_noise_and_gaps():
    rng = np.random.default_rng(8)
    t = np.arange(400)
    T = 34.5
    truth = 45 + 40 * np.sin(2 * np.pi * t / T) + 12 * np.sin(4 * np.pi * t / T + 1)
    truth = truth + np.repeat(rng.normal(0, 1.5, 400 // 34 + 1), 34)[:400]  # stride-to-stride changes
    y = truth + _ar1(rng, (400,), 6.0, 0.5)
    y[100:106] = np.nan
    x, info = periodic_smooth_series(y, np.full(400, T), 50.0)
    ok = np.isfinite(y)
    assert np.mean(np.abs(x - truth)[ok]) < 0.6 * np.mean(np.abs(y - truth)[ok])
    assert np.all(np.isfinite(x[100:106])) and np.max(np.abs(x[100:106] - truth[100:106])) < 10
    assert 4.0 < info["noise_sd"] < 8.0
    # without a stride lag the series is returned as it is
    same, info2 = periodic_smooth_series(y, None, 50.0)
    assert np.array_equal(same, y, equal_nan=True) and np.isnan(info2["noise_sd"])


def test_stride_lags_follow_the_stride(runner_views):
    m, truth, noisy = runner_views
    lag = stride_lags(noisy, 50.0)
    T = 50.0 * 2 / m.gait.step_freq_hz
    assert lag is not None and abs(np.nanmedian(lag) - T) < 1.5
    rng = np.random.default_rng(2)
    walk = np.concatenate([np.cumsum(rng.normal(0, 3.0, (200, 17, 2)), axis=0) + 500, np.ones((200, 17, 1))], -1)
    assert stride_lags(walk, 50.0) is None


def test_short_clip_of_under_two_strides_is_still_smoothed(runner_views):
    """A clip of 1.7 strides (the validation set's 60-70 frame clips) has a stride lag and is
    smoothed across strides; one of 1.2 strides (too short to measure a period) is not."""
    m, truth, noisy = runner_views
    T = 50.0 * 2 / m.gait.step_freq_hz
    short = int(1.7 * T)
    lag = stride_lags(noisy[:short], 50.0)
    assert lag is not None and abs(np.nanmedian(lag) - T) < 1.5
    assert np.isfinite(lag).sum() >= short - T - 2  # frames with a partner one stride later
    sm = periodic_smooth(noisy[:short], 50.0)
    err = lambda kp: np.sqrt(np.nanmean(np.sum((kp[..., :2] - truth[:short, :, :2]) ** 2, -1)))  # noqa: E731
    assert sm is not None and err(sm) < 0.8 * err(noisy[:short])
    assert stride_lags(noisy[:int(1.2 * T)], 50.0) is None


def test_confidence_weighting_learns_from_the_clip(runner_views):
    """Detections whose confidence is low are worse: a second pass weighted by what the
    clip's own residuals say about the scores beats equal weights; constant scores change
    nothing."""
    from probreg.filtering import score_noise_scale

    _, truth, _ = runner_views
    rng = np.random.default_rng(21)
    F = len(truth)
    z = np.abs(rng.standard_normal((F, 17)))  # per-detection error scale
    score = np.clip(0.95 - 0.1 * z + rng.normal(0, 0.02, (F, 17)), 0.05, 1.0)
    noisy = truth.copy()
    noisy[..., :2] += _ar1(rng, (F, 17, 2), 4.0, 0.5) * (0.3 + z)[..., None]
    noisy[..., 2] = score
    err = lambda kp: np.sqrt(np.nanmean(np.sum((kp[..., :2] - truth[..., :2]) ** 2, -1)))  # noqa: E731
    plain = periodic_smooth(noisy, 50.0, score_weights=False)
    weighted = periodic_smooth(noisy, 50.0)
    assert err(weighted) < 0.9 * err(plain)
    # the learned noise scale follows the true one
    rel = score_noise_scale(noisy, truth, 4.0)
    assert np.corrcoef(rel.ravel(), z.ravel())[0, 1] > 0.6
    # uninformative (constant) scores: no second pass
    flat = noisy.copy()
    flat[..., 2] = 0.9
    assert score_noise_scale(flat, truth, 4.0) is None
    assert np.allclose(periodic_smooth(flat, 50.0), periodic_smooth(flat, 50.0, score_weights=False),
                       equal_nan=True)


def test_periodic_smoothing_keeps_camera_shake(runner_views):
    # a shaking broadcast camera moves every joint alike by several px per frame; that
    # is image motion the per-frame cameras also see, not detector noise: the smoother
    # must keep it in every joint and still remove the noise
    _, truth, noisy = runner_views
    rng = np.random.default_rng(5)
    shake = np.cumsum(rng.normal(0, 3.0, (len(truth), 1, 2)), axis=0)
    shaken_truth = truth[..., :2] + shake
    kp = noisy.copy()
    kp[..., :2] += shake
    sm = periodic_smooth(kp, 50.0)
    assert sm is not None
    err = lambda x: np.sqrt(np.nanmean(np.sum((x[..., :2] - shaken_truth) ** 2, -1)))  # noqa: E731
    assert err(sm) < 0.6 * err(kp)
    # the posture (knee angle in the image) comes out as well as without any shake
    calm = periodic_smooth(noisy, 50.0)
    e_shaken = np.sqrt(np.mean((_knee2d(sm) - _knee2d(truth)) ** 2))
    e_calm = np.sqrt(np.mean((_knee2d(calm) - _knee2d(truth)) ** 2))
    assert e_shaken < 1.1 * e_calm


def test_common_reference_ignores_a_missing_trunk_joint(runner_views):
    from probreg.filtering.periodic import _TRUNK, _common_mode

    _, truth, _ = runner_views
    xy = truth[..., :2]  # noise-free: what is left is what the missing joints do
    ok = np.ones(xy.shape[:2], bool)
    trunk = xy[:, list(_TRUNK)].mean(1)
    full = _common_mode(xy, ok, 50.0, 4.0, trunk)
    # both shoulders disappear in every other frame: the plain mean would jump by their
    # offset from the trunk centre, the common reference must not
    ok2 = ok.copy()
    ok2[::2, J["l_shoulder"]] = False
    ok2[::2, J["r_shoulder"]] = False
    xy2 = np.where(ok2[..., None], xy, np.nan)
    with np.errstate(invalid="ignore"):
        trunk2 = np.nanmean(xy2[:, list(_TRUNK)], axis=1)
    part = _common_mode(xy2, ok2, 50.0, 4.0, trunk2)
    def jumps(d):  # frame-to-frame jumps of a difference of references (a slow drift is
        # harmless: the relative tracks carry it and the output adds it back)
        return np.linalg.norm(d[1:-1] - 0.5 * (d[:-2] + d[2:]), axis=-1).mean()

    assert jumps(trunk2 - trunk) > 5.0
    assert jumps(part - full) < 0.5


def test_a_joint_without_any_stride_pair_is_still_smoothed(runner_views, monkeypatch):
    """Keypoints only in the first half of a clip whose stride lags are known only in the second
    (a bootstrap copy of a clip whose athlete leaves the picture): no detected frame has a partner
    one stride later.  The stride-to-stride variance was then a mean over nothing (NaN), which
    made every joint's fit NaN with a "Mean of empty slice" warning."""
    import warnings

    from probreg.filtering import periodic

    _, truth, noisy = runner_views
    F = 160
    kp = noisy[:F].copy()
    kp[F // 2:] = np.nan
    lag = np.full(F, np.nan)
    lag[F // 2:] = 35.0
    monkeypatch.setattr(periodic, "_lags_of", lambda rel_t, fps, min_strides: lag)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        sm = periodic_smooth(kp, 50.0)
    assert sm is not None
    seen = sm[: F // 2, :, :2]
    assert np.all(np.isfinite(seen))
    # still a smoothing of the data: closer to the truth than the noisy detections
    err = lambda x: np.sqrt(np.mean((x - truth[: F // 2, :, :2]) ** 2))  # noqa: E731
    assert err(seen) < err(noisy[: F // 2, :, :2])


def test_noise_model_tells_the_trunks_own_motion_from_correlated_noise():
    """Spine and thorax moving steadily against the pelvis between frames (as at 25 fps) make the
    variances of the differences grow with the lag like strongly correlated noise: the AR(1) fit
    alone takes 2 px of white noise for 3-7 px at a correlation near its limit; the refit with the
    motion as a part of its own gets the 2 px back.  Noise without such motion keeps the AR(1) fit."""
    from probreg.filtering.basic import NOISE_RHO_MOTION, _ar1_fit, _lag_variances

    for seed in range(5):
        rng = np.random.default_rng(seed)
        kp = np.zeros((250, 17, 3))
        kp[:, [J["spine"], J["thorax"]], :2] = 1.6 * np.arange(250)[:, None, None] * np.array([1, -1])[None, :, None]
        kp[..., :2] += rng.normal(0, 2.0, (250, 17, 2))
        rel = kp[:, [J["spine"], J["thorax"]], :2] - kp[:, [J["pelvis"]], :2]
        ar1_sd, ar1_rho = _ar1_fit(_lag_variances(rel, (1, 2, 3)), (1, 2, 3))
        sd, rho = noise_model(kp)
        assert ar1_sd > 3.0 and abs(sd - 2.0) < 0.35 and rho < 0.3, (seed, ar1_sd, ar1_rho, sd, rho)
        plain = kp.copy()
        plain[:, :, :2] = _ar1(rng, (250, 17, 2), 2.0, 0.5)
        rel = plain[:, [J["spine"], J["thorax"]], :2] - plain[:, [J["pelvis"]], :2]
        fit = _ar1_fit(_lag_variances(rel, (1, 2, 3)), (1, 2, 3))
        assert fit[1] < NOISE_RHO_MOTION and noise_model(plain) == fit
    # eight frames measure lags 1-3 (20 differences at least) but not lag 4: the AR(1) fit stands
    short = np.zeros((8, 17, 3))
    short[:, [J["spine"], J["thorax"]], :2] = 2.5 * np.arange(8)[:, None, None] * np.array([1, -1])[None, :, None]
    short[..., :2] += np.random.default_rng(0).normal(0, 2.0, (8, 17, 2))
    rel = short[:, [J["spine"], J["thorax"]], :2] - short[:, [J["pelvis"]], :2]
    fit = _ar1_fit(_lag_variances(rel, (1, 2, 3)), (1, 2, 3))
    assert fit[1] >= NOISE_RHO_MOTION and np.isfinite(fit[0]) and noise_model(short) == fit


def test_noise_model_on_real_runners_at_25_fps(shared_data):
    """Real running (the CMU clips of ``shared/data/mocap``, 60 fps taken every 2nd-3rd frame: 25 fps)
    seen side-on with the athlete ~450 px tall, plus 3 px of AR(1) noise (correlation 0.3): the trunk's
    own motion makes the AR(1) fit read more noise than there is.  The refit never reads more than
    the AR(1) fit, and where that fit reaches the gate (two of the seven runners) it comes at least
    1 px nearer the truth."""
    import glob

    from probreg.filtering.basic import NOISE_RHO_MOTION, _ar1_fit, _lag_variances

    files = sorted(glob.glob(str(shared_data / "mocap" / "*.npz")))
    if not files:
        pytest.skip("no mocap clips")
    gated = 0
    for f in files:
        d = np.load(f)
        joints = d["joints3d"][:: int(round(float(d["fps"]) / 25.0))]
        kp = _side_view(joints, f=8000.0)
        kp[..., :2] += _ar1(np.random.default_rng(0), kp.shape[:2] + (2,), 3.0, 0.3)
        rel = kp[:, [J["spine"], J["thorax"]], :2] - kp[:, [J["pelvis"]], :2]
        ar1_sd, ar1_rho = _ar1_fit(_lag_variances(rel, (1, 2, 3)), (1, 2, 3))
        sd, _ = noise_model(kp)
        assert abs(sd - 3.0) <= abs(ar1_sd - 3.0) + 1e-9, f
        if ar1_rho >= NOISE_RHO_MOTION:
            gated += 1
            assert abs(sd - 3.0) + 1.0 <= abs(ar1_sd - 3.0), (f, ar1_sd, sd)
    assert gated >= 1
