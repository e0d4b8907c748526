"""The cleaning chain of a clip's 2D keypoints: cross-stride smoothing for noisy clips with
repeating strides, Hampel + gap filling + Butterworth otherwise, clean keypoints left alone."""

from __future__ import annotations

import numpy as np

from .basic import (
    NOISE_FLOOR_LEG_FRAC,
    NOISE_FLOOR_PX,
    butterworth_columns,
    fill_gaps,
    hampel_columns,
    keypoints_noisy,
    noise_model,
)
from .identity import relabel_left_right
from .periodic import periodic_smooth

__all__ = ["clean_keypoints", "detection_status"]


def clean_keypoints(keypoints_px, fps, cutoff_hz="auto", half_window=4, n_sigma=3.0, max_gap=10,
                    noise_floor_px=NOISE_FLOOR_PX, noise_floor_leg_frac=NOISE_FLOOR_LEG_FRAC, relabel=True):
    """Left/right labels repaired from the motion, then Hampel outlier rejection, short-gap filling
    and zero-phase low-pass of every coordinate.

    Parameters
    ----------
    keypoints_px : ndarray, shape (F, J, 3)
        ``(x, y, score)``; NaN = missing.
    fps : float
    cutoff_hz : float, "auto" or None
        Low-pass cut-off (None: no low-pass; "auto": when the estimated detection
        noise exceeds ``noise_floor_px`` or, when less, ``noise_floor_leg_frac`` of the legs'
        image length (:func:`probreg.filtering.keypoints_noisy`), cross-stride smoothing
        (:func:`periodic_smooth`) or, for clips without repeating strides, a 7 Hz
        Butterworth low-pass; otherwise none: a low-pass also flattens the true
        knee-flexion peaks, so clean keypoints are better left alone).

    relabel : bool
        Set the legs' left/right labels right first (:func:`probreg.filtering.relabel_left_right`);
        False for keypoints that were relabelled already.

    Returns
    -------
    ndarray, shape (F, J, 3)
        Cleaned coordinates; filled joints get score 0.5 (still usable), unfillable stay NaN.
    """
    kp = np.asarray(keypoints_px, float)
    noise = noise_model(kp)[0] if kp.shape[1] == 17 else np.inf
    if relabel and kp.shape[1] == 17 and np.isfinite(noise):
        # legs whose left/right labels the detector got the wrong way round for some frames are
        # set right first (:func:`probreg.filtering.relabel_left_right`)
        kp = relabel_left_right(kp, noise)[0]
    noisy = keypoints_noisy(kp, noise, noise_floor_px, noise_floor_leg_frac)
    periodic = cutoff_hz == "auto" and noisy
    if cutoff_hz == "auto":
        cutoff_hz = 7.0 if noisy else None
    # outlier scale: a clean track's own curvature at turning points must not look like an outlier
    scale = max(1.0, 2.0 * noise) if np.isfinite(noise) else 1.0
    out = kp.copy()
    # raw detections: the cross-stride smoother rejects outliers itself and fills short gaps
    sm = periodic_smooth(kp, fps, fill_max_gap=max_gap) if periodic else None
    done = (np.all(np.isfinite(kp[..., :2]), -1).sum(0) >= len(kp) // 2 if sm is not None  # joints it took
            else np.zeros(kp.shape[1], bool))
    F, nj = kp.shape[:2]
    xy = hampel_columns(kp[..., :2].reshape(F, -1), half_window, n_sigma, min_scale=scale).reshape(F, nj, 2) \
        if noisy else kp[..., :2].copy()
    # an outlier in x or y removes the joint
    xy[~np.all(np.isfinite(xy), -1)] = np.nan
    for j in range(nj):
        for c in range(2):
            xy[:, j, c] = fill_gaps(xy[:, j, c], max_gap)
    # the smoother's joints take its fit (the low-pass would be overwritten; their NaNs are
    # those of the filled series, which is all the score bookkeeping below needs)
    low = np.flatnonzero(~done) if cutoff_hz else []
    if len(low):
        xy[:, low] = butterworth_columns(xy[:, low].reshape(F, -1), fps, cutoff_hz).reshape(F, len(low), 2)
    out[..., :2] = xy
    out[np.isfinite(xy[..., 0]) & ~np.isfinite(kp[..., 2]), 2] = 0.5
    out[~np.isfinite(xy[..., 0])] = np.nan
    if sm is not None:  # else: clip without repeating strides (or not noisy), keep the low-pass
        use = done[None, :] & np.all(np.isfinite(sm[..., :2]), -1)
        out[..., :2] = np.where(use[..., None], sm[..., :2], out[..., :2])
        out[use & ~np.isfinite(kp[..., 2]), 2] = 0.5
        out[done[None, :] & ~use] = np.nan
    return out


def detection_status(raw_px, cleaned_px=None):
    """Per-frame status of the athlete's 2D keypoints (``run.json``: ``keypoint_status``).

    ``no_detection``: no joint in the frame, before or after cleaning (its angles are NaN);
    ``interpolated``: no joint detected, but the cleaning bridged the frame from its neighbours
    (a short gap); ``partial``: some joints missing after cleaning (angles that need them are
    NaN); ``ok``: every joint there.  ``raw_px`` and ``cleaned_px`` (default: ``raw_px``) are
    ``(F, J, 2 or 3)`` with NaN for missing.

    >>> raw = np.ones((4, 17, 3)); raw[1] = np.nan; raw[2] = np.nan; raw[3, 5] = np.nan
    >>> cleaned = raw.copy(); cleaned[1] = 1.0
    >>> detection_status(raw, cleaned)
    ['ok', 'interpolated', 'no_detection', 'partial']
    """
    raw = np.asarray(raw_px, float)[..., :2]
    cleaned = raw if cleaned_px is None else np.asarray(cleaned_px, float)[..., :2]
    F = len(raw)
    raw_none = np.isnan(raw).reshape(F, -1).all(axis=1)
    gone = np.isnan(cleaned).reshape(F, -1)
    names = np.array(["no_detection", "interpolated", "partial", "ok"], object)
    tests = np.column_stack([raw_none & gone.all(axis=1), raw_none, gone.any(axis=1), np.ones(F, bool)])
    return names[np.argmax(tests, axis=1)].tolist()
