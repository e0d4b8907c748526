"""How much do the results depend on the lens distortion assumed?

Broadcast zoom lenses are rarely calibrated, and the distortion they have at a
given zoom is usually unknown.  A sports scientist who reports knee angles
from such footage wants to know whether that matters for *their* clip.
:func:`distortion_study` answers it the direct way: the whole pipeline
(lanes -> family -> posterior -> angles, :func:`probreg.pipeline.run_clip`)
is run once per hypothesised radial coefficient ``k1`` (the other
coefficients held at the nominal ``--dist``), and the results are compared
with the reference hypothesis:

* camera height and FOV (median and 90 % interval);
* every angle: mean and largest per-frame change of the posterior median, and
  the mean width of its 90 % band (is the change small against the band?);
* the gait summaries (cadence, step length, peak swing knee flexion, ...);
* lane evidence: how straight the lane lines are once undistorted under the
  hypothesis (RMS distance of their support points from straight lines, with
  each frame's posterior-median focal length).  Lines of the straight *are*
  straight, so the hypotheses that leave them straightest are the ones the
  image supports; with few, short lines in a zoomed-in view this evidence is
  weak, and the table says how weak.

``k1`` acts on normalised image coordinates (OpenCV), so the same ``k1``
moves pixels far less at a narrow field of view; the table also gives each
hypothesis as the displacement of the image corner in pixels at the clip's
median focal length, which is what can be compared between zoom levels.

Every hypothesis writes a complete result folder (``OUT/k1_+0.100/...``), and so does a
run with the lens inferred from the lanes (``OUT/lens_inferred``: ``k1`` sampled in the
posterior, :mod:`probreg.calibration.lens`); ``OUT/sensitivity.json``, ``sensitivity.csv`` and
``sensitivity.md`` hold the comparison, ``sensitivity.png`` each angle's band with the lens
inferred against every fixed ``k1``, and ``decomposition.png`` the shares of the inferred run's
bands due to the lens, the camera, the limbs and the keypoints.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .geometry import fov_from_focal
from .io.clip import write_json
from .lanes import line_straightness_px, undistort_frame_lanes
from .io import atomic_output_dir, load_clip
from .pipeline import RunOptions, run_clip

__all__ = ["DistortionStudy", "corner_shift_px", "distortion_study", "lane_straightness_curve", "parse_k1_list",
           "plumb_line_summary"]

ANGLES = ("knee_l", "knee_r", "hip_l", "hip_r", "elbow_l", "elbow_r", "trunk_lean")
ANGLE_STATS = ("mean_deg", "mean_abs_change_deg", "max_abs_change_deg", "mean_band_deg")
GAIT = ("cadence_spm", "step_length_m", "speed_mps", "contact_time_s", "flight_time_s",
        "peak_knee_flexion_swing_deg", "knee_flexion_touchdown_deg")


def corner_shift_px(dist, focal_px, image_size):
    """Radial displacement (px) that ``dist`` causes at the image corner.

    Positive: pushed outwards (pincushion); negative: pulled inwards (barrel).

    >>> round(corner_shift_px([-0.1, 0, 0, 0, 0], 2000.0, (1920, 1080)), 2)
    -33.35
    >>> corner_shift_px([0, 0, 0, 0, 0], 2000.0, (1920, 1080))
    0.0
    """
    k1, k2, _, _, k3 = (float(v) for v in np.asarray(dist, float).reshape(5))
    w, h = image_size
    r = math.hypot((w - 1) / 2, (h - 1) / 2) / float(focal_px)
    r2 = r * r
    return float(focal_px * r * r2 * (k1 + r2 * (k2 + r2 * k3)))


def parse_k1_list(text):
    """``"-0.2,-0.1,0,0.1"`` -> sorted unique floats; clear errors for bad values.

    >>> parse_k1_list("0.1, -0.1,0")
    [-0.1, 0.0, 0.1]
    >>> parse_k1_list("0.1,abc")
    Traceback (most recent call last):
    ...
    ValueError: --k1: 'abc' is not a number
    """
    vals = []
    for tok in str(text).split(","):
        tok = tok.strip()
        if not tok:
            continue
        try:
            vals.append(float(tok))
        except ValueError:
            raise ValueError(f"--k1: {tok!r} is not a number") from None
    return _checked_k1(vals)


def _checked_k1(values):
    """Sorted unique hypotheses; clear errors for none, NaN or implausible values."""
    vals = [float(v) for v in values]
    for v in vals:
        if not math.isfinite(v) or abs(v) >= 1.0:
            raise ValueError(f"--k1: {v} is outside (-1, 1); radial coefficients of real lenses are far smaller")
    if not vals:
        raise ValueError("--k1: give at least one value, e.g. --k1=-0.1,0,0.1")
    return sorted(set(vals))


@dataclass
class DistortionStudy:
    """Result of :func:`distortion_study`: one row per hypothesis (dicts, JSON-ready)."""

    rows: list
    reference_k1: float
    out_dir: Path
    plumb_line: dict = field(default_factory=dict)
    # the run with the lens inferred from the lanes (k1 interval, angles, band_decomposition)
    inferred: dict = field(default_factory=dict)

    def row(self, k1):
        for r in self.rows:
            if np.isclose(r["k1"], k1):
                return r
        raise KeyError(k1)

    def to_markdown(self):
        ref = self.reference_k1
        lines = [f"Reference hypothesis: k1 = {ref:+.3f}. Angle changes are of the posterior median, "
                 "per frame, against the reference; the band is the mean width of the 90 % band.", "",
                 "| k1 | corner shift (px) | lane straightness (px) | height (m) [90 %] | FOV (deg) | "
                 "knee: mean / max change (deg) | knee band (deg) | hip: mean / max change | "
                 "elbow: mean / max change | step length (m) | peak swing knee (deg) | frames ok |",
                 "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in self.rows:
            a = r["angles"]

            def ch(*names):
                m = [a[n]["mean_abs_change_deg"] for n in names if n in a]
                x = [a[n]["max_abs_change_deg"] for n in names if n in a]
                return f"{np.nanmean(m):.2f} / {np.nanmax(x):.2f}" if m else "-"

            band = np.nanmean([a[n]["mean_band_deg"] for n in ("knee_l", "knee_r") if n in a])
            g = r["gait"]
            lines.append(
                f"| {r['k1']:+.3f} | {r['corner_shift_px']:+.1f} | {r['lane_straightness_px']:.3f} | "
                f"{r['height_m']['median']:.2f} [{r['height_m']['lo']:.2f}, {r['height_m']['hi']:.2f}] | "
                f"{r['fov_deg']:.2f} | {ch('knee_l', 'knee_r')} | {band:.1f} | {ch('hip_l', 'hip_r')} | "
                f"{ch('elbow_l', 'elbow_r')} | {g.get('step_length_m', {}).get('median', float('nan')):.2f} | "
                f"{g.get('peak_knee_flexion_swing_deg', {}).get('median', float('nan')):.1f} | "
                f"{r['frames_ok']} |")
        best = min(self.rows, key=lambda r: (np.nan_to_num(r["lane_straightness_px"], nan=np.inf)))
        lines += ["", f"Straightest lane lines under k1 = {best['k1']:+.3f} "
                  f"({best['lane_straightness_px']:.3f} px RMS; spread over the hypotheses "
                  f"{_spread([r['lane_straightness_px'] for r in self.rows]):.3f} px)."]
        p = self.plumb_line
        if "best_k1" in p:
            g = np.asarray(p["k1_grid"])
            lines += ["", f"Plumb-line check on a finer grid ({g[0]:+.3f} to {g[-1]:+.3f}, with the cameras of "
                      f"the k1 = {p['cameras_of_k1']:+.3f} run): straightest at k1 = {p['best_k1']:+.3f} "
                      f"({p['best_px']:.3f} px)"
                      + ("; at the edge of the grid, so the lanes favour a value beyond it" if p["at_edge"] else "")
                      + (f"; the curve varies by only {p['range_px']:.3f} px over the grid, so the lanes hardly "
                         "constrain the lens here" if p["range_px"] < 0.02 else "") + "."]
        inf = self.inferred
        if inf.get("angles"):
            k = inf["k1"]
            lines += ["", f"Lens inferred from the lanes (``lens_inferred/``): k1 {k['median']:+.3f} "
                      f"(90 % interval {k['lo']:+.3f} to {k['hi']:+.3f}).", "",
                      "| angle | band, lens inferred (deg) | "
                      + " | ".join(f"band, k1 {r['k1']:+.3f}" for r in self.rows)
                      + " | inferred vs reference: mean change (deg) | lens / camera / limbs / keypoints share |",
                      "|---|---|" + "---|" * len(self.rows) + "---|---|"]
            for name, a in inf["angles"].items():
                d = inf.get("band_decomposition", {}).get(name) or {}
                share = " / ".join(f"{d[g]:.2f}" if d.get(g) is not None else "-"
                                   for g in ("lens", "camera", "limbs", "keypoints"))
                lines.append(f"| {name} | {a['mean_band_deg']:.1f} | "
                             + " | ".join(f"{r['angles'].get(name, {}).get('mean_band_deg', float('nan')):.1f}"
                                          for r in self.rows)
                             + f" | {a['mean_abs_change_deg']:.2f} | {share} |")
        return "\n".join(lines) + "\n"


def _spread(v):
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(np.ptp(v)) if len(v) else float("nan")


def _focal(cams):
    """Per-frame focal lengths of CameraArrays, NaN where a frame has no camera."""
    return np.where(cams.valid, cams.focal_px, np.nan)


def _lane_straightness(result, dist):
    """Straightness of all of a run's frames under its own hypothesis ``dist``, with the frames'
    posterior-median focal lengths; also returns those cameras."""
    cams = result.model.cameras_at(result.height["median"])
    curve = lane_straightness_curve(result.model.reg.frame_lanes, _focal(cams), [dist[0]], dist, max_frames=None)
    return float(curve[0]), cams


def lane_straightness_curve(frame_lanes, focal_px, k1_grid, base_dist=None, max_frames=60):
    """Lane straightness (median over frames, px) as a function of the assumed ``k1``.

    A plumb-line check: lines of the straight are straight, so the ``k1`` that
    leaves them straightest is the one the frames support.  Each frame's lines
    are undistorted with its own focal length (``focal_px``, e.g. the
    posterior-median cameras'); up to ``max_frames`` frames, evenly spaced, are used
    (None: all of them).

    Returns
    -------
    ndarray (len(k1_grid),)
        NaN where no frame has lines.
    """
    base = np.zeros(5) if base_dist is None else np.asarray(base_dist, float).reshape(5)
    focal_px = np.asarray(focal_px, float)
    idx = [i for i, fl in enumerate(frame_lanes) if fl.ok and np.isfinite(focal_px[i])]
    if max_frames is not None and len(idx) > max_frames:
        idx = [idx[int(j)] for j in np.linspace(0, len(idx) - 1, max_frames).round()]
    out = np.full(len(k1_grid), np.nan)
    for j, k1 in enumerate(k1_grid):
        d = base.copy()
        d[0] = float(k1)
        vals = [line_straightness_px(undistort_frame_lanes(frame_lanes[i], d, float(focal_px[i]))
                                     if np.any(d) else frame_lanes[i]) for i in idx]
        vals = np.asarray(vals, float)
        if np.isfinite(vals).any():
            out[j] = float(np.nanmedian(vals))
    return out


def plumb_line_summary(k1_grid, curve):
    """Where a :func:`lane_straightness_curve` is lowest, and how telling it is.

    Returns a dict with ``k1_grid`` and ``straightness_px`` and, when the curve has a
    finite value, ``best_k1``, ``best_px``, ``at_edge`` (the minimum is at an end of the
    grid) and ``range_px`` (max - min; a few hundredths of a px: the lanes hardly constrain
    the lens).

    >>> plumb_line_summary([-0.2, -0.1, 0.0], [0.3, 0.1, 0.2])["best_k1"]
    -0.1
    """
    grid, curve = np.asarray(k1_grid, float), np.asarray(curve, float)
    out = {"k1_grid": grid.tolist(), "straightness_px": curve.tolist()}
    if np.isfinite(curve).any():
        j = int(np.nanargmin(curve))
        out.update(best_k1=float(grid[j]), best_px=float(curve[j]), at_edge=bool(j in (0, len(grid) - 1)),
                   range_px=float(np.nanmax(curve) - np.nanmin(curve)))
    return out


def distortion_study(clip_dir, out_dir, k1_values, options: RunOptions = RunOptions(), reference_k1=None,
                     log=print, infer=True):
    """Run the pipeline once per hypothesised ``k1`` and compare the results.

    Parameters
    ----------
    clip_dir : path
        A clip folder (``CLIP_FORMAT.md``) with frames and keypoints.
    out_dir : path
        Gets one result folder per hypothesis and the comparison files.
    k1_values : sequence of float
        Hypothesised radial coefficients (OpenCV, normalised coordinates).
    options : RunOptions
        As for ``probreg run``; ``options.dist`` gives the nominal distortion whose
        other coefficients are kept (and whose ``k1`` is the default reference).
    reference_k1 : float or None
        Hypothesis the others are compared with (added to the runs when missing);
        default: the nominal ``k1`` when ``options.dist`` is given, else 0 if it is
        among the values, else the first value.
    infer : bool
        Also run the clip with the lens inferred from its lanes (``OUT/lens_inferred``): its
        ``k1`` interval, each angle's band against those of the fixed ``k1`` runs and the band
        decomposition (``sensitivity.png``, ``decomposition.png``).

    Returns
    -------
    DistortionStudy

    Raises
    ------
    ValueError
        For an empty or invalid list of hypotheses; errors of :func:`run_clip`
        (missing clip, no lanes, ...) pass through unchanged.
    """
    ks = _checked_k1(k1_values)
    if Path(clip_dir).is_dir() or not Path(clip_dir).exists():
        load_clip(clip_dir)  # the clip's input errors before the first of the runs starts
    base = np.zeros(5) if options.dist is None else np.asarray(options.dist, float).reshape(5)
    if reference_k1 is None:
        reference_k1 = (float(base[0]) if options.dist is not None else 0.0 if any(np.isclose(0.0, ks))
                        else ks[0])
    reference_k1 = float(reference_k1)
    # a hypothesis within 5e-4 of the reference is the reference (no near-duplicate runs)
    ks = sorted([k for k in ks if abs(k - reference_k1) >= 5e-4] + [reference_k1])
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=options.overwrite, inputs=[clip_dir], log=log) as tmp:
        study = _study_into(tmp, clip_dir, ks, base, reference_k1, options, log, infer=infer)
    return replace(study, out_dir=out_dir)


def _angle_changes(res, ref_res):
    """Per angle of ``res``: its mean, the mean and largest per-frame change of its posterior
    median against ``ref_res``, and the mean width of its 90 % band."""
    angles = {}
    for name in ANGLES:
        if name not in res.angle_summary or name not in ref_res.angle_summary:
            continue
        med, lo, hi = res.angle_summary[name]
        diff = np.abs(med - ref_res.angle_summary[name][0])
        ok = np.isfinite(diff)
        angles[name] = {"mean_deg": float(np.nanmean(med)),
                        "mean_abs_change_deg": float(np.mean(diff[ok])) if ok.any() else float("nan"),
                        "max_abs_change_deg": float(np.max(diff[ok])) if ok.any() else float("nan"),
                        "mean_band_deg": float(np.nanmean(hi - lo))}
    return angles


def _inferred_run(out_dir, clip_dir, options, ref_res, log):
    """The clip run with the lens inferred from its lanes (``OUT/lens_inferred``): its ``k1``
    interval, every angle's band and change against the reference, the band decomposition."""
    sub = out_dir / "lens_inferred"
    log(f"k1 inferred from the lanes: {sub}")
    res = run_clip(clip_dir, sub, replace(options, dist=None, lens="infer", overwrite=False), log=log)
    angles = _angle_changes(res, ref_res)
    return {"k1": {k: res.lens.get(k) for k in ("median", "lo", "hi", "source")}, "height_m": dict(res.height),
            "angles": angles, "band_decomposition": res.band_decomposition, "result_dir": sub.name}


def _figures(out_dir, study):
    """``sensitivity.png`` (each angle's mean band width: lens inferred and every fixed k1) and
    ``decomposition.png`` (where the inferred run's bands come from)."""
    from .report.html import _subplots, decomposition_figure

    names = [a for a in ANGLES if all(a in r["angles"] for r in study.rows)]
    if not names:
        return
    series = [(f"k1 {r['k1']:+.3f}", [r["angles"][a]["mean_band_deg"] for a in names]) for r in study.rows]
    if study.inferred.get("angles"):
        k = study.inferred["k1"]
        series.insert(0, (f"inferred {k['median']:+.3f} [{k['lo']:+.3f}, {k['hi']:+.3f}]",
                          [study.inferred["angles"].get(a, {}).get("mean_band_deg", np.nan) for a in names]))
    fig, ax = _subplots(1, 1, figsize=(max(6.0, 1.3 * len(names) + 3), 3.8))
    x = np.arange(len(names))
    w = 0.8 / len(series)
    for j, (label, vals) in enumerate(series):
        ax.bar(x + (j - (len(series) - 1) / 2) * w, vals, width=w, label=label)
    ax.set_xticks(x, names)
    ax.set_ylabel("mean 90 % band width (deg)")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(out_dir / "sensitivity.png", dpi=110)
    if study.inferred.get("band_decomposition"):
        decomposition_figure(study.inferred["band_decomposition"], title="lens inferred").savefig(
            out_dir / "decomposition.png", dpi=110)


def _study_into(out_dir, clip_dir, ks, base, reference_k1, options, log, infer=True):
    """Run every hypothesis into ``out_dir`` (the study's temporary folder) and write the summaries."""
    runs = {}
    for k1 in ks:
        d = base.copy()
        d[0] = k1
        sub = out_dir / f"k1_{k1:+.3f}"
        log(f"k1 = {k1:+.3f}: {sub}")
        opts = replace(options, dist=tuple(float(v) for v in d) if np.any(d) else None)
        res = run_clip(clip_dir, sub, replace(opts, overwrite=False), log=log)
        straight, cams = _lane_straightness(res, d)
        runs[k1] = (res, d, straight, cams)
    ref_res = next(v for k, v in runs.items() if np.isclose(k, reference_k1))[0]
    rows = []
    for k1, (res, d, straight, cams) in runs.items():
        f_med = float(np.nanmedian(cams.focal_px[cams.valid])) if cams.valid.any() else float("nan")
        w = res.model.reg.image_size[0]
        angles = _angle_changes(res, ref_res)
        gait = {k: dict(v) for k, v in res.gait.items() if k in GAIT}
        for k, v in gait.items():
            v["change"] = float(v["median"] - ref_res.gait[k]["median"]) if k in ref_res.gait else float("nan")
        rows.append({
            "k1": float(k1), "dist": [float(v) for v in d],
            "corner_shift_px": corner_shift_px(d, f_med, res.model.reg.image_size) if np.isfinite(f_med)
            else float("nan"),
            "lane_straightness_px": straight,
            "height_m": dict(res.height),
            "fov_deg": float(fov_from_focal(f_med, w)),
            "frames_ok": int(cams.valid.sum()),
            "angles": angles, "gait": gait, "result_dir": Path(res.out_dir).name,
        })
    # plumb-line curve on a fine grid, with the cameras of the run whose own hypothesis left the
    # straightest lines (its focal lengths come from lines undistorted consistently; a run that
    # ignores a strong lens gets them wrong, and k1 scales with f^2)
    k_cam = min(runs, key=lambda k: np.nan_to_num(runs[k][2], nan=np.inf))
    ref_cams = runs[k_cam][3]
    lo, hi = min(ks), max(ks)
    pad = max(0.1 * (hi - lo), 0.02)
    grid = np.linspace(lo - pad, hi + pad, 41)
    curve = lane_straightness_curve(ref_res.model.reg.frame_lanes, _focal(ref_cams), grid, base)
    plumb = {**plumb_line_summary(grid, curve), "cameras_of_k1": float(k_cam)}
    inferred = _inferred_run(out_dir, clip_dir, options, ref_res, log) if infer else {}
    study = DistortionStudy(rows=rows, reference_k1=reference_k1, out_dir=out_dir, plumb_line=plumb,
                            inferred=inferred)
    write_json(out_dir / "sensitivity.json", {"reference_k1": study.reference_k1, "rows": rows,
                                              "plumb_line": plumb, "inferred": inferred})
    _figures(out_dir, study)
    with open(out_dir / "sensitivity.csv", "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["k1", "corner_shift_px", "lane_straightness_px", "height_m", "height_lo_m", "height_hi_m",
                     "fov_deg", "frames_ok"] + [f"{n}_{q}" for n in ANGLES for q in ANGLE_STATS])
        for r in rows:
            wr.writerow([r["k1"], r["corner_shift_px"], r["lane_straightness_px"], r["height_m"]["median"],
                         r["height_m"]["lo"], r["height_m"]["hi"], r["fov_deg"], r["frames_ok"]] +
                        [r["angles"].get(n, {}).get(q, "") for n in ANGLES for q in ANGLE_STATS])
    (out_dir / "sensitivity.md").write_text("# Lens-distortion sensitivity\n\n" + study.to_markdown())
    return study
