"""Camera cuts from the lanes (probreg.calibration.cuts): exact families of simulated broadcast
cameras that pan and zoom, spliced at a cut; known answers."""

from dataclasses import replace

import numpy as np
import pytest

from probreg.calibration import CalibrationFamily
from probreg.calibration.cuts import (
    GEOMETRIC_CUT,
    PROBE_FOV_DEG,
    family_signature,
    family_steps,
    find_clip_cuts,
    geometric_cuts,
    signature_noise,
)


def _cameras(height_m, distance_m, n=60, seed=3):
    from probreg.sim import config_from_preset, synthesize

    cfg = config_from_preset("run", seed, n_frames=n, image_size=(1280, 720))
    cfg = replace(cfg, camera=replace(cfg.camera, height_m=height_m, distance_m=distance_m))
    clip = synthesize(cfg, seed=seed, preset="run")
    return clip.cameras


@pytest.fixture(scope="module")
def shots():
    a = _cameras(9.0, 30.0)
    b = _cameras(11.0, 40.0)
    with np.errstate(invalid="ignore"):  # from_camera normalises the lines behind the camera too
        fam = [CalibrationFamily.from_camera(c) for c in a[:35] + b[35:]]
        same = [CalibrationFamily.from_camera(c) for c in a]
    return fam, same, a[0].image_size


def test_a_cut_between_two_cameras_is_found_at_its_frame(shots):
    fam, same, size = shots
    sig = family_signature(fam, size)
    assert sig.shape == (60, len(PROBE_FOV_DEG)) and np.isfinite(sig).mean() > 0.8
    steps = family_steps(sig)
    assert np.nanmax(steps[np.r_[1:30, 41:60]]) < GEOMETRIC_CUT / 3  # the camera pans and zooms
    assert steps[35] > 1.5 * GEOMETRIC_CUT
    assert geometric_cuts(sig) == [35]
    cuts, info = find_clip_cuts(np.full(60, 0.003), fam, size)  # colours alike: the lanes find it
    assert cuts == [35] and info["vetoed"] == []
    assert np.all(np.isnan(info["steps"][30:40]))  # the steps around a cut straddle it


def test_one_camera_has_no_cut_and_vetoes_a_colour_jump(shots):
    _, same, size = shots
    change = np.full(60, 0.003)
    change[20] = 0.4  # a flash or a graphic: the colours jump, the camera stays
    cuts, info = find_clip_cuts(change, same, size)
    assert cuts == [] and info["vetoed"] == [20]


def test_lanes_lost_for_a_while_are_no_cut_but_a_camera_change_behind_them_is(shots):
    fam, same, size = shots
    change = np.full(60, 0.003)
    change[[25, 40]] = 0.5  # the picture changes where the lanes vanish and come back
    gap = [None if 25 <= i < 40 else f for i, f in enumerate(same)]
    assert find_clip_cuts(change, gap, size)[0] == []  # the same camera on both sides: bridged
    gap_cut = [None if 25 <= i < 40 else f for i, f in enumerate(fam)]
    assert find_clip_cuts(change, gap_cut, size)[0] == [25, 40]  # another camera after it
    none = [None] * 60
    assert find_clip_cuts(change, none, size)[0] == [25, 40]  # no lanes at all: the colours decide


def test_a_noisy_family_raises_the_bar(shots):
    _, same, size = shots
    sig = family_signature(same, size)
    rng = np.random.default_rng(0)
    noisy = sig + rng.standard_t(2, size=sig.shape) * 0.1  # a grazing camera's crowded lines
    assert signature_noise(noisy) > 10 * signature_noise(sig)
    assert geometric_cuts(noisy) == []
    jump = noisy.copy()
    jump[30:] += 6.0  # a change far beyond that noise is still a cut
    assert geometric_cuts(jump) == [30]
