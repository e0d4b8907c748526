"""probreg on clips from an independent generator, run the way a user runs it.

Every clip of ``shared/data/validation`` (ten clips from a generator that is not probreg's:
cameras across the infield, grazing, steep, wide, long lens, 25 fps, real mocap motion) goes
through the command line exactly as a user types it, ``probreg run CLIP --out OUT --seed 0``
with the default priors and no lens given, in a fresh process (start-up, imports, image
decoding and writing included in the wall time).  Each result is scored against the clip's
ground truth:

* knee-angle error of the posterior median (deg, both knees, every frame) next to the planar 2D
  peer's (the validation README's Butterworth column), and the fraction of frames whose true
  knee angle lies inside the 90 % band;
* the knee error of ``probreg lift`` given the clip's true cameras and true limb lengths, from the
  same keypoints (``probreg lift CLIP --cameras groundtruth/cameras.json --segments ...``): what the
  lifting costs by itself, so that the rest of the first column is the calibration's;
* camera height error (%) and whether its 90 % interval holds the truth; the same for the
  athlete's stature (the calibrated intervals of ``camera.json`` and ``run.json``);
* camera side (the camera centre on the same side of the athlete's lane as the true one) and
  camera position error after one shift along ``x`` per clip (the along-track position is not
  observable; the shift is the median difference of the pelvis ``x``), in % of the horizontal
  camera-athlete distance;
* the clip verdict of ``run.json`` with its reasons, the exit code and the wall time.

With ``--reseed N`` every clip runs a second time with ``--seed N``, and a table per set shows
how far the results move with the seed alone (the sampler's and the bootstrap's random numbers):
the knee error, its band's coverage, the camera height and the verdict.  With ``--jitter-px S``
every clip runs once more, with seed 0, on a copy whose 2D keypoints are moved by normal noise of
``S`` pixels (e.g. 0.05, far below a detector's noise): how far an imperceptible change of the
input moves the same numbers.

The same is done on the held-out set (:mod:`probreg.sim.heldout`: 40 randomised set-ups of
probreg's own generator over the set-ups real broadcasts have, seeds fixed before any tuning;
``--set heldout``).  Both sets check; they are never used to fit anything.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from ..geometry import JOINT_INDEX, SEGMENT_BONES, joint_angles
from ..io.clip import load_groundtruth, read_cameras_json
from ..inference.gait_check import Z90
from ..io.results import read_angles_csv
from .common import BenchReport, find_shared_data, md_table
from .posterior import angle_error_deg, score_result, true_gait

__all__ = ["run", "score_validation", "peer_knee_errors", "speed_line", "gait_coverage_table", "GAIT_NUMBERS",
           "seed_rows"]


def peer_knee_errors(readme: Path):
    """``{clip: knee error deg}`` of the planar 2D peer (Butterworth 6 Hz column) from the
    validation README's table ``| clip | raw | Butterworth 6 Hz |``."""
    out = {}
    for line in readme.read_text(encoding="utf-8").splitlines():
        m = re.match(r"\|\s*(v\d\d_\w+)\s*\|\s*([\d.]+)\s*\|\s*([\d.]+)\s*\|\s*$", line)
        if m:
            out[m.group(1)] = float(m.group(3))
    return out


def _stature_interval(out_dir: Path):
    """The stature's median and 90 % interval as the run reports it (``run.json``'s ``athlete``:
    the calibrated interval); from ``posterior.nc``'s draws for a result without it."""
    st = json.loads((out_dir / "run.json").read_text()).get("athlete", {}).get("stature_m")
    if st is not None:
        return float(st["median"]), float(st["lo"]), float(st["hi"])
    import xarray as xr

    with xr.open_dataset(out_dir / "posterior.nc", group="posterior") as post:
        s = np.asarray(post["stature"]).ravel()
    return float(np.median(s)), float(np.percentile(s, 5)), float(np.percentile(s, 95))


def score_validation(clip_dir: Path, out_dir: Path):
    """Scores of one result folder against a validation clip's ground truth (see the module
    docstring); extends :func:`probreg.bench.posterior.score_result`."""
    s = score_result(clip_dir, out_dir)
    gt = load_groundtruth(clip_dir)
    j = np.load(out_dir / "joints3d.npz")["median"]
    pel_est = j[:, JOINT_INDEX["pelvis"]]
    pel_true = gt.joints3d_track_m[:, JOINT_INDEX["pelvis"]]
    ok = np.all(np.isfinite(pel_est), -1)
    shift = float(np.median(pel_true[ok, 0] - pel_est[ok, 0])) if ok.any() else 0.0
    cams = read_cameras_json(out_dir / "camera.json")
    pos, side_ok = [], []
    for i, c in cams.items():
        if c is None or i >= len(gt.cameras):
            continue
        g = gt.cameras[i]
        C = c.C + np.array([shift, 0.0, 0.0])
        dist = np.linalg.norm(g.C[:2] - pel_true[i, :2])
        pos.append(100 * np.linalg.norm(C - g.C) / dist)
        side_ok.append(np.sign(c.C[1] - pel_true[i, 1]) == np.sign(g.C[1] - pel_true[i, 1]))
    s["trunk_lean_deg"] = angle_error_deg(gt, out_dir, ("trunk_lean",))
    st_true = float(gt.athlete["stature_m"])
    st_med, st_lo, st_hi = _stature_interval(out_dir)
    run = json.loads((out_dir / "run.json").read_text())
    pattern = run.get("diagnostics", {}).get("cadence_stride_pattern_spm")
    truth = true_gait(clip_dir)["cadence_spm"]
    sp = s["gait"].get("speed_mps")
    if sp is not None:  # the interval of the draws alone: gait_check widened it by the speed's scatter
        se = float(run.get("diagnostics", {}).get("speed_scatter", {}).get("se_mps") or 0.0)
        extra = Z90 * se if np.isfinite(se) else 0.0
        lo, hi = (sp["median"] - np.sqrt(max(sp["median"] - sp["lo"], extra) ** 2 - extra**2),
                  sp["median"] + np.sqrt(max(sp["hi"] - sp["median"], extra) ** 2 - extra**2))
        sp["inside_draws"] = bool(lo <= sp["truth"] <= hi)
    s.update({
        "pattern_cadence_pct": 100 * (pattern / truth - 1) if pattern is not None and truth else float("nan"),
        "position_pct": float(np.mean(pos)) if pos else float("nan"),
        "side_ok": bool(side_ok) and bool(np.mean(side_ok) > 0.5),
        "stature_true": st_true, "stature_med": st_med,
        "stature_in_interval": bool(st_lo <= st_true <= st_hi),
        "verdict": run.get("verdict", "n/a"), "verdict_reasons": run.get("verdict_reasons", []),
        "camera_side": run.get("camera_side", {}).get("chosen", "n/a"),
        "gait_verdict": run.get("gait_verdict", "n/a"), "gait_verdict_reasons": run.get("gait_verdict_reasons", []),
    })
    return s


def gait_table(scores):
    """The cadence (``gait.json``) against the truth, split by the gait verdict
    (:mod:`probreg.inference.gait_check`): rows ``[gait verdict, clips, mean |error| %, largest
    |error| %, clips above 5 %, intervals holding the truth]``; a clip without a cadence counts
    as above 5 % and as a miss.

    >>> s = {"a": {"gait_verdict": "ok", "gait": {"cadence_spm": {"rel_pct": -2.0, "inside": True}}},
    ...      "b": {"gait_verdict": "unreliable", "gait": {}}}
    >>> gait_table(s)
    [['ok', 1, 2.0, 2.0, 0, '1 of 1'], ['unreliable', 1, nan, nan, 1, '0 of 1']]
    """
    rows = []
    for verdict in ("ok", "unreliable"):
        sel = [s for s in scores.values() if s.get("gait_verdict") == verdict]
        if not sel:
            continue
        cad = [s.get("gait", {}).get("cadence_spm") for s in sel]
        err = [abs(c["rel_pct"]) for c in cad if c is not None and np.isfinite(c["rel_pct"])]
        big = sum(c is None or not np.isfinite(c["rel_pct"]) or abs(c["rel_pct"]) > 5 for c in cad)
        rows.append([verdict, len(sel), float(np.mean(err)) if err else float("nan"),
                     float(np.max(err)) if err else float("nan"), big,
                     f"{sum(bool(c and c['inside']) for c in cad)} of {len(sel)}"])
    return rows


def pattern_cadence_line(scores):
    """One sentence on the stride pattern's cadence (``run.json``
    ``diagnostics.cadence_stride_pattern_spm``) against the truth.

    >>> line = pattern_cadence_line({"a": {"pattern_cadence_pct": -0.5}, "b": {"pattern_cadence_pct": 3.0}, "c": {}})
    >>> line[line.index("within"):]
    'within 2 % of the truth on 1 of 3 clips; mean abs. error 1.75 %, largest 3.00 % (2 clips with a value).'
    """
    e = np.array([abs(v.get("pattern_cadence_pct", np.nan)) for v in scores.values()], float)
    ok = np.isfinite(e)
    stats = f"mean abs. error {np.mean(e[ok]):.2f} %, largest {np.max(e[ok]):.2f} %" if ok.any() else "no value"
    return ("Cadence of the stride pattern (`diagnostics.cadence_stride_pattern_spm`, the gait check's "
            f"reference): within 2 % of the truth on {int(np.sum(e[ok] <= 2))} of {len(e)} clips; {stats} "
            f"({int(ok.sum())} clips with a value).")


def speed_line(scores):
    """One sentence on the running speed (``gait.json``) against the truth: errors, and how many 90 %
    intervals hold it, with and without the stride-to-stride scatter's standard error
    (:func:`probreg.inference.gait_check.speed_scatter`, ``diagnostics.speed_scatter``).

    >>> s = {"a": {"gait": {"speed_mps": {"rel_pct": -40.0, "inside": True, "inside_draws": False}}},
    ...      "b": {"gait": {"speed_mps": {"rel_pct": 4.0, "inside": True, "inside_draws": True}}}, "c": {}}
    >>> line = speed_line(s)
    >>> line[line.index("mean"):line.index(";")]
    'mean abs. error 22.0 %, largest 40.0 %'
    >>> line[line.index("hold"):]
    'hold the truth on 2 of 2 clips (1 of 2 without the scatter).'
    """
    sp = [v["gait"]["speed_mps"] for v in scores.values() if "speed_mps" in v.get("gait", {})]
    if not sp:
        return "Running speed: no clip with a speed and its truth."
    e = np.abs([x["rel_pct"] for x in sp])
    return (f"Running speed (`gait.json` `speed_mps`) against the truth: mean abs. error {np.mean(e):.1f} %, "
            f"largest {np.max(e):.1f} %; 90 % intervals hold the truth on {sum(x['inside'] for x in sp)} of {len(sp)} "
            f"clips ({sum(x.get('inside_draws', x['inside']) for x in sp)} of {len(sp)} without the scatter).")


#: the numbers of ``gait.json`` whose intervals :func:`gait_coverage_table` scores
GAIT_NUMBERS = ("cadence_spm", "step_length_m", "speed_mps", "contact_time_s", "flight_time_s",
                "knee_flexion_touchdown_deg", "peak_knee_flexion_swing_deg")


def gait_coverage_table(scores):
    """Rows ``[gait number, intervals holding the truth where the gait verdict is ok, ... where it is
    unreliable, all]`` for every number of ``gait.json`` (:data:`GAIT_NUMBERS`) with a truth.

    >>> s = {"a": {"gait_verdict": "ok", "gait": {"cadence_spm": {"inside": True}}},
    ...      "b": {"gait_verdict": "unreliable", "gait": {"cadence_spm": {"inside": False}}}}
    >>> gait_coverage_table(s)
    [['cadence_spm', '1 of 1', '0 of 1', '1 of 2 (50 %)']]
    """
    rows = []
    for name in GAIT_NUMBERS:
        by = {v: [s["gait"][name]["inside"] for s in scores.values()
                  if s.get("gait_verdict") == v and name in s.get("gait", {})] for v in ("ok", "unreliable")}
        every = by["ok"] + by["unreliable"]
        if every:
            ok, bad = by["ok"], by["unreliable"]
            rows.append([name, f"{sum(ok)} of {len(ok)}", f"{sum(bad)} of {len(bad)}",
                         f"{sum(every)} of {len(every)} ({100 * sum(every) / len(every):.0f} %)"])
    return rows


def _run_cli(clip: Path, out: Path, extra=(), seed=0):
    """``probreg run`` in a fresh process; returns (exit code, wall s, last stderr line)."""
    cmd = [sys.executable, "-m", "probreg", "run", str(clip), "--out", str(out), "--seed", str(int(seed)), *extra]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    err = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    return proc.returncode, dt, (err[-1] if err else "")


def _true_camera_knee(clip: Path, work: Path):
    """Knee error (deg, both knees, every frame) of ``probreg lift`` given the clip's true cameras
    and true limb lengths, from the same keypoints: what the lifting costs by itself, the floor
    under any calibration.  NaN when the lifting gives no knee angle."""
    from ..pipeline import RunOptions

    gt_dir = clip / "groundtruth"
    segs = json.loads((gt_dir / "athlete.json").read_text()).get("segments_m", {})
    work.mkdir(parents=True, exist_ok=True)
    seg_file = work / "segments.json"
    seg_file.write_text(json.dumps({k: v for k, v in segs.items() if k in SEGMENT_BONES}))
    out = work / "lift"
    cmd = [sys.executable, "-m", "probreg", "lift", str(clip), "--cameras", str(gt_dir / "cameras.json"),
           "--segments", str(seg_file), "--out", str(out), "--min-score", str(RunOptions().min_score)]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0 or not (out / "angles.csv").exists():
        return float("nan")
    truth = joint_angles(load_groundtruth(clip).joints3d_track_m)
    ang = read_angles_csv(out / "angles.csv")
    err = []
    for k in ("knee_l", "knee_r"):
        frames, med = ang[k][0].astype(int), ang[k][1]
        e = np.abs(med - truth[k][frames])
        err.append(e[np.isfinite(e)])
    err = np.concatenate(err)
    return float(np.mean(err)) if len(err) else float("nan")


def _heldout_clips(root):
    """The held-out clips under ``root`` (written there when missing)."""
    from ..sim.heldout import HELDOUT_SEEDS, heldout_config, write_heldout

    root = Path(root)
    names = []
    for seed in HELDOUT_SEEDS:
        _, kind, far = heldout_config(seed)
        names.append(f"heldout_{seed}_{kind}" + ("_far" if far else ""))
    if not all((root / n / "clip.json").exists() for n in names):
        write_heldout(root, overwrite=True)
    return [root / n for n in names]


def judge_dirs(args, tmp, name):
    """``(suite root, kept outputs)`` of a benchmark on a generated judge set: ``--suite-dir`` and
    ``--keep-outputs`` when given, else folders under the temporary ``tmp``."""
    root = Path(getattr(args, "suite_dir", None) or Path(tmp) / name)
    keep = Path(args.keep_outputs) if getattr(args, "keep_outputs", None) else Path(tmp) / "out"
    return root, keep


def real_time_clips(args, tmp):
    """The validation clips (when ``shared/data`` is found) and the held-out clips (``--heldout-dir``,
    written there when missing): the clips a check must leave alone."""
    shared = find_shared_data(getattr(args, "shared", None))
    val = shared / "validation" if shared else None
    clips = sorted(p for p in val.iterdir() if (p / "clip.json").exists()) if val is not None and val.is_dir() else []
    return clips + _heldout_clips(Path(getattr(args, "heldout_dir", None) or Path(tmp) / "heldout"))


def _score_set(clips, peer, tmp):
    rows, scores = [], {}
    for clip in clips:
        out = Path(tmp) / clip.name
        code, dt, last = _run_cli(clip, out)
        if not (out / "angles.csv").exists():
            rows.append([clip.name, "no result", "", "", "", "", "", "", "", "", f"exit {code}: {last}", dt])
            scores[clip.name] = {"exit": code, "time_s": dt, "failed": True, "error": last}
            continue
        run = json.loads((out / "run.json").read_text())
        if run.get("verdict") == "uncalibrated" and not (out / "posterior.nc").exists():
            # nothing estimated (no frame calibrated): flagged, nothing to score
            reasons = "; ".join(run.get("verdict_reasons", []))
            rows.append([clip.name, "uncalibrated", "", "", "", "", "", "", "", "", f"uncalibrated ({reasons}), "
                         f"exit {code}", dt])
            scores[clip.name] = {"exit": code, "time_s": dt, "failed": False, "uncalibrated": True,
                                 "verdict": "uncalibrated", "verdict_reasons": run.get("verdict_reasons", [])}
            continue
        s = score_validation(clip, out)
        s.update(exit=code, time_s=dt, failed=False,
                 knee_true_camera_deg=_true_camera_knee(clip, Path(tmp) / f"{clip.name}.true_camera"))
        scores[clip.name] = s
        p = peer.get(clip.name, float("nan"))
        reasons = "; ".join(s["verdict_reasons"])
        rows.append([clip.name, s["knee_deg"], s["knee_true_camera_deg"], p, 100 * s["knee_coverage"], s["height_pct"],
                     "yes" if s["height_in_interval"] else "no",
                     "yes" if s["stature_in_interval"] else "no",
                     "yes" if s["side_ok"] else "**no**", s["position_pct"],
                     f"{s['verdict']}" + (f" ({reasons})" if reasons else "") + f", exit {code}", dt])
    return rows, scores


def jittered_clip(clip, where, sd_px):
    """A copy of the clip folder ``clip`` as ``where/<clip name>`` whose 2D keypoints are moved by
    normal noise of ``sd_px`` pixels (the same numbers for a clip every time: seeded by its name);
    everything else is linked (copied where links cannot be made).  Returns the copy's path."""
    import shutil
    import zlib

    dst = Path(where) / clip.name
    dst.mkdir(parents=True)
    for item in clip.iterdir():
        if item.name != "keypoints2d.json":
            try:
                (dst / item.name).symlink_to(item.resolve())
            except OSError:
                (shutil.copytree if item.is_dir() else shutil.copyfile)(item, dst / item.name)
    doc = json.loads((clip / "keypoints2d.json").read_text())
    rng = np.random.default_rng(zlib.crc32(clip.name.encode()))
    for f in doc["frames"]:
        f["keypoints"] = f.get("keypoints") and [
            [k[0] + float(rng.normal(0, sd_px)), k[1] + float(rng.normal(0, sd_px)), *k[2:]]
            if k[0] is not None and k[1] is not None else k for k in f["keypoints"]]
    (dst / "keypoints2d.json").write_text(json.dumps(doc))
    return dst


def _reseed_scores(clips, where, seed, jitter_px=0.0):
    """Every clip run again with ``--seed seed`` (on a copy with keypoints jittered by ``jitter_px``
    pixels when that is not 0, :func:`jittered_clip`) into ``where/<clip>`` and scored (no
    true-camera lifting); a run without a result is ``{"failed": True}``, one that calibrated
    nothing ``{"uncalibrated": True}``."""
    Path(where).mkdir(parents=True, exist_ok=True)
    out = {}
    for clip in clips:
        res = Path(where) / clip.name
        src = jittered_clip(clip, Path(where) / "inputs", jitter_px) if jitter_px else clip
        code, dt, last = _run_cli(src, res, seed=seed)
        run = json.loads((res / "run.json").read_text()) if (res / "run.json").exists() else None
        if run is None or not (res / "angles.csv").exists():
            out[clip.name] = {"failed": True, "verdict": f"failed (exit {code}: {last})"}
        elif run.get("verdict") == "uncalibrated" and not (res / "posterior.nc").exists():
            out[clip.name] = {"uncalibrated": True, "verdict": "uncalibrated"}
        else:
            out[clip.name] = {**score_validation(clip, res), "exit": code, "time_s": dt}
    return out


def _unflagged_knee(scores):
    """``(mean knee error of the unflagged clips, their number)``."""
    knees = [s["knee_deg"] for s in scores.values() if not s.get("failed") and not s.get("uncalibrated")
             and s["verdict"] == "ok"]
    return (float(np.mean(knees)) if knees else float("nan")), len(knees)


def seed_rows(first, second):
    """Per clip scored under two seeds: knee error, knee band coverage (%), camera height error (%)
    under each and the verdicts, then a row with the largest changes; and how many verdicts changed.
    A clip without a score (failed, uncalibrated) has NaN numbers and its state as the verdict.

    >>> a = {"c1": {"knee_deg": 3.0, "knee_coverage": 0.9, "height_pct": 5.0, "verdict": "ok"},
    ...      "c2": {"knee_deg": 6.0, "knee_coverage": 0.7, "height_pct": 9.0, "verdict": "unreliable"}}
    >>> b = {"c1": {"knee_deg": 3.5, "knee_coverage": 0.8, "height_pct": 4.0, "verdict": "unreliable"},
    ...      "c2": {"knee_deg": 6.1, "knee_coverage": 0.7, "height_pct": 9.0, "verdict": "unreliable"}}
    >>> rows, changed = seed_rows(a, b)
    >>> rows[0][-1], rows[1][-1], changed
    ('**ok -> unreliable**', 'unreliable', 1)
    >>> [round(float(v), 2) for v in rows[-1][1:7:2]]  # largest changes: knee, coverage, height
    [0.5, 10.0, 1.0]
    """
    rows, deltas, changed = [], [], 0
    for name, s in first.items():
        t = second.get(name, {"failed": True, "verdict": "not run"})
        vals = []
        for sc in (s, t):
            scored = not sc.get("failed") and not sc.get("uncalibrated")
            vals.append([sc[k] * f if scored else float("nan") for k, f in
                         (("knee_deg", 1), ("knee_coverage", 100), ("height_pct", 1))])
        same = s.get("verdict") == t.get("verdict")
        changed += not same
        verdict = s.get("verdict") if same else f"**{s.get('verdict')} -> {t.get('verdict')}**"
        rows.append([name, vals[0][0], vals[1][0], vals[0][1], vals[1][1], vals[0][2], vals[1][2], verdict])
        deltas.append(np.abs(np.subtract(vals[1], vals[0])))
    with warnings.catch_warnings(action="ignore", category=RuntimeWarning):  # a column of NaN only
        big = np.nanmax(np.array(deltas, float), 0) if deltas else np.full(3, np.nan)
    rows.append(["**largest change**", big[0], "", big[1], "", big[2], "", f"{changed} of {len(rows)} changed"])
    return rows, changed


def _summary(scores, peer):
    uncal = [n for n, s in scores.items() if s.get("uncalibrated")]
    ok = [s for s in scores.values() if not s.get("failed") and not s.get("uncalibrated")]
    unflagged = [s for s in ok if s["verdict"] == "ok"]
    names_ok = [n for n, s in scores.items() if not s.get("failed") and not s.get("uncalibrated")]

    def good(n):
        s = scores[n]
        return s["knee_deg"] <= 4 and s["knee_deg"] < peer.get(n, np.inf)

    nan = float("nan")
    return {
        "clips": len(scores), "failed": sum(s.get("failed", False) for s in scores.values()),
        "flagged": sum(s["verdict"] != "ok" for s in ok) + len(uncal), "n_scored": len(ok),
        "uncalibrated": uncal,
        "knee_deg_mean_all": float(np.mean([s["knee_deg"] for s in ok])) if ok else nan,
        "knee_deg_mean_unflagged": float(np.mean([s["knee_deg"] for s in unflagged])) if unflagged else nan,
        "knee_true_camera_mean_unflagged": float(np.nanmean([s["knee_true_camera_deg"] for s in unflagged]))
        if unflagged else nan,
        "knee_true_camera_mean_all": float(np.nanmean([s["knee_true_camera_deg"] for s in ok])) if ok else nan,
        "true_camera_over_4": [n for n in names_ok if scores[n]["knee_true_camera_deg"] > 4],
        "peer_knee_deg_mean": float(np.mean([peer[n] for n in names_ok if n in peer])) if any(
            n in peer for n in names_ok) else nan,
        "knee_coverage_mean": float(np.mean([s["knee_coverage"] for s in ok])) if ok else nan,
        "min_unflagged_coverage": float(min([s["knee_coverage"] for s in unflagged], default=nan)),
        "height_hits": sum(s["height_in_interval"] for s in ok),
        "stature_hits": sum(s["stature_in_interval"] for s in ok),
        "side_right": sum(s["side_ok"] for s in ok),
        "position_pct_mean_unflagged": float(np.mean([s["position_pct"] for s in unflagged])) if unflagged else nan,
        "position_pct_max_unflagged": float(max([s["position_pct"] for s in unflagged], default=nan)),
        "unflagged_bad": [n for n in names_ok if scores[n]["verdict"] == "ok" and not good(n)],
        "unflagged_over_6": [n for n in names_ok if scores[n]["verdict"] == "ok" and scores[n]["knee_deg"] > 6],
        "time_s_median": float(np.median([s["time_s"] for s in scores.values()])) if scores else nan,
        "time_s_max": float(max((s["time_s"] for s in scores.values()), default=nan)),
    }


def _hits_text(hits, n):
    """``"10 of 10 (100 %; ...)"``: the count, its share and how likely it is from intervals that hold
    the truth 90 % of the time (binomial), so that a share above 95 % on few clips reads as what it is.

    >>> _hits_text(10, 10)
    '10 of 10 (100 %; 90 % intervals hold at least this many with probability 0.35)'
    """
    from scipy.stats import binom

    if not n:
        return "0 of 0"
    return (f"{hits} of {n} ({100 * hits / n:.0f} %; 90 % intervals hold at least this many with probability "
            f"{binom.sf(hits - 1, n, 0.9):.2f})")


def _targets(summary):
    n = summary["n_scored"]
    return [
        ("every clip good (knee <= 4 deg and better than the peer where known) or flagged", "all",
         "not met by: " + (", ".join(summary["unflagged_bad"]) or "none"), not summary["unflagged_bad"]),
        ("no unflagged clip above 6 deg", "none", ", ".join(summary["unflagged_over_6"]) or "none",
         not summary["unflagged_over_6"]),
        ("clips flagged (uncalibrated included)", "<= 10 %", f"{summary['flagged']} of {summary['clips']}"
         + (f" ({len(summary['uncalibrated'])} uncalibrated)" if summary["uncalibrated"] else ""),
         summary["flagged"] <= 0.1 * max(summary["clips"], 1)),
        ("mean knee error, unflagged clips", "<= 3 deg", f"{summary['knee_deg_mean_unflagged']:.2f} deg "
         f"(all clips {summary['knee_deg_mean_all']:.2f}, peer {summary['peer_knee_deg_mean']:.2f}; with the true "
         f"cameras and limb lengths {summary['knee_true_camera_mean_unflagged']:.2f} unflagged, "
         f"{summary['knee_true_camera_mean_all']:.2f} all; above 4 deg even so: "
         f"{', '.join(summary['true_camera_over_4']) or 'none'})",
         summary["knee_deg_mean_unflagged"] <= 3),
        ("knee 90 % band coverage, mean", "85-95 %", f"{100 * summary['knee_coverage_mean']:.1f} %",
         0.85 <= summary["knee_coverage_mean"] <= 0.95),
        ("knee coverage, worst unflagged clip", ">= 75 %", f"{100 * summary['min_unflagged_coverage']:.1f} %",
         summary["min_unflagged_coverage"] >= 0.75),
        ("camera height 90 % interval holds the truth", "80-95 % of clips (a count within half a clip)",
         _hits_text(summary["height_hits"], n), 0.8 * n <= summary["height_hits"] <= 0.95 * n + 0.5),
        ("stature 90 % interval holds the truth", "80-95 % of clips (a count within half a clip)",
         _hits_text(summary["stature_hits"], n), 0.8 * n <= summary["stature_hits"] <= 0.95 * n + 0.5),
        ("camera on the correct side", "every clip", f"{summary['side_right']} of {n}", summary["side_right"] == n),
        ("camera position, unflagged clips", "<= 10 % each, <= 3 % mean",
         f"mean {summary['position_pct_mean_unflagged']:.1f} %, max {summary['position_pct_max_unflagged']:.1f} %",
         summary["position_pct_max_unflagged"] <= 10 and summary["position_pct_mean_unflagged"] <= 3),
        ("no traceback / failed run", "none", f"{summary['failed']} failed", summary["failed"] == 0),
        ("wall time per clip (CLI)", "not worse than before (validation: median 26 s before issue 25, "
         "same machine)", f"median {summary['time_s_median']:.1f} s, max {summary['time_s_max']:.1f} s",
         summary["time_s_median"] <= 30),
    ]


OTHER_ANGLES_NOTE = (
    "The issues' targets are set on the knee; the other angles of `angles.csv` are scored the same way "
    "(posterior median against the truth, both sides, every frame; the share of frames inside the 90 % "
    "band), so that an angle that fails while the knee does not is seen (0.2.0.dev20: a ground track run "
    "backwards negated every hip angle and the trunk lean of the grazing clip heldout_9028 under an `ok` "
    "verdict, knee 3.6 deg, hip 47.9 deg). No target in the issues.\n")


def other_angle_rows(scores):
    """Per scored clip: hip, elbow and trunk-lean errors and band coverage, and the verdict; a last
    row with the means over the unflagged clips."""
    rows, unflagged = [], []
    for name, s in scores.items():
        if s.get("failed") or s.get("uncalibrated"):
            continue
        rows.append([name, s["hip_deg"], 100 * s["hip_coverage"], s["elbow_deg"], 100 * s["elbow_coverage"],
                     s["trunk_lean_deg"], s["verdict"]])
        if s["verdict"] == "ok":
            unflagged.append(rows[-1][1:6])
    if unflagged:
        rows.append([f"**mean, {len(unflagged)} unflagged**", *np.nanmean(np.array(unflagged, float), 0), ""])
    return rows


HEADER = ["clip", "knee err deg", "knee err, true camera deg", "peer knee err deg", "knee in 90 % band %",
          "camera height err %", "height in 90 %", "stature in 90 %", "camera side right", "camera position err %",
          "verdict (reasons), exit", "wall s"]


def run(args=None):
    rep = BenchReport("validation", "Independent validation clips and the held-out set, end to end through "
                                    "the command line")
    rep.add(__doc__.split("\n\n", 1)[1])
    which = getattr(args, "clip_set", "all") or "all"
    only = getattr(args, "only", None)
    sets = []
    shared = find_shared_data(getattr(args, "shared", None))
    vdir = None if shared is None else shared / "validation"
    if which in ("validation", "all"):
        if vdir is None or not vdir.is_dir():
            rep.add("**Validation clips skipped**: `shared/data/validation` was not found (give `--shared PATH`).\n")
        else:
            sets.append(("validation clips (independent generator)", peer_knee_errors(vdir / "README.md"),
                         sorted(p for p in vdir.iterdir() if (p / "clip.json").exists())))
    with tempfile.TemporaryDirectory(prefix="probreg-heldout-") as scratch:
        if which in ("heldout", "all"):
            sets.append(("held-out set (probreg's generator, 40 randomised set-ups, seeds fixed before tuning; "
                         "100 frames each; no peer numbers)", {},
                         _heldout_clips(getattr(args, "heldout_dir", None) or scratch)))
        _run_sets(rep, sets, only, getattr(args, "keep_outputs", None), getattr(args, "reseed", None),
                  getattr(args, "jitter_px", None))
    return rep


def _run_sets(rep, sets, only, keep=None, reseed=None, jitter_px=None):
    """Run and score every set; ``keep``: a folder that receives every run's result folder
    (``keep/<clip>``; none of them may exist yet: an old result would be scored as new), else
    they go to a temporary folder.  ``reseed``: a second seed every clip also runs with
    (``keep/seed<N>/<clip>``), for the seed-stability table; ``jitter_px``: the sd (px) of the
    noise on the keypoints of a copy every clip also runs on (``keep/jitter<S>/<clip>``)."""
    # the further runs: (folder, seed, keypoint jitter px, label of the second run, section title)
    variants = ([(f"seed{reseed}", reseed, 0.0, f"seed {reseed}", "Seed stability")] if reseed is not None else []) + (
        [(f"jitter{jitter_px:g}", 0, float(jitter_px), f"jittered {jitter_px:g} px",
          f"Stability under keypoint jitter ({jitter_px:g} px)")] if jitter_px else [])
    for title, peer, clips in sets:
        if only:
            clips = [c for c in clips if c.name in set(only.split(","))]
        if not clips:
            continue
        if keep is not None:
            # each clip's result folder and its true-camera lifting's work folder
            there = [c.name for c in clips if any((Path(keep) / n).exists() for n in (
                c.name, f"{c.name}.true_camera", *(f"{v[0]}/{c.name}" for v in variants)))]
            if there:
                raise ValueError(f"{keep}: result folders already there ({', '.join(there[:3])}"
                                 f"{', ...' if len(there) > 3 else ''}); give an empty or new folder")
            Path(keep).mkdir(parents=True, exist_ok=True)
            rows, scores = _score_set(clips, peer, keep)
            again = [_reseed_scores(clips, Path(keep) / v[0], v[1], v[2]) for v in variants]
        else:
            with tempfile.TemporaryDirectory() as tmp:
                rows, scores = _score_set(clips, peer, tmp)
                again = [_reseed_scores(clips, Path(tmp) / v[0], v[1], v[2]) for v in variants]
        summary = _summary(scores, peer)
        rep.numbers[title] = summary
        rep.add(f"## {title[0].upper() + title[1:]}: per clip\n")
        rep.add(md_table(HEADER, rows))
        rep.add(f"### Targets (issue 25) on the {title.split(' (')[0]}\n")
        rep.add(md_table(["target", "wanted", "measured", "met"],
                         [[a, b, c, "yes" if d else "**no**"] for a, b, c, d in _targets(summary)]))
        rep.add(f"### Hips, elbows and the trunk lean on the {title.split(' (')[0]}\n\n" + OTHER_ANGLES_NOTE)
        rep.add(md_table(["clip", "hip err deg", "hip in 90 % band %", "elbow err deg", "elbow in 90 % band %",
                          "trunk lean err deg", "verdict"], other_angle_rows(scores)))
        gt = gait_table(scores)
        if gt:
            rep.add(f"### Cadence by gait verdict on the {title.split(' (')[0]}\n\nThe gait verdict "
                    "(`run.json` `gait_verdict`, `probreg.inference.gait_check`) checks the contacts' cadence "
                    "against the stride period of the 2D pattern; no target in the issues.\n")
            rep.add(md_table(["gait verdict", "clips", "cadence mean abs. error %", "largest %", "above 5 % or none",
                              "90 % intervals holding the truth"], gt))
            flagged = [f"{n} ({'; '.join(s['gait_verdict_reasons'])})" for n, s in scores.items()
                       if s.get("gait_verdict") == "unreliable"]
            rep.add("Gait numbers flagged: " + ("; ".join(flagged) or "none") + ".\n")
            rep.add(pattern_cadence_line(scores) + "\n")
            rep.add(speed_line(scores) + "\n")
            rep.add("Every gait number's 90 % interval against the truth (the true contacts, pelvis speed and "
                    "knee angles; `probreg.bench.posterior.true_gait`), by gait verdict; no target in the issues:\n")
            rep.add(md_table(["gait number", "holding the truth, gait verdict ok", "gait verdict unreliable", "all"],
                             gait_coverage_table(scores)))
        for (_, seed, jit, label, head), second in zip(variants, again):
            rows_s, changed = seed_rows(scores, second)
            means = [_unflagged_knee(sc) for sc in (scores, second)]
            how = (f"with `--seed {seed}` (`--reseed {seed}`; the first run's seed is 0)" if not jit else
                   f"on a copy whose keypoints are moved by normal noise of {jit:g} px (`--jitter-px {jit:g}`; seed 0)")
            rep.add(f"### {head} on the {title.split(' (')[0]}\n\nEvery clip run again {how}: verdicts that changed: "
                    f"**{changed} of {len(rows_s) - 1}**; unflagged clips' mean knee error {means[0][0]:.2f} deg over "
                    f"{means[0][1]} clips (first run), {means[1][0]:.2f} deg over {means[1][1]} ({label}).\n")
            rep.add(md_table(["clip", "knee err deg, first run", label, "knee in 90 % band %, first run", label,
                              "camera height err %, first run", label, "verdict"], rows_s))
