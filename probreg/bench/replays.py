"""Slow-motion replays: found by the clip's time-base check, and right once their slow-down is given.

Every clip of the replay set (:mod:`probreg.sim.replays`: 24 held-out set-ups recorded at 1, 2, 3,
4 or 6 times the frame rate they are labelled with, or at half of it; seeds fixed before the
check ran on any of them) goes through the command line as a user runs a replay's file,
``probreg run CLIP --out OUT --seed 0``, and again with its true slow-down, ``--slow-motion N``.
Each result is scored against the ground truth:

* the time base ``run.json`` reports (``"time_base"``: ``status`` and the estimated factor,
  :mod:`probreg.inference.time_base`) against the true factor;
* the knee-angle error of the posterior median (deg, both knees, every frame);
* the cadence of ``gait.json`` against the runner's true cadence in real time;
* the clip verdict with its reasons.

Clips in real time must not be flagged: the same check is read from runs of the validation
clips (``shared/data/validation``, an independent generator) and of the held-out set (40 clips).
Two guards of the check were added after its first run on these sets (``docs/method.md``,
"Slow-motion replays"): the pelvis's swing bounded to what a runner's can be, and the search
for strides shorter than a runner's; the first run's numbers are given there.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from ..io.clip import load_groundtruth
from .common import BenchReport, md_table, verdict_text
from .cuts import _run_kept, knee_errors
from .validation import judge_dirs, real_time_clips

__all__ = ["score_replay", "run"]


def score_replay(clip_dir: Path, out_dir: Path):
    """Scores of one result folder of a replay (or real-time) clip: time base, knee error, cadence."""
    clip_dir, out_dir = Path(clip_dir), Path(out_dir)
    run = json.loads((out_dir / "run.json").read_text())
    gt = load_groundtruth(clip_dir)
    err = knee_errors(gt, out_dir)
    ok = np.isfinite(err)
    gait = json.loads((out_dir / "gait.json").read_text()) if (out_dir / "gait.json").exists() else {}
    step_hz = (gt.athlete.get("gait") or {}).get("step_freq_hz")
    cad = (gait.get("cadence_spm") or {}).get("median")
    tb = run.get("time_base") or {}
    pattern = tb.get("cadence_spm")
    return {"status": tb.get("status", "n/a"), "factor": tb.get("factor"), "bounce_g": tb.get("bounce_g"),
            "pattern_cadence_spm": float(pattern) if pattern is not None else float("nan"),
            "knee_deg": float(np.mean(err[ok])) if ok.any() else float("nan"),
            "cadence_spm": float(cad) if cad is not None else float("nan"),
            "cadence_true_spm": 60.0 * float(step_hz) if step_hz else float("nan"),
            "verdict": run.get("verdict", "n/a"), "reasons": run.get("verdict_reasons", [])}


def _expected(factor):
    return "ok" if factor == 1 else "slow" if factor > 1 else "fast"


def _fmt(v, f="{:.2f}"):
    return "n/a" if v is None or not np.isfinite(v) else f.format(v)


def _replay_rows(clips, keep):
    rows, counts = [], {"found": 0, "replays": 0, "false": 0, "realtime": 0, "knee": [], "knee_given": [],
                        "cad": [], "cad_given": [], "contacts_given": [], "ok_given": 0,
                        "factor_err": []}
    for clip in clips:
        gen = json.loads((clip / "clip.json").read_text())["generator"]
        factor = float(gen["slow_motion"])
        _run_kept(clip, keep / clip.name, ())
        s = score_replay(clip, keep / clip.name) if (keep / clip.name / "run.json").exists() else None
        g = None
        if factor != 1:
            out = keep / f"{clip.name}_given"
            _run_kept(clip, out, ("--slow-motion", f"{factor:g}"))
            g = score_replay(clip, out) if (out / "run.json").exists() else None
        if s is None:
            rows.append([clip.name, f"{factor:g}", "failed"] + [""] * 9)
            continue
        want = _expected(factor)
        if factor == 1:
            counts["realtime"] += 1
            counts["false"] += s["status"] != "ok"
        else:
            counts["replays"] += 1
            counts["found"] += s["status"] == want
            counts["knee"].append(s["knee_deg"])
            counts["cad"].append(abs(s["pattern_cadence_spm"] / s["cadence_true_spm"] - 1))
            if s["status"] == want and s["factor"] is not None:
                counts["factor_err"].append(abs(s["factor"] / factor - 1))
            if g is not None:
                counts["knee_given"].append(g["knee_deg"])
                counts["cad_given"].append(abs(g["pattern_cadence_spm"] / g["cadence_true_spm"] - 1))
                counts["contacts_given"].append(abs(g["cadence_spm"] / g["cadence_true_spm"] - 1))
                counts["ok_given"] += g["status"] == "ok"
        cad = lambda r: f"{_fmt(r['pattern_cadence_spm'], '{:.0f}')} / {_fmt(r['cadence_spm'], '{:.0f}')}"  # noqa: E731
        rows.append([clip.name, f"{factor:g}", f"{s['status']} (want {want})", _fmt(s["factor"]),
                     _fmt(s["bounce_g"]), s["knee_deg"], cad(s), _fmt(s["cadence_true_spm"], "{:.0f}"),
                     verdict_text(s["verdict"], s["reasons"]), g["knee_deg"] if g else float("nan"),
                     cad(g) if g else "n/a",
                     verdict_text(g["verdict"], g["reasons"]) if g else "n/a"])
    return rows, counts


def run(args):
    rep = BenchReport("replays", "Slow-motion replays: the clip's time base checked, and the slow-down given")
    rep.add(__doc__.split("\n", 1)[1].strip())
    from ..sim.replays import REPLAY_SEEDS, write_replay_clip

    with tempfile.TemporaryDirectory(prefix="probreg-bench-replays-") as tmp:
        root, keep = judge_dirs(args, tmp, "replays")
        clips = [write_replay_clip(root, seed) for seed in REPLAY_SEEDS]
        rows, c = _replay_rows(clips, keep)
        rep.add("## Replay set (probreg's generator, held-out set-ups; 200 frames as played)\n\n" + md_table(
            ["clip", "true slow-down", "time base found", "factor estimated", "pelvis bounce g", "knee err deg",
             "cadence spm: stride pattern / contacts", "true cadence spm", "verdict (reasons)", "given: knee err deg",
             "given: cadence spm, pattern / contacts",
             "given: verdict (reasons)"], rows))
        real = real_time_clips(args, tmp)
        real_rows, flagged = [], []
        for clip in real:
            out = keep / clip.name
            _run_kept(clip, out, ())
            if not (out / "run.json").exists():
                real_rows.append([clip.name, "failed", "", "", ""])
                continue
            tb = json.loads((out / "run.json").read_text()).get("time_base") or {}
            flagged += [clip.name] if tb.get("status", "ok") != "ok" else []
            real_rows.append([clip.name, tb.get("status", "n/a"), _fmt(tb.get("bounce_g")),
                              _fmt(tb.get("cadence_spm"), "{:.0f}"), _fmt(tb.get("speed_mps"))])
        rep.add("## Clips in real time (validation and held-out set)\n\n" + md_table(
            ["clip", "time base", "pelvis bounce g", "cadence spm", "speed m/s"], real_rows))
        med = lambda v: float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")  # noqa: E731
        rep.numbers.update({"replays_found": c["found"], "replays": c["replays"], "false_flags_replay_set": c["false"],
                            "false_flags_real_time": len(flagged), "real_time_clips": len(real)})
        rep.add("## Summary\n\n" + md_table(["measure", "value"], [
            ["replays (factor 2-6) and sped-up clips (0.5) whose time base was found wrong, in the right direction",
             f"{c['found']} of {c['replays']}"],
            ["estimated factor, those found: median relative error", _fmt(100 * med(c["factor_err"]), "{:.0f} %")],
            ["real-time clips of the replay set flagged", f"{c['false']} of {c['realtime']}"],
            ["real-time validation and held-out clips flagged", f"{len(flagged)} of {len(real)}"
             + (f" ({', '.join(flagged)})" if flagged else "")],
            ["knee error, replays run as labelled: median deg", _fmt(med(c["knee"]))],
            ["knee error, replays run with --slow-motion: median deg", _fmt(med(c["knee_given"]))],
            ["cadence error of the stride pattern, as labelled / with --slow-motion: median (clips with one)",
             f"{_fmt(100 * med(c['cad']), '{:.0f}')} % / {_fmt(100 * med(c['cad_given']), '{:.1f}')} %"],
            ["cadence error of the contacts (gait.json), with --slow-motion: median",
             f"{_fmt(100 * med(c['contacts_given']), '{:.1f}')} %"],
            ["replays with --slow-motion whose time base then reads ok", f"{c['ok_given']} of {len(c['knee_given'])}"],
        ]))
    return rep
