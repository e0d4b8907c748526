"""`probreg opensim`: clean errors without OpenSim or Pose2Sim; scaling + IK with bands when both are there.

The end-to-end test needs the optional ``opensim`` package and Pose2Sim's ``OpenSim_Setup`` folder
(an installed Pose2Sim, or ``PROBREG_POSE2SIM_SETUP=DIR``); it skips cleanly without them.
"""

import json
import os
import sys

import numpy as np
import pytest

from probreg.cli import main
from probreg.io import load_groundtruth, read_angles_csv
from probreg.osim_ik import OpenSimUnavailable, find_pose2sim_setup, read_ik_bands


def test_without_opensim_the_command_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "opensim", None)  # import opensim -> ImportError
    assert main(["opensim", str(tmp_path), "--pose2sim-setup", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "pip install 'probreg[opensim]'" in err and "Traceback" not in err


def test_a_folder_that_is_not_pose2sims_setup_is_named(tmp_path):
    with pytest.raises(OpenSimUnavailable, match="not Pose2Sim's OpenSim_Setup.*Model_Pose2Sim_simple.osim"):
        find_pose2sim_setup(tmp_path)


def _setup_or_skip():
    pytest.importorskip("opensim")
    try:
        return find_pose2sim_setup(os.environ.get("PROBREG_POSE2SIM_SETUP"))
    except OpenSimUnavailable as exc:
        pytest.skip(str(exc))


@pytest.mark.slow
def test_scaling_and_ik_with_bands_agree_with_probregs_knee(small_clip, tmp_path):
    setup = _setup_or_skip()
    from probreg.inference import SamplerSettings
    from probreg.pipeline import RunOptions, run_clip

    gt = load_groundtruth(small_clip)
    res = tmp_path / "res"
    fast = SamplerSettings(n_walkers=20, burn_in=100, chunk=150, max_steps=600, n_draws=12, seed=1)
    run_clip(small_clip, res, RunOptions(sampler=fast, dist=tuple(gt.cameras[0].dist), report=False),
             log=lambda *a: None)
    assert main(["opensim", str(res), "--pose2sim-setup", str(setup), "--draws", "4", "--quiet"]) == 0
    out = res / "opensim"
    for name in ("ik_angles.mot", "ik_bands.csv", "model_scaled.osim", "ik.json"):
        assert (out / name).exists(), name
    info = json.loads((out / "ik.json").read_text())
    assert info["n_draws"] == 4 and "knee_angle_r" in info["rotational"]
    bands = read_ik_bands(out / "ik_bands.csv")
    f, med, lo, hi = bands["knee_angle_r"]
    ok = np.isfinite(med)
    assert ok.mean() > 0.9 and np.all(lo[ok] <= med[ok] + 1e-6) and np.all(med[ok] <= hi[ok] + 1e-6)
    # OpenSim's knee angle (negative = flexion in Pose2Sim's model) follows probreg's knee flexion
    _, knee, _, _ = read_angles_csv(res / "angles.csv")["knee_r"]
    k = knee[f.astype(int)]
    both = ok & np.isfinite(k)
    assert np.corrcoef(np.abs(med[both]), k[both])[0, 1] > 0.95
    assert np.mean(np.abs(np.abs(med[both]) - k[both])) < 6.0
