"""Can the gait numbers be used? A check of the ones that rest on the detected ground contacts.

``gait.json``'s cadence, step length, contact and flight time and the knee angles at touchdown
and in swing all come from the contacts the lifting finds (the ankles' along-track speed,
:func:`probreg.lifting.trajectory.detect_contacts`). Where the cast ankles are noisy (a grazing
or steep view, a detector's ankles) contacts flicker, merge or go missing, and those numbers
come out wrong with intervals that do not say so: on the tuning clips of the held-out
generator (seeds 7501-7540, not the held-out set; 0.2.0.dev12's step time) the contacts'
cadence was 6-97 % off on 8 of 39 clips, seven of them with the clip verdict ``ok`` (their
angles were good).

A second, independent estimate of the step time exists: the stride period of the whole-body
2-D pattern (:func:`probreg.filtering.stride_lags`, which the cross-stride smoothing uses).
It needs no camera and no contact; on the 80 tuning clips (seeds 7501-7540 and 8101-8140) it
was within 2 % of the true cadence on 78, and off by a factor of two (a lag of two strides)
on the other two. Those two are caught by the pattern itself (:func:`pattern_stride_frames`):
half their lag repeats the pattern nearly as well as the lag (mismatch ratio 1.7), where on
every other clip half a stride (the legs swapped) mismatches at least 8 times more. The checks:

``cadence x steps/min from the contacts, y from the stride pattern``
    the two differ by more than :data:`CADENCE_TOLERANCE` (a factor of two either way is
    reported too: which of them is wrong cannot be told);
``cadence x steps/min from the contacts, outside a runner's (120-330)``
    no stride pattern to compare with (a clip shorter than 1.5 strides), and the contacts'
    cadence is not a runner's (:data:`RUNNING_CADENCE_SPM`; seen at
    200-300 fps of real time, where contacts split: 818-18000 steps/min);
``touchdowns too few for a cadence``
    the contacts gave no cadence at all;
``contact time x s longer than a step (y s)``
    no flight phase: not running, or contacts merged across steps.

Any of them makes the gait verdict ``"unreliable"`` (``run.json`` ``gait_verdict`` and
``gait_verdict_reasons``; each contact-based number in ``gait.json`` has ``"status"``). The
clip verdict is not touched: the angles do not rest on the contacts' timing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CADENCE_TOLERANCE", "CONTACT_NUMBERS", "RUNNING_CADENCE_SPM", "HALF_LAG_RATIO", "gait_check",
           "pattern_cadence_spm", "pattern_stride_frames"]

#: steps per minute a runner makes in real time: a slow jog (~140) to the fastest sprinters
#: (~5 steps/s), with margins; below it the motion is slowed (or it is a walk, which probreg's
#: models do not describe either) (also :mod:`probreg.inference.time_base`'s)
RUNNING_CADENCE_SPM = (120.0, 330.0)

#: the gait numbers that rest on the detected contacts (``speed_mps`` does not: the ground track)
CONTACT_NUMBERS = ("cadence_spm", "step_length_m", "contact_time_s", "flight_time_s",
                   "peak_knee_flexion_swing_deg", "knee_flexion_touchdown_deg")

#: largest relative difference between the contacts' cadence and the stride pattern's: the
#: pattern is within 2 % of the truth, and a cadence is reported to a few per cent. On the tuning
#: clips 7501-7540 the 29 clips it passed had cadence errors of 1.9 % on average (none above 5 %)
#: and 10 were flagged (8 of them 6-97 % off; 7511 at 4.4 %; 7508 because the pattern's lag was
#: two strides, which :func:`pattern_stride_frames` now halves: 30 pass, 1.8 %, 9 flagged); at 8 %
#: the passed clips held errors up to 7.5 %.
CADENCE_TOLERANCE = 0.05


#: a stride lag whose half repeats the 2-D pattern with less than this times its own mismatch is
#: two strides (the tuning clips: 1.7 on the two such clips, 8 and more on the 78 others)
HALF_LAG_RATIO = 3.0


def pattern_stride_frames(keypoints_px, fps, lags=None):
    """The stride period (frames) of the whole-body 2-D pattern: the median of the per-frame
    stride lags (``lags``, else :func:`probreg.filtering.stride_lags` of ``keypoints_px``), halved
    when half of it repeats the pattern nearly as well (:data:`HALF_LAG_RATIO`: the lag was two
    strides); NaN without repeating strides.

    >>> t = np.arange(300.0)[:, None, None]
    >>> rng = np.random.default_rng(1)
    >>> kp = np.concatenate([100 * np.sin(2 * np.pi * t / 30 + np.arange(17)[None, :, None] + [0, 1])
    ...                      + rng.normal(0, 0.5, (300, 17, 2)), np.ones((300, 17, 1))], -1)
    >>> round(pattern_stride_frames(kp, 50.0, lags=np.full(300, 60.0)), 1)  # a lag of two periods
    30.0
    >>> round(pattern_stride_frames(kp, 50.0, lags=np.full(300, 30.0)), 1)  # half of one does not repeat
    30.0
    """
    from ..filtering import pattern_mismatch, stride_lags

    lag = stride_lags(keypoints_px, fps) if lags is None else lags
    if lag is None or not np.isfinite(lag).any():
        return float("nan")
    period = float(np.nanmedian(lag))
    half, whole = pattern_mismatch(keypoints_px, fps, [period / 2, period])
    return period / 2 if np.isfinite(half) and np.isfinite(whole) and half < HALF_LAG_RATIO * whole else period


def pattern_cadence_spm(stride_frames, fps):
    """Steps per minute of a stride period in frames (two steps a stride); NaN without one.

    >>> round(pattern_cadence_spm(34.0, 50.0), 1), pattern_cadence_spm(None, 50.0)
    (176.5, nan)
    """
    sf = float("nan") if stride_frames is None else float(stride_frames)
    return 120.0 * fps / sf if np.isfinite(sf) and sf > 0 else float("nan")


def gait_check(gait, stride_frames, fps, tolerance=CADENCE_TOLERANCE):
    """The gait verdict: ``(gait, status, reasons)``, ``gait`` a copy of the summary
    ({name: {"median", "lo", "hi", "unit"}}) whose contact-based numbers carry
    ``"status"`` (``"ok"`` or ``"unreliable"``; ``speed_mps`` is always ``"ok"``).

    ``stride_frames`` is the clip's stride period from the 2-D pattern (frames; NaN or None
    when the clip shows no repeating strides: then the cadence is not cross-checked).

    >>> g = {"cadence_spm": {"median": 180.0}, "contact_time_s": {"median": 0.15}, "speed_mps": {"median": 6.0}}
    >>> gait_check(g, 33.3, 50.0)[1:]
    ('ok', [])
    >>> out, status, reasons = gait_check(g, 40.0, 50.0)  # the pattern says 150 steps/min
    >>> status, reasons, out["cadence_spm"]["status"], out["speed_mps"]["status"]
    ('unreliable', ['cadence 180 steps/min from the contacts, 150 from the stride pattern'], 'unreliable', 'ok')
    >>> gait_check({"cadence_spm": {"median": 180.0}, "contact_time_s": {"median": 0.5}}, None, 50.0)[2]
    ['contact time 0.50 s longer than a step (0.33 s)']
    >>> gait_check({"cadence_spm": {"median": 1000.0}}, None, 200.0)[2]  # no stride pattern to compare with
    ["cadence 1000 steps/min from the contacts, outside a runner's (120-330)"]
    """
    reasons = []
    cadence = _median(gait, "cadence_spm")
    if not np.isfinite(cadence) or cadence <= 0:
        reasons.append("touchdowns too few for a cadence")
    else:
        pattern = pattern_cadence_spm(stride_frames, fps)
        lo, hi = RUNNING_CADENCE_SPM
        if np.isfinite(pattern) and abs(cadence / pattern - 1.0) > tolerance:
            reasons.append(f"cadence {cadence:.0f} steps/min from the contacts, {pattern:.0f} from the stride pattern")
        elif not np.isfinite(pattern) and not lo <= cadence <= hi:  # nothing to compare with: a runner's range
            reasons.append(f"cadence {cadence:.0f} steps/min from the contacts, outside a runner's ({lo:.0f}-{hi:.0f})")
        contact, step = _median(gait, "contact_time_s"), 60.0 / cadence
        if np.isfinite(contact) and contact > 1.1 * step:
            reasons.append(f"contact time {contact:.2f} s longer than a step ({step:.2f} s)")
    status = "unreliable" if reasons else "ok"
    out = {k: {**v, "status": status if k in CONTACT_NUMBERS else "ok"} for k, v in gait.items()}
    return out, status, reasons


def _median(gait, name):
    v = gait.get(name, {}).get("median")
    return float("nan") if v is None else float(v)
