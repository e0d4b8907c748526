"""Cameras that move along the track: found by the feet-slide check, and static clips left alone.

Every clip of the rail set (:mod:`probreg.sim.rails`: 20 held-out set-ups whose camera runs on a
rail at 0, 1/4, 1/2, 3/4 or all of the runner's speed; seeds fixed before the check ran on any of
them) goes through the command line as a user runs it, ``probreg run CLIP --out OUT --seed 0``.
probreg assumes a static camera; the check (:func:`probreg.inference.gait_check.stance_slide`)
asks whether the planted feet stand still, and when they run backwards it makes the gait
verdict ``unreliable`` (``feet slide back ...``) with every gait number, the speed included.
Each result is scored against the ground truth:

* the feet-slide measure of ``run.json`` (``diagnostics.stance_slide.backslide``: the slower
  ankle's 20th-percentile along-track speed over the pelvis's; a planted foot seen from a camera
  moving at ``f`` of the runner's speed gives ``-f / (1 - f)``) and the gait verdict;
* the running speed of ``gait.json`` against the runner's true speed, the knee-angle error of
  the posterior median, the hip-angle and trunk-lean errors of ``angles.csv`` (since 0.2.0.dev20:
  a camera as fast as the runner leaves the ground track no velocity, and until then it could
  turn the running direction round and negate them), the stature and the camera height (at
  mid-clip for a moving camera) against the truth, and the clip verdict.

Static clips must not be flagged by it: the same is read from runs of the validation clips
(``shared/data/validation``, an independent generator) and of the held-out set (40 clips), with
their speed errors: the check also finds static clips whose along-track positions do not hold
together (the per-frame pan of a long lens), and whose speed is then wrong.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from ..io.clip import load_groundtruth
from .common import BenchReport, md_table, verdict_text
from .cuts import _run_kept, knee_errors
from .posterior import angle_error_deg
from .validation import judge_dirs, real_time_clips

__all__ = ["score_rail", "run"]


def _true_speed(athlete):
    return float(athlete.get("speed_mps") or (athlete.get("gait") or {}).get("speed_mps") or np.nan)


def score_rail(clip_dir: Path, out_dir: Path):
    """Scores of one result folder (a rail clip or a static one): feet slide, gait verdict, speed,
    knee, stature and camera height errors, clip verdict."""
    clip_dir, out_dir = Path(clip_dir), Path(out_dir)
    run = json.loads((out_dir / "run.json").read_text())
    gait = json.loads((out_dir / "gait.json").read_text()) if (out_dir / "gait.json").exists() else {}
    gt = load_groundtruth(clip_dir)
    err = knee_errors(gt, out_dir)
    ok = np.isfinite(err)
    slide = (run.get("diagnostics") or {}).get("stance_slide") or {}
    speed = (gait.get("speed_mps") or {}).get("median")
    stature = ((run.get("athlete") or {}).get("stature_m") or {}).get("median")
    cams = [c for c in gt.cameras if c is not None]
    height = (run.get("height_m") or {}).get("median")
    true_h = float(cams[len(cams) // 2].C[2]) if cams else np.nan
    rel = lambda est, true: 100 * (float(est) / true - 1) if est is not None and true > 0 else np.nan  # noqa: E731
    reasons = run.get("gait_verdict_reasons", [])
    backslide = slide.get("backslide")
    return {"backslide": float("nan") if backslide is None else float(backslide),
            "sliding": any(r.startswith("feet slide back") for r in reasons),
            "gait_verdict": run.get("gait_verdict", "n/a"), "gait_reasons": reasons,
            "speed_err_pct": rel(speed, _true_speed(gt.athlete)),
            "knee_deg": float(np.mean(err[ok])) if ok.any() else np.nan,
            "hip_deg": angle_error_deg(gt, out_dir, ("hip_l", "hip_r")),
            "trunk_lean_deg": angle_error_deg(gt, out_dir, ("trunk_lean",)),
            "track_off_heading": (run.get("diagnostics") or {}).get("track_off_heading"),
            "stature_err_pct": rel(stature, float(gt.athlete.get("stature_m", np.nan))),
            "height_err_pct": rel(height, true_h), "verdict": run.get("verdict", "n/a"),
            "reasons": run.get("verdict_reasons", [])}


def _row(name, s, *lead):
    return [name, *lead, s["backslide"], verdict_text(s["gait_verdict"], s["gait_reasons"]), s["speed_err_pct"],
            s["knee_deg"], s["hip_deg"], s["trunk_lean_deg"], s["stature_err_pct"], s["height_err_pct"],
            verdict_text(s["verdict"], s["reasons"])]


HEADER = ["feet slide (backslide)", "gait verdict (reasons)", "speed err %", "knee err deg", "hip err deg",
          "trunk lean err deg", "stature err %", "camera height err %", "clip verdict (reasons)"]


def _mean_abs(v):
    v = np.abs(np.asarray(v, float))
    return float(np.mean(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")


def run(args):
    rep = BenchReport("rails", "Cameras on a rail: the feet-slide check on moving and static cameras")
    rep.add(__doc__.split("\n", 1)[1].strip())
    from ..sim.rails import RAIL_SEEDS, rail_config, write_rail_clip

    with tempfile.TemporaryDirectory(prefix="probreg-bench-rails-") as tmp:
        root, keep = judge_dirs(args, tmp, "rails")
        rows, by_frac = [], {}
        for seed in RAIL_SEEDS:
            clip = write_rail_clip(root, seed)
            frac = rail_config(seed)[1]
            _run_kept(clip, keep / clip.name, ())
            if not (keep / clip.name / "run.json").exists():
                rows.append([clip.name, f"{frac:g}", "failed"] + [""] * (len(HEADER) - 1))
                continue
            s = score_rail(clip, keep / clip.name)
            by_frac.setdefault(frac, []).append(s)
            rows.append(_row(clip.name, s, f"{frac:g}"))
        rep.add("## Rail set (probreg's generator, held-out set-ups, 100 frames)\n\n"
                + md_table(["clip", "rail speed / runner's", *HEADER], rows))
        static_rows, static = [], []
        for clip in real_time_clips(args, tmp):
            out = keep / clip.name
            _run_kept(clip, out, ())
            if not (out / "run.json").exists():
                static_rows.append([clip.name, "failed"] + [""] * (len(HEADER) - 1))
                continue
            s = score_rail(clip, out)
            static.append((clip.name, s))
            static_rows.append(_row(clip.name, s))
        rep.add("## Static cameras (validation clips and held-out set)\n\n" + md_table(["clip", *HEADER], static_rows))
        summary = []
        for frac in sorted(by_frac):
            ss = by_frac[frac]
            summary.append([f"rail at {frac:g} of the runner's speed", f"{sum(s['sliding'] for s in ss)} of {len(ss)}",
                            float(np.nanmedian([s["backslide"] for s in ss])),
                            _mean_abs([s["speed_err_pct"] for s in ss]), _mean_abs([s["knee_deg"] for s in ss]),
                            _mean_abs([s["hip_deg"] for s in ss]), _mean_abs([s["stature_err_pct"] for s in ss]),
                            f"{sum(s['verdict'] != 'ok' for s in ss)} of {len(ss)}"])
        for label, group in (("static, feet-slide flagged", [s for _, s in static if s["sliding"]]),
                             ("static, not flagged by it", [s for _, s in static if not s["sliding"]])):
            summary.append([label, f"{len(group)} of {len(static)}",
                            float(np.nanmedian([s["backslide"] for s in group])) if group else float("nan"),
                            _mean_abs([s["speed_err_pct"] for s in group]), _mean_abs([s["knee_deg"] for s in group]),
                            _mean_abs([s["hip_deg"] for s in group]), _mean_abs([s["stature_err_pct"] for s in group]),
                            f"{sum(s['verdict'] != 'ok' for s in group)} of {len(group)}"])
        flagged = [n for n, s in static if s["sliding"]]
        rep.add("## Summary\n\n" + md_table(
            ["clips", "flagged by the feet-slide check", "median backslide", "mean abs speed err %",
             "mean knee err deg", "mean hip err deg", "mean abs stature err %", "clip verdict not ok"], summary)
            + ("\nStatic clips flagged: " + ", ".join(flagged) + ".\n" if flagged else ""))
        moving = [s for f, ss in by_frac.items() if f >= 0.5 for s in ss]
        rep.numbers.update({"rails_half_speed_or_more_flagged": sum(s["sliding"] for s in moving),
                            "rails_half_speed_or_more": len(moving),
                            "static_rails_flagged": sum(s["sliding"] for s in by_frac.get(0.0, [])),
                            "static_flagged": len(flagged), "static_clips": len(static)})
    return rep
