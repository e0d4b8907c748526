"""Gait-cycle curves: known answers on constructed angle series and contacts."""

import numpy as np

from probreg.analysis import mean_cycle_curve
from probreg.inference import BAND_SCALE, gait_cycle_bands
from probreg.io.results import read_gait_cycle_csv, write_gait_cycle_csv


def _contacts(F, period, offset):
    c = np.zeros((F, 2), bool)
    for side, off in enumerate(offset):
        for start in range(off, F, period):
            c[start:start + period // 3, side] = True
    return c


def test_cycle_curve_of_a_periodic_angle_is_its_period_shape():
    F, P = 200, 36
    c = _contacts(F, P, (4, 22))
    t = np.arange(F)
    knee = 60 + 50 * np.sin(2 * np.pi * (t - 4) / P)  # phase 0 at each left touchdown
    curve = mean_cycle_curve(knee, c[:, 0])
    expect = 60 + 50 * np.sin(2 * np.pi * np.linspace(0, 1, 101))
    # linear resampling of 36 samples per cycle: error <= A (2 pi / 36)^2 / 8 = 0.19 deg
    assert np.max(np.abs(curve - expect)) < 0.2
    # a cycle with a short gap is bridged; one mostly missing is left out
    gappy = knee.copy()
    gappy[10:13] = np.nan
    gappy[4 + 2 * P + 2:4 + 3 * P - 2] = np.nan
    assert np.max(np.abs(mean_cycle_curve(gappy, c[:, 0]) - expect)) < 2.0


def test_bands_are_over_draws_and_use_each_sides_touchdowns():
    F, P, S = 200, 36, 40
    c = _contacts(F, P, (4, 22))
    t = np.arange(F)
    rng = np.random.default_rng(1)
    shift = rng.normal(0, 3.0, S)[:, None]  # each draw's offset: the spread the band must show
    point = {"knee_l": 60 + 50 * np.sin(2 * np.pi * (t - 4) / P) + 0 * shift,
             "knee_r": 60 + 50 * np.sin(2 * np.pi * (t - 22) / P) + 0 * shift}
    noisy = {k: v + shift for k, v in point.items()}
    out = gait_cycle_bands(point, noisy, c, inflation=1.0)
    assert set(out) == {("knee", "L"), ("knee", "R")}
    for side in "LR":
        pct, med, lo, hi, n = out[("knee", side)]
        assert np.allclose(med, 60 + 50 * np.sin(2 * np.pi * pct / 100), atol=0.2)  # both sides in phase
        q5, q95 = np.percentile(shift, [5, 95])
        med_shift = np.median(shift)
        assert np.allclose(hi - med, q95 - med_shift) and np.allclose(med - lo, med_shift - q5)
        assert n == len(np.flatnonzero(np.diff(c[:, 0 if side == "L" else 1].astype(int)) == 1)) - 1
    scaled = gait_cycle_bands(point, noisy, c)
    w1 = out[("knee", "L")][3] - out[("knee", "L")][2]
    wk = scaled[("knee", "L")][3] - scaled[("knee", "L")][2]
    assert np.allclose(wk, BAND_SCALE["knee"] * w1)


def test_gait_cycle_csv_round_trip(tmp_path):
    pct = np.linspace(0, 100, 101)
    curves = {("knee", "L"): (pct, pct * 1.0, pct - 1, pct + 1, 3)}
    p = write_gait_cycle_csv(tmp_path / "gait_cycle.csv", curves)
    assert p.read_text().splitlines()[0] == "angle,side,cycle_pct,median_deg,lo_deg,hi_deg"
    back = read_gait_cycle_csv(p)
    assert np.allclose(back[("knee", "L")][2], pct - 1)


def _late_contacts(F, stride, first, late, missed=()):
    """Contacts (F, 2): left touchdowns every ``stride`` frames from ``first[0]``, right ones from
    ``first[1]``, each foot's touchdowns ``late`` frames late (a lifting's offset per foot), 40 % of
    a stride long; touchdowns in ``missed`` (frame numbers before the offset) not seen."""
    c = np.zeros((F, 2), bool)
    for side in (0, 1):
        t = first[side]
        while t < F:
            if round(t) not in missed:
                a = int(np.rint(t + late[side]))
                c[a:min(F, a + int(0.4 * stride)), side] = True
            t += stride
    return c


def test_cadence_is_right_when_one_foots_touchdowns_are_late_or_missed():
    """Steps alternating short and long (one foot's touchdowns 5 frames late) do not move the
    cadence, and neither does a missed touchdown; the steps' median alone gave 23 % too few."""
    from types import SimpleNamespace

    from probreg.analysis import gait_summary, step_time_s

    stride = 34.0  # frames at 50 fps: 176.5 steps/min
    F = 300
    c = _late_contacts(F, stride, (10.0, 27.0), (0.0, 5.0), missed=(146,))
    track = SimpleNamespace(contacts=c, velocity_mps=np.tile([6.0, 0.0], (F, 1)))
    angles = {"knee_l": np.full(F, 30.0), "knee_r": np.full(F, 30.0)}
    g = gait_summary(track, angles, 50.0)
    assert abs(g["cadence_spm"] - 60 * 50 / (stride / 2)) < 0.5
    assert abs(g["step_length_m"] - 6.0 * stride / 2 / 50) < 0.01
    # what the steps alone say (both feet's touchdowns in one list): 12 and 22 frames alternating
    tds = np.flatnonzero(np.diff(c.astype(int), axis=0).max(1) == 1) + 1
    assert 60 / step_time_s(tds, 50.0) < 0.8 * g["cadence_spm"]
