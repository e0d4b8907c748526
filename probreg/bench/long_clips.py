"""Long clips: do the intervals hold over a whole straight?

Every clip probreg's intervals were calibrated and judged on has 40-250 frames; a user's clip of a
whole straight has more (20 s is 1000 frames at 50 fps).  Seven clips of probreg's default
generator with 1000 frames, at seeds fixed before their first run (:data:`LONG_SEEDS`; never
tuned on), and each one's first 250 frames cut from it (the same scene, camera and keypoints: what
the length alone changes), go through the command line as a user runs them, ``probreg run CLIP
--out OUT --seed 0``.  Scored against the ground truth: the knee error of the posterior median
and the knee bands' coverage, the camera height's error, whether its 90 % interval
(``camera.json``) holds the truth and how wide it is, the same for the stature (``run.json``'s
``athlete``), the verdict and the wall time.

Until 0.2.0.dev29 the limbs' consistency term sharpened the camera height with every frame while
its bias stayed, and the 1000-frame clips' height intervals held the truth on 3 of 7
(``docs/method.md``, "Long clips"); since then that term holds at most 100 frames of evidence
(:data:`probreg.inference.heights.LIMB_EVIDENCE_FRAMES`).  With ``--suite-dir DIR`` the clips are
written there once and reused; ``--keep-outputs DIR`` keeps the results (and reuses them).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .common import BenchReport, md_table, verdict_text
from .cuts import _run_kept
from .posterior import score_result
from .validation import _stature_interval, judge_dirs

__all__ = ["LONG_SEEDS", "LONG_FRAMES", "CUT_FRAMES", "write_long_clip", "cut_clip", "run"]

#: seeds of the long clips, fixed before their first run (11 was the first long clip tried by hand)
LONG_SEEDS = (11, 9601, 9602, 9603, 9604, 9605, 9606)
LONG_FRAMES = 1000
CUT_FRAMES = 250


#: ``clip.json``'s generator name of the clips this bench writes (a clip found there is reused only with it)
GENERATOR = "probreg.bench.long_clips"


def write_long_clip(root, seed, n_frames=LONG_FRAMES, jobs=None):
    """The default generator's clip at ``seed`` with ``n_frames`` frames in ``root/long_<seed>``
    (:func:`probreg.sim.replays.write_generated_clip`: written atomically, a clip this bench wrote
    there before is reused, a folder probreg did not write is refused); returns its path."""
    from ..sim import config_from_preset
    from ..sim.replays import write_generated_clip

    cfg = config_from_preset("default", int(seed), n_frames=int(n_frames))
    return write_generated_clip(Path(root) / f"long_{seed}", cfg, seed, GENERATOR, {}, "default", jobs=jobs)


def cut_clip(src, dst, n_frames):
    """The first ``n_frames`` frames of the clip ``src`` as the clip ``dst``: images (hard links
    where the file system allows, else copies), ``clip.json``, the keypoints of those frames and
    the ground truth cut likewise, written atomically (:func:`probreg.io.output.atomic_output_dir`:
    a folder probreg did not write is refused).  A cut of the same clip to the same length written
    there before is reused.

    >>> import tempfile, numpy as np
    >>> root = Path(tempfile.mkdtemp())
    >>> (root / "a" / "frames").mkdir(parents=True); (root / "a" / "groundtruth").mkdir()
    >>> for i in range(4): _ = (root / "a" / "frames" / f"{i:06d}.jpg").write_bytes(b"x")
    >>> _ = (root / "a" / "clip.json").write_text('{"fps": 50, "image_size": [8, 8], "n_frames": 4}')
    >>> _ = (root / "a" / "keypoints2d.json").write_text(
    ...     '{"format": "h36m17", "frames": [{"frame": 0, "keypoints": null}, {"frame": 3, "keypoints": null}]}')
    >>> np.save(root / "a" / "groundtruth" / "joints3d.npy", np.zeros((4, 17, 3)))
    >>> _ = (root / "a" / "groundtruth" / "cameras.json").write_text('{"frames": [{"frame": 0}, {"frame": 3}]}')
    >>> b = cut_clip(root / "a", root / "b", 2)
    >>> sorted(p.name for p in (b / "frames").iterdir()), json.loads((b / "clip.json").read_text())["n_frames"]
    (['000000.jpg', '000001.jpg'], 2)
    >>> np.load(b / "groundtruth" / "joints3d.npy").shape, json.loads((b / "keypoints2d.json").read_text())["frames"]
    ((2, 17, 3), [{'frame': 0, 'keypoints': None}])
    >>> cut_clip(root / "a", root / "b", 2) == b     # reused
    True
    >>> shutil.rmtree(root)
    """
    from ..io.output import MARKER, atomic_output_dir

    src, dst, n = Path(src), Path(dst), int(n_frames)
    made_by = {"name": GENERATOR, "cut_from": src.name, "frames": n}
    try:
        if json.loads((dst / "clip.json").read_text()).get("generator") == made_by and (dst / MARKER).exists():
            return dst
    except (OSError, ValueError):
        pass
    with atomic_output_dir(dst) as out:
        (out / "frames").mkdir()
        for p in sorted((src / "frames").iterdir()):
            if p.stem.isdigit() and int(p.stem) < n:
                try:
                    os.link(p, out / "frames" / p.name)
                except OSError:
                    shutil.copy2(p, out / "frames" / p.name)
        meta = json.loads((src / "clip.json").read_text())
        (out / "clip.json").write_text(json.dumps({**meta, "n_frames": n, "generator": made_by}, indent=1))
        kp = json.loads((src / "keypoints2d.json").read_text())
        kp["frames"] = [f for f in kp["frames"] if int(f["frame"]) < n]
        (out / "keypoints2d.json").write_text(json.dumps(kp))
        (out / "groundtruth").mkdir()
        for p in (src / "groundtruth").iterdir():
            if p.suffix == ".npy":
                np.save(out / "groundtruth" / p.name, np.load(p)[:n])
            elif p.name == "cameras.json":
                cams = json.loads(p.read_text())
                cams["frames"] = [c for c in cams["frames"] if int(c["frame"]) < n]
                (out / "groundtruth" / p.name).write_text(json.dumps(cams))
            else:
                shutil.copy2(p, out / "groundtruth" / p.name)
    return dst


HEADER = ["clip", "frames", "knee err deg", "knee in 90 % band %", "camera height err %", "height in 90 %",
          "height interval width %", "stature err %", "stature in 90 %", "verdict (reasons)", "wall s"]


def _score(clip, out, wall):
    s = score_result(clip, out)
    athlete = json.loads((clip / "groundtruth" / "athlete.json").read_text())
    st_true = float(athlete["stature_m"])
    st_med, st_lo, st_hi = _stature_interval(out)
    run = json.loads((out / "run.json").read_text())
    return {"knee_deg": s["knee_deg"], "knee_coverage": 100 * s["knee_coverage"],
            "height_err_pct": 100 * (s["h_med"] / s["h_true"] - 1), "height_in": s["height_in_interval"],
            "height_width_pct": 100 * (s["h_hi"] / s["h_lo"] - 1),
            "stature_err_pct": 100 * (st_med / st_true - 1), "stature_in": bool(st_lo <= st_true <= st_hi),
            "verdict": run.get("verdict", "n/a"), "reasons": run.get("verdict_reasons", []), "wall_s": wall}


def _summary_row(label, scores):
    n = len(scores)
    mean = lambda k: float(np.mean([abs(s[k]) if k.endswith("err_pct") else s[k] for s in scores])) if n else np.nan  # noqa: E731
    return [label, n, mean("knee_deg"), mean("knee_coverage"), mean("height_err_pct"),
            f"{sum(s['height_in'] for s in scores)} of {n}", mean("height_width_pct"), mean("stature_err_pct"),
            f"{sum(s['stature_in'] for s in scores)} of {n}", f"{sum(s['verdict'] != 'ok' for s in scores)} of {n}",
            mean("wall_s")]


def run(args):
    rep = BenchReport("long-clips", "Long clips: the intervals over a whole straight (1000 frames) and its first 250")
    rep.add(__doc__.split("\n", 1)[1].strip())
    with tempfile.TemporaryDirectory(prefix="probreg-bench-long-") as tmp:
        root, keep = judge_dirs(args, tmp, "long")
        rows, by_len, failed = [], {CUT_FRAMES: [], LONG_FRAMES: []}, []
        for seed in LONG_SEEDS:
            long_clip = write_long_clip(root, seed)
            short_clip = cut_clip(long_clip, root / f"long_{seed}_first{CUT_FRAMES}", CUT_FRAMES)
            for clip, n in ((short_clip, CUT_FRAMES), (long_clip, LONG_FRAMES)):
                code, wall = _run_kept(clip, keep / clip.name, ())
                if not (keep / clip.name / "run.json").exists():
                    failed.append(clip.name)
                    rows.append([clip.name, n, f"failed (exit {code})"] + [""] * (len(HEADER) - 3))
                    continue
                s = _score(clip, keep / clip.name, wall)
                by_len[n].append(s)
                rows.append([clip.name, n, s["knee_deg"], s["knee_coverage"], s["height_err_pct"],
                             "yes" if s["height_in"] else "no", s["height_width_pct"], s["stature_err_pct"],
                             "yes" if s["stature_in"] else "no", verdict_text(s["verdict"], s["reasons"]), s["wall_s"]])
        rep.add("## Per clip\n\n" + md_table(HEADER, rows))
        rep.add("## Summary\n\n" + md_table(
            ["clips", "n", "mean knee err deg", "mean knee coverage %", "mean abs height err %", "height in 90 %",
             "mean height interval width %", "mean abs stature err %", "stature in 90 %", "verdict not ok",
             "mean wall s"],
            [_summary_row(f"first {CUT_FRAMES} frames", by_len[CUT_FRAMES]),
             _summary_row(f"whole clip, {LONG_FRAMES} frames", by_len[LONG_FRAMES])])
            + ("\nFailed runs: " + ", ".join(failed) + ".\n" if failed else ""))
        for n, ss in by_len.items():
            rep.numbers.update({f"height_in_{n}": sum(s["height_in"] for s in ss),
                                f"stature_in_{n}": sum(s["stature_in"] for s in ss), f"clips_{n}": len(ss)})
    return rep
