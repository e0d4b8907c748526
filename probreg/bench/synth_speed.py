"""Generation speed: a 300-frame 1080p clip with images (target <= 30 s on 2 cores)."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from ..sim import config_from_preset, synthesize, write_clip
from .common import BenchReport, md_table

__all__ = ["run"]


def run(args=None):
    repeats = int(getattr(args, "repeats", None) or 3)
    jobs = getattr(args, "jobs", None)
    rep = BenchReport("synth-speed", "Synthetic clip generation speed")
    rows = []
    totals = []
    for r in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            clip = synthesize(config_from_preset("default", 1000 + r, n_frames=300), seed=1000 + r)
            t1 = time.perf_counter()
            write_clip(clip, Path(tmp) / "clip", images=True, jobs=jobs)
            t2 = time.perf_counter()
        totals.append(t2 - t0)
        rows.append([r, t1 - t0, t2 - t1, t2 - t0])
    rep.add("300 frames, 1920x1080, JPEG, preset `default` (seeds 1000..), simulation + rendering "
            "+ writing, rendering spread over the machine's cores.\n")
    rep.add(md_table(["run", "simulate s", "render+write s", "total s"], rows))
    med = float(np.median(totals))
    rep.add(f"Median total: **{med:.1f} s** (target <= 30 s): "
            f"{'met' if med <= 30 else 'NOT met'}.\n")
    rep.numbers["median_total_s"] = med
    return rep
