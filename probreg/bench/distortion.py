"""Lens distortion: what ignoring it costs, what knowing it recovers, how sensitive results are.

Two clips, generated here with fixed seeds:

* ``wide_k25``: preset ``wide`` (seed 501; FOV about 30 deg, camera 6.9 m high and
  22 m from the athlete's lane) rendered through a strongly barrel-distorted
  lens, ``k1 = -0.25`` (the image corner moves about 26 px at the true focal length);
* ``distorted_a``: the benchmark suite's distorted clip (preset ``distorted``,
  seed 112; FOV about 10 deg, ``k1 = -0.063``: the corner moves < 1 px).

Each is run through ``probreg sensitivity`` (the whole pipeline per hypothesised
``k1``, default priors, the other coefficients at their true values) and every
hypothesis is scored against the ground truth as in ``bench posterior``: knee
error of the posterior median, pelvis-aligned MPJPE, camera height, location
and FOV.  The lane straightness column is the evidence the frames themselves
give (RMS px of the lane support points from straight lines after undistortion
under the hypothesis): the true lens should leave the straightest lines.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..inference import ModelPriors
from ..io.clip import load_groundtruth
from ..pipeline import RunOptions, run_clip
from ..sensitivity import distortion_study, lane_straightness_curve, plumb_line_summary
from ..sim import config_from_preset, synthesize, write_clip
from .common import BenchReport, md_table
from .posterior import score_result

__all__ = ["run", "CLIPS"]

#: name -> (preset, seed, k1 override or None, hypotheses)
CLIPS = {
    "wide_k25": ("wide", 501, -0.25, [-0.4, -0.25, -0.1, 0.0, 0.1]),
    "distorted_a": ("distorted", 112, None, [-0.2, 0.0, 0.2]),
}


def make_clip(name, out_dir, n_frames=250):
    """Generate one of :data:`CLIPS` (with images) into ``out_dir``."""
    preset, seed, k1, _ = CLIPS[name]
    cfg = config_from_preset(preset, seed, n_frames=n_frames)
    if k1 is not None:
        cfg = replace(cfg, camera=replace(cfg.camera, dist=(k1, 0.0, 0.0, 0.0, 0.0)))
    return write_clip(synthesize(cfg, seed=seed, preset=preset), out_dir, images=True, overwrite=True)


def run(args=None):
    rep = BenchReport("distortion", "Lens distortion: ignoring it, knowing it, sensitivity to it")
    rep.add(__doc__.split("\n\n", 1)[1])
    numbers = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (_, _, _, hyps) in CLIPS.items():
            clip = make_clip(name, Path(tmp) / name)
            gt = load_groundtruth(clip)
            true = np.asarray(gt.cameras[0].dist, float)
            ks = sorted(set(float(k) for k in hyps))  # the true k1 (the reference) is added by the study
            t0 = time.perf_counter()
            study = distortion_study(clip, Path(tmp) / f"{name}_sens", ks,
                                     RunOptions(report=False, dist=tuple(true)), log=lambda *a: None)
            dt = time.perf_counter() - t0
            rows = []
            for r in study.rows:
                s = score_result(clip, study.out_dir / r["result_dir"])
                rows.append([f"{r['k1']:+.3f}" + (" (true)" if np.isclose(r["k1"], true[0], atol=1e-4) else ""),
                             r["corner_shift_px"], r["lane_straightness_px"], s["knee_deg"], s["mpjpe_cm"],
                             s["height_pct"], s["loc_pct"], s["fov_deg"],
                             r["angles"]["knee_l"]["mean_abs_change_deg"] / 2
                             + r["angles"]["knee_r"]["mean_abs_change_deg"] / 2])
                numbers.setdefault(name, {})[f"{r['k1']:+.3f}"] = {
                    "knee_deg": s["knee_deg"], "mpjpe_cm": s["mpjpe_cm"], "height_pct": s["height_pct"],
                    "fov_deg": s["fov_deg"], "lane_straightness_px": r["lane_straightness_px"]}
            fov = float(np.median([c.fov_deg for c in gt.cameras]))
            rep.add(f"## {name}: true k1 = {true[0]:+.3f}, FOV {fov:.1f} deg, athlete "
                    f"{gt.athlete['stature_m']:.2f} m (prior mean 1.76 m); {len(study.rows)} runs in {dt:.0f} s\n")
            rep.add(md_table(["k1 assumed", "corner shift px", "lane straightness px", "knee err deg", "MPJPE cm",
                              "height err %", "location err %", "FOV err deg",
                              "knee change vs true-k1 run deg"], rows, floatfmt="{:.3f}"))
            best = min(study.rows, key=lambda r: np.nan_to_num(r["lane_straightness_px"], nan=np.inf))
            p = study.plumb_line
            rep.add(f"Straightest lane lines among the runs: k1 = {best['k1']:+.3f}. Plumb-line check on a "
                    f"41-value grid ({p['k1_grid'][0]:+.3f} to {p['k1_grid'][-1]:+.3f}) with the cameras of the "
                    f"straightest run (k1 = {p['cameras_of_k1']:+.3f}): straightest at k1 = {p.get('best_k1', float('nan')):+.3f} "
                    f"(curve range {p.get('range_px', float('nan')):.3f} px).\n")
            numbers[name]["plumb_line_k1"] = p.get("best_k1")
            # the same with the athlete's stature known (sd 2 cm): the metric scale no longer rests
            # on the stature prior, so what is left is the geometry of the lens hypothesis
            st = float(gt.athlete["stature_m"])
            priors = ModelPriors.from_options(stature=st, stature_sd=0.02)
            rows2 = []
            for k1 in (float(true[0]), 0.0):
                d = true.copy()
                d[0] = k1
                opts = RunOptions(report=False, priors=priors, dist=tuple(d) if np.any(d) else None)
                res = run_clip(clip, Path(tmp) / f"{name}_stature_{k1:+.3f}", opts, log=lambda *a: None)
                s2 = score_result(clip, res.out_dir)
                rows2.append([f"{k1:+.3f}" + (" (true)" if k1 == float(true[0]) else ""), s2["knee_deg"],
                              s2["mpjpe_cm"], s2["height_pct"], s2["loc_pct"], s2["fov_deg"]])
                numbers[name][f"stature_known_{k1:+.3f}"] = {k: s2[k] for k in ("knee_deg", "mpjpe_cm",
                                                                               "height_pct", "fov_deg")}
                if k1 == float(true[0]):
                    cams = res.model.cameras_at(res.height["median"])
                    grid = np.asarray(p["k1_grid"])
                    curve = lane_straightness_curve(res.model.reg.frame_lanes,
                                                    np.where(cams.valid, cams.focal_px, np.nan), grid, true)
                    k_pl = plumb_line_summary(grid, curve)["best_k1"]
                    numbers[name]["plumb_line_k1_stature_known"] = k_pl
            rep.add(f"With the athlete's stature known ({st:.2f} m, sd 2 cm):\n")
            rep.add(md_table(["k1 assumed", "knee err deg", "MPJPE cm", "height err %", "location err %",
                              "FOV err deg"], rows2, floatfmt="{:.3f}"))
            rep.add(f"Plumb-line check with these cameras: straightest at k1 = {k_pl:+.3f} (the k1 it reports "
                    "scales with the square of the focal length the run estimated).\n")
    rep.numbers = numbers
    return rep
