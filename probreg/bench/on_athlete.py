"""Do the keypoints lie on the athlete of the clip's own images, upright?  The verdict's checks, measured.

:func:`probreg.lanes.on_athlete_fraction` scores one frame: the share of points along the 2-D
skeleton's bones whose colour is unlike every colour of a ring around it.  A run takes the median
over the frames (``run.json`` ``diagnostics.keypoints_on_athlete``) and says ``keypoints off the
athlete`` below a third (:class:`probreg.inference.verdict.VerdictThresholds`).  This benchmark
computes the same clip score on three sets of clips:

* the **tuning** clips: 40 set-ups of the held-out generator at seeds 8101-8140 (the check was
  developed on them; ``--suite-dir`` reuses them, else they are written);
* the ten **validation** clips of ``shared/data/validation`` (independent generator; checked,
  never tuned on; skipped when absent);
* the 40 **held-out** clips (:mod:`probreg.sim.heldout`; ``--heldout-dir``; checked, never tuned on).

Each clip is scored with its own keypoints and with keypoints that belong to other images, as a
user's mistake would make them: scaled by 0.5, 0.75, 1.33 and 2 about the image corner (a pose
model run on a resized copy of the frames) and moved 100 px to the right (a crop's or padding's
offset).  Then with keypoints that lie on the athlete but off the joint centres, as a detector's
bias puts them: each joint moved by a fixed 10 % or 20 % of the skeleton's extent in a direction
of its own, plus white noise of 3 % of it per frame (a real nano pose model is 7-13 % off on the
validation renders, ``reports/bench_video.md``).  And with the clip's own keypoints on frames where a
second runner in the same kit stands beside the athlete (a copy of the athlete's box pasted 0.8 of
the skeleton's extent to the side, across the ring the check compares with: a sprint heat's
neighbour at its worst).  The own and the biased keypoints must stay above the limit, the
mismatched ones below it; the twin shows how close a neighbour in the same kit brings a clip's own
keypoints to a false flag (the check compares the skeleton with every colour of the ring, the
twin's too).

The same table gives the upside-down check (:func:`probreg.inference.verdict.trunk_down_fraction`:
the share of frames whose trunk points down in the image; the verdict's limit is a half) for the
clip's own keypoints and for them with ``y`` pointing up (``y' = H - 1 - y``, a biomechanics tool's
convention).

Last, a few clips run end to end through the command line (``probreg run CLIP --out OUT --seed
0``) with their keypoints scaled by 0.5 and 2: the verdict, its reasons and the camera height's
error, which such keypoints move far (before this check, under an ``ok`` verdict).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..inference.verdict import VerdictThresholds, trunk_down_fraction
from ..io import load_clip
from ..io.clip import load_groundtruth, write_keypoints_json
from ..io.frames import iter_frames
from ..lanes import on_athlete_fraction
from .common import BenchReport, find_shared_data, md_table
from .validation import _heldout_clips

__all__ = ["MISMATCHES", "clip_scores", "run"]

#: keypoints of other images: (name, function of the (17, 2) pixel coordinates)
MISMATCHES = (
    ("x0.5", lambda xy: xy * 0.5),
    ("x0.75", lambda xy: xy * 0.75),
    ("x1.33", lambda xy: xy * 1.33),
    ("x2", lambda xy: xy * 2.0),
    ("+100 px", lambda xy: xy + np.array([100.0, 0.0])),
)
#: a detector's bias: each joint off its centre by this share of the skeleton's extent
BIASES = (0.10, 0.20)
TUNING_SEEDS = range(8101, 8141)
#: a second runner in the same kit beside the athlete: a copy of the athlete's box this many
#: skeleton extents to the side (the box is 1.2 extents wide: at 0.8 the copy crosses the ring)
NEIGHBOUR_OFFSET = 0.8


def with_neighbour(image, xy, offset=NEIGHBOUR_OFFSET):
    """``image`` with a copy of the athlete's box (the skeleton's box grown by a tenth of its
    extent) pasted ``offset`` extents to the right, or to the left where the right has no room."""
    ok = np.isfinite(xy).all(axis=1)
    lo, hi = xy[ok].min(axis=0), xy[ok].max(axis=0)
    ext = float(np.max(hi - lo))
    h, w = image.shape[:2]
    x0, y0 = np.maximum(np.floor(lo - 0.1 * ext).astype(int), 0)
    x1, y1 = np.minimum(np.ceil(hi + 0.1 * ext).astype(int), [w, h])
    dx = int(offset * ext) * (1 if x1 + int(offset * ext) <= w else -1)
    out = image.copy()
    if 0 <= x0 + dx and x1 + dx <= w and x1 > x0 and y1 > y0:
        out[y0:y1, x0 + dx:x1 + dx] = image[y0:y1, x0:x1]
    return out


def clip_scores(clip_dir, seed=5):
    """The clip score (median over frames of :func:`on_athlete_fraction`) of the clip's own
    keypoints, of each of :data:`MISMATCHES`, of each of :data:`BIASES` and of the own keypoints
    beside a twin (:func:`with_neighbour`), then :func:`trunk_down_fraction` of the own keypoints
    and of them with ``y`` pointing up; ``{name: score}`` in that order."""
    clip = load_clip(clip_dir)
    xy_all = clip.keypoints_px[..., :2]
    seen = np.isfinite(xy_all).all(axis=-1).sum(axis=1) >= 2  # frames with a skeleton to measure
    xy_seen = xy_all[seen]
    spans = np.nanmax(xy_seen, axis=1) - np.nanmin(xy_seen, axis=1)  # (frames, 2)
    extent = float(np.median(spans.max(axis=-1))) if seen.any() else 1.0
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(17, 2))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    names = ["own"] + [m[0] for m in MISMATCHES] + [f"bias {b:.0%}" for b in BIASES] + ["neighbour"]
    per_frame = {n: [] for n in names}
    for i, img in iter_frames(clip):
        xy = xy_all[i]
        if np.isfinite(xy).all(axis=1).sum() < 8:
            continue
        per_frame["own"].append(on_athlete_fraction(img, xy))
        for name, move in MISMATCHES:
            per_frame[name].append(on_athlete_fraction(img, move(xy)))
        for b in BIASES:
            off = b * extent * dirs + rng.normal(0.0, 0.03 * extent, (17, 2))
            per_frame[f"bias {b:.0%}"].append(on_athlete_fraction(img, xy + off))
        if img is not None:
            per_frame["neighbour"].append(on_athlete_fraction(with_neighbour(img, xy), xy))
    out = {}
    for n, v in per_frame.items():
        v = np.asarray(v, float)
        v = v[np.isfinite(v)]
        out[n] = float(np.median(v)) if len(v) else float("nan")
    flipped = clip.keypoints_px.copy()
    flipped[..., 1] = clip.image_size[1] - 1 - flipped[..., 1]
    out["trunk down"], out["trunk down, y up"] = trunk_down_fraction(clip.keypoints_px), trunk_down_fraction(flipped)
    return out


def _set_rows(clips):
    rows, scores = [], {}
    for clip in clips:
        s = clip_scores(clip)
        scores[clip.name] = s
        rows.append([clip.name] + [s[k] for k in s])
    return rows, scores


def _summary(scores, limit):
    own = np.array([s["own"] for s in scores.values()])
    mis = np.array([s[m[0]] for s in scores.values() for m in MISMATCHES])
    bias = np.array([s[f"bias {b:.0%}"] for s in scores.values() for b in BIASES])
    twin = np.array([s["neighbour"] for s in scores.values()])
    down = np.array([s["trunk down"] for s in scores.values()])
    up = np.array([s["trunk down, y up"] for s in scores.values()])
    return {"clips": len(own), "own_min": float(np.nanmin(own)), "own_max": float(np.nanmax(own)),
            "trunk_down_max": float(np.nanmax(down)), "trunk_down_y_up_min": float(np.nanmin(up)),
            "own_flagged": int(np.sum(own < limit)), "mismatched_max": float(np.nanmax(mis)),
            "mismatched_mean": float(np.nanmean(mis)), "mismatched_missed": int(np.sum(~(mis < limit))),
            "mismatched_n": int(len(mis)), "biased_min": float(np.nanmin(bias)),
            "biased_flagged": int(np.sum(bias < limit)), "biased_n": int(len(bias)),
            "twin_min": float(np.nanmin(twin)), "twin_median": float(np.nanmedian(twin)),
            "twin_flagged": int(np.sum(twin < limit))}


def _scaled_copy(clip_dir, dst, scale):
    """A copy of the clip (frames linked, not copied) whose keypoints are scaled about the corner."""
    dst.mkdir(parents=True)
    for item in Path(clip_dir).iterdir():
        if item.name == "keypoints2d.json":
            continue
        (dst / item.name).symlink_to(item.resolve(), target_is_directory=item.is_dir())
    kp = load_clip(clip_dir).keypoints_px.copy()
    kp[..., :2] *= scale
    write_keypoints_json(dst / "keypoints2d.json", kp)
    return dst


def _end_to_end(clips, tmp):
    """``probreg run`` on each clip with its keypoints as they are and scaled by 0.5 and 2."""
    rows = []
    for clip in clips:
        truth = np.median([c.C[2] for c in load_groundtruth(clip).cameras if c is not None])
        for scale in (1.0, 0.5, 2.0):
            src = clip if scale == 1.0 else _scaled_copy(clip, Path(tmp) / f"{clip.name}_x{scale:g}", scale)
            out = Path(tmp) / f"out_{clip.name}_x{scale:g}"
            proc = subprocess.run([sys.executable, "-m", "probreg", "run", str(src), "--out", str(out),
                                   "--seed", "0", "--quiet"], capture_output=True, text=True)
            if not (out / "run.json").exists():
                rows.append([clip.name, f"x{scale:g}", f"exit {proc.returncode}", "", "", "", ""])
                continue
            run = json.loads((out / "run.json").read_text())
            h = (run.get("height_m") or {}).get("median")
            on = ((run.get("diagnostics") or {}).get("keypoints_on_athlete") or {}).get("median")
            rows.append([clip.name, f"x{scale:g}", proc.returncode, on if on is not None else float("nan"),
                         100 * abs(h - truth) / truth if h is not None else float("nan"), run["verdict"],
                         "; ".join(run.get("verdict_reasons", [])) or "-"])
            shutil.rmtree(out, ignore_errors=True)
    return rows


def run(args=None):
    rep = BenchReport("on-athlete", "Do the keypoints lie on the athlete of the clip's own images?")
    rep.add(__doc__.split("\n\n", 1)[1])
    limit = VerdictThresholds().min_on_athlete
    header = (["clip", "own"] + [m[0] for m in MISMATCHES] + [f"bias {b:.0%}" for b in BIASES]
              + ["neighbour in the same kit", "trunk down", "trunk down, y up"])
    with tempfile.TemporaryDirectory(prefix="probreg-onathlete-") as tmp:
        from ..sim.heldout import write_heldout

        tuning_root = Path(getattr(args, "suite_dir", None) or Path(tmp) / "tuning")

        def tuning_clip(seed):
            return next((p for p in sorted(tuning_root.glob(f"tuning_{seed}_*")) if (p / "clip.json").exists()), None)

        missing = [s for s in TUNING_SEEDS if tuning_clip(s) is None]
        if missing:  # written once (~7 min on two cores); --suite-dir keeps them for the next run
            write_heldout(tuning_root, seeds=missing, label="tuning", jobs=getattr(args, "jobs", None))
        tuning = [tuning_clip(s) for s in TUNING_SEEDS]
        shared = find_shared_data(getattr(args, "shared", None))
        vdir = None if shared is None else shared / "validation"
        validation = (sorted(p for p in vdir.iterdir() if (p / "clip.json").exists())
                      if vdir is not None and vdir.is_dir() else [])
        heldout = _heldout_clips(getattr(args, "heldout_dir", None) or Path(tmp) / "heldout")
        sets = [("tuning clips (seeds 8101-8140; developed on)", tuning),
                ("validation clips (independent generator; checked)", validation),
                ("held-out clips (checked, never tuned on)", heldout)]
        summary_rows = []
        for title, clips in sets:
            if not clips:
                rep.add(f"**{title[0].upper() + title[1:]}: skipped** (not found; give `--shared PATH`).\n")
                continue
            rows, scores = _set_rows(clips)
            s = _summary(scores, limit)
            rep.numbers[title] = s
            summary_rows.append([title, s["clips"], f"{s['own_min']:.2f}-{s['own_max']:.2f}",
                                 f"{s['own_flagged']} of {s['clips']}",
                                 f"{s['mismatched_max']:.2f} (mean {s['mismatched_mean']:.2f})",
                                 f"{s['mismatched_missed']} of {s['mismatched_n']}", f"{s['biased_min']:.2f}",
                                 f"{s['biased_flagged']} of {s['biased_n']}",
                                 f"{s['twin_min']:.2f} (median {s['twin_median']:.2f})",
                                 f"{s['twin_flagged']} of {s['clips']}", f"{s['trunk_down_max']:.2f}",
                                 f"{s['trunk_down_y_up_min']:.2f}"])
            rep.add(f"## {title[0].upper() + title[1:]}: clip scores\n")
            rep.add(md_table(header, rows))
        rep.add(f"## Summary (the verdict's limit: {limit:.2f})\n")
        rep.add(md_table(["set", "clips", "own keypoints", "own flagged", "mismatched, largest",
                          "mismatched not flagged", "biased, smallest", "biased flagged",
                          "beside a twin, smallest", "beside a twin, flagged",
                          "trunk down, largest share of frames", "y up: smallest"], summary_rows))
        picks = [c for c in validation if c.name in ("v05_distorted", "v08_tele")] or heldout[2:4]
        rep.add("## End to end: keypoints in the pixels of a copy scaled by 0.5 and 2\n\n"
                "`probreg run CLIP --out OUT --seed 0` on the clip as it is (x1) and with its keypoints scaled "
                "about the image corner; the camera height's error against the truth (median over frames).\n")
        rep.add(md_table(["clip", "keypoints", "exit", "keypoints on athlete", "camera height err %", "verdict",
                          "reasons"], _end_to_end(picks, tmp)))
    return rep
