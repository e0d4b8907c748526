"""From bootstrap liftings to credible bands: angle bands and gait intervals.

The spread of the propagated liftings is scaled per angle family (:data:`BAND_SCALE`, fitted on
held-out clips by ``probreg bench band-calibration``) and by how much noisier the data's angles
are than the bootstrap's (:func:`bootstrap_noise_ratio`), and widened by a smoothing-bias term
from the angle's curvature; gait intervals likewise with :data:`GAIT_BAND_SCALE`.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["NOISE_RATIO_POWER", "NOISE_RATIO_RANGE", "bootstrap_noise_ratio", "noise_ratio_factor",
           "STATIC_INTERVAL_SCALE", "static_interval", "BAND_CURVATURE_S2", "angle_bands", "STANCE_WINDOW",
           "stance_window", "BAND_SCALE", "BAND_RATE_REF_FPS", "BAND_RATE_POWER", "frame_rate_factor",
           "angle_curvature", "gait_intervals", "GAIT_BAND_SCALE", "GAIT_NUMBER_FACTORS", "NONNEGATIVE_GAIT_SUFFIXES",
           "GAIT_CYCLE_ANGLES", "gait_cycle_bands"]

#: Curvature weight (s^2) of the bands of the cross-stride smoothed angles: the smoothing's bias
#: grows with the curvature of the angle curve (about half the squared smoothing time times the
#: second derivative), which the bootstrap cannot show.  Chosen on held-out synthetic clips
#: (``probreg bench band-calibration``): among 0-0.0015 s^2 it evens out the per-clip knee
#: coverage most (mean distance from 90 %: 6.3 points without, 3.0 with it; fast runners,
#: whose curves bend most, were under-covered) at 7 % more width.
BAND_CURVATURE_S2 = 0.001


#: Part of every detected contact (fractions of its length) in which the ankle is taken
#: to stand still.  Real runners' ankles are not still at the ends of a contact: in the
#: CMU running mocap (``shared/data/mocap``, 7 clips, 4 subjects) the ankle moves 1-2 cm
#: forward from heel strike to foot flat (first ~15 % of stance; 5 cm for the jogger)
#: and rises with the heel from ~45 %; in between it slides by 0.019 of the running
#: speed (median of 18 contacts; sd 0.04), i.e. well inside :data:`STILLNESS_SYS_SD`.
#: Skipping the first 15 % also skips the 1-3 frames by which detected contacts tend to
#: start early (late swing, where the ankle still moves).
STANCE_WINDOW = (0.15, 0.45)

def stance_window(a, b, window=STANCE_WINDOW):
    """Frames ``(first, n)`` of the planted part (fractions ``window``) of a contact that
    runs over frames ``a`` to ``b - 1``; at least two frames.

    >>> stance_window(10, 31)  # a 21-frame contact: frames 13-19
    (13, 7)
    """
    i0 = int(round(window[0] * (b - a)))
    return int(a) + i0, max(2, int(round(window[1] * (b - a))) - i0 + 1)


#: Scale of the bootstrap deviations per angle family, fitted with the curvature term above
#: for 90 % pooled coverage on the held-out clips of ``probreg bench band-calibration``; the
#: trunk lean is not smoothed across strides and gets no curvature term.
BAND_SCALE = {"knee": 1.30, "hip": 1.44, "elbow": 1.90, "trunk_lean": 1.39}

#: :data:`BAND_SCALE` was fitted on clips at this frame rate (the band-calibration clips are all
#: at 50 fps) ...
BAND_RATE_REF_FPS = 50.0
#: ... and below it the bootstrap deviations are scaled by ``(BAND_RATE_REF_FPS / fps) **
#: BAND_RATE_POWER`` as well (:func:`frame_rate_factor`; 1.25 at 25 fps).  On the tuning twins of
#: the held-out set (``probreg.sim.heldout`` seeds 7501-7530 with images, never the held-out seeds;
#: ``probreg run``, default priors) the knee bands held the truth in 86.3 % of the frames of the
#: ten 25 fps clips and 91.8 % of the nineteen calibrated 50 fps ones (clips with the verdict ``ok``:
#: 87.6 % and 94.2 %), the least covered 25 fps clip 74 %: the 25 fps clips' bands were too narrow
#: by about a quarter.  Why is not known; the noise ratio (:func:`bootstrap_noise_ratio`) did not
#: differ between the two rates.  European broadcasts are 25 fps.  Above the reference rate the
#: factor stays 1 (not measured).
BAND_RATE_POWER = 0.32


def frame_rate_factor(fps):
    """The factor on the bootstrap deviations of a clip at ``fps`` frames per second
    (:data:`BAND_RATE_POWER`): 1 at :data:`BAND_RATE_REF_FPS` and above, or when ``fps`` is None.

    >>> frame_rate_factor(50.0), round(frame_rate_factor(25.0), 3), frame_rate_factor(60.0)
    (1.0, 1.248, 1.0)
    """
    if fps is None or not np.isfinite(fps) or fps <= 0:
        return 1.0
    return float(max(1.0, BAND_RATE_REF_FPS / float(fps)) ** BAND_RATE_POWER)

#: Widening of the 90 % intervals of the clip's static quantities (camera height, stature, limb
#: lengths, the lens's ``k1``) about their posterior median.  The clip model's posterior is
#: narrower than its errors: on the 26 non-grazing tuning clips (``probreg.sim.heldout`` seeds
#: 8101-8141, 8601-8630, 8801-8821 and the lens suite ``lens_1``-``lens_8``; never the held-out
#: or validation clips) the true log camera height sat at an rms of 1.5 posterior sds from the
#: posterior mean, and the 90 % intervals held the true height on 19 and the true stature on 21
#: of all 30 tuning clips.  The terms of the likelihood treat the lane geometry, the planted feet
#: and the limbs' consistency as exact where they are not, and which of them misleads changes
#: from clip to clip (tempering the height terms alone moved the stand clips' heights further
#: off, ``docs/method.md``), so the intervals are calibrated as the angle bands are
#: (:data:`BAND_SCALE`): the model's 5 % and 95 % quantiles move away from the median by this
#: factor, the smallest of 1, 1.25, 1.5, 1.75, 2 with which the pooled tuning coverage reached
#: 90 % for both heights (height 27, stature 28 of 30; ``k1`` 10 of 10 lens clips with
#: ``|k1| >= 0.1``).  The draws themselves (``posterior.nc``, the propagation) are the model's.
STATIC_INTERVAL_SCALE = 1.75


def static_interval(draws, scale=STATIC_INTERVAL_SCALE, positive=True, lo=5.0, hi=95.0):
    """Median and calibrated 90 % interval of a static quantity's posterior draws.

    ``lo``/``hi`` are the draws' quantiles moved away from the median by ``scale`` (in log for a
    ``positive`` quantity, so the interval stays positive); ``model_lo``/``model_hi`` are the
    draws' own quantiles.

    >>> d = static_interval(np.exp(np.random.default_rng(0).normal(np.log(10.0), 0.05, 20000)), scale=2.0)
    >>> round(d["median"], 1), round(d["model_lo"], 2), round(d["lo"], 2), round(d["hi"] * d["lo"] / d["median"] ** 2, 2)
    (10.0, 9.22, 8.51, 1.0)
    >>> static_interval([-0.2, -0.1, 0.0], positive=False, scale=1.0)["lo"]
    -0.19
    """
    x = np.asarray(draws, float).ravel()
    x = x[np.isfinite(x)]
    if positive:
        x = x[x > 0]
    if not len(x):
        return {"median": float("nan"), "lo": float("nan"), "hi": float("nan"), "model_lo": float("nan"),
                "model_hi": float("nan"), "interval_scale": float(scale)}
    q_lo, med, q_hi = np.percentile(x, [lo, 50.0, hi])
    if positive:
        w_lo, w_hi = med * (q_lo / med) ** scale, med * (q_hi / med) ** scale
    else:
        w_lo, w_hi = med + scale * (q_lo - med), med + scale * (q_hi - med)
    return {"median": float(med), "lo": float(w_lo), "hi": float(w_hi), "model_lo": float(q_lo),
            "model_hi": float(q_hi), "interval_scale": float(scale)}


def angle_curvature(series, fps):
    """Second derivative (deg/s^2) of an angle series, from differences over ~40 ms.

    NaN where the series or a neighbour is missing; the ends take their nearest value.

    >>> t = np.arange(50) / 50.0
    >>> bool(np.allclose(angle_curvature(3.0 * (50 * t) ** 2 / 2500, 50.0), 6.0))
    True
    """
    x = np.asarray(series, float)
    lag = max(1, int(round(0.04 * fps)))
    c = np.full(x.shape, np.nan)
    if len(x) > 2 * lag:
        c[lag:-lag] = (x[2 * lag:] - 2 * x[lag:-lag] + x[:-2 * lag]) * (fps / lag) ** 2
        c[:lag], c[-lag:] = c[lag], c[-lag - 1]
    return c


def _band_family(name):
    return name if name == "trunk_lean" else name.rsplit("_", 1)[0]


#: Power of the noise-ratio correction of the bootstrap bands (:func:`bootstrap_noise_ratio`):
#: each angle's bootstrap deviation is multiplied by ``ratio ** NOISE_RATIO_POWER``.  The ratio
#: of one clip is itself an estimate (two noise levels fitted from ~100-250 frames each), so it
#: is only partly trusted.  On the tuning twin of the held-out set (``probreg.sim.heldout`` seeds
#: 7501-7540, never the held-out seeds; 39 calibrated clips, bands rescaled for 90 % pooled
#: coverage each time) the mean distance of the per-clip knee coverage from 90 % was 5.4 points
#: with no correction (power 0), 4.5 at 0.5, 4.4 at 0.75 and 5.0 at 1; hip 6.1 / 4.5 / 5.7 /
#: 6.9, elbow 8.4 / 7.0 / 7.2 / 7.3; the least covered clip went from 74 to 76 % (knee), 70 to
#: 80 % (hip) and 47 to 58 % (elbow) at 0.5.  The clip's ratio and its coverage correlated at
#: -0.60 (knee): bands were too narrow where the data were noisier than the bootstrap's copies.
NOISE_RATIO_POWER = 0.5

#: Range the noise ratio is clipped to before the power (a smoother's estimate on very few
#: frames can be far off).
NOISE_RATIO_RANGE = (0.25, 4.0)


def bootstrap_noise_ratio(noise_point, noise_noisy):
    """Per angle: the noise the cross-stride angle smoothing found in the data's liftings over the
    noise it found in the bootstrap's (medians over the draws).

    The bootstrap re-simulates the detector noise from a model of it (level and frame-to-frame
    correlation from the trunk, per-joint levels from the cleaning's residuals) and cleans the
    copies again; the lifted angles of those copies should be as noisy as the data's own.  The
    smoother estimates that noise in the same way in both (``noise_sd`` of
    :func:`probreg.lifting.smooth_angles_across_strides`): a ratio above 1 says the data's
    angles are noisier than the bootstrap thinks (its bands too narrow), below 1 the reverse.
    Angles without both estimates are left out.

    >>> r = bootstrap_noise_ratio({"knee_l": np.array([4.0, 4.2, 3.8])}, {"knee_l": np.array([2.0, 2.1, np.nan])})
    >>> round(r["knee_l"], 3)
    1.951
    """
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for name, pts in noise_point.items():
            if name not in noise_noisy:
                continue
            p, q = float(np.nanmedian(pts)), float(np.nanmedian(noise_noisy[name]))
            if np.isfinite(p) and np.isfinite(q) and p > 0 and q > 0:
                out[name] = p / q
    return out


def noise_ratio_factor(ratio):
    """The factor :func:`angle_bands` applies to an angle's bootstrap deviation for a noise
    ``ratio`` (:data:`NOISE_RATIO_POWER`, :data:`NOISE_RATIO_RANGE`; 1 for None or NaN).

    >>> noise_ratio_factor(4.0), noise_ratio_factor(100.0), noise_ratio_factor(None)
    (2.0, 2.0, 1.0)
    """
    if ratio is None or not np.isfinite(ratio):
        return 1.0
    return float(np.clip(ratio, *NOISE_RATIO_RANGE) ** NOISE_RATIO_POWER)


def _bootstrap_scale(family, name, inflation, noise_ratio, fps=None):
    """The factor on an angle's bootstrap deviations: ``inflation`` when given, else the family's
    :data:`BAND_SCALE` times the clip's :func:`frame_rate_factor` and the angle's
    :func:`noise_ratio_factor`."""
    if inflation is not None:
        return float(inflation)
    return (BAND_SCALE.get(family, max(BAND_SCALE.values())) * frame_rate_factor(fps)
            * noise_ratio_factor((noise_ratio or {}).get(name)))


def angle_bands(angles_point, angles_noisy, fps=None, lo=5.0, hi=95.0, inflation=None, noise_ratio=None):
    """Per-frame median and band of every angle.

    The median is that of the point liftings (no re-simulated noise, which would add its
    own bias).  Each side of the band is ``sqrt((k g d)^2 + (a c)^2)``: ``d`` the bootstrap's
    deviation from its own median (5th or 95th percentile), ``k`` the angle family's scale
    (:data:`BAND_SCALE`) times the clip's :func:`frame_rate_factor`, ``g`` the angle's
    noise-ratio factor (:func:`noise_ratio_factor` of ``noise_ratio[name]``,
    :func:`bootstrap_noise_ratio`; 1 when not given), ``c`` the
    curvature of the median curve (:func:`angle_curvature`) and ``a``
    :data:`BAND_CURVATURE_S2` (0 for the trunk lean; the term is left out where the
    curvature cannot be computed, or when ``fps`` is None).  ``inflation`` = a number scales
    every bootstrap band by it and leaves the curvature and the noise ratio out (1.0: the raw
    bootstrap band, for calibration studies).

    Returns
    -------
    dict name -> (median, lo, hi), each (F,)
    """
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for name, pts in angles_point.items():
            med = np.nanmedian(pts, 0)
            noisy = angles_noisy[name]
            centre = np.nanmedian(noisy, 0)
            dev_lo = centre - np.nanpercentile(noisy, lo, 0)
            dev_hi = np.nanpercentile(noisy, hi, 0) - centre
            fam = _band_family(name)
            k = _bootstrap_scale(fam, name, inflation, noise_ratio, fps)
            if inflation is not None:
                bias = 0.0
            else:
                a = 0.0 if fam == "trunk_lean" or fps is None else BAND_CURVATURE_S2
                bias = a * np.abs(angle_curvature(med, fps)) if a > 0 else 0.0
                bias = np.where(np.isfinite(bias), bias, 0.0)
            out[name] = (med, med - np.hypot(k * dev_lo, bias), med + np.hypot(k * dev_hi, bias))
    return out


#: Scale of the bootstrap deviations of the gait numbers, fitted on synthetic calibration clips
#: for 90 % coverage over all clips and numbers (``probreg bench band-calibration``: its own
#: calibration clips, never the validation or held-out sets, which only check it).  Re-fitted at
#: 0.2.0.dev19, 2.25 -> 2.54: the bench's fit had drifted to 2.45 by dev12 and the constant was left.
#: Re-fitted at 0.2.0.dev26, 2.54 -> 3.43, after the generator's legs left their plane (dev24).
#: Since 0.2.0.dev27 the cadence published is the stride pattern's with an interval of its own
#: (:func:`probreg.inference.gait_check.pattern_cadence_interval`) and is left out of the fit; on the
#: eight preset clips the fit was then 2.37, which held too few truths out of sample (suite 66 of 84).
#: 0.2.0.dev28: fitted on 24 clips, the eight presets and sixteen set-ups of the broadened generator
#: (steep, wide, grazing, far; seeds 9501-9516), where the raw intervals held 58.0 % of the truths:
#: one pooled scale would be 3.33; with each number's factor (:data:`GAIT_NUMBER_FACTORS`) the common
#: scale is 3.29 (``probreg.bench.band_calibration.fit_gait_scales``).
GAIT_BAND_SCALE = 3.29

#: Each gait number's factor on :data:`GAIT_BAND_SCALE` (1 for a number not listed): its median ratio of
#: error to raw half-interval over the median of all numbers' ratios, on the calibration clips above
#: (0.2.0.dev28; one pooled scale covered speed on 24 of 24 clips and flight time on 18 of 23).
GAIT_NUMBER_FACTORS = {"step_length_m": 0.85, "speed_mps": 0.77, "contact_time_s": 1.20, "flight_time_s": 1.41,
                       "peak_knee_flexion_swing_deg": 1.00, "knee_flexion_touchdown_deg": 0.96}

#: Name endings of the gait numbers that cannot be negative (their intervals stop at zero).
NONNEGATIVE_GAIT_SUFFIXES = ("_spm", "_m", "_mps", "_s")

def gait_intervals(gait_point, gait_noisy, lo=5.0, hi=95.0, inflation=None):
    """Median and 90 % interval of every gait number.

    The median is that of the point liftings; each side of the interval is the bootstrap
    liftings' deviation from their own median (contacts detected anew on re-noised
    keypoints: step timing varies there and only there) scaled by ``inflation`` (default
    :data:`GAIT_BAND_SCALE` times the number's :data:`GAIT_NUMBER_FACTORS`).

    Numbers that cannot be negative (rates, lengths, speeds, times: names ending in
    ``_spm``, ``_m``, ``_mps``, ``_s``) are cut at zero, the interval and the median: a widened
    interval of a short, uncertain contact time once reached -0.013 s, and a flight time (the
    step time less the contact time) came out at -3.26 s from contacts that lasted the whole
    clip (a ground track run backwards, 0.2.0.dev20; its gait verdict ``unreliable``).  The
    median always lies inside its interval.

    >>> g = gait_intervals({"cadence_spm": np.full(9, 170.0)},
    ...                    {"cadence_spm": 170.0 + np.linspace(-4.0, 4.0, 9)}, inflation=1.0)
    >>> [round(float(x), 1) for x in g["cadence_spm"]]
    [170.0, 166.4, 173.6]
    >>> g = gait_intervals({"contact_time_s": np.full(9, 0.05)},
    ...                    {"contact_time_s": 0.05 + np.linspace(-0.04, 0.04, 9)}, inflation=2.0)
    >>> [round(float(x), 3) for x in g["contact_time_s"]]
    [0.05, 0.0, 0.122]
    >>> g = gait_intervals({"flight_time_s": np.full(9, -3.26)},
    ...                    {"flight_time_s": np.linspace(-3.3, 0.1, 9)}, inflation=1.0)
    >>> [round(float(x), 3) for x in g["flight_time_s"]]
    [0.0, 0.0, 0.0]

    By default each side is the common scale times the number's factor (the raw upper deviation
    here is 0.009 s):

    >>> g = gait_intervals({"flight_time_s": np.full(9, 0.1)}, {"flight_time_s": 0.1 + np.linspace(-0.01, 0.01, 9)})
    >>> bool(np.isclose(g["flight_time_s"][2] - 0.1, 0.009 * GAIT_BAND_SCALE * GAIT_NUMBER_FACTORS["flight_time_s"]))
    True
    """
    import warnings

    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for name, v in gait_point.items():
            k = GAIT_BAND_SCALE * GAIT_NUMBER_FACTORS.get(name, 1.0) if inflation is None else float(inflation)
            med = float(np.nanmedian(v))
            w = np.asarray(gait_noisy.get(name, v), float)
            c = np.nanmedian(w)
            low, high = med - k * (c - np.nanpercentile(w, lo)), med + k * (np.nanpercentile(w, hi) - c)
            if name.endswith(NONNEGATIVE_GAIT_SUFFIXES):  # NaN stays NaN (max would turn it into 0)
                med, low, high = (x if np.isnan(x) else max(x, 0.0) for x in (med, low, high))
            out[name] = (med, low, high)
    return out


#: Angles of the gait-cycle curves: (angle, side) -> the angle series; side "L"/"R" also picks the
#: foot whose touchdowns delimit the cycle (the elbows' cycle is that of the same-side foot).
GAIT_CYCLE_ANGLES = {("knee", "L"): "knee_l", ("knee", "R"): "knee_r", ("hip", "L"): "hip_l",
                     ("hip", "R"): "hip_r", ("elbow", "L"): "elbow_l", ("elbow", "R"): "elbow_r"}


def gait_cycle_bands(angles_point, angles_noisy, contacts, n_points=101, lo=5.0, hi=95.0, inflation=None,
                     noise_ratio=None, fps=None):
    """Angle curves over the gait cycle (0-100 %, touchdown to touchdown of the same foot), with
    credible bands over posterior draws.

    For every draw, each angle is normalised over each complete cycle of its side's foot
    (``contacts`` (F, 2), ``[left, right]``, detected once for the clip) and averaged over the
    cycles: the band is the spread of that mean curve over the draws (the uncertainty of the
    athlete's typical cycle), not the cycle-to-cycle variation.  As in :func:`angle_bands`, the
    median is that of the point liftings and each side of the band the bootstrap draws'
    deviation from their own median, scaled by the angle family's :data:`BAND_SCALE`, the clip's
    :func:`frame_rate_factor` (``fps``) and the angle's noise-ratio factor
    (:func:`noise_ratio_factor`; or by ``inflation`` alone).

    Returns
    -------
    dict (angle, side) -> (cycle_pct (n,), median (n,), lo (n,), hi (n,), n_cycles)
        Only pairs with at least one complete cycle; NaN where no draw had a usable cycle.
    """
    import warnings

    from ..analysis import gait_cycles, mean_cycle_curve

    c = np.asarray(contacts, bool)
    pct = np.linspace(0.0, 100.0, n_points)
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for (angle, side), name in GAIT_CYCLE_ANGLES.items():
            if name not in angles_point:
                continue
            contact = c[:, 0 if side == "L" else 1]
            n_cyc = len(gait_cycles(contact))
            if n_cyc == 0:
                continue
            pts = np.array([mean_cycle_curve(a, contact, n_points) for a in np.atleast_2d(angles_point[name])])
            noisy = np.array([mean_cycle_curve(a, contact, n_points) for a in np.atleast_2d(angles_noisy[name])])
            med = np.nanmedian(pts, 0)
            centre = np.nanmedian(noisy, 0)
            k = _bootstrap_scale(angle, name, inflation, noise_ratio, fps)
            lo_c = med - k * (centre - np.nanpercentile(noisy, lo, 0))
            hi_c = med + k * (np.nanpercentile(noisy, hi, 0) - centre)
            out[(angle, side)] = (pct, med, lo_c, hi_c, n_cyc)
    return out
