"""Cameras on a rail: the held-out set's set-ups with a camera that moves along the track.

Besides the static pan/tilt/zoom cameras probreg models, broadcasts use cameras on a rail beside
the straight (or on a tracking vehicle) that run with the athletes.  Their lanes look the same as a
static camera's (the lines run along the direction of travel, so a move along it leaves them in
place), and probreg, assuming a static camera, reads the runner's motion relative to the moving
camera: a planted foot runs backwards.  A clip of this set is one of the held-out set's set-ups
(:func:`probreg.sim.heldout.heldout_config`) with its camera on a rail at a share ``rail_frac``
of the runner's mean speed (:attr:`probreg.sim.synth.CameraSetup.rail_frac`; 0 is the static
camera, as a control); ``clip.json`` ``"generator"`` records it.

:data:`RAIL_SEEDS` were fixed when this set was written, before the feet-slide check
(:func:`probreg.inference.gait_check.stance_slide`) was run on any of them; it was designed on
other seeds (7601-7608) and is only reported here (``probreg bench rails``), never tuned on.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from .heldout import heldout_config
from .replays import write_generated_clip

__all__ = ["RAIL_SEEDS", "RAIL_FRACS", "rail_config", "write_rail_clip"]

#: seeds of the rail set (20 clips, four per share), fixed before any run
RAIL_SEEDS = tuple(range(9801, 9821))
#: shares of the runner's speed the camera moves at, taken in turn by the seeds (0: static)
RAIL_FRACS = (0.0, 0.25, 0.5, 0.75, 1.0)


def rail_config(seed, n_frames=100):
    """``(config, rail_frac, name)`` of rail clip ``seed``.

    >>> cfg, frac, name = rail_config(9803)
    >>> frac, cfg.camera.rail_frac, name.startswith("rail_9803_f0.5_")
    (0.5, 0.5, True)
    """
    cfg, kind, far = heldout_config(seed, n_frames)
    frac = RAIL_FRACS[(int(seed) - RAIL_SEEDS[0]) % len(RAIL_FRACS)]
    name = f"rail_{seed}_f{frac:g}_{kind}" + ("_far" if far else "")
    return replace(cfg, camera=replace(cfg.camera, rail_frac=frac)), frac, name


def write_rail_clip(root, seed, n_frames=100, jobs=None):
    """Write rail clip ``seed`` to ``root/<name>`` atomically (a clip of this seed written there
    before is kept; a folder holding files probreg did not write is refused).  Returns its path."""
    cfg, frac, name = rail_config(seed, n_frames)
    return write_generated_clip(Path(root) / name, cfg, seed, "probreg.sim.rails", {"rail_frac": frac}, "rail",
                                jobs=jobs)
