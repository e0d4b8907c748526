"""Known answers for each reason of the clip verdict: one input built to trigger it, one not to."""

import numpy as np
import pytest

from probreg.calibration import CameraSide
from probreg.geometry import JOINT_INDEX
from probreg.inference import bone_length_cv, clip_verdict, posterior_modes

GOOD = dict(n_frames=100, calibrated=100, frames_with_angles=100, rhat=1.01, ess=900)


def _side(llr_track, llr_knee, source="evidence"):
    cues = {"ground_track": {"llr": llr_track}, "knee_fold": {"llr": llr_knee}}
    llr = llr_track + llr_knee
    return CameraSide(chosen="main" if llr >= 0 else "far", source=source,
                      log_evidence={"main": llr / 2, "far": -llr / 2}, cues=cues)


def test_a_clean_clip_is_ok():
    rng = np.random.default_rng(1)
    verdict, reasons = clip_verdict(**GOOD, log_height_draws=rng.normal(np.log(15), 0.05, 4000),
                                    log_height_prior_sd=0.5, side=_side(40.0, 30.0),
                                    bone_cv_pct={"thigh": 3.0, "shank": 4.0, "upper_arm": 4.0, "forearm": 6.0})
    assert (verdict, reasons) == ("ok", [])


def test_no_angle_and_no_calibrated_frame_is_uncalibrated():
    assert clip_verdict(250, 0, 0) == ("uncalibrated", ["frames_with_angles 0/250", "calibrated_frames 0/250"])


def test_few_calibrated_frames_are_unreliable():
    assert clip_verdict(250, 100, 250) == ("unreliable", ["calibrated_frames 100/250"])
    assert clip_verdict(250, 125, 250) == ("ok", [])


@pytest.mark.parametrize("rhat, ess, reason", [(1.12, 900, "R-hat 1.12"), (1.01, 45, "ESS 45")])
def test_a_sampler_that_did_not_mix_is_unreliable(rhat, ess, reason):
    assert clip_verdict(100, 100, 100, rhat=rhat, ess=ess) == ("unreliable", [reason])
    assert clip_verdict(100, 100, 100, rhat=1.05, ess=150) == ("ok", [])


def test_a_multimodal_height_posterior_is_unreliable():
    rng = np.random.default_rng(2)
    two = np.r_[rng.normal(np.log(8), 0.03, 3000), rng.normal(np.log(16), 0.03, 2000)]
    verdict, reasons = clip_verdict(**GOOD, log_height_draws=two, log_height_prior_sd=2.0)  # wide prior
    assert verdict == "unreliable" and reasons == ["posterior multimodal (camera height modes 8.0 m, 16.0 m)"]
    skewed = rng.gamma(4.0, 0.05, 5000)  # one skewed mode is not two
    assert clip_verdict(**GOOD, log_height_draws=skewed, log_height_prior_sd=0.5) == ("ok", [])


def test_posterior_modes_known_answers():
    rng = np.random.default_rng(3)
    assert len(posterior_modes(rng.normal(0, 1, 5000))) == 1
    m = posterior_modes(np.r_[rng.normal(-2, 0.2, 2500), rng.normal(2, 0.2, 2500)])
    assert len(m) == 2 and abs(m[0] + 2) < 0.1 and abs(m[1] - 2) < 0.1
    # a small bump (5 % of the mass) under the threshold is not a mode
    assert len(posterior_modes(np.r_[rng.normal(0, 0.2, 4900), rng.normal(3, 0.2, 100)], min_rel_height=0.2)) == 1


def test_posterior_modes_do_not_depend_on_the_order_or_a_thinning_of_the_draws():
    """Two modes whose dip lies just below the threshold (two unit normals 3.6 apart): every
    draw counts, so sorted, as drawn or shuffled the answer is the same (the KDE of an even
    thinning to 5,000 draws once found one mode for some orders and two for others)."""
    rng = np.random.default_rng(7)
    x = np.r_[rng.normal(0, 1, 45000), rng.normal(3.6, 1, 45000)]
    found = [posterior_modes(v) for v in (np.sort(x), x, rng.permutation(x), rng.permutation(x))]
    assert all(len(m) == 2 for m in found)
    assert all(np.allclose(m, found[0]) for m in found)


def test_few_effective_draws_do_not_resolve_close_modes():
    """The kernel is sized by the effective sample size: 90,000 correlated draws worth 150
    independent ones cannot tell two modes 3.6 sd apart from one broad one (the dip is within
    the density's Monte Carlo error), while modes 8 sd apart stay two."""
    rng = np.random.default_rng(8)
    close = np.r_[rng.normal(0, 1, 45000), rng.normal(3.6, 1, 45000)]
    assert len(posterior_modes(close)) == 2
    assert len(posterior_modes(close, ess=150)) == 1
    far = np.r_[rng.normal(0, 1, 45000), rng.normal(8.0, 1, 45000)]
    assert len(posterior_modes(far, ess=150)) == 2
    # the verdict passes the height's ESS along
    v, r = clip_verdict(**{**GOOD, "ess": 150.0}, log_height_draws=0.02 * close, log_height_prior_sd=2.0)
    assert v == "ok", r
    v, r = clip_verdict(**{**GOOD, "ess": 150.0}, log_height_draws=0.02 * far, log_height_prior_sd=2.0)
    assert v == "unreliable" and r[0].startswith("posterior multimodal")


def test_a_prior_dominated_height_is_unreliable():
    rng = np.random.default_rng(4)
    verdict, reasons = clip_verdict(**GOOD, log_height_draws=rng.normal(np.log(12), 0.4, 4000),
                                    log_height_prior_sd=0.5)
    assert verdict == "unreliable" and reasons[0].startswith("prior-dominated height (posterior log-sd 0.40")
    assert clip_verdict(**GOOD, log_height_draws=rng.normal(np.log(12), 0.05, 4000),
                        log_height_prior_sd=0.5) == ("ok", [])


def test_weak_or_contradicting_side_evidence_is_unreliable():
    v, r = clip_verdict(**GOOD, side=_side(1.0, 0.2))
    assert v == "unreliable" and r == ["camera_side evidence ratio 3.32"]
    v, r = clip_verdict(**GOOD, side=_side(60.0, -40.0))
    assert v == "unreliable" and r[0].endswith("(cues disagree)")
    assert clip_verdict(**GOOD, side=_side(60.0, 40.0)) == ("ok", [])
    assert clip_verdict(**GOOD, side=_side(0.0, 0.0, source="given")) == ("ok", [])  # the user said so


def test_inconsistent_bone_lengths_are_unreliable(rng):
    F = 60
    j = np.zeros((F, 17, 3))
    for s in ("l", "r"):
        j[:, JOINT_INDEX[f"{s}_hip"]] = [0, 0, 0.9]
        j[:, JOINT_INDEX[f"{s}_knee"]] = [0, 0, 0.45]
        j[:, JOINT_INDEX[f"{s}_ankle"]] = [0, 0, 0.05]
        j[:, JOINT_INDEX[f"{s}_shoulder"]] = [0, 0, 1.4]
        j[:, JOINT_INDEX[f"{s}_elbow"]] = [0, 0, 1.1]
        j[:, JOINT_INDEX[f"{s}_wrist"]] = [0.25, 0, 1.1]
    noisy = j + rng.normal(0, 0.01, j.shape)  # ~1 cm: a clean lifting
    cv = bone_length_cv(noisy)
    assert max(cv.values()) < 10 and clip_verdict(**GOOD, bone_cv_pct=cv) == ("ok", [])
    broken = j.copy()
    broken[::3, JOINT_INDEX["l_ankle"]] = [0, 0.6, 0.3]  # every third shank is 70 % too long
    v, r = clip_verdict(**GOOD, bone_cv_pct=bone_length_cv(broken))
    assert v == "unreliable" and r[0].startswith("bone length cv") and r[0].endswith("(shank)")


def test_a_superhuman_running_speed_is_unreliable():
    # a camera that puts the athlete at the wrong scale makes them run 33 m/s; the fastest
    # sprinters reach about 12.4 m/s, a sprint at 11.5 m/s is fine
    assert clip_verdict(**GOOD, speed_mps=33.04) == ("unreliable", ["running speed 33.0 m/s"])
    assert clip_verdict(**GOOD, speed_mps=11.5) == ("ok", [])
    assert clip_verdict(**GOOD, speed_mps=float("nan")) == ("ok", [])


def test_a_stature_far_outside_its_prior_is_a_conflict():
    from probreg.inference import NormalPrior

    rng = np.random.default_rng(4)
    prior = NormalPrior(1.80, 0.16)
    verdict, reasons = clip_verdict(**GOOD, stature_draws=rng.normal(0.98, 0.03, 2000), stature_prior=prior)
    assert verdict == "unreliable" and reasons == ["stature prior conflict (posterior 0.98 m, prior 1.80 +- 0.16 m)"]
    # a short junior (1.52 m, 1.75 sd below the prior mean) is no conflict
    assert clip_verdict(**GOOD, stature_draws=rng.normal(1.52, 0.03, 2000), stature_prior=prior) == ("ok", [])


def test_an_undecided_family_branch_is_unreliable():
    from probreg.inference.evidence import BranchChoice

    close = BranchChoice("narrow", "evidence", {"narrow": -50.0, "wide": -51.5})
    assert clip_verdict(**GOOD, branch=close) == ("unreliable", ["branch evidence ratio 4.48"])
    clear = BranchChoice("wide", "evidence", {"narrow": -232.5, "wide": -93.2})
    assert clip_verdict(**GOOD, branch=clear) == ("ok", [])
    given = BranchChoice("narrow", "given", {"narrow": None})
    assert clip_verdict(**GOOD, branch=given) == ("ok", [])


def test_a_height_that_barely_fixes_the_camera_is_unreliable():
    """Near the family's top the focal length moves many percent per percent of height: flagged
    above 3.3 (and at the top itself, infinite); a broadcast camera (about 1) and an unknown
    sensitivity (NaN) are not."""
    verdict, reasons = clip_verdict(**GOOD, member_sensitivity=12.0)
    assert verdict == "unreliable"
    assert reasons == ["height barely fixes the camera (focal length 12 % per % of height)"]
    assert clip_verdict(**GOOD, member_sensitivity=float("inf")) == (
        "unreliable", ["height barely fixes the camera (the height interval reaches the family's top)"])
    assert clip_verdict(**GOOD, member_sensitivity=1.1) == ("ok", [])
    assert clip_verdict(**GOOD, member_sensitivity=3.2) == ("ok", [])  # either side of 3.3
    assert clip_verdict(**GOOD, member_sensitivity=3.4)[0] == "unreliable"
    assert clip_verdict(**GOOD, member_sensitivity=float("nan")) == ("ok", [])


def test_lanes_that_mostly_do_not_fit_the_camera_are_unreliable():
    assert clip_verdict(**GOOD, lanes_agree=(64, 100)) == ("unreliable", ["lanes_agree_frames 64/100"])
    # 80 % of the frames with lanes agree: ok; frames without lanes do not count against it
    assert clip_verdict(**GOOD, lanes_agree=(80, 100)) == ("ok", [])
    assert clip_verdict(**GOOD, lanes_agree=(60, 70)) == ("ok", [])
    assert clip_verdict(**GOOD, lanes_agree=(0, 0)) == ("ok", [])


def _trunk_with_noise(rng, rho, sd=3.0, F=250):
    """Keypoints of a still trunk (pelvis, spine, thorax) plus AR(1) noise of correlation ``rho``."""
    from probreg.inference.propagation import _ar1_noise

    kp = np.zeros((F, 17, 3))
    kp[..., 2] = 1.0
    kp[:, :, 1] = 500.0 - 10.0 * np.arange(17)  # joints apart, all still
    kp[..., :2] += _ar1_noise(rng, (F, 17, 2), sd, rho)
    return kp


def test_keypoint_noise_at_the_noise_models_bound_is_unreliable():
    from probreg.filtering import noise_model
    from probreg.filtering.basic import NOISE_RHO_MAX

    rng = np.random.default_rng(3)
    # moderately correlated noise: measured inside the model's range, no reason
    sd, rho = noise_model(_trunk_with_noise(rng, 0.5))
    assert abs(sd - 3.0) < 0.5 and abs(rho - 0.5) < 0.15
    assert clip_verdict(**GOOD, noise_rho=rho) == ("ok", [])
    # a slow drift (correlation 0.99): the fit ends at its bound, where the level is not identified
    sd, rho = noise_model(_trunk_with_noise(rng, 0.99))
    assert rho == NOISE_RHO_MAX
    verdict, reasons = clip_verdict(**GOOD, noise_rho=rho)
    assert verdict == "unreliable"
    assert reasons == ["keypoint noise unidentified (frame-to-frame correlation 0.90, the bound of the noise model)"]


@pytest.mark.parametrize("sd, flagged", [(4.0, False), (14.0, True)])
def test_knee_bands_too_wide_to_measure_the_knee_are_unreliable(sd, flagged):
    from probreg.inference import angle_bands, knee_band_width

    # 400 draws per frame of knees spread by ``sd``: the raw bootstrap band is 2 x 1.645 sd wide
    rng = np.random.default_rng(7)
    point = {k: np.full((400, 50), 60.0) for k in ("knee_l", "knee_r", "hip_l")}
    noisy = {k: 60.0 + rng.normal(0, sd if k != "hip_l" else 30.0, (400, 50)) for k in point}
    width = knee_band_width(angle_bands(point, noisy, inflation=1.0))
    assert abs(width - 2 * 1.645 * sd) < 0.1 * sd  # the hip's wide band does not count
    verdict, reasons = clip_verdict(**GOOD, knee_band_deg=width)
    assert (verdict == "unreliable") == flagged
    assert reasons == ([f"knee band wide (mean 90 % band {width:.1f} deg)"] if flagged else [])


def _runner(direction=(1.0, 0.0), n=50):
    """Joints whose pelvis runs 10 m at 1 m height in ``direction`` from the track's origin."""
    d = np.asarray(direction, float) / np.hypot(*direction)
    s = np.linspace(0.0, 10.0, n)
    pelvis = np.stack([s * d[0], s * d[1], np.ones(n)], 1)
    return np.repeat(pelvis[:, None], 17, 1)


@pytest.mark.parametrize("azimuth, elevation", [(0.0, 0.0), (20.0, 0.0), (50.0, 0.0), (0.0, 40.0), (30.0, 30.0)])
def test_view_obliquity_known_answers(azimuth, elevation):
    from probreg.geometry import Camera
    from probreg.inference.verdict import view_obliquity

    # every frame's camera sits on a ray from the runner's pelvis at a fixed azimuth (from the
    # sagittal normal, towards the direction of travel) and elevation: the view's angle from the
    # side is then known, arccos(cos az cos el)
    for direction in ((1.0, 0.0), (-1.0, 0.0), (1.0, 1.0)):
        joints = _runner(direction)
        d = np.append(np.asarray(direction) / np.hypot(*direction), 0.0)
        normal = np.array([-d[1], d[0], 0.0])
        a, e = np.radians(azimuth), np.radians(elevation)
        offset = 30.0 * (np.cos(e) * (np.cos(a) * -normal + np.sin(a) * d) + np.sin(e) * np.array([0, 0, 1.0]))
        cams = [Camera.look_at(p + offset, p, fov_deg=20.0) for p in joints[:, JOINT_INDEX["pelvis"]]]
        cams[3] = None  # a frame without a camera does not count
        want = np.degrees(np.arccos(np.cos(a) * np.cos(e)))
        assert view_obliquity(cams, joints) == pytest.approx(want, abs=1e-6)
    assert np.isnan(view_obliquity([None] * 50, joints))


@pytest.mark.parametrize("obliquity, flagged", [(20.0, False), (34.0, False), (48.4, True)])
def test_an_oblique_view_is_unreliable(obliquity, flagged):
    verdict, reasons = clip_verdict(**GOOD, obliquity_deg=obliquity)
    assert (verdict == "unreliable") == flagged
    assert reasons == ([f"oblique view ({obliquity:.0f} deg from the side)"] if flagged else [])
    assert clip_verdict(**GOOD, obliquity_deg=float("nan")) == ("ok", [])


def test_every_reason_the_verdict_gives_is_explained():
    from probreg.inference import NormalPrior
    from probreg.inference.evidence import BranchChoice
    from probreg.inference.verdict import explain_reason

    side = _side(0.5, -0.2)
    branch = BranchChoice("narrow", "evidence", {"narrow": -10.0, "wide": -11.0})
    rng = np.random.default_rng(3)
    _, reasons = clip_verdict(
        100, 10, 0, rhat=1.3, ess=40, log_height_draws=np.r_[rng.normal(1.0, 0.02, 500), rng.normal(1.6, 0.02, 500)],
        log_height_prior_sd=0.05, side=side, bone_cv_pct={"shank": 40.0}, speed_mps=30.0,
        stature_draws=np.full(50, 3.0), stature_prior=NormalPrior(1.80, 0.16),
        member_sensitivity=float("inf"), lanes_agree=(10, 100), noise_rho=0.9, knee_band_deg=50.0,
        obliquity_deg=60.0, knee_peak_deg=40.0, left_right_exchanged={"legs": 0.45}, branch=branch,
        limb_px=1.0, noise_px=2.0, fps=50.0)
    # every check fires once (ESS and multimodality from the same draws)
    starts = ("frames_with_angles", "calibrated_frames", "lanes_agree_frames", "R-hat", "ESS",  # no angles: not short
              "posterior multimodal", "prior-dominated height", "height barely fixes the camera",
              "camera_side evidence ratio", "branch evidence ratio", "bone length cv", "running speed",
              "stature prior conflict", "keypoint noise unidentified", "knee band wide", "oblique view",
              "knee flexion peak", "legs too short in the image", "left/right labels unsure")
    assert [next(r for r in reasons if r.startswith(k)) for k in starts]
    assert len(reasons) == len(starts)
    beyond = clip_verdict(100, 100, 100, knee_peak_deg=175.0)[1] + clip_verdict(10, 10, 10, fps=50.0)[1]
    for r in reasons + beyond + ["no plausible camera (...)", "lanes no_lines 40/40"]:
        meaning, todo = explain_reason(r)
        assert meaning and todo
    assert explain_reason("not a reason") is None


def _knees(peak, low=10.0, n=100, fps=50.0, cadence_hz=1.4):
    """Both knees of a runner whose flexion swings between ``low`` and ``peak`` deg, half a stride
    apart: a band summary as :func:`probreg.inference.angle_bands` gives it (median, lo, hi)."""
    t = np.arange(n) / fps
    out = {}
    for name, phase in (("knee_l", 0.0), ("knee_r", np.pi)):
        k = low + (peak - low) * 0.5 * (1 + np.sin(2 * np.pi * cadence_hz * t + phase))
        out[name] = (k, k - 5, k + 5)
    return out


def test_knee_flexion_peak_known_answers():
    from probreg.inference.verdict import knee_flexion_peak

    # the 95th percentile of a sinusoid between 10 and 110 deg: 10 + 100 (1 + sin(0.45 pi)) / 2
    want = 10 + 100 * 0.5 * (1 + np.sin(0.45 * np.pi))
    assert knee_flexion_peak(_knees(110.0), 50.0) == pytest.approx(want, abs=0.5)
    assert knee_flexion_peak(_knees(60.0), 50.0) == pytest.approx(10 + 50 * 0.5 * (1 + np.sin(0.45 * np.pi)), abs=0.5)
    # frames without a knee angle do not count; one knee alone is enough
    knees = _knees(110.0)
    gappy = {k: tuple(np.where(np.arange(100) % 4 == 0, np.nan, a) for a in v) for k, v in knees.items()}
    assert knee_flexion_peak(gappy, 50.0) == pytest.approx(want, abs=2.0)
    assert knee_flexion_peak({"knee_l": knees["knee_l"]}, 50.0) == pytest.approx(want, abs=0.5)
    # under a second of knee angles (here 0.8 s at 50 fps, 1.6 s at 25 fps): too short at 50 fps
    short = {k: tuple(a[:40] for a in v) for k, v in knees.items()}
    assert np.isnan(knee_flexion_peak(short, 50.0)) and np.isfinite(knee_flexion_peak(short, 25.0))
    assert np.isnan(knee_flexion_peak({"hip_l": knees["knee_l"]}, 50.0))


@pytest.mark.parametrize("peak, flagged", [(120.0, False), (85.0, False), (60.0, True), (35.0, True)])
def test_knees_that_never_bend_as_a_runners_do_are_unreliable(peak, flagged):
    from probreg.inference.verdict import knee_flexion_peak

    value = knee_flexion_peak(_knees(peak), 50.0)
    verdict, reasons = clip_verdict(**GOOD, knee_peak_deg=value)
    assert (verdict == "unreliable") == flagged
    assert reasons == ([f"knee flexion peak {value:.0f} deg"] if flagged else [])
    assert clip_verdict(**GOOD, knee_peak_deg=float("nan")) == ("ok", [])


def test_real_running_and_the_generators_runner_bend_the_knee_beyond_the_limit(shared_data):
    """The limit's premise: every real run of the CMU capture (7 runs, 4 subjects, 2.6-4.2 m/s) and
    probreg's own runner peak well above 80 deg."""
    from probreg.geometry.skeleton import joint_angles
    from probreg.inference.verdict import VerdictThresholds, knee_flexion_peak
    from probreg.sim import config_from_preset, synthesize

    limit, top = VerdictThresholds().min_knee_peak_deg, VerdictThresholds().max_knee_peak_deg
    for path in sorted((shared_data / "mocap").glob("*.npz")):
        d = np.load(path)
        a = joint_angles(d["joints3d"])
        peak = knee_flexion_peak({k: (np.asarray(a[k]),) * 3 for k in ("knee_l", "knee_r")}, float(d["fps"]))
        assert limit + 15 < peak < top - 25, (path.name, peak)  # and well inside the knee's range
    clip = synthesize(config_from_preset("run", 3, n_frames=100), seed=3, preset="run")
    a = joint_angles(clip.motion.joints_track_m)
    peak = knee_flexion_peak({k: (np.asarray(a[k]),) * 3 for k in ("knee_l", "knee_r")}, clip.config.fps)
    assert limit + 15 < peak < top - 25


@pytest.mark.parametrize("peak, flagged", [(135.0, False), (155.0, False), (165.0, True), (180.0, True)])
def test_knees_folded_beyond_a_human_knee_are_unreliable(peak, flagged):
    from probreg.inference.verdict import knee_flexion_peak

    value = knee_flexion_peak(_knees(peak, low=20.0), 50.0)
    verdict, reasons = clip_verdict(**GOOD, knee_peak_deg=value)
    assert (verdict == "unreliable") == flagged
    assert reasons == ([f"knee flexion beyond the knee's range (peak {value:.0f} deg)"] if flagged else [])


@pytest.mark.parametrize("limb_px, noise_px, flagged", [
    (45.0, 3.0, False),            # the validation clips' legs: 11-23 noise sds
    (9.5, 3.0, False),             # a bit over three noise sds
    (8.5, 3.0, True),              # under three
    (0.0, 0.0, True),              # every joint on one point, no noise to speak of
    (1.5, float("nan"), True),     # noise unknown: two pixels at least
    (5.0, None, False),
])
def test_legs_a_few_noise_sds_long_in_the_image_are_unreliable(limb_px, noise_px, flagged):
    verdict, reasons = clip_verdict(**GOOD, limb_px=limb_px, noise_px=noise_px)
    assert (verdict == "unreliable") == flagged
    if flagged:
        noise = f"{noise_px:.1f} px" if noise_px and np.isfinite(noise_px) else "unknown"
        assert reasons == [f"legs too short in the image ({limb_px:.1f} px, keypoint noise {noise})"]
    assert clip_verdict(**GOOD, limb_px=float("nan"), noise_px=3.0) == ("ok", [])


def test_leg_length_in_the_image_reads_thighs_and_shanks_only():
    from probreg.geometry import JOINT_INDEX
    from probreg.inference.verdict import limb_image_length

    rng = np.random.default_rng(2)
    kp = rng.normal(500, 300, (30, 17, 3))           # arms, trunk, head anywhere
    for s in ("l", "r"):
        kp[:, JOINT_INDEX[f"{s}_hip"], :2] = (100.0, 100.0)
        kp[:, JOINT_INDEX[f"{s}_knee"], :2] = (100.0, 160.0)   # thighs 60 px
        kp[:, JOINT_INDEX[f"{s}_ankle"], :2] = (148.0, 196.0)  # shanks 60 px
    assert limb_image_length(kp) == pytest.approx(60.0)
    kp[::2, JOINT_INDEX["l_knee"]] = np.nan          # a missing knee drops its two limbs, not the frame
    assert limb_image_length(kp) == pytest.approx(60.0)
    assert np.isnan(limb_image_length(np.full((5, 17, 2), np.nan)))


@pytest.mark.parametrize("frac, flagged", [(0.0, False), (0.3, False), (0.34, True), (0.5, True)])
def test_legs_relabelled_in_a_third_of_the_frames_are_unsure(frac, flagged):
    verdict, reasons = clip_verdict(**GOOD, left_right_exchanged={"legs": frac})
    assert (verdict == "unreliable") == flagged
    assert reasons == ([f"left/right labels unsure (legs exchanged in {100 * frac:.0f} % of frames)"]
                       if flagged else [])
    assert clip_verdict(**GOOD, left_right_exchanged={"legs": float("nan")}) == ("ok", [])


@pytest.mark.parametrize("frames, fps, flagged", [
    (12, 50.0, True),      # 0.24 s: a quarter of a stride
    (49, 50.0, True),
    (50, 50.0, False),     # one second: the limit
    (60, 50.0, False),     # the shortest validation clips (1.2 s)
    (24, 25.0, True),
    (40, 25.0, False),     # v07_random_25fps: 1.6 s
    (12, None, False),     # frame rate not given: no check
])
def test_clips_under_a_second_of_angles_are_short(frames, fps, flagged):
    verdict, reasons = clip_verdict(frames, frames, frames, rhat=1.01, ess=900, fps=fps)
    assert (verdict == "unreliable") == flagged
    if flagged:
        assert reasons == [f"short clip ({frames} frames with angles, {frames / fps:.2f} s; a stride takes ~0.7 s, "
                           "the checks need 1 s)"]
    # the frames that carry angles count, not the clip's frames
    assert clip_verdict(200, 200, frames, rhat=1.01, ess=900, fps=fps)[1][:1] == (reasons[:1] if flagged else [])
