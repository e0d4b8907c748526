"""The whole pipeline for one clip: frames -> lanes -> family -> posterior -> angles -> result folder.

Writes the result layout of ``CLIP_FORMAT.md``: ``angles.csv``, ``joints3d.npz``, ``camera.json``,
``posterior.nc`` and ``report.html``; OpenSim's ``markers.trc`` and ``angles.mot`` (:mod:`probreg.io.opensim`)
and the gait-cycle curves ``gait_cycle.csv`` (:func:`probreg.inference.gait_cycle_bands`) (plus ``gait.json``
and ``run.json`` with diagnostics and per-frame statuses: ``ok``; ``bridged`` (no lanes in this frame, camera
interpolated from its neighbours); ``bridged_inconsistent`` (lanes found but their family leaves the clip's zoom
path, so it is treated like a frame without lanes); ``bridged_no_member`` (lanes found, but their family has no
member at the clip's camera height, e.g. a misdetected line; bridged likewise); ``inconsistent`` and
``no_member`` (the same two cases at the clip's start or end, where there is nothing to bridge from: no camera);
``missing_image`` (the clip has no image file for this frame: no camera), ``bad_image`` (its image does not
decode, or has another size) and ``bridged_missing_image``, ``bridged_bad_image`` (likewise, camera interpolated
from its neighbours); otherwise the lane status of the frame, e.g. ``too_few_lines``, ``no_straight``).

``run.json`` also holds the clip ``verdict`` (``"ok"``, ``"unreliable"`` or ``"uncalibrated"``,
:func:`probreg.inference.verdict.clip_verdict`) with ``verdict_reasons``, the camera side and the evidence for
both sides (``camera_side``), the notes about the input (``input_notes``: ignored files, missing images, absurd
keypoints, frames without a detection), the 2D keypoints' per-frame ``keypoint_status``
(:func:`probreg.filtering.detection_status`) and, when keypoints lay far outside the image, their count per
frame (``keypoints_outside_image``).
"""

from __future__ import annotations

import os
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .analysis import GAIT_FIELDS
from .calibration.lens import LensPrior, lens_registration
from .calibration.registration import camera_json, left_out_notes, register_clip
from .calibration.side import requested_side
from .filtering import detection_status
from .geometry import JOINT_INDEX, JOINT_NAMES
from .geometry.rays import _as_list
from .inference import (STATIC_INTERVAL_SCALE, ModelPriors, angle_bands, bootstrap_noise_ratio, gait_cycle_bands,
                        gait_check, gait_intervals, pattern_cadence_spm, speed_scatter, stance_slide, static_interval)
from .inference.heights import HEIGHT_SYSTEMATIC_SD, height_terms_note
from .inference.model import PARAM_NAMES, SEGMENTS, ClipModel, NoCalibrationError
from .inference.sampling import SamplerSettings
from .inference.evidence import BRANCHES, BranchChoice, laplace_log_evidence
from .inference.verdict import (bone_length_cv, clip_verdict, knee_band_width, knee_flexion_peak, limb_image_length,
                                trunk_down_fraction, view_obliquity)
from .inference.parallel import default_workers, fork_call, in_background, warm_imports
from .inference.time_base import time_base_check
from .inference.gait_check import with_time_base
from .io.clip import (FPS_RANGE, MIN_ATHLETE_FRAMES, MIN_ATHLETE_JOINTS, ClipFormatError, athlete_frames, load_clip,
                      with_slow_motion, write_json)
from .io.frames import has_frames
from .io.output import atomic_output_dir, prepare_output
from .io.provenance import software_versions
from .io.opensim import write_mot, write_trc
from .io.results import write_angles_csv, write_gait_cycle_csv, write_joints_npz
from .io.video import VIDEO_SUFFIXES, is_video, link_or_copy, probe_video  # noqa: F401 -- re-exported
from .lanes.shots import is_shot_option, restrict_clip

__all__ = ["RunOptions", "RunResult", "run_clip", "run_source", "detect_athlete", "probe_video", "is_video",
           "VIDEO_SUFFIXES", "posterior_inference_data"]


@dataclass(frozen=True)
class RunOptions:
    """Options of :func:`run_clip` (all settable from the command line)."""

    priors: ModelPriors = field(default_factory=ModelPriors)
    sampler: SamplerSettings = field(default_factory=SamplerSettings)
    dist: tuple | None = None
    # the lens when ``dist`` is not given: "infer" (k1 from the lane lines' curvature, sampled in
    # the posterior; :mod:`probreg.calibration.lens`) or "none" (assumed free of distortion)
    lens: str = "infer"
    lens_prior: LensPrior = field(default_factory=LensPrior)
    min_score: float = 0.3
    # the family branch: "auto" (decided by evidence, probreg.inference.evidence), "narrow" or "wide"
    branch: str = "auto"
    report: bool = True
    # move a non-empty output folder that holds files probreg did not write aside (never deleted)
    overwrite: bool = False
    # "auto" (decided by evidence; clip.json "camera_side" when given there), "main" or "far"
    camera_side: str = "auto"
    # None: the calibrated bands (probreg.inference.BAND_SCALE and BAND_CURVATURE_S2); a number
    # scales the bootstrap band by it, without the curvature term (1.0: raw bootstrap bands)
    band_inflation: float | None = None
    # systematic allowance on the camera height (sd of log height; 0: none): probreg.inference.heights
    height_allowance: float = HEIGHT_SYSTEMATIC_SD
    # progress(desc, total) -> a bar with update(n) and close() (e.g. tqdm); None: no bars
    progress: object = None
    # the shot estimated when a clip has cuts (lanes.shots): "longest", "all" (reason "camera cut") or its number
    shot: str = "longest"
    # a slow-motion replay's slow-down: the clip's fps times it is real time (inference.time_base)
    slow_motion: float = 1.0


@dataclass
class RunResult:
    out_dir: Path
    model: ClipModel | None
    posterior: object
    angle_summary: dict
    height: dict
    gait: dict
    diagnostics: dict
    timings: dict
    verdict: str = "ok"
    verdict_reasons: tuple = ()
    camera_side: object = None
    # (angle, side) -> (cycle_pct, median, lo, hi, n_cycles): gait_cycle.csv
    gait_cycle: dict = field(default_factory=dict)
    frame_status: list = field(default_factory=list)
    # run.json's "lens", "athlete" (stature, limb lengths: static_interval) and "band_decomposition"
    lens: dict = field(default_factory=dict)
    athlete: dict = field(default_factory=dict)
    band_decomposition: dict = field(default_factory=dict)
    branch: object = None  # the family branch (probreg.inference.evidence.BranchChoice)
    band_noise_ratio: dict = field(default_factory=dict)  # run.json's: bands.bootstrap_noise_ratio
    gait_verdict_reasons: tuple = ()  # run.json's: probreg.inference.gait_check (gait.json's "status")
    time_base: dict = field(default_factory=dict)  # run.json's: probreg.inference.time_base.time_base_check


#: report figures drawn in a forked process while the files are written (html.run_figures, html.posterior_figures)
REPORT_FIGURES_ELSEWHERE = ("angles", "gait_cycle", "decomposition")


def _arviz():
    with warnings.catch_warnings(action="ignore", category=FutureWarning):  # ArviZ announces its 1.0 refactor
        import arviz as az
    return az


def posterior_inference_data(sampler, burn=0, keypoints_px=None, frame_lanes=None, names=PARAM_NAMES):
    """ArviZ InferenceData from the emcee sampler (walkers as chains; ``posterior`` and
    ``sample_stats.lp`` as ``az.from_emcee`` makes them, built directly from the arrays, which is
    ~70x faster), with the observed keypoints and vanishing points as ``observed_data`` and
    derived quantities."""
    az = _arviz()

    chain = sampler.get_chain()[burn:]  # (draw, chain, D)
    idata = az.from_dict(posterior={n: chain[:, :, i].T for i, n in enumerate(names)},
                         sample_stats={"lp": sampler.get_log_prob()[burn:].T})
    post = idata.posterior
    post.attrs.update(inference_library="emcee", reported_interval_scale=STATIC_INTERVAL_SCALE)
    post["height_m"] = np.exp(post["log_height"])
    from .inference import SEGMENT_PROPORTIONS

    for s in SEGMENTS:
        post[f"{s}_m"] = post["stature"] * SEGMENT_PROPORTIONS[s] * post[f"m_{s}"]
    obs = {}
    if keypoints_px is not None:
        obs["keypoints_px"] = np.asarray(keypoints_px, float)
    if frame_lanes is not None:
        obs["vanishing_point"] = np.array([fl.vanishing_point if fl.vanishing_point is not None
                                           else np.full(3, np.nan) for fl in frame_lanes])
        obs["n_lane_lines"] = np.array([len(fl.lines) for fl in frame_lanes])
    if obs:
        dims = {"keypoints_px": ["frame", "joint", "coord"], "vanishing_point": ["frame", "homogeneous"],
                "n_lane_lines": ["frame"]}
        od = az.from_dict(observed_data=obs, dims=dims,
                          coords={"joint": list(JOINT_NAMES), "coord": ["x", "y", "score"], "homogeneous": list("xyw")})
        idata.extend(od)
    return idata


def _diagnostics(sampler, tau, idata, names=PARAM_NAMES):
    az = _arviz()

    post = idata.posterior[["log_height", "stature"]]
    ess, rhat = az.ess(post), az.rhat(post)
    return {
        "acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
        "tau": {n: float(t) for n, t in zip(names, tau)},
        "steps": int(sampler.iteration), "walkers": int(sampler.nwalkers),
        "steps_per_tau": float(sampler.iteration / np.max(tau)) if np.all(np.isfinite(tau)) else float("nan"),
        "ess_height": float(ess["log_height"]), "ess_stature": float(ess["stature"]),
        "rhat_height": float(rhat["log_height"]), "rhat_stature": float(rhat["stature"])}


#: how ``run.json``'s ``band_decomposition`` is computed (written beside it)
DECOMPOSITION_METHOD = (
    "one group at a time: lens (k1), camera (height), limbs (stature, proportions) vary over 16 posterior draws "
    "with the others at their posterior medians; the point liftings' variance (mean over frames) is the group's "
    "part; keypoints: the variance the bootstrap of the detector noise adds; shares = parts / their sum; "
    "parts_over_total = sum of parts / the band's variance (interactions are not attributed)")


def _lens_summary(options, lens, flat):
    """The lens of a run for ``camera.json`` (``k1``: median and 90 % interval) and ``run.json``:
    inferred (the posterior's ``k1`` draws), given (``--dist``) or assumed free of distortion."""
    if lens is not None and lens.given_k1 is None:
        return {"source": "inferred", **static_interval(flat[:, -1], positive=False),
                "prior_interval": list(options.lens_prior.interval(0.9)), **lens.to_dict()}
    k1 = float(options.dist[0]) if options.dist is not None else 0.0
    return {"source": "given" if options.dist is not None else "assumed", "median": k1, "lo": k1, "hi": k1,
            **(lens.to_dict() if lens is not None else {})}


def _frame_status(lanes, camera, inconsistent, gap_distance):
    """The ``run.json`` status of one frame (see the module docstring)."""
    if lanes.status in ("missing_image", "bad_image"):  # no image file, or one that does not decode
        return lanes.status if camera is None else f"bridged_{lanes.status}"
    if camera is None:
        if not lanes.ok:
            return lanes.status
        return "inconsistent" if inconsistent else "no_member"
    if inconsistent:
        return "bridged_inconsistent"
    if not lanes.ok:
        return "bridged"
    return "ok" if gap_distance == 0 else "bridged_no_member"


def _copy_extra(tmp, extra_files):
    for name, src in (extra_files or {}).items():
        (tmp / name).write_bytes(Path(src).read_bytes())


def _on_athlete(reg):
    """``run.json``'s ``diagnostics.keypoints_on_athlete``: the median over the shot's frames of
    :func:`probreg.lanes.on_athlete_fraction` (the lane step measures it), and how many frames
    had an image and a pose to measure it on."""
    lo, hi = reg.shots.frames
    v = np.array([fl.extra.get("on_athlete", np.nan) for fl in reg.frame_lanes[lo:hi]], float)
    v = v[np.isfinite(v)]
    return {"median": float(np.median(v)) if len(v) else float("nan"), "frames": int(len(v))}


def _write_uncalibrated(clip, reg, side, out_dir, options, error, t0, log, inputs, extra_files=None):
    """The result folder of a clip no frame of which calibrates: every file of the layout, with
    NaN angles and joints, null cameras, the lane status of every frame and the verdict
    ``"uncalibrated"`` (nothing is estimated without a camera)."""
    from .geometry import ANGLE_NAMES

    out_dir = Path(out_dir)
    F = clip.n_frames
    counts, message = reg.status_counts(), str(error)
    reasons = [f"calibrated_frames 0/{F}", f"frames_with_angles 0/{F}"] + (
        [f"no plausible camera ({message})"] if error.reason in ("no_plausible_height", "no_finite_posterior")
        else []) + [
        f"lanes {k} {v}/{F}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1])]
    status = [fl.status for fl in reg.frame_lanes]
    timings = {"total_s": time.perf_counter() - t0}
    nan = np.full(F, np.nan)
    summ = {k: (nan, nan, nan) for k in ANGLE_NAMES}
    with atomic_output_dir(out_dir, overwrite=options.overwrite, inputs=inputs, log=log) as tmp:
        _copy_extra(tmp, extra_files)
        write_angles_csv(tmp / "angles.csv", clip.fps, {k: nan for k in ANGLE_NAMES})
        write_joints_npz(tmp / "joints3d.npz", np.full((F, len(JOINT_NAMES), 3), np.nan))
        write_trc(tmp / "markers.trc", np.full((F, len(JOINT_NAMES), 3), np.nan), clip.fps)
        write_mot(tmp / "angles.mot", clip.fps, {k: nan for k in ANGLE_NAMES})
        write_gait_cycle_csv(tmp / "gait_cycle.csv", {})
        write_json(tmp / "camera.json", camera_json([None] * F, float("nan"), F))
        write_json(tmp / "run.json", {"verdict": "uncalibrated", "verdict_reasons": reasons, "error": message,
                                     "camera_side": side.to_dict(), "input_notes": list(clip.notes),
                                     "shots": reg.shots.to_dict() if reg.shots is not None else None,
                                     "timings_s": timings, "frame_status": status, "gait_verdict": "uncalibrated",
                                     "keypoint_status": detection_status(clip.keypoints_px),
                                     "lane_status_counts": counts, "gait_verdict_reasons": [],
                                     "software": software_versions()})
        result = RunResult(out_dir=out_dir, model=None, posterior=None, angle_summary=summ, height={},
                           gait={}, diagnostics={}, timings=timings, verdict="uncalibrated",
                           verdict_reasons=tuple(reasons), camera_side=side, frame_status=status)
        if options.report:
            from .report.html import uncalibrated_report

            uncalibrated_report(tmp / "report.html", clip, reg, result)
    log(f"uncalibrated: {message}; lane statuses {counts}")
    return result


def _branch_candidate(clip, reg, options, given, branch):
    """One branch's ``(registration, side, lens, model)`` (raises :class:`NoCalibrationError`)."""
    h0 = options.priors.camera_height.centre()
    side = reg.orient(h0, clip.keypoints_px, branch, fps=clip.fps, given=given)
    lens, model_reg, dist = None, reg, options.dist
    k1_only = dist is not None and dist[0] != 0 and not np.any(np.asarray(dist, float)[1:])
    if (dist is None and options.lens == "infer") or k1_only:
        # lines undistorted at their own best fit (default prior); a given k1 is then a sharp prior, and the
        # plumb line ties it to the focal length, i.e. the height (zoom ratios then chosen by the lines)
        lens, model_reg = lens_registration(reg, options.lens_prior, height_m=h0, zoom_from_lines=k1_only)
        if k1_only and lens is not None:
            lens, dist = replace(lens, prior=LensPrior.given(dist[0]), given_k1=float(dist[0])), None
    model = ClipModel(model_reg, clip.keypoints_px, clip.fps, clip.athlete_lane, priors=options.priors,
                      dist=dist, branch=branch, lens=lens, height_systematic_sd=options.height_allowance)
    return reg, side, lens, model


def _forked_evidence(clip, reg, options, given, branch):
    """Start the log evidence of ``branch`` in a forked process (the caller builds the other branch
    meanwhile); returns a function that waits for ``("ok", log_z)`` or ``("error", message)``."""
    parent = os.getpid()

    def work():  # a forked process changes its own copy of ``reg``; run here, it takes one
        try:
            r = reg if os.getpid() != parent else reg.branch_copy()
            return "ok", laplace_log_evidence(_branch_candidate(clip, r, options, given, branch)[3],
                                              seed=options.sampler.seed)[0]
        except NoCalibrationError as exc:
            return "error", (str(exc), exc.reason)

    return fork_call(work)


def _branch_models(clip, reg, options, given, log):
    """The clip model of the family branch the evidence picks (``options.branch``: ``"auto"``
    compares both, :mod:`probreg.inference.evidence`), with its own camera side and lens:
    ``(registration, side, lens, model, BranchChoice)``.  Raises :class:`NoCalibrationError`
    when no branch has a camera."""
    t0 = time.perf_counter()
    if options.branch != "auto":
        cand = _branch_candidate(clip, reg, options, given, options.branch)
        choice = BranchChoice(options.branch, "given", {options.branch: None})
    else:
        # the narrow branch (the usual broadcast camera) is built here, the wide one's evidence
        # comes from a forked process meanwhile; the wide model is built here only if it wins
        wide = _forked_evidence(clip, reg, options, given, "wide")
        logz, errors, reasons, cand = {}, {}, {}, None
        try:
            cand = _branch_candidate(clip, reg.branch_copy(), options, given, "narrow")
            logz["narrow"] = laplace_log_evidence(cand[3], seed=options.sampler.seed)[0]
        except NoCalibrationError as exc:
            errors["narrow"], reasons["narrow"] = str(exc), exc.reason
        status, value = wide()
        if status == "ok":
            logz["wide"] = float(value)
        else:
            errors["wide"], reasons["wide"] = value
        if not logz:
            reg.orient(options.priors.camera_height.centre(), clip.keypoints_px, "narrow", fps=clip.fps,
                       given=given)  # the side the uncalibrated result reports
            b = "narrow" if "narrow" in errors else "wide"
            raise NoCalibrationError(errors[b], reasons[b])
        chosen = max(logz, key=logz.get)
        choice = BranchChoice(chosen, "evidence" if len(logz) > 1 else "only",
                              {b: logz.get(b) for b in BRANCHES}, errors)
        if chosen == "wide":
            cand = _branch_candidate(clip, reg, options, given, "wide")
    r, side, lens, model = cand
    if model.temper_height_terms() < 1:  # after the choice: the branches' evidence compared them untempered
        log(f"warning: {height_terms_note(model.height_conflict)}: those terms tempered by {model.height_temper:.3g} "
            "(run.json diagnostics.height_terms)")
    model.timings["branch_s"] = time.perf_counter() - t0
    log(f"camera side: {side.chosen} ({side.source}; log-evidence ratio {side.log_ratio:.1f})")
    log(f"family branch: {choice.chosen} ({choice.source}"
        + (f"; log-evidence ratio {choice.log_ratio:.1f}" if np.isfinite(choice.log_ratio) else "") + ")")
    if lens is not None:
        log(("lens: k1 given, the lines undistorted at their own best fit" if lens.given_k1 is not None
             else "lens: k1 from the lane lines") + f" (corner shift {lens.kappa_star * lens.evidence.r_ref:+.2f} px "
            f"at the best fit; {lens.evidence.n_frames} frames, {lens.evidence.n_lines} lines)")
    return r, side, lens, model, choice


def run_clip(clip_dir, out_dir, options: RunOptions = RunOptions(), log=print, protect=(), extra_files=None):
    """Run the full pipeline on a clip folder and write the result folder.

    Raises
    ------
    ClipFormatError
        For a missing or malformed clip, a clip without frames or without keypoints.
    ValueError
        When the options do not fit the clip (e.g. a camera-height prior outside what the lanes allow).

    A clip no frame of which calibrates (no lanes of the straight anywhere) is not an error: its
    result folder is written with verdict ``"uncalibrated"``, NaN angles and every frame's lane status.

    ``protect``: more inputs the output may not be or lie in; ``extra_files`` ({name: path}): copied in.

    The run's numerical libraries (BLAS) use one thread: its work is shared out over processes
    (:mod:`probreg.inference.parallel`) on small arrays, and BLAS threads on top only compete
    with them (the benchmark suite's ``run_a`` with ``PROBREG_WORKERS=1``: the same wall time
    with or without them, 25 % less CPU without).  The caller's limits are restored afterwards.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _run_clip(clip_dir, out_dir, options, log, protect, extra_files)


def _run_clip(clip_dir, out_dir, options, log, protect, extra_files):
    t0 = time.perf_counter()
    # options that cannot work are refused before any work
    if options.lens not in ("infer", "none"):
        raise ValueError(f"lens must be 'infer' or 'none', got {options.lens!r}")
    if options.branch not in (*BRANCHES, "auto"):
        raise ValueError(f"branch must be auto, narrow or wide, got {options.branch!r}")
    if not is_shot_option(options.shot):
        raise ValueError(f"shot must be 'longest', 'all' or a shot's number, got {options.shot!r}")
    inputs = [clip_dir, *protect]
    prepare_output(out_dir, inputs=inputs, overwrite=options.overwrite)  # before any work
    clip = with_slow_motion(load_clip(clip_dir, min_score=options.min_score), options.slow_motion)
    for note in clip.notes:
        log(f"warning: {note}")
    if clip.keypoints_px is None:
        raise ClipFormatError(f"{clip_dir}: no keypoints2d.json (run 'probreg detect' first)")
    if not has_frames(clip):
        raise ClipFormatError(f"{clip_dir}: no frames/ folder or video.mp4")
    if (seen := athlete_frames(clip.keypoints_px)) < MIN_ATHLETE_FRAMES:
        raise ValueError(f"{clip_dir}: only {seen} frames have a detected athlete (at least {MIN_ATHLETE_JOINTS} "
                         f"joints); the model needs at least {MIN_ATHLETE_FRAMES}")
    given = requested_side(options.camera_side, clip.meta, clip.path / "clip.json")
    warm = []
    reg = register_clip(clip, progress=options.progress, started=lambda: warm.append(warm_imports()),
                        background=fork_call if default_workers() >= 2 else None, shot=options.shot)
    t1 = time.perf_counter()
    log(f"lanes: {reg.status_counts()} ({t1 - t0:.1f} s)")
    if reg.shots.split:  # one static camera per shot: the other shots' frames are left out, and said so
        clip = restrict_clip(clip, reg.shots)
        log(f"warning: {clip.notes[-1]}")
    for note in left_out_notes(reg):  # frames of another size or that do not decode are left out, and said so
        log(f"warning: {note}")
        clip = replace(clip, notes=(*clip.notes, note))
    for thread in warm:
        thread.join()  # before the branch evidence forks
    try:
        reg, side, lens, model, branch = _branch_models(clip, reg, options, given, log)
    except NoCalibrationError as exc:
        return _write_uncalibrated(clip, reg, reg.camera_side, out_dir, options, exc, t0, log, inputs, extra_files)
    smp = options.sampler
    # the bootstrap's re-noised keypoints do not depend on the posterior: made on the other core
    # while the sampler runs on this one (the propagation's workers make the rest)
    n_copies = -(-smp.n_draws // smp.draws_per_noise_copy)
    ahead = (model.bootstrap_copies_ahead(np.random.default_rng([smp.seed, 1]), n_copies)
             if model.bootstraps_noise(smp.bootstrap_noise) else None)
    sampler, tau = model.sample(smp, progress=options.progress)
    flat = sampler.get_chain().reshape(-1, len(model.param_names))  # (steps x walkers, D)
    rng = np.random.default_rng(smp.seed)
    draws = flat[rng.choice(len(flat), min(smp.n_draws, len(flat)), replace=False)]
    copies, seeds = ahead() if ahead is not None else (None, None)
    prop = model.propagate(draws, rng, bootstrap_noise=smp.bootstrap_noise, progress=options.progress,
                           draws_per_noise_copy=smp.draws_per_noise_copy, noise_copies=copies, noise_copy_seeds=seeds)
    joints, gait = prop["joints"], prop["gait"]
    decomposition = model.band_decomposition(draws, prop, rng)
    idata = posterior_inference_data(sampler, keypoints_px=clip.keypoints_px, frame_lanes=reg.frame_lanes,
                                     names=model.param_names)
    if options.report:
        from .report.html import posterior_figures, render_figures, run_report

        early = fork_call(lambda: posterior_figures(model.priors, idata))
    diag = _diagnostics(sampler, tau, idata, names=model.param_names)
    diag["height_terms"], diag["given_lens"] = model.height_conflict, model.given_lens_conflict()  # do they agree?
    height = static_interval(np.exp(flat[:, 0]))  # calibrated 90 % interval (and the model's own)
    athlete = {f"{k}_m": static_interval(v) for k, v in {"stature": flat[:, 1], **model.lengths(flat)}.items()}
    lens_doc = _lens_summary(options, lens, flat)
    with warnings.catch_warnings(action="ignore", category=RuntimeWarning):
        pa, pn = prop["angles_point"], prop["angles"]
        ratio = bootstrap_noise_ratio(prop["angle_noise_point"], prop["angle_noise"])  # 1 without bootstrap noise
        summ = angle_bands(pa, pn, clip.fps, inflation=options.band_inflation, noise_ratio=ratio)
        gait_s = {k: {"median": m, "lo": lo, "hi": hi, "unit": GAIT_FIELDS[k]} for k, (m, lo, hi) in
                  gait_intervals(prop["gait_point"], gait, inflation=options.band_inflation).items()}
        joints_med = np.nanmedian(prop["joints_point"], 0)
        cam_list = _as_list(model.cameras_at(height["median"]))
        diag["stance_slide"] = slide = stance_slide(cam_list, joints_med, clip.fps)  # do planted feet stand?
        diag["speed_scatter"] = spread = speed_scatter(joints_med, clip.fps, stride := model.stride_frames())
        diag["track_off_heading"] = off = model.track_off_heading(height["median"])  # a track run backwards?
        gait_s, gait_status, gait_reasons = gait_check(gait_s, stride, clip.fps, slide=slide, scatter=spread,
                                                       off_heading=off, lags=model.pattern_lags())
        time_base = {**time_base_check(model.kp, clip.fps, joints_med[:, JOINT_INDEX["pelvis"], 2], stride,
                                       gait_s.get("speed_mps", {}).get("median"), model.raw, slide.get("speed_mps")),
                     "slow_motion": options.slow_motion}
        gait_s, gait_status, gait_reasons = with_time_base(gait_s, gait_status, gait_reasons, time_base)  # rates off?
        cycles = gait_cycle_bands(pa, pn, model.contacts, inflation=options.band_inflation, noise_ratio=ratio,
                                  fps=clip.fps)
    timings = {"total_s": time.perf_counter() - t0, "lanes_s": t1 - t0, **model.timings}
    out_dir = Path(out_dir)
    n_angle = int(np.sum(np.any(np.isfinite(np.array([v[0] for v in summ.values()])), axis=0)))
    prior_h = options.priors.camera_height
    # the largest at the median and the model's 90 % interval's ends: a posterior that reaches
    # towards the family's fold is not pinned by the value at its median
    sens = [model.member_sensitivity(height[k]) for k in ("model_lo", "median", "model_hi")]
    sensitivity = max((v for v in sens if not np.isnan(v)), default=float("nan"))
    status = [_frame_status(reg.frame_lanes[i], c, bool(model.inconsistent[i]), model.gap_distance[i])
              for i, c in enumerate(cam_list)]
    agree = (status.count("ok"), sum(status.count(k) for k in ("ok", "bridged_no_member", "bridged_inconsistent")))
    diag["view_obliquity_deg"] = obliquity = view_obliquity(cam_list, joints_med)
    diag["knee_flexion_peak_deg"] = knee_peak = knee_flexion_peak(summ, clip.fps)
    diag["cadence_stride_pattern_spm"] = pattern_cadence_spm(model.stride_frames(), clip.fps)  # gait_check's
    diag["left_right_exchanged"] = exchanged = {"legs": float(model.exchanged[:, 0].mean())}  # the arms: never
    diag["leg_image_px"] = legs_px = limb_image_length(model.kp)  # thighs and shanks: long enough to read?
    diag["keypoints_on_athlete"] = on_athlete = _on_athlete(reg)  # are the keypoints on these images' athlete?
    diag["trunk_down_fraction"] = trunk_down = trunk_down_fraction(model.kp)  # y pointing up, not down?
    # frames whose two farthest lane lines merged into one ridge, left out (lanes.detection._merged_ends)
    diag["merged_far_lines_frames"] = [i for i, fl in enumerate(reg.frame_lanes) if fl.extra.get("merged_lines")]
    verdict, reasons = clip_verdict(  # over the frames of the shot estimated (all but with --shot all)
        reg.shots.frames[1] - reg.shots.frames[0], calibrated=sum(c is not None for c in cam_list),
        frames_with_angles=n_angle, cuts=reg.shots.cuts if reg.shots.chosen is None else None,
        rhat=diag["rhat_height"], ess=diag["ess_height"], log_height_draws=flat[:, 0],
        log_height_prior_sd=getattr(prior_h, "log_sd", None), side=side, bone_cv_pct=bone_length_cv(joints_med),
        speed_mps=gait_s.get("speed_mps", {}).get("median"),
        stature_draws=flat[:, 1], stature_prior=options.priors.stature, branch=branch,
        member_sensitivity=sensitivity, lanes_agree=agree, noise_rho=model.noise_rho,
        knee_band_deg=knee_band_width(summ), obliquity_deg=obliquity, knee_peak_deg=knee_peak,
        left_right_exchanged=exchanged, time_base=time_base, lens_conflict=diag.get("given_lens"),
        limb_px=legs_px, noise_px=model.noise_sd, fps=clip.fps, on_athlete=on_athlete["median"],
        trunk_down=trunk_down)
    result = RunResult(out_dir=out_dir, model=model, posterior=idata, angle_summary=summ, height=height,
                       gait=gait_s, diagnostics=diag, timings=timings, verdict=verdict,
                       verdict_reasons=tuple(reasons), camera_side=side, gait_cycle=cycles,
                       frame_status=status, lens=lens_doc, band_decomposition=decomposition,
                       branch=branch, athlete=athlete, band_noise_ratio=ratio, gait_verdict_reasons=tuple(gait_reasons),
                       time_base=time_base)
    # posterior.nc (xarray, ~0.5 s) is written on the other core, and has ended before the folder is kept or removed
    with atomic_output_dir(out_dir, overwrite=options.overwrite, inputs=inputs, log=log) as tmp, \
            in_background(lambda: idata.to_netcdf(str(tmp / "posterior.nc"))):
        if options.report:  # most figures render on the other core while the files are written here
            figures = fork_call(lambda: render_figures(clip, result, REPORT_FIGURES_ELSEWHERE))
        _copy_extra(tmp, extra_files)
        bands = [{k: v[i] for k, v in summ.items()} for i in range(3)]  # median, lo, hi per angle
        write_angles_csv(tmp / "angles.csv", clip.fps, *bands)
        write_joints_npz(tmp / "joints3d.npz", joints_med, samples=joints)
        write_trc(tmp / "markers.trc", joints_med, clip.fps)
        write_mot(tmp / "angles.mot", clip.fps, *bands)
        write_gait_cycle_csv(tmp / "gait_cycle.csv", cycles)
        cj = camera_json(cam_list, height["median"], clip.n_frames, height["lo"], height["hi"])
        cj["k1"] = {k: lens_doc[k] for k in ("median", "lo", "hi", "source")}
        write_json(tmp / "camera.json", cj)
        write_json(tmp / "gait.json", gait_s)
        extra = {} if (kpo := clip.keypoints_outside) is None else {"keypoints_outside_image": kpo.tolist()}
        write_json(tmp / "run.json", {"verdict": verdict, "verdict_reasons": reasons,
                                     "gait_verdict": gait_status, "gait_verdict_reasons": gait_reasons,
                                     "camera_side": side.to_dict(), "branch": branch.to_json(),
                                     "shots": reg.shots.to_dict(), "input_notes": list(clip.notes), **extra,
                                     "time_base": time_base, "diagnostics": diag, "timings_s": timings,
                                     "height_m": height, "height_member_sensitivity": sensitivity,
                                     "height_allowance": options.height_allowance, "athlete": athlete,
                                     "lens": lens_doc, "band_decomposition": decomposition,
                                     "band_decomposition_method": DECOMPOSITION_METHOD,
                                     "frame_status": status, "keypoint_status": detection_status(model.raw, model.kp),
                                     "noise_px": model.noise_sd,
                                     "noise_rho": model.noise_rho, "band_noise_ratio": ratio, "n_draws": len(draws),
                                     "priors": options.priors.describe(), "software": software_versions()})
        if options.report:  # a failure in a process draws its figures again here, and raises as itself
            run_report(tmp / "report.html", clip, result, joints_med, cam_list, rendered={**early(), **figures()})
    if gait_reasons:
        log(f"warning: gait numbers from the contacts unreliable ({'; '.join(gait_reasons)}): see gait.json's status")
    log(f"height {height['median']:.2f} m [{height['lo']:.2f}, {height['hi']:.2f}]; "
        f"{diag['steps']} steps (tau max {max(diag['tau'].values()):.0f}); total {timings['total_s']:.1f} s")
    return result


def detect_athlete(clip, model_path, det_model=None, athlete=None, min_score=0.3, progress=None):
    """H36M keypoints (F, 17, 3) of the athlete in every frame of ``clip`` with an ONNX pose model.

    The athlete is the person the camera follows: by default the large, central person of the
    first frames, then followed from frame to frame (:func:`probreg.detect.detect_sequence`);
    ``athlete`` = ``(x, y)`` (a point on them) or ``(x0, y0, x1, y1)`` (their box) in the first
    frame picks another one.
    """
    from .detect import detect_sequence, load_pose_model
    from .geometry import coco_to_h36m
    from .io.frames import iter_frames_counted

    model = load_pose_model(model_path)
    detector = load_pose_model(det_model) if det_model else None
    box = point = None
    if athlete is not None:
        a = [float(v) for v in athlete]
        if len(a) == 2:
            point = a
        elif len(a) == 4:
            box = a
        else:
            raise ValueError(f"--athlete takes x,y (a point on the athlete) or x0,y0,x1,y1 (their box), got {athlete}")
    if model.needs_box and detector is None and box is None:
        raise ValueError(f"{model_path} is a top-down model: it needs --det-model (a YOLO-pose model that finds "
                         f"the person) or the athlete's box in the first frame (run: --athlete, detect: --box)")
    frames = iter_frames_counted(clip, progress, "detection")
    try:
        coco = detect_sequence(frames, model, detector, box=box, point=point, min_score=min_score)
    finally:
        frames.close()
    return coco_to_h36m(coco)


def run_source(source, out_dir, options: RunOptions = RunOptions(), model=None, det_model=None, athlete=None,
               fps=None, log=print, extra_files=None):
    """``probreg run``: a clip folder, or a video file, to a result folder.

    A video (:data:`VIDEO_SUFFIXES`) is decoded with OpenCV and needs ``model`` (an ONNX pose
    model): the athlete is detected and followed in every frame, then the clip runs as a clip
    folder would.  A clip folder runs as it is; with ``model`` its keypoints are detected anew
    (its own ``keypoints2d.json`` is left untouched).  The detected keypoints (``keypoints2d.json``)
    and the clip description used (``input_clip.json``) are kept in the result folder.
    """
    import tempfile

    from .io.clip import write_keypoints_json

    if fps is not None and not FPS_RANGE[0] <= float(fps) <= FPS_RANGE[1]:  # NaN fails too
        raise ValueError(f"--fps must be a frame rate between {FPS_RANGE[0]:g} and {FPS_RANGE[1]:g}, got {fps}")
    source = Path(source)
    video = is_video(source)
    if not video and model is None:
        return run_clip(source, out_dir, options, log=log, extra_files=extra_files)
    if video and model is None:
        raise ValueError(f"{source} is a video: give a pose model with --model POSE.onnx to find the athlete "
                         f"(see the README: 'A pose model')")
    prepare_output(out_dir, inputs=[source], overwrite=options.overwrite)
    with tempfile.TemporaryDirectory(prefix="probreg-clip-") as scratch:
        clip_dir = Path(scratch) / (source.stem if video else source.name)
        clip_dir.mkdir()
        if video:
            rate, size, n = probe_video(source, fps)
            link_or_copy(source, clip_dir / "video.mp4")
            write_json(clip_dir / "clip.json", {"fps": rate, "image_size": list(size), "n_frames": n,
                                                "source": {"video": str(source)}})
            log(f"video: {n} frames, {size[0]}x{size[1]}, {rate:g} fps")
        else:
            if not (source / "clip.json").is_file():
                raise ClipFormatError(f"{source}: no clip.json (not a clip folder)")
            (clip_dir / "clip.json").write_bytes((source / "clip.json").read_bytes())
            for name in ("frames", "video.mp4"):
                if (source / name).exists():
                    link_or_copy(source / name, clip_dir / name)
        clip = load_clip(clip_dir, min_score=options.min_score)
        if not has_frames(clip):
            raise ClipFormatError(f"{source}: no frames to detect the athlete in")
        kp = detect_athlete(clip, model, det_model, athlete, min_score=options.min_score, progress=options.progress)
        found = int(np.sum(np.isfinite(kp[:, 0, 0])))
        log(f"detection: athlete found in {found}/{len(kp)} frames")
        write_keypoints_json(clip_dir / "keypoints2d.json", kp)
        return run_clip(clip_dir, out_dir, options, log=log, protect=[source],
                        extra_files={"keypoints2d.json": clip_dir / "keypoints2d.json",
                                     "input_clip.json": clip_dir / "clip.json", **(extra_files or {})})
