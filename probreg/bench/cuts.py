"""Camera cuts: are they found, and what does estimating one shot give?

1. **The cut set** (:mod:`probreg.sim.cuts`: 20 clips of one runner filmed by two cameras of the
   held-out set's kinds, cut between 35 % and 65 % of the clip; half cut to another set-up, half
   to the same kind of camera moved by 15-40 %; :data:`~probreg.sim.cuts.CUT_SEEDS` fixed before
   the detection was tuned, never tuned on).  Every clip goes through the command line twice, in
   fresh processes: ``probreg run CLIP --out OUT --seed 0`` (the default: cuts found, the longest
   shot estimated) and with ``--shot all`` (the clip taken as one camera, as probreg did before
   cuts were found).  Scored: the cut found at its frame, cuts found where there is none, the knee
   error of the posterior median over the frames with angles (against the runner's truth), the
   camera height against the true camera of the frames estimated, and the verdict.  For the clip
   taken as one camera, the verdict is also given without the reason ``camera cut``: what
   probreg said of such clips before it found cuts.
2. **Clips without a cut**: the lane step alone (:func:`probreg.calibration.register_clip`, where
   the cuts are found) on the independent validation clips (``shared/data/validation``), the
   held-out set (:mod:`probreg.sim.heldout`): any cut found there is a false one; the largest colour change and lane step show the margins to the thresholds.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..geometry import joint_angles
from ..io.clip import load_groundtruth
from .common import BenchReport, md_table, verdict_text
from .validation import _run_cli, judge_dirs, real_time_clips

__all__ = ["run", "score_cut_result"]


def knee_errors(gt, out_dir: Path):
    """Absolute knee-angle errors (deg, both knees, every frame; NaN where the result has none) of a
    result folder's posterior median against the ground truth ``gt``."""
    truth = joint_angles(gt.joints3d_track_m)
    est = joint_angles(np.load(Path(out_dir) / "joints3d.npz")["median"].astype(float))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.concatenate([np.abs(est[k] - truth[k]) for k in ("knee_l", "knee_r")])


def score_cut_result(clip_dir: Path, out_dir: Path):
    """Scores of one result of a cut clip: the cuts and shot of ``run.json``, the knee error over
    the frames with angles, the camera height against the true camera of the frames estimated."""
    clip_dir, out_dir = Path(clip_dir), Path(out_dir)
    run = json.loads((out_dir / "run.json").read_text())
    shots = run.get("shots") or {}
    gt = load_groundtruth(clip_dir)
    err = knee_errors(gt, out_dir)
    ok = np.isfinite(err)
    a, b = shots.get("frames_estimated", [0, len(gt.cameras)])
    h_true = float(np.median([c.C[2] for c in gt.cameras[a:b]]))
    cam = json.loads((out_dir / "camera.json").read_text())["height_m"]
    h = cam.get("median")
    h_ok = h is not None and np.isfinite(h)
    return {"cuts": shots.get("cuts", []), "frames": [a, b], "knee_deg": float(np.mean(err[ok])) if ok.any() else
            float("nan"), "frames_with_knee": int(ok.sum() // 2), "height_true": h_true,
            "height_err_pct": 100 * (h / h_true - 1) if h_ok else float("nan"),
            "height_in": bool(h_ok and cam["lo"] <= h_true <= cam["hi"]),
            "verdict": run.get("verdict", "n/a"), "reasons": run.get("verdict_reasons", [])}


def _cut_clips(root):
    from ..sim.cuts import CUT_SEEDS, write_cut_clip

    root = Path(root)
    paths = []
    for seed in CUT_SEEDS:
        path = root / f"cut_{seed}"
        if not (path / "clip.json").exists():
            write_cut_clip(path, seed)
        paths.append(path)
    return paths


def _run_kept(clip, out, extra):
    """``probreg run`` into ``out`` (see :func:`probreg.bench.validation._run_cli`), or the kept result
    of an earlier run of this benchmark there (its exit code and wall time stored beside it)."""
    note = out.parent / f"{out.name}.bench.json"
    try:
        doc = json.loads(note.read_text()) if note.exists() else None
    except (OSError, ValueError):
        doc = {}
    if doc is not None and (not isinstance(doc, dict) or set(doc) != {"exit", "wall_s"}):
        raise FileExistsError(f"{note}: not a note of this benchmark; it is left as it is (choose another "
                              "--keep-outputs)")
    if doc is not None and (out / "run.json").exists():
        return doc["exit"], doc["wall_s"]
    code, dt, _ = _run_cli(clip, out, extra)
    note.parent.mkdir(parents=True, exist_ok=True)
    note.write_text(json.dumps({"exit": code, "wall_s": dt}))
    return code, dt


def _no_cut_rows(clips):
    from ..calibration import register_clip
    from ..io.clip import load_clip

    rows = []
    for clip in clips:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            shots = register_clip(load_clip(clip)).shots
        rows.append([clip.name, ", ".join(map(str, shots.cuts)) or "none", shots.change_max, shots.step_max,
                     ", ".join(map(str, shots.vetoed)) or "none"])
    return rows


def run(args):
    rep = BenchReport("cuts", "Camera cuts: found from the lanes and the colours; one shot estimated")
    rep.add(__doc__.split("\n", 1)[1].strip())
    with tempfile.TemporaryDirectory(prefix="probreg-bench-cuts-") as tmp:
        root, keep = judge_dirs(args, tmp, "cuts")
        rows, found, knees, knees_all, heights, walls = [], 0, [], [], [], []
        flagged = flagged_all = flagged_before = false_cuts = 0
        clips = _cut_clips(root)
        no_cut = real_time_clips(args, tmp)  # written first
        for clip in clips:
            meta = json.loads((clip / "clip.json").read_text())["generator"]
            res = {}
            for mode, extra in (("shot", ()), ("all", ("--shot", "all"))):
                out = keep / f"{clip.name}_{mode}"
                code, dt = _run_kept(clip, out, extra)
                res[mode] = score_cut_result(clip, out) if (out / "run.json").exists() else None
                res[mode + "_exit"], res[mode + "_wall"] = code, dt
            s, a = res["shot"], res["all"]
            if s is None or a is None:
                rows.append([clip.name, meta["shots"], meta["cut"], "failed", "", "", "", "", "", "", "", "", ""])
                continue
            hit = meta["cut"] in s["cuts"]
            found += hit
            false_cuts += len([c for c in s["cuts"] if c != meta["cut"]])
            knees.append(s["knee_deg"])
            knees_all.append(a["knee_deg"])
            heights.append(abs(s["height_err_pct"]))
            walls.append(res["shot_wall"])
            flagged += s["verdict"] != "ok"
            flagged_all += a["verdict"] != "ok"
            before = [r for r in a["reasons"] if not r.startswith("camera cut")]
            flagged_before += bool(before)
            rows.append([clip.name, meta["shots"], meta["cut"], ", ".join(map(str, s["cuts"])) or "none",
                         f"{s['frames'][0]}-{s['frames'][1] - 1}", s["knee_deg"], s["height_err_pct"],
                         "yes" if s["height_in"] else "no", verdict_text(s["verdict"], s["reasons"]),
                         a["knee_deg"], a["verdict"], "; ".join(before) or "none (ok)", res["shot_wall"]])
        n = len(clips)
        rep.add("## The cut set (20 clips, seeds fixed before tuning)\n\n" + md_table(
            ["clip", "shots", "true cut", "cuts found", "frames estimated", "knee err deg", "height err %",
             "height in 90 %", "verdict (reasons)", "as one camera: knee err deg", "as one camera: verdict",
             "as one camera: the other checks' reasons (before cuts were found)", "wall s"], rows))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            summary = [
                ["cut found at its frame", f"{found} of {n}"],
                ["cuts found where there is none (in these clips)", str(false_cuts)],
                ["knee error, one shot (mean / median over clips)",
                 f"{np.nanmean(knees):.2f} / {np.nanmedian(knees):.2f} deg"],
                ["knee error, taken as one camera (mean / median)",
                 f"{np.nanmean(knees_all):.2f} / {np.nanmedian(knees_all):.2f} deg"],
                ["camera height error, one shot (median |%|)", f"{np.nanmedian(heights):.1f} %"],
                ["verdict not ok: one shot / taken as one camera", f"{flagged} / {flagged_all} of {n}"],
                ["taken as one camera, flagged by the other checks alone (before cuts were found)",
                 f"{flagged_before} of {n}"],
                ["wall time per clip, one shot (median)", f"{np.median(walls):.1f} s" if walls else "n/a"],
            ]
        rep.add("### Summary\n\n" + md_table(["measure", "value"], summary))
        rep.numbers.update(found=found, n=n, false_cuts=false_cuts, flagged_before=flagged_before)

        rows = _no_cut_rows(no_cut)
        wrong = [r for r in rows if r[1] != "none"]
        n_val = sum(not c.name.startswith("heldout_") for c in no_cut)
        rep.add("## Clips without a cut (the lane step alone)\n\n"
                f"Clips: {len(rows)} ({f'the {n_val} validation clips and ' if n_val else ''}"
                f"the {len(rows) - n_val} held-out clips). Cuts found in them: **{len(wrong)}** "
                f"({', '.join(r[0] for r in wrong) or 'none'}). Largest colour change "
                f"{max(r[2] for r in rows):.4f} (threshold 0.05), largest lane step "
                f"{np.nanmax([r[3] for r in rows]):.4f} (threshold 0.10 or 30 x the clip's own noise).\n\n"
                + md_table(["clip", "cuts found", "largest colour change", "largest lane step",
                            "colour cuts vetoed by the lanes"], rows, floatfmt="{:.4f}"))
        rep.numbers.update(no_cut_clips=len(rows), no_cut_false=len(wrong))
    return rep
