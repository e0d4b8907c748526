"""Calibration of the credible bands on held-out synthetic clips (not the benchmark suite).

The bootstrap spread of the propagated angles misses part of the estimator's
error (the smoothing flattens true peaks and pulls true stride-to-stride
differences towards the neighbouring strides, which re-simulated noise cannot show),
so the reported bands scale the bootstrap deviations by a factor
(``probreg.posterior.BAND_INFLATION``).  This benchmark measures the factor that
puts 90 % of the true knee angles inside the 90 % band on clips whose seeds are
outside the benchmark suite; the coverage study on the suite (``bench
posterior``) then tests it out of sample.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..io.clip import load_groundtruth
from ..io.results import read_angles_csv
from ..pipeline import RunOptions, run_clip
from ..skeleton import joint_angles
from ..synth import config_from_preset, synthesize, write_clip
from .common import BenchReport, md_table

__all__ = ["run", "HELD_OUT"]

HELD_OUT = [("run", 901), ("jog", 902), ("fast", 903), ("tele", 904), ("wide", 905), ("high", 906),
            ("long_step", 907), ("distorted", 908)]


def run(args=None):
    rep = BenchReport("band-calibration", "Band calibration on held-out synthetic clips")
    rep.add(__doc__.split("\n\n", 1)[1])
    z_all, rows = [], []
    z_other = {"hip": [], "elbow": []}  # the same ratio for the other limb angles
    with tempfile.TemporaryDirectory() as tmp:
        for preset, seed in HELD_OUT:
            clip_dir = Path(tmp) / f"{preset}_{seed}"
            # as long as the suite's clips: the cross-stride smoothing (and so its bias) depends on
            # the number of strides in a clip
            write_clip(synthesize(config_from_preset(preset, seed, n_frames=250), seed=seed), clip_dir)
            gt = load_groundtruth(clip_dir)
            dist = tuple(gt.cameras[0].dist) if np.any(gt.cameras[0].dist) else None
            run_clip(clip_dir, Path(tmp) / "out", RunOptions(report=False, band_inflation=1.0, dist=dist),
                     log=lambda *a: None)
            ang = read_angles_csv(Path(tmp) / "out" / "angles.csv")
            truth = joint_angles(gt.joints3d_track_m)
            def ratios(joint):
                zs = []
                for k in (f"{joint}_l", f"{joint}_r"):
                    f, med, lo, hi = ang[k]
                    t = truth[k][f.astype(int)]
                    with np.errstate(invalid="ignore", divide="ignore"):
                        z = np.where(t >= med, (t - med) / (hi - med), (med - t) / (med - lo))
                    zs.append(z[np.isfinite(z)])
                return np.concatenate(zs)

            z = ratios("knee")
            z_all.append(z)
            for joint in z_other:
                z_other[joint].append(ratios(joint))
            rows.append([f"{preset} (seed {seed})", 100 * np.mean(z <= 1.0), float(np.percentile(z, 90)),
                         *[float(np.percentile(z_other[j][-1], 90)) for j in z_other]])
    z = np.concatenate(z_all)
    k90 = float(np.percentile(z, 90))
    rep.add(md_table(["clip", "knee: coverage of the raw bootstrap band %",
                      "knee: 90th percentile of abs. error / half-band", "hip: same", "elbow: same"], rows))
    rep.add(f"Over all {len(z)} knee-frames: raw coverage {100 * np.mean(z <= 1):.1f} %; the inflation that "
            f"gives 90 % coverage is **{k90:.2f}**.\n")
    for joint, zs in z_other.items():
        zj = np.concatenate(zs)
        rep.add(f"{joint.capitalize()} angles with the knee's factor: {100 * np.mean(zj <= k90):.1f} % inside "
                f"(their own 90 % factor would be {np.percentile(zj, 90):.2f}).\n")
    rep.numbers["inflation"] = k90
    return rep
