"""Broadcast clips that cut from one camera to another, for the camera-cut benchmark.

A broadcast edit follows one athlete from camera to camera.  A clip of this set is one runner
(one :func:`~probreg.sim.synth.synthesize` run) filmed by two cameras of the held-out set's
kinds (:func:`probreg.sim.heldout.heldout_config`); the frames before the cut come from the
first camera, the rest from the second, at the first's frame rate and image size.  Every other
pair cuts to a camera of an independently drawn set-up (often another kind, side or lens); the
others cut to a camera of the same kind and side moved by 15-40 % in height and in distance,
whose picture looks much like the first (the hard case for a cut found from the colours).

:data:`CUT_SEEDS` were fixed when this set was written, before the cut detection was tuned; it
is only reported (``probreg bench cuts``), never tuned on.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io.clip import atomic_output_dir
from .heldout import heldout_config
from .synth import synthesize, write_clip

__all__ = ["CUT_SEEDS", "cut_config", "write_cut_clip"]

#: seeds of the camera-cut set (20 clips), fixed before tuning
CUT_SEEDS = tuple(range(9601, 9621))


def cut_config(seed, n_frames=100):
    """``(first, second, cut, description)``: the configurations of the two cameras' clips (one
    runner), the first frame of the second camera, and a short description.

    >>> a, b, cut, what = cut_config(9601)
    >>> a.stature_m == b.stature_m and a.fps == b.fps and a.image_size == b.image_size and 35 <= cut <= 65
    True
    """
    first, kind, far = heldout_config(seed, n_frames)
    rng = np.random.default_rng([int(seed), 31])
    cut = int(round(n_frames * rng.uniform(0.35, 0.65)))
    if int(seed) % 2:  # another set-up: its camera, at this clip's frame rate and image size
        other, kind2, far2 = heldout_config(int(seed) + 1000, n_frames)
        cam = other.camera
        scale = first.image_size[1] / other.image_size[1]
        cam = replace(cam, athlete_height_px=cam.athlete_height_px * scale)
        what = f"{kind}{'_far' if far else ''} -> {kind2}{'_far' if far2 else ''}"
    else:  # the same kind of camera, moved
        fh, fd = (float(rng.uniform(1.15, 1.4)) ** rng.choice([-1, 1]) for _ in range(2))
        cam = replace(first.camera, height_m=first.camera.height_m * fh, distance_m=first.camera.distance_m * fd)
        what = f"{kind}{'_far' if far else ''} moved (height x{fh:.2f}, distance x{fd:.2f})"
    return first, replace(first, camera=cam), cut, what


def write_cut_clip(out_dir, seed, n_frames=100, jobs=None):
    """Write the cut clip of ``seed`` to ``out_dir`` (a clip folder of CLIP_FORMAT with its
    ground truth; ``clip.json`` gains ``"generator": {"cut": frame, ...}``), atomically
    (:func:`probreg.io.clip.atomic_output_dir`: a folder that holds files probreg did not write
    is refused); returns the path.  Both cameras' clips are rendered whole and spliced."""
    first, second, cut, what = cut_config(seed, n_frames)
    with tempfile.TemporaryDirectory(prefix="probreg-cut-") as tmp, atomic_output_dir(Path(out_dir)) as out:
        parts = [write_clip(synthesize(cfg, seed=int(seed), preset="cut"), Path(tmp) / name, images=True, jobs=jobs)
                 for name, cfg in (("a", first), ("b", second))]
        (out / "frames").mkdir()
        (out / "groundtruth").mkdir()
        for i in range(n_frames):
            src = parts[0] if i < cut else parts[1]
            shutil.copy(src / "frames" / f"{i:06d}.jpg", out / "frames" / f"{i:06d}.jpg")
        kps = [json.loads((p / "keypoints2d.json").read_text()) for p in parts]
        kps[0]["frames"] = kps[0]["frames"][:cut] + kps[1]["frames"][cut:]
        (out / "keypoints2d.json").write_text(json.dumps(kps[0]))
        cams = [json.loads((p / "groundtruth" / "cameras.json").read_text()) for p in parts]
        cams[0]["frames"] = cams[0]["frames"][:cut] + cams[1]["frames"][cut:]
        (out / "groundtruth" / "cameras.json").write_text(json.dumps(cams[0]))
        for name in ("joints3d.npy", "contacts.npy", "joints2d.npy"):
            a, b = (np.load(p / "groundtruth" / name) for p in parts)
            np.save(out / "groundtruth" / name, a if name != "joints2d.npy" else np.concatenate([a[:cut], b[cut:]]))
        shutil.copy(parts[0] / "groundtruth" / "athlete.json", out / "groundtruth" / "athlete.json")
        meta = json.loads((parts[0] / "clip.json").read_text())
        meta["generator"] = {"name": "probreg.sim.cuts", "seed": int(seed), "cut": cut, "shots": what}
        (out / "clip.json").write_text(json.dumps(meta, indent=1))
    return Path(out_dir)
