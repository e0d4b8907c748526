"""Keypoint noise estimates and the classic cleaning chain (Hampel, gap filling, Butterworth)."""

from __future__ import annotations

import functools

import numpy as np
from scipy.ndimage import median_filter

from ..geometry import JOINT_INDEX

__all__ = ["hampel", "hampel_columns", "fill_gaps", "butterworth", "butterworth_columns", "keypoint_noise_px", "noise_model", "leg_length_px",
           "keypoints_noisy", "NOISE_FLOOR_PX", "NOISE_FLOOR_LEG_FRAC"]

#: detector noise (px, :func:`noise_model`) up to which a clip's keypoints count as clean and are
#: left alone (a low-pass also flattens the true knee-flexion peaks) ...
NOISE_FLOOR_PX = 1.5
#: ... or up to this fraction of the leg's length in the image, when that is less: what a pixel of
#: noise does to an angle depends on how long the limbs are in the image.  The 1.5 px were set on
#: the benchmark suite, whose athletes' legs (hip-knee-ankle) are 174 px long in the median clip:
#: 1.5 / 174 = 0.86 %.  Without it a small athlete (a wide view at 720p, leg ~50 px) with 1.2 px
#: of noise -- 2.5 % of its leg, as much as the suite's clips have -- was taken as clean and lifted
#: unsmoothed (knee error 8.3 deg with its true camera, 3.3 deg smoothed; tuning clip 8857 of
#: ``probreg.sim.heldout``'s generator, a seed outside the held-out set)
NOISE_FLOOR_LEG_FRAC = 0.0086

#: hip, knee and ankle of the left and right leg (H36M-17 indices)
_LEGS = tuple(tuple(JOINT_INDEX[f"{side}_{j}"] for j in ("hip", "knee", "ankle")) for side in "lr")


def leg_length_px(keypoints_px):
    """Median image length (px) of the legs, thigh plus shank (hip-knee-ankle), over frames and
    both sides; NaN without a frame that shows a whole leg.

    >>> kp = np.full((3, 17, 3), np.nan); kp[:, 4, :2] = [0, 0]; kp[:, 5, :2] = [0, 30]; kp[:, 6, :2] = [0, 58]
    >>> leg_length_px(kp)
    58.0
    """
    kp = np.asarray(keypoints_px, float)
    if kp.ndim != 3 or kp.shape[1] != 17:
        return float("nan")
    lengths = np.concatenate([np.linalg.norm(kp[:, h, :2] - kp[:, k, :2], axis=-1)
                              + np.linalg.norm(kp[:, k, :2] - kp[:, a, :2], axis=-1) for h, k, a in _LEGS])
    lengths = lengths[np.isfinite(lengths)]
    return float(np.median(lengths)) if len(lengths) else float("nan")


def keypoints_noisy(keypoints_px, noise_px=None, floor_px=NOISE_FLOOR_PX, floor_leg_frac=NOISE_FLOOR_LEG_FRAC):
    """Whether a clip's keypoints are noisy enough to smooth: their noise (``noise_px``, else
    :func:`noise_model`'s) is unknown or above ``floor_px`` or, when less, ``floor_leg_frac`` of
    the legs' image length (:func:`leg_length_px`; None: the pixel floor alone).

    >>> kp = np.full((3, 17, 3), np.nan); kp[:, 4, :2] = [0, 0]; kp[:, 5, :2] = [0, 25]; kp[:, 6, :2] = [0, 50]
    >>> keypoints_noisy(kp, 1.2), keypoints_noisy(kp * 8, 1.2), keypoints_noisy(kp, 1.2, floor_leg_frac=None)
    (True, False, False)
    """
    if noise_px is None:
        noise_px = noise_model(keypoints_px)[0] if np.shape(keypoints_px)[1:2] == (17,) else float("nan")
    if not np.isfinite(noise_px):
        return True
    floor = float(floor_px)
    if floor_leg_frac is not None:
        leg = leg_length_px(keypoints_px)
        if np.isfinite(leg):
            floor = min(floor, float(floor_leg_frac) * leg)
    return bool(noise_px > floor)


def keypoint_noise_px(keypoints_px, joints=(0, 7, 8)):
    """Robust estimate of the per-coordinate detection noise (px) from the trunk joints.

    The trunk (pelvis, spine, thorax in H36M order) moves smoothly relative to
    itself: second differences of the spine and thorax *relative to the pelvis*
    (camera pan and shake cancel) are noise, with standard deviation
    ``sqrt(12) sigma`` for white noise (``sqrt(6)`` for the second difference,
    ``sqrt(2)`` for the difference of two joints).  Returns ~0 for exact input.

    >>> rng = np.random.default_rng(0)
    >>> kp = np.zeros((400, 17, 3)); kp[..., :2] += rng.normal(0, 2.0, (400, 17, 2))
    >>> abs(keypoint_noise_px(kp) - 2.0) < 0.2
    True
    """
    kp = np.asarray(keypoints_px, float)[:, list(joints), :2]
    rel = kp[:, 1:] - kp[:, :1]
    d2 = rel[2:] - 2 * rel[1:-1] + rel[:-2]
    d2 = d2[np.isfinite(d2)]
    if len(d2) < 10:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d2)) / np.sqrt(12))


#: the largest frame-to-frame noise correlation :func:`noise_model` fits (beyond it the differences
#: over 1-3 frames cannot tell the noise's level from its correlation)
NOISE_RHO_MAX = 0.9
#: a lag-1 noise correlation from which :func:`noise_model` takes the growth of the variances with
#: the lag for the trunk's own motion (refitted with it)
NOISE_RHO_MOTION = 0.8


def noise_model(keypoints_px, joints=(0, 7, 8), lags=(1, 2, 3)):
    """Detector noise of a clip: per-coordinate sd (px) and frame-to-frame correlation.

    Uses the trunk joints relative to the pelvis (camera motion cancels, the
    trunk's own motion over a few frames is mostly small).  For AR(1) noise with sd
    ``s`` and lag-1 correlation ``r``, differences over ``k`` frames have
    variance ``2 s^2 (1 - r^k)`` (doubled again for the difference of two
    joints).  ``r`` and ``s`` are fitted to the robust (MAD) variances at
    ``lags`` by least squares in log variance: two lags alone give a ratio
    that 250 frames measure too loosely (``r`` then wanders towards 1 and
    ``s`` with it).  Where that fit reaches :data:`NOISE_RHO_MOTION`, the growth
    with the lag is taken for the trunk's own motion as much as the data allow
    (:func:`_with_motion`, lags 1-4; the AR(1) fit stands where that refit cannot
    be made, e.g. too few frames for lag 4).

    Returns
    -------
    sd_px : float
    rho : float

    >>> rng = np.random.default_rng(1)
    >>> e = np.zeros((4000, 17, 2)); w = rng.normal(0, 1, e.shape)
    >>> for t in range(1, 4000): e[t] = 0.5 * e[t - 1] + np.sqrt(0.75) * w[t]
    >>> sd, rho = noise_model(np.concatenate([3 * e, np.ones((4000, 17, 1))], -1))
    >>> bool(abs(sd - 3) < 0.2 and abs(rho - 0.5) < 0.06)
    True
    """
    kp = np.asarray(keypoints_px, float)[:, list(joints), :2]
    rel = kp[:, 1:] - kp[:, :1]
    sd, rho = _ar1_fit(_lag_variances(rel, lags), lags)
    if rho < NOISE_RHO_MOTION:
        return sd, rho
    # a correlation this high says the variances grow with the lag as the trunk's own motion does
    # (at 25 fps the trunk moves more between frames): refitted with that motion as a part of its own
    refit = _with_motion(rel)
    return refit if np.isfinite(refit[0]) else (sd, rho)


def _ar1_fit(v, lags):
    """AR(1) noise ``(sd, rho)`` from the variances ``v`` of the differences over ``lags``: least
    squares in log variance over a grid of ``rho`` (:func:`noise_model`)."""
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        return float("nan"), 0.0
    r = np.linspace(0.0, NOISE_RHO_MAX, 181)[:, None]
    g = 2 * (1 - r ** np.asarray(lags)[None, :])  # (R, K): variance per unit s^2
    log_s2 = np.mean(np.log(v)[None] - np.log(g), axis=1)
    cost = np.sum((np.log(v)[None] - np.log(g) - log_s2[:, None]) ** 2, axis=1)
    i = int(np.argmin(cost))
    return float(np.exp(0.5 * log_s2[i])), float(r[i, 0])


def _lag_variances(rel, lags):
    """Robust (MAD) variance of the differences over each lag of joints relative to the pelvis, per
    coordinate of one joint (halved: the difference of two joints); NaN with fewer than 20."""
    v = []
    for k in lags:
        d = rel[k:] - rel[:-k]
        d = d[np.isfinite(d)]
        v.append((1.4826 * np.median(np.abs(d))) ** 2 / 2 if len(d) >= 20 else np.nan)
    return np.array(v)


def _with_motion(rel, lags=(1, 2, 3, 4)):
    """:func:`noise_model`'s fit with the trunk's own motion as a second part of the variances:
    ``2 s^2 (1 - r^k) + m k^2`` (AR(1) noise levels off with the lag, motion that is steady over a
    few frames grows with its square), ``s^2`` and ``m`` non-negative, least squares relative to
    each variance; ``(s, r)``.

    >>> rng = np.random.default_rng(0)  # spine and thorax drifting 1.6 px a frame from the pelvis, 2 px of noise
    >>> drift = 1.6 * np.arange(250)[:, None, None] * np.array([1, -1])[None, :, None]
    >>> rel = drift + rng.normal(0, 2.0 * np.sqrt(2), (250, 2, 2))
    >>> [round(x, 1) for x in _ar1_fit(_lag_variances(rel, (1, 2, 3)), (1, 2, 3)) + _with_motion(rel)]
    [6.4, 0.9, 1.8, 0.0]
    """
    v = _lag_variances(rel, lags)
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        return float("nan"), 0.0
    L = np.asarray(lags, float)
    r = np.linspace(0.0, NOISE_RHO_MAX, 181)[:, None]
    a1 = 2 * (1 - r ** L[None]) / v[None]  # (R, K): the noise's column per unit s^2, relative
    a2 = np.broadcast_to(L**2 / v, a1.shape)  # the motion's column per unit m, relative
    # per r: the unconstrained 2x2 least squares, else the better one-column fit (a part at zero)
    s11, s12, s22 = np.sum(a1 * a1, 1), np.sum(a1 * a2, 1), np.sum(a2 * a2, 1)
    b1, b2 = np.sum(a1, 1), np.sum(a2, 1)
    det = s11 * s22 - s12**2
    with np.errstate(divide="ignore", invalid="ignore"):
        both = np.column_stack([(s22 * b1 - s12 * b2) / det, (s11 * b2 - s12 * b1) / det])
    cands = [both, np.column_stack([b1 / s11, np.zeros_like(b1)]), np.column_stack([np.zeros_like(b2), b2 / s22])]
    best_cost, best_s2 = np.full(len(r), np.inf), np.zeros(len(r))
    for x in cands:
        ok = np.all(np.isfinite(x) & (x >= 0), axis=1)
        cost = np.sum((a1 * x[:, :1] + a2 * x[:, 1:] - 1) ** 2, axis=1)
        better = ok & (cost < best_cost)
        best_cost, best_s2 = np.where(better, cost, best_cost), np.where(better, x[:, 0], best_s2)
    i = int(np.argmin(best_cost))
    return float(np.sqrt(best_s2[i])), float(r[i, 0])


def hampel(x, half_window=4, n_sigma=3.0, min_scale=1.0):
    """Mark outliers (NaN) in a 1-D series: farther than ``n_sigma`` robust standard
    deviations from the running median.  NaNs stay NaN.

    >>> y = hampel(np.array([0., 1, 2, 30, 4, 5, 6, 7, 8]), half_window=2)
    >>> bool(np.isnan(y[3])), float(y[4])
    (True, 4.0)
    """
    return hampel_columns(np.asarray(x, float)[:, None], half_window, n_sigma, min_scale)[:, 0]


def _filled_columns(X, ok, use):
    """The columns ``use`` of ``X`` (F, K) with their missing samples (not ``ok``) linearly
    interpolated from the observed ones (each such column has at least one)."""
    t = np.arange(len(X))
    return np.column_stack([np.interp(t, t[ok[:, k]], X[ok[:, k], k]) for k in np.flatnonzero(use)])


def hampel_columns(X, half_window=4, n_sigma=3.0, min_scale=1.0):
    """:func:`hampel` of every column of ``X`` (F, K) at once: the running medians of all
    columns in one filter pass, the same result as column by column (medians are exact).

    >>> X = np.column_stack([[0., 1, 2, 30, 4, 5, 6, 7, 8], [np.nan] * 8 + [1.0]])
    >>> Y = hampel_columns(X, half_window=2)
    >>> np.isnan(Y[:, 0]).tolist().index(True), np.isnan(Y[:, 1]).sum()   # a column too short: as it was
    (3, np.int64(8))
    """
    X = np.array(X, float)  # a copy
    ok = np.isfinite(X)
    use = ok.sum(0) >= 3
    if not use.any():
        return X
    xi = _filled_columns(X, ok, use)
    size = (2 * half_window + 1, 1)
    med = median_filter(xi, size=size, mode="nearest")
    mad = 1.4826 * median_filter(np.abs(xi - med), size=size, mode="nearest")
    sub = X[:, use]
    sub[np.abs(xi - med) > n_sigma * np.maximum(mad, min_scale)] = np.nan
    X[:, use] = sub
    return X


def fill_gaps(x, max_gap=10):
    """Linear interpolation over NaN runs of at most ``max_gap`` samples (longer gaps stay NaN).

    >>> fill_gaps(np.array([1., np.nan, 3, np.nan, np.nan, np.nan, 7]), max_gap=1).tolist()[:3]
    [1.0, 2.0, 3.0]
    """
    x = np.asarray(x, float).copy()
    bad = ~np.isfinite(x)
    if not bad.any() or bad.all():
        return x
    idx = np.arange(len(x))
    filled = np.interp(idx, idx[~bad], x[~bad])
    edges = np.diff(np.concatenate([[0], bad.astype(int), [0]]))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if b - a <= max_gap and a > 0 and b < len(x):
            x[a:b] = filled[a:b]
    return x


@functools.lru_cache(maxsize=64)
def _butter_design(order, wn):
    """The low-pass design, computed once per (order, normalised cut-off): scipy's design costs
    ~1 ms, and the propagation filters thousands of series with a handful of designs.
    ``scipy.signal`` is imported here, not with the module: its import (with ``scipy.stats``)
    takes ~0.7 s, which ``probreg run`` spends in a thread while the lanes are found."""
    from scipy.signal import butter

    b, a = butter(order, wn)
    b.setflags(write=False)
    a.setflags(write=False)
    return b, a


def butterworth(x, fps, cutoff_hz=6.0, order=4):
    """Zero-phase Butterworth low-pass (effective ``order``) of a 1-D series; NaN runs are
    bridged for filtering and restored afterwards.  Series too short are returned unchanged."""
    return butterworth_columns(np.asarray(x, float)[:, None], fps, cutoff_hz, order)[:, 0]


def butterworth_columns(X, fps, cutoff_hz=6.0, order=4):
    """:func:`butterworth` of every column of ``X`` (F, K) at once: one ``filtfilt`` over the
    columns that are long enough, bit for bit the result column by column (one call for a
    clip's 34 keypoint coordinates costs a fourteenth of 34 calls).

    >>> t = np.arange(100.0); X = np.column_stack([np.sin(t / 5), np.full(100, np.nan)]); X[10, 0] = np.nan
    >>> Y = butterworth_columns(X, 50.0, 6.0)
    >>> bool(np.isnan(Y[10, 0])), bool(np.isnan(Y[:, 1]).all()), bool(np.abs(Y[20:80, 0] - X[20:80, 0]).max() < 0.01)
    (True, True, True)
    """
    X = np.asarray(X, float)
    out = X.copy()
    ok = np.isfinite(X)
    use = ok.sum(0) >= 3 * (order + 1)
    if not use.any() or not 0 < cutoff_hz < fps / 2:
        return out
    xi = _filled_columns(X, ok, use)
    # filtfilt runs the filter twice: a design of half the order gives the stated order
    # (as Pose2Sim/Sports2D do for their "4th-order" filter)
    from scipy.signal import filtfilt

    b, a = _butter_design(max(order // 2, 1), float(cutoff_hz / (fps / 2)))
    y = filtfilt(b, a, xi, axis=0, padlen=min(3 * max(len(a), len(b)), len(xi) - 1))
    out[:, use] = np.where(ok[:, use], y, np.nan)
    return out


def _lowpass_series(x, fps, cutoff_hz):
    """Butterworth low-pass of every column of a (F, ...) array (NaN-tolerant)."""
    return butterworth_columns(x.reshape(len(x), -1), fps, cutoff_hz).reshape(x.shape)
