"""A randomised held-out set of broadcast set-ups, its seeds fixed before any tuning.

The benchmark suite (``probreg synth --suite bench``) holds the generator's typical set-ups,
and probreg was tuned on it.  This set is drawn over the set-ups real broadcasts have and the
suite lacks, so that a result on it says how probreg does on set-ups nobody tuned for:

* the camera's side: one in three across the infield (the runner goes right to left);
* the camera's kind, one of five equally likely: main stand (6-22 m high, 30-90 m away),
  grazing (2-5 m high, 60-110 m away, long lens), steep near (18-30 m high, 15-30 m away),
  wide near (3-10 m high, 10-25 m away, athlete 150-250 px, hFOV up to 35°, radial lens
  distortion k1 in +-0.25) and long lens (90-120 m away, athlete 550-700 px);
* 25 or 50 frames per second, 1280x720 or 1920x1080;
* stature uniform over 1.50-2.10 m, any running style, any lane.

:data:`HELDOUT_SEEDS` were fixed when this set was written (issue 25), before anything was tuned
against it; never tune on it (``probreg bench validation`` only reports it).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from .runner import STYLES
from .synth import CameraSetup, SynthConfig, synthesize, write_clip

__all__ = ["HELDOUT_SEEDS", "KINDS", "heldout_config", "write_heldout"]

#: the seeds of the held-out set (40 set-ups), fixed before tuning
HELDOUT_SEEDS = tuple(range(9001, 9041))
#: camera kinds of the held-out set
KINDS = ("stand", "grazing", "steep_near", "wide_near", "long_lens")


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def heldout_config(seed, n_frames=100):
    """The :class:`~probreg.sim.synth.SynthConfig` of held-out set-up ``seed`` and its kind.

    >>> cfg, kind, far = heldout_config(9001)
    >>> kind in KINDS and 1.5 <= cfg.stature_m <= 2.1 and cfg.fps in (25.0, 50.0)
    True
    """
    rng = np.random.default_rng([int(seed), 2025])
    kind = KINDS[int(rng.integers(len(KINDS)))]
    far = bool(rng.uniform() < 1 / 3)
    cam = dict(along_m=_u(rng, -30, 30), roll_deg=_u(rng, -1.0, 1.0),
               offset_frac=(_u(rng, -0.1, 0.1), _u(rng, -0.06, 0.06)), jitter_deg=_u(rng, 0.003, 0.015),
               follow_lag_s=_u(rng, 0.08, 0.25), zoom_drift=_u(rng, 0.0, 0.05), infield=far)
    if kind == "stand":
        cam.update(height_m=_u(rng, 6, 22), distance_m=_u(rng, 30, 90), athlete_height_px=_u(rng, 250, 450))
    elif kind == "grazing":
        cam.update(height_m=_u(rng, 2, 5), distance_m=_u(rng, 60, 110), athlete_height_px=_u(rng, 300, 500),
                   fov_range_deg=(1.5, 30.0))
    elif kind == "steep_near":
        cam.update(height_m=_u(rng, 18, 30), distance_m=_u(rng, 15, 30), athlete_height_px=_u(rng, 250, 400))
    elif kind == "wide_near":
        k1 = _u(rng, -0.25, 0.25)
        cam.update(height_m=_u(rng, 3, 10), distance_m=_u(rng, 10, 25), athlete_height_px=_u(rng, 150, 250),
                   fov_range_deg=(2.0, 35.0), dist=(k1, 0.0, 0.0, 0.0, 0.0))
    else:  # long lens
        cam.update(height_m=_u(rng, 6, 30), distance_m=_u(rng, 90, 120), athlete_height_px=_u(rng, 550, 700),
                   fov_range_deg=(1.5, 30.0))
    fps = 25.0 if rng.uniform() < 0.3 else 50.0
    size = (1280, 720) if rng.uniform() < 0.5 else (1920, 1080)
    scale = size[1] / 1080  # athlete heights above are for 1080p
    cam["athlete_height_px"] *= scale
    cfg = SynthConfig(style=str(rng.choice(sorted(STYLES))), stature_m=_u(rng, 1.50, 2.10),
                      n_frames=int(n_frames), fps=fps, image_size=size, athlete_lane=int(rng.integers(1, 9)),
                      camera=CameraSetup(**cam), mid_x_m=_u(rng, 25, 65))
    return cfg, kind, far


def write_heldout(out_dir, n_frames=100, seeds=HELDOUT_SEEDS, jobs=None, overwrite=False, label="heldout"):
    """Write the held-out clips to ``out_dir/<label>_<seed>_<kind>[_far]``; returns their paths.

    ``label`` names clips of the same generator drawn at other seeds (e.g. ``"calibration"`` for
    ``probreg bench band-calibration``'s), in the folder's name and the clip's preset."""
    out_dir = Path(out_dir)
    paths = []
    for seed in seeds:
        cfg, kind, far = heldout_config(seed, n_frames)
        name = f"{label}_{seed}_{kind}" + ("_far" if far else "")
        clip = synthesize(replace(cfg), seed=int(seed), preset=f"{label}:{kind}")
        paths.append(write_clip(clip, out_dir / name, images=True, jobs=jobs, overwrite=overwrite))
    return paths
