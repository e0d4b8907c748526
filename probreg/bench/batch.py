"""A season on a cluster, measured here: ``probreg batch`` throughput with 1 and 2 workers.

``--repeats N`` synthetic clips (default 6; 100 frames, 1920x1080, the ``run`` preset with seeds
1-N, rendered once) go through the command line, ``probreg batch MANIFEST --out DIR --workers W``,
in a fresh process (cluster start-up included), first with one worker, then with two into a new
folder, then the two-worker batch is run again (every clip finished: all skipped).  Measured: wall
time, clips per minute, the speed-up of two workers over one, and the rerun's wall time against
the first run's.  The per-clip CPU time gives the arithmetic for a season in ``docs/batch.md``.
"""

from __future__ import annotations

import csv
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .common import BenchReport, md_table


def _batch(manifest, out, workers):
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "probreg", "batch", str(manifest), "--out", str(out),
                           "--workers", str(workers), "--quiet"], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    with open(Path(out) / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    return wall, proc.returncode, rows


def run(args=None):
    from ..sim import config_from_preset, synthesize, write_clip

    n = int(getattr(args, "repeats", None) or 6)
    rep = BenchReport("batch", "`probreg batch` on Dask: throughput with 1 and 2 workers, rerun of a finished batch")
    rep.add(__doc__.split("\n\n", 1)[1])
    try:
        import distributed  # noqa: F401
    except ImportError:
        rep.add("**Not measured**: Dask distributed is not installed (`pip install 'probreg[dask]'`).\n")
        return rep
    with tempfile.TemporaryDirectory(prefix="probreg-bench-batch-") as tmp:
        tmp = Path(tmp)
        for seed in range(1, n + 1):
            write_clip(synthesize(config_from_preset("run", seed, n_frames=100), seed=seed, preset="run"),
                       tmp / f"clip{seed:02d}", images=True)
        manifest = tmp / "season.csv"
        manifest.write_text("clip\n" + "".join(f"clip{s:02d}\n" for s in range(1, n + 1)))
        w1, c1, r1 = _batch(manifest, tmp / "w1", 1)
        w2, c2, r2 = _batch(manifest, tmp / "w2", 2)
        w3, c3, r3 = _batch(manifest, tmp / "w2", 2)
    cpu = [float(r["wall_s"]) for r in r1 if r.get("wall_s")]
    rows = [["1 worker", n, w1, 60 * n / w1, c1, sum(r["status"] != "failed" for r in r1)],
            ["2 workers", n, w2, 60 * n / w2, c2, sum(r["status"] != "failed" for r in r2)],
            ["2 workers, rerun of the finished batch", n, w3, 60 * n / w3, c3,
             sum(r["skipped"] == "yes" for r in r3)]]
    rep.add(md_table(["run", "clips", "wall s", "clips / min", "exit", "results (rerun: skipped)"], rows))
    speedup = w1 / w2
    rep.numbers.update(clips=n, wall_1=w1, wall_2=w2, wall_rerun=w3, speedup=speedup,
                       per_clip_s_mean=sum(cpu) / len(cpu) if cpu else float("nan"))
    rep.add(f"Per clip, one core: {rep.numbers['per_clip_s_mean']:.1f} s on average (100 frames).\n")
    rep.add("## Targets (issue 29)\n")
    rep.add(md_table(["target", "wanted", "measured", "met"], [
        ["2 workers vs 1 on 2 cores", ">= 1.7x throughput", f"{speedup:.2f}x", "yes" if speedup >= 1.7 else "**no**"],
        ["rerun of a finished batch", "<= 25 % of the first wall time + 3 s", f"{w3:.1f} s vs {w2:.1f} s "
         f"({100 * w3 / w2:.0f} %)", "yes" if w3 <= 0.25 * w2 + 3 else "**no**"]]))
    return rep
