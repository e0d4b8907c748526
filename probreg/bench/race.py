"""A race, not a lone runner: the same clips with other runners in the lanes next to the athlete.

Every clip probreg's generator made before 0.2.0.dev35 showed the athlete alone on the track; a
broadcast of a race shows the field.  Other runners hide lane lines, bring edges of their own
limbs into the lane step (only the athlete's region is masked out), and lend the colours of skin
and kit to the ring around the athlete that ``keypoints off the athlete`` compares the skeleton
with (:func:`probreg.lanes.on_athlete_fraction`).  Here each clip runs twice through the command
line, ``probreg run CLIP --out OUT --seed 0``: as it is (the athlete alone) and as the same race
with ``RIVALS`` other runners (:func:`probreg.sim.synth.simulate_rivals`: the nearest lanes, 2.5 m
ahead or behind at most, speeds within 3 % of the athlete's, other kits and skin tones).  The
athlete, the cameras and the keypoints are the same in both (the rivals draw their own random
numbers): what changes is only what the frames show.  The keypoints stay the athlete's (a pose
model that follows the athlete; a detector that jumps to another runner is another failure).

Per clip: the median ``keypoints_on_athlete`` score, the frames calibrated from their own lanes
(``run.json`` ``frame_status`` ``ok``), the knee error, the
camera height error and the verdict, alone and in the race.  Sets: the tuning clips (seeds
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

#: other runners in each race clip
RIVALS = 3
#: the tuning clips of this bench (developed on; the held-out set is only checked)
TUNING_SEEDS = tuple(range(8101, 8121))


def race_clip(alone: Path, root: Path, rivals=RIVALS, jobs=None):
    """The race version of a generated clip ``alone`` (its generator, preset and seed from its
    ``clip.json``), written once to ``root/<name>`` (reused when there)."""
    from ..sim import synthesize, write_clip
    from ..sim.heldout import heldout_config

    dst = Path(root) / alone.name
    if (dst / "clip.json").exists():
        return dst
    meta = json.loads((alone / "clip.json").read_text())
    gen = meta["generator"]
    cfg, _, _ = heldout_config(int(gen["seed"]), int(meta["n_frames"]))
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
        s.update(knee_deg=sc["knee_deg"], height_pct=sc["height_pct"], knee_coverage=sc["knee_coverage"])
    return s


def _pair_rows(pairs, tmp):
    rows, scores = [], {}
    for alone, race in pairs:
        a, r = _one(alone, Path(tmp) / "out" / f"{alone.name}_alone"), _one(race, Path(tmp) / "out" / f"{alone.name}_race")
        scores[alone.name] = (a, r)
        rows.append([alone.name, _f(a.get("on_athlete")), _f(r.get("on_athlete")),
                     f"{a.get('calibrated', 0)}/{a.get('n_frames', 0)}", f"{r.get('calibrated', 0)}/{r.get('n_frames', 0)}",
                     _f(a.get("knee_deg")), _f(r.get("knee_deg")), _f(a.get("height_pct")), _f(r.get("height_pct")),
                     verdict_text(a["verdict"], a["reasons"]), verdict_text(r["verdict"], r["reasons"])])
    return rows, scores


def _f(v):
    return float("nan") if v is None else float(v)


def summarise(scores):
    """Counts and means over a set's pairs: verdicts that changed (ok -> not ok: the race flagged
    a clip the athlete alone passed; not ok -> ok), clips the race flags for ``keypoints off the
    athlete``, and knee errors over the clips ``ok`` in both.

    >>> s = summarise({"a": ({"verdict": "ok", "reasons": [], "knee_deg": 3.0},
    ...                      {"verdict": "unreliable", "reasons": ["keypoints off the athlete (20 %)"], "knee_deg": 3.1}),
    ...                "b": ({"verdict": "ok", "reasons": [], "knee_deg": 2.0}, {"verdict": "ok", "reasons": [], "knee_deg": 2.5})})
    >>> s["ok_to_flagged"], s["off_athlete"], s["knee_alone"], s["knee_race"]
    (1, 1, 2.0, 2.5)
    """
    pairs = list(scores.values())
    both_ok = [(a, r) for a, r in pairs if a["verdict"] == "ok" and r["verdict"] == "ok"]
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
    }


def run(args=None):
    from ..sim.heldout import write_heldout

    rep = BenchReport("race", "A race, not a lone runner: other runners beside the athlete")
    rep.add(__doc__.split("\n\n", 1)[1])
    header = ["clip", "on athlete, alone", "in the race", "calibrated, alone", "in the race", "knee err deg, alone",
              "in the race", "camera height err %, alone", "in the race", "verdict alone", "verdict in the race"]
    with tempfile.TemporaryDirectory(prefix="probreg-race-") as tmp:
        tuning_root = Path(getattr(args, "suite_dir", None) or Path(tmp) / "tuning")

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
            pairs = [(c, race_clip(c, root / f"race{RIVALS}", jobs=getattr(args, "jobs", None))) for c in clips]
            rows, scores = _pair_rows(pairs, tmp)
            s = summarise(scores)
            rep.numbers[title] = s
            rep.add(f"## {title[0].upper() + title[1:]}: per clip\n")
            rep.add(md_table(header, rows))
            summary.append([title, s["clips"], f"{s['ok_alone']} -> {s['ok_race']}", s["ok_to_flagged"],
                            s["flagged_to_ok"], s["off_athlete"], s["on_athlete_race_min"], s["failed"],
                            f"{s['knee_alone']:.2f} -> {s['knee_race']:.2f} ({s['both_ok']} clips)", s["knee_worse_1deg"]])
        rep.add(f"## Summary ({RIVALS} other runners)\n")
        rep.add(md_table(["set", "clips", "verdict ok, alone -> race", "ok alone, flagged in the race",
                          "flagged alone, ok in the race", "race flagged 'keypoints off the athlete'",
                          "keypoints on athlete, smallest in a race", "race runs failed",
                          "knee err deg, clips ok in both: alone -> race", "of those, knee worse by > 1 deg"], summary))
    return rep
