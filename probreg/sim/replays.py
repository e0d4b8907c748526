"""Slow-motion replays (and a clip at the wrong frame rate), for the time-base benchmark.

Broadcasts replay their best views in slow motion: a camera records at several times the
broadcast's frame rate and the replay plays those frames at the broadcast's rate.  A clip of
this set is one of the held-out set's set-ups (:func:`probreg.sim.heldout.heldout_config`:
its camera, lens, athlete and image size) recorded at ``played fps x factor`` and labelled
with the played rate in ``clip.json``, as a replay's file is.  Factors 2, 3, 4 and 6 are
replays, factor 1 a clip in real time, and factor 0.5 a 25 fps recording labelled 50 fps
(its motion runs twice too fast).  ``clip.json`` ``"generator"`` records ``slow_motion``
(the factor) and ``capture_fps``; the ground truth is per frame as in any clip.

:data:`REPLAY_SEEDS` were fixed when this set was written, before the time-base check
(:mod:`probreg.inference.time_base`) was run on any of them; it is only reported
(``probreg bench replays``), never tuned on.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import replace
from pathlib import Path

from ..io.clip import atomic_output_dir
from ..io.output import MARKER
from .heldout import heldout_config
from .synth import synthesize, write_clip

__all__ = ["REPLAY_SEEDS", "REPLAY_FACTORS", "replay_config", "write_replay_clip", "write_generated_clip"]

#: seeds of the replay set (24 clips, four per factor), fixed before any run
REPLAY_SEEDS = tuple(range(9701, 9725))
#: slow-down factors, taken in turn by the seeds (1: real time; 0.5: motion twice too fast)
REPLAY_FACTORS = (1.0, 2.0, 3.0, 4.0, 6.0, 0.5)


def replay_config(seed, n_frames=200):
    """``(config, played_fps, factor, name)``: the generator's configuration (recorded at
    ``played_fps * factor``), the frame rate the clip is labelled with, the factor and a name.

    >>> cfg, played, factor, name = replay_config(9704)
    >>> factor, cfg.fps == played * factor, name.startswith("replay_9704_x4")
    (4.0, True, True)
    >>> replay_config(9706)[1:3]  # a 25 fps recording labelled 50 fps
    (50.0, 0.5)
    """
    cfg, kind, far = heldout_config(seed, n_frames)
    factor = REPLAY_FACTORS[(int(seed) - REPLAY_SEEDS[0]) % len(REPLAY_FACTORS)]
    played = 50.0 if factor < 1 else cfg.fps
    name = f"replay_{seed}_x{factor:g}_{kind}" + ("_far" if far else "")
    return replace(cfg, fps=played * factor), played, factor, name


def write_replay_clip(root, seed, n_frames=200, jobs=None):
    """Write the replay clip of ``seed`` to ``root/<name>`` (:func:`replay_config`) atomically,
    labelled with the played rate (:func:`probreg.io.clip.atomic_output_dir`: a folder that holds
    files probreg did not write is refused); a replay clip of this seed written there before is
    kept.  Returns its path."""
    cfg, played, factor, name = replay_config(seed, n_frames)
    return write_generated_clip(Path(root) / name, cfg, seed, "probreg.sim.replays",
                                {"slow_motion": factor, "capture_fps": cfg.fps}, "replay", fps=played, jobs=jobs)


def write_generated_clip(out, cfg, seed, generator, extra, preset, fps=None, jobs=None):
    """Write the clip of ``cfg`` (``seed``) to ``out`` atomically, its ``clip.json`` ``"generator"``
    named ``generator`` (``preset`` recorded) with ``extra`` entries and its frame rate labelled
    ``fps`` (default: the recorded one).  A folder that holds files probreg did not write is refused; one this
    generator wrote for this seed before is kept as it is.  Returns ``out``."""
    out = Path(out)
    try:
        gen = json.loads((out / "clip.json").read_text()).get("generator", {})
    except (OSError, ValueError):
        gen = {}
    if gen.get("name") == generator and gen.get("seed") == int(seed) and (out / MARKER).exists():
        return out
    with tempfile.TemporaryDirectory(prefix="probreg-clip-") as tmp, atomic_output_dir(out) as final:
        src = write_clip(synthesize(cfg, seed=int(seed), preset=preset), Path(tmp) / out.name, images=True, jobs=jobs)
        for item in src.iterdir():
            if item.name != MARKER:
                shutil.move(str(item), final / item.name)
        meta = json.loads((final / "clip.json").read_text())
        meta["fps"] = float(cfg.fps if fps is None else fps)
        meta["generator"] = {**meta["generator"], "name": generator, "seed": int(seed), **extra}
        (final / "clip.json").write_text(json.dumps(meta, indent=1))
    return out
