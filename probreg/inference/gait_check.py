"""Can the gait numbers be used? A check of the ones that rest on the detected ground contacts.

``gait.json``'s step length, contact and flight time, the knee angles at touchdown and in swing,
and the contacts' cadence (``cadence_contacts_spm``; the cadence published is the 2-D stride
pattern's, :func:`pattern_cadence_interval`, where the clip has one) come from the contacts the
lifting finds (the ankles' along-track speed, :func:`probreg.lifting.trajectory.detect_contacts`).
Where the cast ankles are noisy (a grazing or steep view, a detector's ankles) contacts flicker,
merge or go missing, and those numbers come out wrong with intervals that do not say so: on the
tuning clips of the held-out
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
    no flight phase: not running, or contacts merged across steps;
``feet slide back (stance ankles at x times the pelvis speed)``
    a foot on the ground stands still, so in any frame where one ankle is planted the slower
    ankle's along-track speed is about 0; here it runs backwards (:func:`stance_slide`: the
    slower ankle's 20th-percentile speed, read across the viewing rays, is below
    -:data:`MAX_STANCE_BACKSLIDE` times the pelvis's mean speed).  The along-track positions do not
    hold together: the camera moved along the track (a rail or tracking camera; probreg assumes
    a static one), or the per-frame pan is off (lanes nearly parallel in a long lens) and
    carries the runner back and forth.  Then the speed, the step length and the contacts are
    wrong too, and every gait number is marked unreliable, the speed included.  (Designed on
    the tuning twins 7501-7520, static cameras: at most -0.51 on a 25 fps steep view (-1.18 on a
    clip whose scale was wrong); rails at a quarter of the runner's speed -0.17 and -0.31, at half
    -0.53 to -0.73, at three quarters -2.6 and -6.5 (seeds 7601-7608).  The judged rail set and
    the static clips' rate are in ``reports/bench_rails.md``.)
``speed x m/s from the ground track, y m/s from the pelvis``
    the two measures of the running speed disagree by more than a factor of
    :data:`MAX_SPEED_RATIO`.  ``gait.json``'s speed is the ground track's (the Kalman-smoothed
    contacts); :func:`stance_slide` also reads the pelvis's displacement over the clip.  Over whole
    strides the feet move as far as the pelvis, and the same camera gives both their scale, so
    they agree to a few per cent (the pelvis's speed varies by about 5 % within a stride; a clip's
    partial stride moves its mean less).  Where they do not, the ground track is not the
    athlete's: feet cast onto the ground along a grazing ray move metres with a tenth of a degree
    of tilt (0.2.0.dev24: a grazing 25 fps clip of the held-out set, 3.2 m/s, had a track at 12.2
    m/s and a pelvis at 3.5 m/s, and published 12.2 m/s as an ``ok`` speed).  The speed is then
    marked unreliable too (and, as with every reason, the contact-based numbers).

Any of them makes the gait verdict ``"unreliable"`` (``run.json`` ``gait_verdict`` and
``gait_verdict_reasons``; each contact-based number in ``gait.json`` has ``"status"``). The
clip verdict is not touched: the angles do not rest on the contacts' timing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CADENCE_TOLERANCE", "CONTACT_NUMBERS", "RUNNING_CADENCE_SPM", "HALF_LAG_RATIO", "MAX_STANCE_BACKSLIDE",
           "MAX_OFF_HEADING", "MAX_SPEED_RATIO", "Z90", "gait_check", "pattern_cadence_spm", "pattern_stride_frames",
           "speed_scatter", "stance_slide", "pattern_cadence_interval", "PATTERN_LAG_RESOLUTION_FRAMES",
           "TIME_NUMBERS", "with_time_base"]

#: share of the frames whose ground track may head off the running direction (more than
#: :data:`probreg.lifting.trajectory.MAX_HEADING_DEG` from the straight) before the track's
#: velocity, and with it every gait number, is unreliable: a good track never does (its heading
#: stays within a degree or two of the straight), one from contacts too few or too noisy to
#: give a velocity (a low grazing view) runs backwards or sideways through much of the clip
MAX_OFF_HEADING = 0.1

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


#: the slower ankle may run backwards at most this share of the pelvis's speed (20th percentile)
#: before the feet count as sliding: a camera on a rail at a third of the runner's speed gives
#: -0.5 (a foot planted on the ground, seen from a camera moving at ``f`` of the runner's speed,
#: runs back at ``f / (1 - f)`` of the runner's apparent speed)
MAX_STANCE_BACKSLIDE = 0.5
#: the ground track's speed may differ from the pelvis's mean speed by at most this factor either
#: way: the two agree to a few per cent (see the module), 1.25 leaves a margin of about 2.5x
MAX_SPEED_RATIO = 1.25
#: half-width (s) of the central difference that gives the ankles' speed, and the smallest share
#: of the running direction across the viewing ray (below it the ray runs along the track, where
#: a cast ankle's position is mostly depth noise) for a frame to count
SLIDE_HALF_WINDOW_S = 0.06
SLIDE_MIN_ACROSS = 0.5


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


#: resolution (frames) of a stride lag read off the 2-D pattern (the mismatch's minimum is found
#: to a fraction of a frame): with the lags' stride-to-stride scatter it makes the standard error of
#: the pattern's stride period (:func:`pattern_cadence_interval`).  A quarter frame, with the normal
#: 90 % point, held the true cadence on 76 of the 80 tuning clips (seeds 7501-7540 and 8101-8140,
#: 25 and 50 fps; 57 of 80 from the lags' scatter alone)
PATTERN_LAG_RESOLUTION_FRAMES = 0.25


def pattern_cadence_interval(stride_frames, fps, lags=None, z=None):
    """The stride pattern's cadence (steps/min) and its interval: ``(median, lo, hi)``.

    The stride period ``P`` (:func:`pattern_stride_frames`) is the median of the per-frame stride
    lags ``lags`` (frames; scaled to ``P`` when the pattern halved them); its standard error is
    their scatter over the strides the clip spans, ``sd / sqrt(F_lags / P)``, and
    :data:`PATTERN_LAG_RESOLUTION_FRAMES` in quadrature.  The interval is ``P -+ z se`` turned into
    steps per minute (``z``: :data:`Z90` by default).  NaN without a stride period.

    >>> m, lo, hi = pattern_cadence_interval(34.0, 50.0, np.full(170, 34.0))  # 5 strides, no scatter
    >>> round(m, 1), round(lo, 1), round(hi, 1)
    (176.5, 174.4, 178.6)
    >>> [round(v, 1) for v in pattern_cadence_interval(34.0, 50.0, 34.0 + np.tile([-1.0, 1.0], 85))]
    [176.5, 172.2, 181.0]
    >>> pattern_cadence_interval(float("nan"), 50.0)
    (nan, nan, nan)
    """
    z = Z90 if z is None else float(z)
    sf = float("nan") if stride_frames is None else float(stride_frames)
    if not np.isfinite(sf) or sf <= 0 or not np.isfinite(fps) or fps <= 0:
        return float("nan"), float("nan"), float("nan")
    lag = np.asarray([] if lags is None else lags, float).ravel()
    lag = lag[np.isfinite(lag) & (lag > 0)]
    if len(lag):
        lag = lag * (sf / np.median(lag))  # a period halved by the pattern: its lags too
        se = float(np.hypot(np.std(lag) / np.sqrt(max(len(lag) / sf, 1.0)), PATTERN_LAG_RESOLUTION_FRAMES))
    else:
        se = PATTERN_LAG_RESOLUTION_FRAMES
    hi = pattern_cadence_spm(sf - z * se, fps) if sf > z * se else float("inf")
    return pattern_cadence_spm(sf, fps), pattern_cadence_spm(sf + z * se, fps), hi


def stance_slide(cameras, joints_track_m, fps):
    """Do the planted feet stand still?  ``{"backslide", "speed_mps", "frames"}``.

    Per frame the along-track speed of each ankle (central difference over
    +-:data:`SLIDE_HALF_WINDOW_S`), read from its motion across the viewing ray (divided by the
    running direction's share across it; frames where that share is below
    :data:`SLIDE_MIN_ACROSS` are left out: there the cast ankle moves mostly with depth noise),
    and the slower of the two ankles.  ``backslide`` is its 20th percentile over the clip as a
    share of the pelvis's mean speed (its displacement over the clip): ~0 or above when a
    planted foot stands still, ``-f / (1 - f)`` for a camera moving at ``f`` of the runner's
    speed.  NaN (and ``frames`` below 10) when too few frames can be read.

    ``cameras``: per frame a :class:`probreg.geometry.Camera` or None, or (F, 3) centres
    (:func:`probreg.geometry.camera_centres`);
    ``joints_track_m``: (F, 17, 3).

    >>> fps, t = 50.0, np.arange(100) / 50.0
    >>> def foot(phase):  # planted half of the time, then swinging: a mean of 5 m/s
    ...     return np.cumsum(np.maximum(0.0, 5 * np.pi * np.sin(2 * np.pi * 1.5 * t + phase))) / fps
    >>> def joints(shift):  # pelvis at 5 m/s; the frame moves with the camera at ``shift`` m/s
    ...     j = np.zeros((100, 17, 3)); j[:, :, 0] = (5 * t)[:, None]
    ...     j[:, 3, 0], j[:, 6, 0] = foot(0.0), foot(np.pi)
    ...     j[..., 0] -= shift * t[:, None]
    ...     return j
    >>> cams = np.tile([0.0, -40.0, 10.0], (100, 1))
    >>> abs(stance_slide(cams, joints(0.0), fps)["backslide"]) < 0.01  # static camera
    True
    >>> round(stance_slide(cams, joints(2.5), fps)["backslide"], 2)  # on a rail at half the speed
    -1.0
    """
    from ..geometry import JOINT_INDEX, camera_centres

    C = camera_centres(cameras)[:, :2]
    J = np.asarray(joints_track_m, float)
    nan = {"backslide": float("nan"), "speed_mps": float("nan"), "frames": 0}
    idx, dist, u = _travel(J[:, JOINT_INDEX["pelvis"], :2])
    h = max(1, int(round(SLIDE_HALF_WINDOW_S * fps)))
    if len(idx) < 2 or len(J) <= 2 * h or len(C) != len(J):
        return nan
    speed = dist * fps / (idx[-1] - idx[0])
    if u is None:
        return {**nan, "speed_mps": speed}
    with np.errstate(invalid="ignore", divide="ignore"):
        along = []
        for name in ("l_ankle", "r_ankle"):
            xy = J[:, JOINT_INDEX[name], :2]
            vel = np.full_like(xy, np.nan)
            vel[h:-h] = (xy[2 * h:] - xy[:-2 * h]) * fps / (2 * h)
            ray = xy - C
            ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
            across = np.stack([-ray[:, 1], ray[:, 0]], -1)  # unit, horizontal, across the ray
            share = across @ u
            along.append(np.where(np.abs(share) >= SLIDE_MIN_ACROSS, np.sum(vel * across, -1) / share, np.nan))
        slower = np.fmin(*along)
    v = slower[np.isfinite(slower)]
    if len(v) < 10:
        return {**nan, "speed_mps": speed, "frames": int(len(v))}
    return {"backslide": float(np.percentile(v, 20) / speed), "speed_mps": speed, "frames": int(len(v))}


def _travel(pelvis):
    """The frames with a pelvis (``idx``), the distance between the first and the last of them and
    the unit direction of that travel (None when there are fewer than two or they coincide)."""
    idx = np.flatnonzero(np.all(np.isfinite(pelvis), 1))
    if len(idx) < 2:
        return idx, float("nan"), None
    travel = pelvis[idx[-1]] - pelvis[idx[0]]
    dist = float(np.hypot(*travel))
    return idx, dist, (travel / dist if dist >= 1e-6 else None)


def speed_scatter(joints_track_m, fps, stride_frames):
    """How much the pelvis's along-track speed changes from one stride to the next, and what that
    leaves of the clip's mean speed: ``{"se_mps", "sd_mps", "windows", "window_frames"}``.

    A runner's speed averaged over a whole stride changes little within a clip (within a stride
    it rises and falls with every step; over one stride that cancels).  The along-track positions
    come from each frame's camera pan, and where the lanes fix the pan poorly (nearly parallel
    lines in a long lens) its error carries the runner back and forth by tens of centimetres, in
    stretches of several frames that no keypoint bootstrap sees.  So the pelvis's speed over every
    window of one stride (``stride_frames``, the 2-D pattern's period, rounded) along the clip's
    direction of travel is read, ``sd_mps`` is their spread and ``se_mps = sd_mps / sqrt(n)`` the
    standard error of the clip's mean speed, with ``n`` the number of strides the clip spans (at
    least 1: overlapping windows are not independent).  NaN (``windows`` below 3) without a stride
    period or with too few frames.

    >>> fps = 50.0; t = np.arange(200) / fps
    >>> J = np.zeros((200, 17, 3)); J[:, 0, 0] = 6.0 * t  # the pelvis at 6 m/s
    >>> round(speed_scatter(J, fps, 34.0)["se_mps"], 6)
    0.0
    >>> J[:, 0, 0] += 0.3 * np.sign(np.sin(2 * np.pi * t / 0.5))  # a pan error of +-0.3 m over 0.25 s stretches
    >>> out = speed_scatter(J, fps, 34.0)
    >>> out["window_frames"], out["windows"], bool(0.1 < out["se_mps"] < 0.5)
    (34, 166, True)
    """
    from ..geometry import JOINT_INDEX

    nan = {"se_mps": float("nan"), "sd_mps": float("nan"), "windows": 0, "window_frames": 0}
    sf = float("nan") if stride_frames is None else float(stride_frames)
    if not np.isfinite(sf) or sf < 2:
        return nan
    p = np.asarray(joints_track_m, float)[:, JOINT_INDEX["pelvis"], :2]
    ok = np.all(np.isfinite(p), 1)
    idx, _, u = _travel(p)
    w = int(round(sf))
    if len(idx) < 2 or idx[-1] - idx[0] <= w or u is None:
        return {**nan, "window_frames": w}
    start = np.arange(idx[0], idx[-1] - w + 1)
    start = start[ok[start] & ok[start + w]]
    v = (p[start + w] - p[start]) @ u * fps / w
    if len(v) < 3:
        return {**nan, "windows": int(len(v)), "window_frames": w}
    sd = float(np.std(v, ddof=1))
    n = max(1.0, (idx[-1] - idx[0]) / w)
    return {"se_mps": sd / float(np.sqrt(n)), "sd_mps": sd, "windows": int(len(v)), "window_frames": w}


#: the two-sided 90 % point of a normal (the gait intervals are 90 % intervals)
Z90 = 1.6448536269514722


def gait_check(gait, stride_frames, fps, tolerance=CADENCE_TOLERANCE, slide=None, scatter=None, off_heading=None,
               lags=None):
    """The gait verdict: ``(gait, status, reasons)``, ``gait`` a copy of the summary
    ({name: {"median", "lo", "hi", "unit"}}) whose numbers carry ``"status"`` (``"ok"`` or
    ``"unreliable"``: the contact-based ones with any reason; ``speed_mps`` only with feet that slide).

    The cadence published is the stride pattern's when the clip has one
    (:func:`pattern_cadence_interval`, with the per-frame stride ``lags``; ``"source": "stride
    pattern"``, status ``ok``: it needs neither a camera nor a contact): on the 80 tuning clips it was
    0.7 % off the truth on average (79 within 2 %), the contacts' with the true cameras 2.4 % (57).
    The contacts' own cadence, which the checks below use, is then ``cadence_contacts_spm``.

    ``stride_frames`` is the clip's stride period from the 2-D pattern (frames; NaN or None
    when the clip shows no repeating strides: then the cadence is not cross-checked).
    ``slide`` is :func:`stance_slide`'s result: feet sliding back make every number unreliable,
    the speed too.  ``scatter`` is :func:`speed_scatter`'s result: the speed's 90 % interval is
    widened by its standard error (each side ``sqrt(side**2 + (1.645 se)**2)``; the posterior's
    draws share every frame's pan, so their interval leaves that error out).  ``off_heading`` is
    the share of frames whose ground track heads off the running direction
    (:meth:`probreg.inference.ClipModel.track_off_heading`): above :data:`MAX_OFF_HEADING` the
    track's velocity is not the athlete's, and every number, the speed too, is unreliable.

    >>> g = {"cadence_spm": {"median": 180.0}, "contact_time_s": {"median": 0.15}, "speed_mps": {"median": 6.0}}
    >>> gait_check(g, 33.3, 50.0)[1:]
    ('ok', [])
    >>> out, status, reasons = gait_check(g, 40.0, 50.0)  # the pattern says 150 steps/min
    >>> status, reasons, out["cadence_contacts_spm"]["status"], out["speed_mps"]["status"]
    ('unreliable', ['cadence 180 steps/min from the contacts, 150 from the stride pattern'], 'unreliable', 'ok')
    >>> {k: out["cadence_spm"][k] for k in ("median", "source", "status")}  # the pattern's is published
    {'median': 150.0, 'source': 'stride pattern', 'status': 'ok'}
    >>> gait_check({"cadence_spm": {"median": 180.0}, "contact_time_s": {"median": 0.5}}, None, 50.0)[2]
    ['contact time 0.50 s longer than a step (0.33 s)']
    >>> out, status, reasons = gait_check(g, 33.3, 50.0, slide={"backslide": -0.9})
    >>> reasons, out["speed_mps"]["status"]
    (['feet slide back (stance ankles at -0.90 times the pelvis speed)'], 'unreliable')
    >>> gait_check({"cadence_spm": {"median": 1000.0}}, None, 200.0)[2]  # no stride pattern to compare with
    ["cadence 1000 steps/min from the contacts, outside a runner's (120-330)"]
    >>> out, status, reasons = gait_check(g, 33.3, 50.0, off_heading=0.93)
    >>> reasons, out["speed_mps"]["status"]
    (['ground track off the running direction in 93 % of frames'], 'unreliable')
    >>> out, status, reasons = gait_check(g, 33.3, 50.0, slide={"backslide": 0.0, "speed_mps": 3.5})
    >>> reasons, out["speed_mps"]["status"]
    (['speed 6.0 m/s from the ground track, 3.5 m/s from the pelvis'], 'unreliable')
    >>> gait_check(g, 33.3, 50.0, slide={"backslide": 0.0, "speed_mps": 5.2})[1:]  # within 1.25x: agree
    ('ok', [])
    >>> g["speed_mps"].update(lo=5.7, hi=6.4)
    >>> sp = gait_check(g, 33.3, 50.0, scatter={"se_mps": 0.4})[0]["speed_mps"]
    >>> round(sp["lo"], 2), round(sp["hi"], 2)
    (5.28, 6.77)
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
    backslide = float("nan") if not slide else float(slide.get("backslide", float("nan")))
    sliding = bool(np.isfinite(backslide) and backslide < -MAX_STANCE_BACKSLIDE)
    if sliding:
        reasons.append(f"feet slide back (stance ankles at {backslide:.2f} times the pelvis speed)")
    off_track = off_heading is not None and np.isfinite(off_heading) and off_heading > MAX_OFF_HEADING
    if off_track:
        reasons.append(f"ground track off the running direction in {100 * off_heading:.0f} % of frames")
    speed, pelvis = _median(gait, "speed_mps"), float("nan") if not slide else float(slide.get("speed_mps", np.nan))
    disagree = bool(speed > 0 and pelvis > 0 and abs(np.log(speed / pelvis)) > np.log(MAX_SPEED_RATIO))
    if disagree:
        reasons.append(f"speed {speed:.1f} m/s from the ground track, {pelvis:.1f} m/s from the pelvis")
    status = "unreliable" if reasons else "ok"
    out = {k: {**v, "status": status if k in CONTACT_NUMBERS or sliding or off_track or disagree else "ok"}
           for k, v in gait.items()}
    se = float("nan") if not scatter else float(scatter.get("se_mps", float("nan")))
    sp = out.get("speed_mps")
    finite = sp is not None and all(np.isfinite(sp.get(k, np.nan)) for k in ("median", "lo", "hi"))
    if finite and np.isfinite(se) and se > 0:
        m, extra = float(sp["median"]), Z90 * se
        sp["lo"] = max(0.0, m - float(np.hypot(m - sp["lo"], extra)))
        sp["hi"] = m + float(np.hypot(sp["hi"] - m, extra))
    pm, plo, phi = pattern_cadence_interval(stride_frames, fps, lags)
    if np.isfinite(pm):
        contacts = out.pop("cadence_spm", None)
        out["cadence_spm"] = {"median": pm, "lo": plo, "hi": phi, "unit": (contacts or {}).get("unit", "steps/min"),
                              "source": "stride pattern", "status": "ok"}
        if contacts is not None:  # a summary without the contacts' cadence gets none invented
            out["cadence_contacts_spm"] = {**contacts, "source": "contacts"}
    return out, status, reasons


#: the gait numbers that a wrong time base (a replay, a clip running too fast) scales: rates, times
#: and speeds (a step length does not change: speed times step time)
TIME_NUMBERS = ("cadence_spm", "cadence_contacts_spm", "speed_mps", "contact_time_s", "flight_time_s")


def with_time_base(gait, status, reasons, time_base):
    """``(gait, status, reasons)`` of :func:`gait_check` with the time base's verdict
    (:func:`probreg.inference.time_base.time_base_check`): its reason makes the gait verdict
    ``unreliable`` and every number of :data:`TIME_NUMBERS` too.

    >>> g = {"cadence_spm": {"median": 88.0, "status": "ok"}, "step_length_m": {"median": 2.0, "status": "ok"}}
    >>> g, status, reasons = with_time_base(g, "ok", [], {"reason": "slow motion about 2.0x"})
    >>> status, reasons, g["cadence_spm"]["status"], g["step_length_m"]["status"]
    ('unreliable', ['slow motion about 2.0x'], 'unreliable', 'ok')
    """
    reason = (time_base or {}).get("reason")
    if not reason:
        return gait, status, reasons
    gait = {k: {**v, "status": "unreliable"} if k in TIME_NUMBERS else v for k, v in gait.items()}
    return gait, "unreliable", [*reasons, reason]


def _median(gait, name):
    v = gait.get(name, {}).get("median")
    return float("nan") if v is None else float(v)
