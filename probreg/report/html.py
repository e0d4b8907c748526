"""Self-contained HTML reports (figures embedded as PNG) that open in any browser or notebook."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import cv2
import numpy as np

from ..geometry import BONES, JOINT_INDEX, joint_angles
from ..io.frames import read_frame

__all__ = ["HtmlReport", "draw_skeleton", "clip_report", "run_report", "run_figures", "render_figures",
           "posterior_figures", "figure_png", "uncalibrated_report", "gait_cycle_figure",
           "prior_posterior_figure", "status_strip_figure", "sampler_figure",
           "rank_histograms"]


_CSS = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f3f3f3}img{max-width:100%}figure{margin:1em 0}figcaption{color:#555;font-size:90%}
.note{color:#555;font-size:90%}
.banner{background:#fde2e2;border:2px solid #b00;padding:.6em 1em;font-weight:bold}
.warning{background:#fff4d6;border:1px solid #c80;padding:.4em 1em}
.ok{background:#e5f5e5;border:1px solid #3a3;padding:.4em 1em}"""

def _subplots(nrows=1, ncols=1, **kw):
    """``(figure, axes)`` like ``pyplot.subplots``, without pyplot: the library never touches the
    caller's backend or figure manager (a notebook keeps showing its own figures)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=kw.pop("figsize", None))
    return fig, fig.subplots(nrows, ncols, **kw)


def _laid_out(fig):
    """``fig`` fitted by ``tight_layout`` and marked so: :func:`figure_png` then saves it as it is
    (cropping it to a tight box as well would draw it twice, ~40 % of the saving's time)."""
    fig.tight_layout()
    fig._probreg_laid_out = True
    return fig


def figure_png(fig):
    """A matplotlib figure as PNG bytes, as reports embed it (a pyplot figure is closed); cropped
    to its content unless it was laid out already (:func:`_laid_out`)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, **({} if getattr(fig, "_probreg_laid_out", False)
                                              else {"bbox_inches": "tight"}))
    if fig.canvas.manager is not None:  # made by pyplot: release it
        import matplotlib.pyplot as plt

        plt.close(fig)
    return buf.getvalue()


class HtmlReport:
    """Builds one HTML page section by section.

    >>> r = HtmlReport("t"); r.paragraph("hello"); "hello" in r.html()
    True
    """

    def __init__(self, title):
        self.title = title
        self.parts = []

    def heading(self, text, level=2):
        self.parts.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text, cls=None):
        c = f' class="{cls}"' if cls else ""
        self.parts.append(f"<p{c}>{html.escape(text)}</p>")

    def table(self, header, rows, fmt="{:.2f}"):
        def cell(v):
            if isinstance(v, (float, np.floating)):
                return "n/a" if not np.isfinite(v) else fmt.format(v)
            return html.escape(str(v))
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in rows)
        self.parts.append(f"<table><tr>{head}</tr>{body}</table>")

    def figure(self, fig, caption=""):
        """Embed a matplotlib figure (a pyplot figure is closed afterwards), or the PNG bytes
        :func:`figure_png` made of one."""
        self._png(fig if isinstance(fig, bytes) else figure_png(fig), caption)

    def image(self, img_bgr, caption="", max_width=960):
        """Embed an OpenCV image (BGR), downscaled to ``max_width``."""
        h, w = img_bgr.shape[:2]
        if w > max_width:
            img_bgr = cv2.resize(img_bgr, (max_width, int(h * max_width / w)), interpolation=cv2.INTER_AREA)
        ok, png = cv2.imencode(".png", img_bgr)
        if ok:
            self._png(png.tobytes(), caption)

    def _png(self, data, caption):
        b64 = base64.b64encode(data).decode("ascii")
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self.parts.append(f'<figure><img src="data:image/png;base64,{b64}">{cap}</figure>')

    def html(self):
        return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(self.title)}"
                f"</title><style>{_CSS}</style></head><body><h1>{html.escape(self.title)}</h1>"
                + "\n".join(self.parts) + "</body></html>")

    def save(self, path):
        Path(path).write_text(self.html(), encoding="utf-8")
        return Path(path)


def _explain_reasons(rep, reasons):
    """A table of the verdict's reasons with what each means and what can be done about it."""
    from ..inference.verdict import explain_reason

    rows = [(r, *(explain_reason(r) or ("", ""))) for r in reasons]
    rep.table(["reason", "what it means", "what you can do"], rows)


def draw_skeleton(img, joints_px, color=(0, 255, 255), thickness=2):
    """Draw an H36M-17 skeleton (F=1, 17, 2+) on a BGR image in place; NaN joints are skipped."""
    p = np.asarray(joints_px, float)
    for a, b in BONES:
        pa, pb = p[JOINT_INDEX[a], :2], p[JOINT_INDEX[b], :2]
        if np.all(np.isfinite(pa)) and np.all(np.isfinite(pb)):
            cv2.line(img, tuple(int(v) for v in np.round(pa)), tuple(int(v) for v in np.round(pb)),
                     color, thickness, cv2.LINE_AA)
    for q in p:
        if np.all(np.isfinite(q[:2])):
            cv2.circle(img, tuple(int(v) for v in np.round(q[:2])), thickness + 1, color, -1, cv2.LINE_AA)
    return img


def clip_report(clip_dir, out_html):
    """Overview of a synthetic clip: a frame with keypoints, camera and gait ground truth."""
    from ..io.clip import load_clip, load_groundtruth

    clip = load_clip(clip_dir)
    gt = load_groundtruth(clip_dir)
    rep = HtmlReport(f"probreg synthetic clip: {Path(clip_dir).name}")
    ath = gt.athlete
    cams = gt.cameras
    rep.heading("Clip")
    gen = clip.meta.get("generator", {})
    rep.table(["field", "value"], [
        ["frames", clip.n_frames], ["fps", clip.fps], ["image size", f"{clip.image_size[0]}x{clip.image_size[1]}"],
        ["preset / seed", f"{gen.get('preset')} / {gen.get('seed')}"], ["style", ath.get("style")],
        ["athlete lane", clip.athlete_lane], ["stature (m)", ath["stature_m"]],
        ["speed (m/s)", ath["gait"]["speed_mps"]], ["step frequency (steps/s)", ath["gait"]["step_freq_hz"]],
        ["camera height (m)", cams[0].C[2]], ["camera centre (m)", np.round(cams[0].C, 2).tolist()],
        ["FOV range (deg)", f"{min(c.fov_deg for c in cams):.2f}-{max(c.fov_deg for c in cams):.2f}"],
        ["lens distortion", np.round(cams[0].dist, 3).tolist()],
    ])
    if clip.frame_paths:
        mid = len(clip.frame_paths) // 2
        img = read_frame(clip, mid)
        if img is not None:
            draw_skeleton(img, gt.joints2d_px[mid], (0, 255, 0))
            if clip.keypoints_px is not None:
                draw_skeleton(img, clip.keypoints_px[mid], (0, 200, 255), 1)
            rep.image(img, f"frame {mid}: ground-truth skeleton (green), detector-like keypoints (orange)")
    ang = joint_angles(gt.joints3d_track_m)
    t = np.arange(clip.n_frames) / clip.fps
    fig, axes = _subplots(2, 1, figsize=(9, 6), sharex=True)
    for name in ("knee_l", "knee_r", "hip_l", "hip_r"):
        axes[0].plot(t, ang[name], label=name)
    axes[0].set_ylabel("angle (deg)")
    axes[0].legend(ncol=4)
    axes[1].fill_between(t, 0, gt.contacts[:, 0], step="mid", alpha=0.5, label="left contact")
    axes[1].fill_between(t, 1.1, 1.1 + gt.contacts[:, 1], step="mid", alpha=0.5, label="right contact")
    axes[1].set_yticks([])
    axes[1].set_xlabel("time (s)")
    axes[1].legend(ncol=2)
    rep.figure(fig, "Ground-truth joint angles (CLIP_FORMAT definitions) and foot contacts")
    return rep.save(out_html)


def scale_note(stature_prior, stature_draws, interval=None):
    """What sets the metric scale of a run, in words for the report.

    Lanes fix the camera only up to its one degree of freedom, and a 2D skeleton has
    no size of its own: the athlete's stature prior, and the planted feet of a panning
    camera (at a wrong scale they seem to slide; ``posterior.STILLNESS_SYS_SD``), turn
    pixels into metres.  When the clip narrows the stature little beyond its prior, the
    camera height, the limb lengths, step length and speed carry the prior's uncertainty
    (joint angles do not depend on the scale).  ``interval`` ``(lo, hi)`` is the interval to
    quote (the run's calibrated one, :func:`probreg.inference.static_interval`); the draws' own
    90 % interval decides whether the clip added to the prior.

    >>> from probreg.inference.priors import NormalPrior
    >>> rng = np.random.default_rng(0)
    >>> "follows the stature prior" in scale_note(NormalPrior(1.76, 0.10), rng.normal(1.76, 0.095, 4000))
    True
    >>> "follows the stature prior" in scale_note(NormalPrior(1.76, 0.10), rng.normal(1.80, 0.02, 4000))
    False
    """
    lo_p, hi_p = stature_prior.interval(0.9)
    v = np.asarray(stature_draws, float)
    v = v[np.isfinite(v)]
    if len(v) < 2 or not hi_p > lo_p:
        return "Metric scale: no stature draws to judge it by."
    lo, hi = np.percentile(v, [5, 95])
    med = float(np.median(v))
    q_lo, q_hi = (lo, hi) if interval is None else interval
    half = 50.0 * (q_hi - q_lo) / med
    text = (f"Metric scale: athlete's stature {med:.2f} m, 90 % interval [{q_lo:.2f}, {q_hi:.2f}] "
            f"(prior [{lo_p:.2f}, {hi_p:.2f}]).")
    if (hi - lo) > 0.7 * (hi_p - lo_p):
        text += (f" The clip adds little to the prior here, so the metric scale follows the stature prior: "
                 f"camera height, limb lengths, step length and speed are uncertain by about +-{half:.0f} % "
                 f"(90 %), and they are only as right as that prior for this athlete. Joint angles do not "
                 f"depend on the scale. Give the athlete's measured stature (--stature, --stature-sd) to "
                 f"pin it.")
    return text


def _angles_figure(clip, result):
    t = np.arange(clip.n_frames) / clip.fps
    fig, axes = _subplots(3, 1, figsize=(10, 9), sharex=True)
    for ax, names in zip(axes, (("knee_l", "knee_r"), ("hip_l", "hip_r"), ("elbow_l", "elbow_r"))):
        for name, col in zip(names, ("tab:blue", "tab:orange")):
            med, lo, hi = result.angle_summary[name]
            ax.fill_between(t, lo, hi, color=col, alpha=0.25, lw=0)
            ax.plot(t, med, color=col, label=f"{name} (median, 90 % band)")
        ax.set_ylabel("deg")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    return fig


def run_figures(clip, result):
    """The figures of :func:`run_report`, each as a function that draws it: {key: function}
    (only those the run has), so that some can be rendered in another process
    (:func:`render_figures`) while the rest of the report is made."""
    figs = _posterior_figure_makers(result.model.priors, result.posterior)
    if getattr(result, "frame_status", None):
        figs["status"] = lambda: status_strip_figure(result.frame_status, clip.fps)
    figs["angles"] = lambda: _angles_figure(clip, result)
    if getattr(result, "gait_cycle", None):
        figs["gait_cycle"] = lambda: gait_cycle_figure(result.gait_cycle)
    if getattr(result, "band_decomposition", None):
        figs["decomposition"] = lambda: decomposition_figure(result.band_decomposition)
    return figs


def _posterior_figure_makers(priors, idata):
    return {"prior_posterior": lambda: prior_posterior_figure(priors, idata.posterior),
            "sampler": lambda: sampler_figure(idata)}


def posterior_figures(priors, idata):
    """PNG bytes of the two figures of :func:`run_report` that need only the posterior (ArviZ
    ``InferenceData``) and the priors, ``{"prior_posterior", "sampler"}``: they can be drawn
    before the rest of the run's result exists."""
    return {k: figure_png(make()) for k, make in _posterior_figure_makers(priors, idata).items()}


def render_figures(clip, result, keys):
    """PNG bytes of the figures ``keys`` of :func:`run_figures` (those the run has): {key: bytes},
    to pass to :func:`run_report` as ``rendered``."""
    figs = run_figures(clip, result)
    return {k: figure_png(figs[k]()) for k in keys if k in figs}


#: what the angle bands of a run do not hold, said under the angles in every report (docs/validation.md,
#: "Elbows are the weak angle"; measured on the held-out and tuning clips of probreg's generator)
BANDS_LEAVE_OUT = (
    "What the bands do not hold: a systematic bias of the 2D keypoints (the bootstrap re-simulates their "
    "jitter, not a detector's habit of placing a joint too high or too far forward), and, for the elbows, "
    "the arm's mirror image in depth. In a view from the side the image cannot tell an elbow carried towards "
    "the body's midline from one carried outwards; probreg takes the one nearer the shoulder's sagittal "
    "plane, as runners in motion capture carry them. Arms swung across the body then come out 7-9 deg off "
    "at the elbow on average, with bands that miss the truth in 13-30 % of the frames, under any verdict "
    "(the verdict checks the camera and the knee).")


def run_report(out_html, clip, result, joints_median, cameras, rendered=None):
    """Report of a pipeline run: posterior of the calibration and the athlete, angle bands, gait.

    ``rendered`` ({key: PNG bytes}, :func:`render_figures`) holds figures drawn elsewhere; the
    others are drawn here.  The page is the same either way."""
    from ..analysis import GAIT_FIELDS
    from ..inference.heights import height_terms_note

    figs = run_figures(clip, result)
    rendered = dict(rendered or {})

    def fig(key):
        return rendered[key] if key in rendered else figs[key]()

    rep = HtmlReport(f"probreg: {Path(str(clip.path)).name}")
    if result.verdict != "ok":
        rep.paragraph(f"Verdict: {result.verdict}. " + "; ".join(result.verdict_reasons)
                      + ". The results below are written for inspection; do not use them as they stand "
                      "(run.json lists the reasons).", cls="banner")
        _explain_reasons(rep, result.verdict_reasons)
    else:
        rep.paragraph("Verdict: ok (none of probreg's checks on this clip failed: calibrated frames, lanes that "
                      "fit the camera, sampler convergence, posterior shape, camera side and family branch, "
                      "bone lengths, speed and stature, keypoint noise, knee band width, the view's angle).",
                      cls="ok")
    side = getattr(result, "camera_side", None)
    if side is not None:
        rep.paragraph(f"Camera side: {side.chosen} ({side.source}; log-evidence ratio {side.log_ratio:.1f} "
                      f"between the main stand and across the infield).", cls="note")
    for note in (n for n in getattr(clip, "notes", ()) if str(n).startswith("camera cut")):
        rep.paragraph(f"Camera shots: {note} (grey in the per-frame status strip; probreg.lanes.shots).", cls="note")
    for note in (n for n in getattr(clip, "notes", ()) if not str(n).startswith("camera cut")):
        rep.paragraph(f"Input: {note} (run.json input_notes).", cls="note")  # missing or damaged images, ...
    if tb := getattr(result, "time_base", None):
        rep.paragraph(time_base_sentence(tb), cls="note")
    d = result.diagnostics
    h = result.height
    post = result.posterior.posterior
    rep.heading("Calibration and athlete (posterior median, 90 % interval)")
    rows = [["camera height (m)", h["median"], h["lo"], h["hi"]]]
    for var in ["stature_m", "thigh_m", "shank_m", "upper_arm_m", "forearm_m", "trunk_m"]:
        a = result.athlete[var]
        rows.append([var.replace("_m", " (m)"), a["median"], a["lo"], a["hi"]])
    rep.table(["quantity", "median", "5 %", "95 %"], rows, fmt="{:.3f}")
    rep.paragraph("The intervals are the posterior's 90 % intervals widened about the median by the calibrated "
                  f"factor {h['interval_scale']:g} (the model's posterior is narrower "
                  "than its errors on clips with known truth; probreg.inference.STATIC_INTERVAL_SCALE); "
                  "posterior.nc holds the draws themselves.", cls="note")
    if (terms := d.get("height_terms") or {}).get("temper", 1.0) < 1.0:
        rep.paragraph(f"The {height_terms_note(terms)}: they were tempered by "
                      f"{terms['temper']:.3g} (their Birge ratio), so the height's interval spans their "
                      "disagreement (run.json diagnostics.height_terms; probreg.inference.heights.term_conflict).",
                      cls="note")
    st = result.athlete["stature_m"]
    rep.paragraph(scale_note(result.model.priors.stature, post["stature"].values.ravel(), (st["lo"], st["hi"])),
                  cls="note")
    rep.figure(fig("prior_posterior"), "Prior (grey) and posterior (blue) of the "
               "athlete's stature and the camera height: where the posterior is as wide as the prior, the clip "
               "did not measure the quantity")
    if "status" in figs:
        rep.figure(fig("status"), "Per-frame status (run.json frame_status)")
    rep.figure(fig("sampler"), "Sampler diagnostics: trace and rank plots of the log camera "
               "height and the stature, one line (one row of bars) per walker; flat rank histograms (bars up to the "
               "dashed line) mean the walkers mixed. R-hat and ESS below are ArviZ's.")
    rep.paragraph(f"emcee: {d['walkers']} walkers x {d['steps']} steps, acceptance "
                  f"{d['acceptance_fraction']:.2f}, max integrated autocorrelation time "
                  f"{max(d['tau'].values()):.0f} steps ({d['steps_per_tau']:.0f} tau), ESS(height) "
                  f"{d['ess_height']:.0f}, R-hat(height) {d['rhat_height']:.3f}.", cls="note")
    rep.figure(fig("angles"), "Joint angles with 90 % credible bands (calibration, limb lengths and detector noise)")
    rep.paragraph(BANDS_LEAVE_OUT, cls="note")
    ratio = getattr(result, "band_noise_ratio", None) or {}
    if ratio:
        from ..inference.bands import noise_ratio_factor

        rep.paragraph("Detector noise in the angles, the data's over the bootstrap's (the band's bootstrap part "
                      "scaled by the factor in brackets; probreg.inference.bands.bootstrap_noise_ratio): "
                      + ", ".join(f"{k} {v:.2f} (x{noise_ratio_factor(v):.2f})" for k, v in sorted(ratio.items()))
                      + ".", cls="note")
    if "gait_cycle" in figs:
        rep.figure(fig("gait_cycle"),
                   "Joint angles over the gait cycle (touchdown to touchdown of the same foot, 0-100 %; mean over "
                   "the clip's cycles), posterior median with its 90 % credible band over draws (gait_cycle.csv)")
    if "decomposition" in figs:
        rep.figure(fig("decomposition"), "Where the bands come from: share of each angle's band variance due "
                   "to the lens (k1), the camera (height), the limbs (bone lengths) and the keypoints (2D detector "
                   "noise); run.json band_decomposition, method in band_decomposition_method")
    lens = getattr(result, "lens", None)
    if lens:
        if lens.get("source") == "inferred":
            rep.paragraph(f"Lens: k1 {lens['median']:+.3f} (90 % interval {lens['lo']:+.3f} to {lens['hi']:+.3f}; "
                          f"prior {lens['prior_interval'][0]:+.2f} to {lens['prior_interval'][1]:+.2f}), inferred "
                          f"from the curvature of {lens['n_lines']} lane lines in {lens['n_frames']} frames"
                          + ("" if lens.get("informative") else "; the lines show no curvature a plausible lens "
                             "could make (narrow view), so k1 keeps its prior and hardly matters") + ".", cls="note")
        else:
            rep.paragraph(f"Lens: k1 {lens['median']:+.3f} ({lens['source']}).", cls="note")
    rep.heading("Gait")
    gait_reasons = getattr(result, "gait_verdict_reasons", ())
    if any(r.startswith("feet slide back") for r in gait_reasons):  # the along-track positions do not hold
        rep.paragraph("Every gait number from the ground track or the contacts, the speed included, is unreliable: "
                      + "; ".join(gait_reasons)
                      + ". Planted feet stand still, and here they run backwards: the camera moved along the "
                      "track (a rail or tracking camera; probreg assumes a static one), or the positions along "
                      "the track do not hold together from frame to frame (probreg.inference.gait_check). Their "
                      "bands do not cover this; the angles do not rest on the positions along the track.",
                      cls="warning")
    elif any(r.startswith("ground track off") for r in gait_reasons):  # the track's velocity is not the athlete's
        rep.paragraph("Every gait number from the ground track or the contacts, the speed included, is unreliable: "
                      + "; ".join(gait_reasons)
                      + ". The ground track from the feet in contact heads away from the straight's running "
                      "direction: its contacts were too few or too noisy to give the athlete's velocity (in a low "
                      "grazing view a pixel moves a foot cast onto the ground by metres along its ray). The angles "
                      "take the straight's direction there (probreg.lifting.GroundTrack.forward).", cls="warning")
    elif gait_reasons:
        rep.paragraph("The gait numbers that rest on the detected ground contacts are unreliable: "
                      + "; ".join(gait_reasons) + " (probreg.inference.gait_check). Their bands do not "
                      "cover this; the angles do not rest on the contacts' timing.", cls="warning")
    rep.table(["quantity", "median", "5 %", "95 %", "unit", "status"],
              [[k, v["median"], v["lo"], v["hi"], v.get("unit") or GAIT_FIELDS.get(k, ""), v.get("status", "")]
               for k, v in result.gait.items()])
    if (result.gait.get("cadence_spm") or {}).get("source") == "stride pattern":
        rep.paragraph("The cadence is the 2-D stride pattern's (no camera, no contacts; its interval from the "
                      "strides' scatter); cadence_contacts_spm is the contacts' own, which the gait check compares.",
                      cls="note")
    spread = (getattr(result, "diagnostics", None) or {}).get("speed_scatter") or {}
    if np.isfinite(spread.get("se_mps", np.nan)) and spread["se_mps"] > 0:
        rep.paragraph(f"The speed's interval includes the camera pan's error: the runner's speed over one stride "
                      f"({spread['window_frames']} frames) scatters by {spread['sd_mps']:.2f} m/s along the clip, a "
                      f"standard error of {spread['se_mps']:.2f} m/s for its mean (run.json "
                      "diagnostics.speed_scatter).", cls="note")
    if clip.frame_paths:
        mid = len(clip.frame_paths) // 2
        img = read_frame(clip, mid)
        if img is not None and cameras[mid] is not None and np.all(np.isfinite(joints_median[mid])):
            draw_skeleton(img, cameras[mid].project(joints_median[mid]), (0, 255, 0))
            if clip.keypoints_px is not None:
                draw_skeleton(img, clip.keypoints_px[mid], (0, 200, 255), 1)
            rep.image(img, f"frame {mid}: posterior-median 3D skeleton re-projected (green), keypoints (orange)")
    if clip.frame_paths and getattr(result, "model", None) is not None:
        from ..lanes import draw_lanes

        n = len(clip.frame_paths)
        thumbs = []
        for i in sorted({0, n // 3, 2 * n // 3, n - 1}):
            img = read_frame(clip, i)
            if img is not None:
                fl = result.model.reg.frame_lanes[i]
                thumbs.append(cv2.resize(draw_lanes(img, fl), (480, int(480 * img.shape[0] / img.shape[1]))))
        if thumbs:
            h = max(t.shape[0] for t in thumbs)
            grid = [np.pad(t, ((0, h - t.shape[0]), (0, 0), (0, 0))) for t in thumbs]
            rows = [np.hstack(grid[k:k + 2] + [np.zeros_like(grid[0])] * (2 - len(grid[k:k + 2])))
                    for k in range(0, len(grid), 2)]
            rep.image(np.vstack(rows), "Lane lines found in a few frames (the lines the calibration used)",
                      max_width=960)
    rep.heading("Timing")
    rep.table(["stage", "seconds"], [[k, v] for k, v in result.timings.items()])
    rep.paragraph("Uncertainty sources in the bands: the camera height (the one calibration degree of "
                  "freedom), the athlete's limb lengths, and the 2D detector noise (re-simulated from the "
                  "noise level estimated in this clip). Not included: errors of the lane-line detection "
                  "beyond the per-frame fit, systematic detector bias, and model errors of the lifting.",
                  cls="note")
    return rep.save(out_html)


def uncalibrated_report(out_html, clip, registration, result):
    """Report of a clip no frame of which calibrated: the verdict, the lane status of the frames
    and a few frames with the line candidates that were found, so that the user sees why."""
    from ..lanes import draw_lanes

    rep = HtmlReport(f"probreg: {Path(str(clip.path)).name}")
    rep.paragraph("Verdict: uncalibrated. " + "; ".join(result.verdict_reasons)
                  + ". No frame gave a camera, so nothing was estimated: the angle and joint files hold NaN "
                  "(run.json lists every frame's lane status).", cls="banner")
    _explain_reasons(rep, result.verdict_reasons)
    for note in getattr(clip, "notes", ()):
        rep.paragraph(f"Input: {note} (run.json input_notes).", cls="note")
    rep.heading("Lane status of the frames")
    counts = registration.status_counts()
    rep.table(["status", "frames"], [[k, v] for k, v in sorted(counts.items(), key=lambda kv: -kv[1])],
              fmt="{:.0f}")
    rep.paragraph("Lane lines of the straight are needed in at least one frame: a vanishing point and the "
                  "1.22 m spacing of three or more lines. A camera too low above the track (grazing view) "
                  "squeezes the far lines together until they merge; a frame without the straight's lines "
                  "(curve, close-up) has nothing to measure.", cls="note")
    if clip.frame_paths:
        n = len(clip.frame_paths)
        for i in sorted({0, n // 2, n - 1}):
            img = read_frame(clip, i)
            if img is None:
                continue
            fl = registration.frame_lanes[i]
            rep.image(draw_lanes(img, fl), f"frame {i}: lane status {fl.status}, {len(fl.lines)} line(s) drawn",
                      max_width=640)
    return rep.save(out_html)


def gait_cycle_figure(curves):
    """Knee, hip and elbow over the gait cycle, left and right, with bands (a matplotlib figure)."""
    angles = [a for a in ("knee", "hip", "elbow") if any(k[0] == a for k in curves)]
    fig, axes = _subplots(1, max(1, len(angles)), figsize=(4.2 * max(1, len(angles)), 3.6), squeeze=False)
    for ax, angle in zip(axes[0], angles):
        for side, col in (("L", "tab:blue"), ("R", "tab:orange")):
            if (angle, side) not in curves:
                continue
            pct, med, lo, hi, *rest = curves[(angle, side)]
            n = f", {rest[0]} cycles" if rest and rest[0] is not None else ""
            ax.fill_between(pct, lo, hi, color=col, alpha=0.25, lw=0)
            ax.plot(pct, med, color=col, label=f"{side}{n}")
        ax.set_title(f"{angle} flexion")
        ax.set_xlabel("gait cycle (%)")
        ax.set_ylabel("deg")
        ax.legend(fontsize=8)
    return _laid_out(fig)


def prior_posterior_figure(priors, posterior):
    """Prior and posterior densities of the stature and the camera height."""
    fig, axes = _subplots(1, 2, figsize=(10, 3.2))
    for ax, prior, var, label in ((axes[0], priors.stature, "stature", "stature (m)"),
                                  (axes[1], priors.camera_height, "height_m", "camera height (m)")):
        draws = np.asarray(posterior[var]).ravel()
        lo, hi = prior.interval(0.99)
        lo, hi = min(lo, np.percentile(draws, 0.5)), max(hi, np.percentile(draws, 99.5))
        log = var == "height_m"  # the camera height on a log axis (its prior is log-normal)
        x = np.geomspace(lo, hi, 400) if log else np.linspace(lo, hi, 400)
        dens = np.exp(prior.logpdf(x)) * (x if log else 1.0)  # density per log unit on the log axis
        u = np.log(x) if log else x
        ax.fill_between(x, dens / (dens.sum() * (u[1] - u[0])), color="0.6", alpha=0.5, lw=0, label="prior")
        bins = np.geomspace(lo, hi, 61) if log else np.linspace(lo, hi, 61)
        w = np.full(len(draws), 1.0 / (len(draws) * (np.log(bins[1] / bins[0]) if log else bins[1] - bins[0])))
        ax.hist(draws, bins=bins, weights=w, color="tab:blue", alpha=0.7, label="posterior")
        if log:
            ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_yticks([])
        ax.legend(fontsize=8)
    return _laid_out(fig)


#: colours of the status strip: ok, bridged (camera interpolated), no camera, another camera shot
_STATUS_COLOURS = {"ok": (0.2, 0.65, 0.2), "bridged": (0.95, 0.7, 0.1), "none": (0.8, 0.15, 0.15),
                   "other_shot": (0.6, 0.6, 0.6)}


def status_strip_figure(frame_status, fps):
    """One coloured cell per frame: calibrated (green), bridged (orange), no camera (red), another
    camera shot than the one estimated (grey; shown only when the clip has one)."""
    from matplotlib.patches import Patch

    def kind(s):
        return s if s in ("ok", "other_shot") else ("bridged" if s.startswith("bridged") else "none")

    kinds = [kind(s) for s in frame_status]
    rgb = np.array([[_STATUS_COLOURS[k] for k in kinds]])
    fig, ax = _subplots(figsize=(10, 1.1))
    ax.imshow(rgb, aspect="auto", extent=(0, len(kinds) / fps, 0, 1), interpolation="nearest")
    ax.set_yticks([])
    ax.set_xlabel("time (s)")
    counts = {k: kinds.count(k) for k in _STATUS_COLOURS}
    labels = {"ok": "calibrated", "bridged": "bridged (no/inconsistent lanes)", "none": "no camera",
              "other_shot": "another camera shot"}
    shown = [k for k in _STATUS_COLOURS if k != "other_shot" or counts[k]]
    ax.legend(handles=[Patch(color=_STATUS_COLOURS[k], label=f"{labels[k]} {counts[k]}") for k in shown],
              loc="upper center", bbox_to_anchor=(0.5, -0.9), ncol=len(shown), fontsize=8, frameon=False)
    fig.subplots_adjust(bottom=0.5)
    return fig


def rank_histograms(draws, n_bins=20):
    """Rank-plot data of one quantity: the ranks of all draws pooled over chains, histogrammed per
    chain (Vehtari et al. 2021, the plot ``arviz.plot_rank`` draws); uniform when the chains mixed.

    Parameters
    ----------
    draws : ndarray (chains, draws)

    Returns
    -------
    ndarray (chains, n_bins) counts, and the count a uniform histogram would have.

    >>> h, uniform = rank_histograms(np.arange(40.0).reshape(4, 10) % 7, n_bins=5)
    >>> h.shape, float(uniform), int(h.sum())
    ((4, 5), 2.0, 40)
    """
    from scipy.stats import rankdata

    x = np.asarray(draws, float)
    ranks = rankdata(x.ravel()).reshape(x.shape)
    edges = np.linspace(0.5, x.size + 0.5, n_bins + 1)
    h = np.stack([np.histogram(r, edges)[0] for r in ranks])
    return h, x.shape[1] / n_bins


def sampler_figure(idata, max_points=800):
    """Trace and rank plots of the log camera height and the stature, one colour per walker (the
    trace thinned to ``max_points`` steps per walker for drawing; the ranks use every draw)."""
    fig, axes = _subplots(2, 2, figsize=(10, 4.5))
    for row, var in enumerate(("log_height", "stature")):
        vals = np.asarray(idata.posterior[var])  # (chain, draw)
        step = max(1, vals.shape[1] // max_points)
        x = np.arange(vals.shape[1])[::step]
        for c in vals:
            axes[row, 0].plot(x, c[::step], lw=0.4, alpha=0.6)
        axes[row, 0].set_ylabel(var)
        h, uniform = rank_histograms(vals)
        edges = np.linspace(0.0, 1.0, h.shape[1] + 1)
        for k, counts in enumerate(h):  # one row of bars per chain, as ArviZ draws them (one artist per row)
            axes[row, 1].stairs(k + counts / (2.2 * uniform), edges, baseline=k, fill=True, alpha=0.8,
                                color=f"C{k % 10}")
        axes[row, 1].hlines(np.arange(len(h)) + 1 / 2.2, 0.0, 1.0, colors="k", lw=0.3, ls="--")
        axes[row, 1].set_yticks([])
        axes[row, 1].set_ylabel("walker")
        axes[row, 1].set_xlabel("rank among all draws (fraction)" if row == 1 else "")
    axes[1, 0].set_xlabel("step")
    return _laid_out(fig)


def time_base_sentence(tb):
    """One sentence on the clip's time base (``run.json`` ``time_base``) for the report.

    >>> s = time_base_sentence({"fps": 50.0, "status": "ok", "bounce_g": 1.31, "cadence_spm": 172.4, "slow_motion": 1})
    >>> s.split("; ")[0], "1.31 g at the step frequency" in s, "172 steps/min, a runner's" in s
    ('Time base: 50 fps taken as real time', True, True)
    """
    given = f", with --slow-motion {tb['slow_motion']:g}" if tb.get("slow_motion", 1.0) != 1.0 else ""
    what = ("a runner's" if tb.get("status") == "ok" else
            f"not a runner's in real time: {tb.get('reason')}; give a replay's slow-down with --slow-motion N")
    bounce = (f"the pelvis bounces at {tb['bounce_g']:.2f} g at the step frequency" if tb.get("bounce_g") is not None
              else "the pelvis bounce was not measured")
    cadence = (f"the stride pattern gives {tb['cadence_spm']:.0f} steps/min" if tb.get("cadence_spm") is not None
               else "no stride repeats")
    return (f"Time base: {tb['fps']:g} fps taken as real time{given}; {bounce} and {cadence}, {what} "
            "(probreg.inference.time_base).")


#: the groups of a band decomposition, in the order (and colours) they are stacked
DECOMPOSITION_GROUPS = (("lens", "tab:purple"), ("camera", "tab:blue"), ("limbs", "tab:green"),
                        ("keypoints", "tab:orange"))


def decomposition_figure(decomposition, angles=("knee_l", "knee_r", "hip_l", "hip_r", "elbow_l", "elbow_r"),
                         title=None):
    """Stacked bars: for each angle, the shares of its band's variance due to the lens, the
    camera, the limbs and the keypoints (``run.json`` ``band_decomposition``)."""
    names = [a for a in angles if decomposition.get(a) and decomposition[a].get("camera") is not None]
    fig, ax = _subplots(1, 1, figsize=(max(4.0, 1.1 * len(names) + 2.5), 3.6))
    bottom = np.zeros(len(names))
    for g, col in DECOMPOSITION_GROUPS:
        v = np.array([decomposition[a].get(g) or 0.0 for a in names])
        ax.bar(names, v, bottom=bottom, color=col, label=g, width=0.6)
        bottom += v
    ax.set_ylim(0, 1.0)
    ax.set_ylabel("share of band variance")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    return _laid_out(fig)
