"""A race, not a lone runner: the same clips with other runners in the lanes next to the athlete.

Every clip probreg's generator made before 0.2.0.dev35 showed the athlete alone on the track; a
broadcast of a race shows the field.  Other runners hide lane lines, bring edges of their own
limbs into the lane step (only the athlete's region is masked out), and lend the colours of skin
and kit to the ring around the athlete that ``keypoints off the athlete`` compares the skeleton
with (:func:`probreg.lanes.on_athlete_fraction`).  Here each clip runs twice through the command
line, ``probreg run CLIP --out OUT --seed 0``: as it is (the athlete alone) and as the same race
with 3 and with 7 other runners (``RIVALS``; 7: a full eight-lane field;
:func:`probreg.sim.synth.simulate_rivals`: the nearest lanes, 2.5 m
ahead or behind at most, speeds within 3 % of the athlete's, other kits and skin tones).  The
athlete, the cameras and the keypoints are the same in both (the rivals draw their own random
numbers): what changes is only what the frames show.  The keypoints stay the athlete's (a pose
model that follows the athlete; a detector that jumps to another runner is another failure).

Per clip: the median ``keypoints_on_athlete`` score, the frames calibrated from their own lanes
(``run.json`` ``frame_status`` ``ok``), the knee error, the camera height error and the verdict,
alone and in each race; per set, also how often the camera height's 90 % interval and the knee's
90 % band hold the truth.  Sets: the tuning clips (seeds
8101-8120, developed on; ``--suite-dir`` holds or receives them) and the held-out clips
(``--heldout-dir``; checked, never tuned on).  The validation clips come from another generator
and cannot be re-rendered with rivals.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from .common import BenchReport, md_table, verdict_text
from .posterior import score_result
from .validation import _heldout_clips, _run_cli

__all__ = ["RIVALS", "TUNING_SEEDS", "race_clip", "run"]

#: other runners in the race clips (7: one in each other lane of an eight-lane track)
RIVALS = (3, 7)
#: the tuning clips of this bench (developed on; the held-out set is only checked)
TUNING_SEEDS = tuple(range(8101, 8121))


def race_clip(alone: Path, root: Path, rivals=3, jobs=None):
    """The race version of a clip ``alone`` of the held-out generator (:mod:`probreg.sim.heldout`;
    its seed from its ``clip.json``), written once to ``root/<name>`` (reused when there)."""
    from ..sim import synthesize, write_clip
    from ..sim.heldout import heldout_config

    dst = Path(root) / alone.name
    if (dst / "clip.json").exists():
        return dst
    meta = json.loads((alone / "clip.json").read_text())
    gen = meta["generator"]
    cfg, kind, _ = heldout_config(int(gen["seed"]), int(meta["n_frames"]))
    if str(gen.get("preset", "")).partition(":")[2] != kind:  # not a clip of the held-out generator
        raise ValueError(f"{alone}: not a clip of probreg.sim.heldout (preset {gen.get('preset')!r}, expected '...:{kind}')")
    clip = synthesize(replace(cfg, rivals=int(rivals)), seed=int(gen["seed"]), preset=gen["preset"])
    return write_clip(clip, dst, images=True, jobs=jobs)


def _one(clip: Path, out: Path):
    code, dt, last = _run_cli(clip, out)
    if not (out / "run.json").exists():
        return {"exit": code, "error": last, "verdict": "failed", "reasons": [last]}
    run = json.loads((out / "run.json").read_text())
    diag = run.get("diagnostics") or {}
    s = {"exit": code, "time_s": dt, "verdict": run.get("verdict"), "reasons": run.get("verdict_reasons", []),
         "on_athlete": ((diag.get("keypoints_on_athlete") or {}).get("median")),
         "calibrated": sum(1 for st in run.get("frame_status", []) if st == "ok"),  # from its own lanes
         "n_frames": len(run.get("frame_status", []))}
    if (out / "angles.csv").exists() and (out / "camera.json").exists():
        sc = score_result(clip, out)
        s.update(knee_deg=sc["knee_deg"], height_pct=sc["height_pct"], knee_coverage=sc["knee_coverage"],
                 height_in_interval=sc["height_in_interval"])
    return s


def _pair_rows(groups, out_root):
    """Per clip ``[alone, race with RIVALS[0], ...]``: the table's rows and every run's scores."""
    rows, scores = [], {}
    for alone, races in groups:
        runs = [_one(alone, Path(out_root) / f"{alone.name}_alone")]
        runs += [_one(r, Path(out_root) / f"{alone.name}_race{n}") for n, r in zip(RIVALS, races)]
        scores[alone.name] = runs
        cells = [[_f(x.get("on_athlete")) for x in runs], [f"{x.get('calibrated', 0)}/{x.get('n_frames', 0)}" for x in runs],
                 [_f(x.get("knee_deg")) for x in runs], [_f(x.get("height_pct")) for x in runs],
                 [verdict_text(x["verdict"], x["reasons"]) for x in runs]]
        rows.append([alone.name] + [v for group in cells for v in group])
    return rows, scores


def _f(v):
    return float("nan") if v is None else float(v)


def summarise(scores, k=1):
    """Counts and means over a set's clips, alone (run 0) against race ``k``: verdicts that changed
    (ok -> not ok: the race flagged a clip the athlete alone passed; not ok -> ok), races flagged
    for ``keypoints off the athlete``, knee errors over the clips ``ok`` in both, and how many
    camera height intervals and knee bands hold the truth (the bands: mean share of frames).

    >>> s = summarise({"a": [{"verdict": "ok", "reasons": [], "knee_deg": 3.0},
    ...                      {"verdict": "unreliable", "reasons": ["keypoints off the athlete (20 %)"], "knee_deg": 3.1}],
    ...                "b": [{"verdict": "ok", "reasons": [], "knee_deg": 2.0}, {"verdict": "ok", "reasons": [], "knee_deg": 2.5}]})
    >>> s["ok_to_flagged"], s["off_athlete"], s["knee_alone"], s["knee_race"]
    (1, 1, 2.0, 2.5)
    """
    pairs = [(runs[0], runs[k]) for runs in scores.values()]
    both_ok = [(a, r) for a, r in pairs if a["verdict"] == "ok" and r["verdict"] == "ok"]

    def share(key, i):
        vals = [p[i][key] for p in pairs if key in p[i]]
        return (sum(map(bool, vals)), len(vals)) if key == "height_in_interval" else (
            float(np.mean(vals)) if vals else float("nan"))

    return {
        "clips": len(pairs),
        "ok_alone": sum(a["verdict"] == "ok" for a, _ in pairs), "ok_race": sum(r["verdict"] == "ok" for _, r in pairs),
        "ok_to_flagged": sum(a["verdict"] == "ok" and r["verdict"] != "ok" for a, r in pairs),
        "flagged_to_ok": sum(a["verdict"] != "ok" and r["verdict"] == "ok" for a, r in pairs),
        "off_athlete": sum(any(x.startswith("keypoints off the athlete") for x in r["reasons"]) for _, r in pairs),
        "failed": sum(r["verdict"] == "failed" for _, r in pairs),
        "on_athlete_race_min": min((v for v in (_f(r.get("on_athlete")) for _, r in pairs) if np.isfinite(v)),
                                   default=float("nan")),
        "knee_alone": float(np.mean([a["knee_deg"] for a, _ in both_ok])) if both_ok else float("nan"),
        "knee_race": float(np.mean([r["knee_deg"] for _, r in both_ok])) if both_ok else float("nan"),
        "both_ok": len(both_ok),
        "knee_worse_1deg": sum(r["knee_deg"] > a["knee_deg"] + 1 for a, r in both_ok),
        "height_hits_alone": share("height_in_interval", 0), "height_hits_race": share("height_in_interval", 1),
        "knee_coverage_alone": share("knee_coverage", 0), "knee_coverage_race": share("knee_coverage", 1),
    }


def run(args=None):
    from ..sim.heldout import write_heldout

    rep = BenchReport("race", "A race, not a lone runner: other runners beside the athlete")
    rep.add(__doc__.split("\n\n", 1)[1])
    labels = ["alone"] + [f"{n} rivals" for n in RIVALS]
    header = (["clip"] + [f"on athlete, {x}" for x in labels] + [f"calibrated, {x}" for x in labels]
              + [f"knee err deg, {x}" for x in labels] + [f"camera height err %, {x}" for x in labels]
              + [f"verdict, {x}" for x in labels])
    with tempfile.TemporaryDirectory(prefix="probreg-race-") as tmp:
        tuning_root = Path(getattr(args, "suite_dir", None) or Path(tmp) / "tuning")
        out_root = Path(getattr(args, "keep_outputs", None) or Path(tmp) / "out")

        def tuning_clip(seed):
            return next((p for p in sorted(tuning_root.glob(f"tuning_{seed}_*")) if (p / "clip.json").exists()), None)

        missing = [s for s in TUNING_SEEDS if tuning_clip(s) is None]
        if missing:
            write_heldout(tuning_root, seeds=missing, label="tuning", jobs=getattr(args, "jobs", None))
        heldout_root = Path(getattr(args, "heldout_dir", None) or Path(tmp) / "heldout")
        sets = [("tuning clips (seeds 8101-8120; developed on)", [tuning_clip(s) for s in TUNING_SEEDS], tuning_root),
                ("held-out clips (checked, never tuned on)", _heldout_clips(heldout_root), heldout_root)]
        only = [s.strip() for s in (getattr(args, "only", None) or "").split(",") if s.strip()]
        summary = []
        for title, clips, root in sets:
            if only:
                clips = [c for c in clips if any(o in c.name for o in only)]
            if not clips:
                continue
            groups = [(c, [race_clip(c, root / f"race{n}", rivals=n, jobs=getattr(args, "jobs", None)) for n in RIVALS])
                      for c in clips]
            rows, scores = _pair_rows(groups, out_root)
            rep.add(f"## {title[0].upper() + title[1:]}: per clip\n")
            rep.add(md_table(header, rows))
            for k, n in enumerate(RIVALS, start=1):
                s = summarise(scores, k)
                rep.numbers[f"{title}, {n} rivals"] = s
                summary.append([title, n, s["clips"], f"{s['ok_alone']} -> {s['ok_race']}", s["ok_to_flagged"],
                                s["flagged_to_ok"], s["off_athlete"], s["on_athlete_race_min"], s["failed"],
                                f"{s['knee_alone']:.2f} -> {s['knee_race']:.2f} ({s['both_ok']} clips)",
                                s["knee_worse_1deg"],
                                f"{s['height_hits_alone'][0]} -> {s['height_hits_race'][0]} of {s['height_hits_race'][1]}",
                                f"{100 * s['knee_coverage_alone']:.1f} -> {100 * s['knee_coverage_race']:.1f}"])
        rep.add("## Summary\n")
        rep.add(md_table(["set", "other runners", "clips", "verdict ok, alone -> race", "ok alone, flagged in the race",
                          "flagged alone, ok in the race", "race flagged 'keypoints off the athlete'",
                          "keypoints on athlete, smallest in a race", "race runs failed",
                          "knee err deg, clips ok in both: alone -> race", "of those, knee worse by > 1 deg",
                          "camera height interval holds the truth, alone -> race",
                          "knee in 90 % band %, mean, alone -> race"], summary))
    return rep
