"""From a race video to a paper figure: ``probreg run VIDEO --model M`` end to end, then OpenSim.

For each chosen validation clip (``shared/data/validation``; default ``v06_mocap`` and
``v08_tele``) the frames are encoded into an mp4 (OpenCV, ``mp4v``), and the command a user types
runs in a fresh process: ``probreg run race.mp4 --out OUT --model M``.  Measured:

* exit code and wall time (decode, detection with the ONNX pose model, the whole pipeline, writing);
* the result files (``markers.trc``, ``angles.mot``, ``gait_cycle.csv``, ``report.html``,
  ``angles.csv``), that OpenSim's own adapters read the TRC and the MOT (when the ``opensim``
  package is installed), and that the TRC's RKnee-RAnkle distance matches ``joints3d.npz``;
* the knee error against the clip's ground truth with detected 2D keypoints (the real model, not
  the clip's ideal keypoints) and the verdict;
* ``probreg opensim OUT`` (scaling + IK on the median and 10 posterior draws) when OpenSim and
  Pose2Sim's model files are there: wall time and how closely OpenSim's knee angle follows
  probreg's.

The pose model is ``--model PATH`` (default: ``probreg models export-yolo``'s output in
``~/.cache/probreg``); without one nothing is measured and the report says so.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..geometry import JOINT_INDEX
from .common import BenchReport, find_shared_data, md_table

DEFAULT_CLIPS = ("v06_mocap", "v08_tele")


def _mp4(frames_dir, path, fps):
    import cv2

    frames = sorted(Path(frames_dir).glob("*.jpg")) + sorted(Path(frames_dir).glob("*.png"))
    first = cv2.imread(str(frames[0]))
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (first.shape[1], first.shape[0]))
    for f in frames:
        vw.write(cv2.imread(str(f)))
    vw.release()
    return path


def _cli(*args):
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "probreg", *args], capture_output=True, text=True)
    return proc.returncode, time.perf_counter() - t0, proc.stderr.strip().splitlines()[-1:] or [""]


def _opensim_reads(out):
    try:
        import opensim
    except ImportError:
        return "opensim not installed"
    opensim.Logger.removeFileSink()
    trc = opensim.TimeSeriesTableVec3(str(out / "markers.trc"))
    mot = opensim.TimeSeriesTable(str(out / "angles.mot"))
    return f"yes (TRC {trc.getNumRows()} x {trc.getNumColumns()} markers, MOT {mot.getNumRows()} x {mot.getNumColumns()})"


def _pose2sim_setup():
    import os

    from ..osim_ik import OpenSimUnavailable, find_pose2sim_setup

    try:
        import opensim  # noqa: F401
        return find_pose2sim_setup(os.environ.get("PROBREG_POSE2SIM_SETUP"))
    except (ImportError, OpenSimUnavailable):
        return None


def run(args=None):
    from ..detect.models import default_cache_dir
    from ..io.opensim import read_trc
    from ..io.results import read_angles_csv
    from ..osim_ik import read_ik_bands
    from .validation import score_validation

    rep = BenchReport("video", "From a race video to a paper figure: `probreg run VIDEO --model M`, then OpenSim")
    rep.add(__doc__.split("\n\n", 1)[1])
    model = Path(getattr(args, "model", None) or default_cache_dir() / "yolo11n-pose.onnx")
    shared = find_shared_data(getattr(args, "shared", None))
    if not model.is_file():
        rep.add(f"**Not measured**: no pose model at `{model}` (give `--model PATH`).\n")
        return rep
    if shared is None or not (shared / "validation").is_dir():
        rep.add("**Not measured**: `shared/data/validation` was not found (give `--shared PATH`).\n")
        return rep
    only = getattr(args, "only", None)
    names = only.split(",") if only else list(DEFAULT_CLIPS)
    setup = _pose2sim_setup()
    rep.add(f"Model: `{model.name}`. OpenSim IK: " + (f"Pose2Sim files from `{setup}`" if setup else
                                                     "not run (opensim or Pose2Sim's files not installed)") + ".\n")
    rows, ik_rows = [], []
    with tempfile.TemporaryDirectory(prefix="probreg-bench-video-") as tmp:
        for name in names:
            clip = shared / "validation" / name
            fps = json.loads((clip / "clip.json").read_text())["fps"]
            video = _mp4(clip / "frames", Path(tmp) / f"{name}.mp4", fps)
            out = Path(tmp) / f"{name}_result"
            code, dt, last = _cli("run", str(video), "--out", str(out), "--model", str(model), "--quiet", "--seed", "0")
            need = ["markers.trc", "angles.mot", "gait_cycle.csv", "report.html", "angles.csv"]
            have = all((out / n).exists() for n in need)
            if not have:
                rows.append([name, code, dt, "missing files", "", "", "", "", last[0]])
                continue
            names_trc, _, markers = read_trc(out / "markers.trc")
            j = np.load(out / "joints3d.npz")["median"]
            d_trc = np.linalg.norm(markers[:, names_trc.index("RKnee")] - markers[:, names_trc.index("RAnkle")], axis=1)
            d_npz = np.linalg.norm(j[:, JOINT_INDEX["r_knee"]] - j[:, JOINT_INDEX["r_ankle"]], axis=1)
            ok = np.isfinite(d_npz) & np.isfinite(d_trc)
            diff_mm = float(1000 * np.max(np.abs(d_trc[ok] - d_npz[ok]))) if ok.any() else float("nan")
            s = score_validation(clip, out)
            reasons = "; ".join(s["verdict_reasons"])
            rows.append([name, code, dt, "all", _opensim_reads(out), diff_mm, s["knee_deg"],
                         100 * s["knee_coverage"], s["verdict"] + (f" ({reasons})" if reasons else "")])
            rep.numbers[name] = {"exit": code, "wall_s": dt, "trc_vs_npz_mm": diff_mm, "knee_deg": s["knee_deg"],
                                 "verdict": s["verdict"]}
            if setup is not None:
                c2, dt2, last2 = _cli("opensim", str(out), "--draws", "10", "--quiet", "--pose2sim-setup", str(setup))
                if c2 == 0:
                    b = read_ik_bands(out / "opensim" / "ik_bands.csv")
                    f, med, lo, hi = b["knee_angle_r"]
                    knee = read_angles_csv(out / "angles.csv")["knee_r"][1][f.astype(int)]
                    both = np.isfinite(med) & np.isfinite(knee)
                    ik_rows.append([name, c2, dt2, float(np.corrcoef(np.abs(med[both]), knee[both])[0, 1]),
                                    float(np.mean(np.abs(np.abs(med[both]) - knee[both]))),
                                    float(np.nanmean(hi - lo))])
                else:
                    ik_rows.append([name, c2, dt2, float("nan"), float("nan"), last2[0]])
    rep.add("## `probreg run race.mp4 --out OUT --model M`\n")
    rep.add(md_table(["clip", "exit", "wall s", "result files", "OpenSim reads TRC + MOT",
                      "TRC vs joints3d.npz RKnee-RAnkle max diff mm", "knee err deg", "knee in 90 % band %",
                      "verdict"], rows))
    if ik_rows:
        rep.add("## `probreg opensim OUT --draws 10` (scaling + IK with bands)\n")
        rep.add(md_table(["clip", "exit", "wall s", "corr(OpenSim knee, probreg knee)",
                          "mean |OpenSim knee - probreg knee| deg", "mean IK knee band width deg"], ik_rows))
    return rep
