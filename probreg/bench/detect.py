"""A real 2D pose model on the seed paper's frames and on a synthetic clip: speed and plausibility.

The model is an ONNX file (``--model PATH``; default: the ``probreg models
export-yolo`` output in ``~/.cache/probreg``).  Without a model nothing is
measured and the report says so.

* speed: frames per second of the whole detection step (full-frame detection,
  enlarged-crop refinement, athlete choice), 2 cores;
* paper frames: is an athlete found, and how plausible are the keypoints:
  left/right symmetry of thigh and shank lengths (px, ratio near 1 when the
  legs are equally foreshortened), all keypoints inside the frame;
* synthetic clip (probreg's renderer, with ground truth): detection rate,
  mean keypoint error (px) and limb-length consistency over the clip
  (coefficient of variation of the thigh length in px).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from ..detect import default_cache_dir, detect_sequence, load_pose_model
from ..geometry import COCO_NAMES, coco_to_h36m
from ..io.clip import load_clip, load_groundtruth
from ..io.frames import iter_frames
from ..sim import config_from_preset, synthesize, write_clip
from .common import BenchReport, find_shared_data, md_table

__all__ = ["run"]

C = {n: i for i, n in enumerate(COCO_NAMES)}


def _seg(kp, a, b):
    return float(np.linalg.norm(kp[C[a], :2] - kp[C[b], :2]))


def run(args=None):
    rep = BenchReport("detect", "2D pose model: speed and keypoint plausibility")
    rep.add(__doc__.split("\n\n", 1)[1])
    path = Path(getattr(args, "model", None) or default_cache_dir() / "yolo11n-pose.onnx")
    if not path.exists():
        rep.add(f"No model at `{path}`: nothing measured (run `probreg models export-yolo` with the "
                f"`yolo` extra, or pass `--model`).\n")
        return rep
    model = load_pose_model(path)
    rep.add(f"Model: `{path.name}` ({type(model).__name__}, input {model.w}x{model.h}).\n")
    data = find_shared_data(getattr(args, "shared", None))
    if data is not None and (data / "paper_frames").is_dir():
        rows, times = [], []
        for p in sorted((data / "paper_frames").glob("*.jpeg")):
            img = cv2.imread(str(p))
            t0 = time.perf_counter()
            kp = detect_sequence([(0, img)], model)[0]
            times.append(time.perf_counter() - t0)
            found = np.isfinite(kp[:, 0]).sum() >= 10
            if found:
                sym_t = _seg(kp, "l_hip", "l_knee") / max(_seg(kp, "r_hip", "r_knee"), 1e-6)
                sym_s = _seg(kp, "l_knee", "l_ankle") / max(_seg(kp, "r_knee", "r_ankle"), 1e-6)
                h, w = img.shape[:2]
                ok = kp[np.isfinite(kp[:, 0])]
                inside = bool(np.all((ok[:, 0] >= 0) & (ok[:, 0] < w) & (ok[:, 1] >= 0) & (ok[:, 1] < h)))
            else:
                sym_t = sym_s = float("nan")
                inside = False
            rows.append([p.name, found, int(np.isfinite(kp[:, 0]).sum()), sym_t, sym_s, inside,
                         1000 * times[-1]])
        fps = 1.0 / float(np.median(times[1:] if len(times) > 1 else times))
        rep.add("## Seed paper frames (1280x720)\n")
        rep.add(md_table(["frame", "athlete found", "joints >= score", "thigh L/R", "shank L/R",
                          "all inside", "ms"], rows))
        n_found = sum(r[1] for r in rows)
        rep.add(f"Athlete found in {n_found}/{len(rows)} frames; **{fps:.1f} frames/s** (median; target >= 8).\n")
        rep.numbers["paper_fps"] = fps
        rep.numbers["paper_found"] = n_found
    with tempfile.TemporaryDirectory() as tmp:
        clip_dir = write_clip(synthesize(config_from_preset("run", 3, n_frames=100), seed=3), Path(tmp) / "c")
        clip = load_clip(clip_dir)
        gt = load_groundtruth(clip_dir)
        t0 = time.perf_counter()
        coco = detect_sequence(iter_frames(clip), model)
        dt = time.perf_counter() - t0
        h36 = coco_to_h36m(coco)
        found = np.isfinite(h36[:, 0, 0])
        err = np.linalg.norm(h36[..., :2] - gt.joints2d_px, axis=-1)
        thigh = np.linalg.norm(coco[:, C["r_hip"], :2] - coco[:, C["r_knee"], :2], axis=-1)
        cv = float(np.nanstd(thigh) / np.nanmean(thigh)) if np.isfinite(thigh).any() else float("nan")
        rep.add("## Synthetic clip (probreg renderer, 100 frames 1080p, preset run)\n")
        rep.add(md_table(["frames with the athlete", "mean keypoint error px", "median px",
                          "thigh length CV", "frames/s"],
                         [[f"{found.sum()}/{len(found)}", float(np.nanmean(err)), float(np.nanmedian(err)), cv,
                           len(found) / dt]]))
        rep.add("The renderer draws a flat-shaded mannequin, not a person: a detector trained on "
                "photographs may miss it; this row says how far probreg's synthetic benchmark "
                "transfers to a real detector, not how good the detector is.\n")
    return rep
