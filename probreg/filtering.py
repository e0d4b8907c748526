"""Time-series cleaning of keypoint tracks: outlier rejection, gap filling, zero-phase low-pass.

Sports2D/Pose2Sim users filter keypoints with a 4th-order 6 Hz Butterworth
filter; probreg offers the same (``butterworth``) plus a Hampel filter that
removes detector outliers and left/right swaps first, so that one bad
detection does not smear over its neighbours.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import butter, filtfilt

__all__ = ["hampel", "fill_gaps", "butterworth", "clean_keypoints", "keypoint_noise_px"]


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


def hampel(x, half_window=4, n_sigma=3.0, min_scale=1.0):
    """Mark outliers (NaN) in a 1-D series: farther than ``n_sigma`` robust standard
    deviations from the running median.  NaNs stay NaN.

    >>> y = hampel(np.array([0., 1, 2, 30, 4, 5, 6, 7, 8]), half_window=2)
    >>> bool(np.isnan(y[3])), float(y[4])
    (True, 4.0)
    """
    x = np.asarray(x, float).copy()
    ok = np.isfinite(x)
    if ok.sum() < 3:
        return x
    xi = np.interp(np.arange(len(x)), np.flatnonzero(ok), x[ok])
    med = median_filter(xi, size=2 * half_window + 1, mode="nearest")
    mad = 1.4826 * median_filter(np.abs(xi - med), size=2 * half_window + 1, mode="nearest")
    x[np.abs(xi - med) > n_sigma * np.maximum(mad, min_scale)] = np.nan
    return x


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


def butterworth(x, fps, cutoff_hz=6.0, order=4):
    """Zero-phase Butterworth low-pass (effective ``order``) of a 1-D series; NaN runs are
    bridged for filtering and restored afterwards.  Series too short are returned unchanged."""
    x = np.asarray(x, float)
    ok = np.isfinite(x)
    if ok.sum() < 3 * (order + 1) or not 0 < cutoff_hz < fps / 2:
        return x.copy()
    xi = np.interp(np.arange(len(x)), np.flatnonzero(ok), x[ok])
    # filtfilt runs the filter twice: a design of half the order gives the stated order
    # (as Pose2Sim/Sports2D do for their "4th-order" filter)
    b, a = butter(max(order // 2, 1), cutoff_hz / (fps / 2))
    y = filtfilt(b, a, xi, padlen=min(3 * max(len(a), len(b)), len(xi) - 1))
    return np.where(ok, y, np.nan)


def clean_keypoints(keypoints_px, fps, cutoff_hz="auto", half_window=4, n_sigma=3.0, max_gap=10,
                    noise_floor_px=1.5):
    """Hampel outlier rejection, short-gap filling and zero-phase low-pass of every coordinate.

    Parameters
    ----------
    keypoints_px : ndarray, shape (F, J, 3)
        ``(x, y, score)``; NaN = missing.
    fps : float
    cutoff_hz : float, "auto" or None
        Low-pass cut-off (None: no low-pass; "auto": 7 Hz when the estimated detection
        noise exceeds ``noise_floor_px``, otherwise none; a low-pass also flattens the
        true knee-flexion peaks, so clean keypoints are better left alone).

    Returns
    -------
    ndarray, shape (F, J, 3)
        Cleaned coordinates; filled joints get score 0.5 (still usable), unfillable stay NaN.
    """
    kp = np.asarray(keypoints_px, float)
    noise = keypoint_noise_px(kp) if kp.shape[1] == 17 else np.inf
    noisy = not np.isfinite(noise) or noise > noise_floor_px
    if cutoff_hz == "auto":
        cutoff_hz = 7.0 if noisy else None
    # outlier scale: a clean track's own curvature at turning points must not look like an outlier
    scale = max(1.0, 2.0 * noise) if np.isfinite(noise) else 1.0
    out = kp.copy()
    for j in range(kp.shape[1]):
        cols = []
        for c in range(2):
            x = hampel(kp[:, j, c], half_window, n_sigma, min_scale=scale) if noisy else kp[:, j, c]
            cols.append(x)
        # an outlier in x or y removes the joint
        bad = ~np.isfinite(cols[0]) | ~np.isfinite(cols[1])
        for c in range(2):
            x = np.where(bad, np.nan, cols[c])
            x = fill_gaps(x, max_gap)
            if cutoff_hz:
                x = butterworth(x, fps, cutoff_hz)
            out[:, j, c] = x
        filled = np.isfinite(out[:, j, 0]) & ~np.isfinite(kp[:, j, 2])
        out[filled, j, 2] = 0.5
        out[~np.isfinite(out[:, j, 0]), j] = np.nan
    return out
