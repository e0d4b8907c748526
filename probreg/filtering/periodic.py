"""Cross-stride smoothing: running repeats itself, detector noise does not.

Each joint's track relative to the trunk's per-frame common motion is estimated by
penalised least squares with a data term (AR(1) noise precision), a tie to the same phase one
stride later (local stride period from whole-body pattern matching) and a light smoothness
term; outliers and swaps are down-weighted iteratively, and detector scores are turned into
noise scales learned from the clip.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.ndimage import median_filter

from .banded import SeriesSystem, _band_matrix, _BandTerm, _prior_band, _tie_rows, lower_band
from .basic import _lowpass_series, butterworth, butterworth_columns, fill_gaps, hampel_columns, noise_model

__all__ = ["periodic_smooth", "periodic_smooth_series", "score_noise_scale", "stride_lags", "stride_period_frames",
           "pattern_mismatch"]


# --------------------------------------------------------------------------- cross-stride smoothing
#: Fewest repeating strides a clip must show for the cross-stride ties (keypoints and angles).
#: 1.5 is the least over which :func:`stride_period_frames` measures a period at all (it searches
#: lags up to two thirds of the clip).  From 1.5 strides on, the frames of the first half stride
#: have a partner one stride later, and the left/right tie half a stride later reaches nearly
#: every frame.  The value was chosen on the tuning clips cut to 55 and 65 frames (1.5-1.9
#: strides; two windows each, exact cameras).  Against the former 2 strides, the knee-angle error
#: went 5.98 -> 4.88 deg at 55 frames and 5.64 -> 3.84 deg at 65 frames.  Of the 60 windows of
#: 55 frames, one got worse (+0.4 deg).  Clips of 2 strides and more are unchanged.
MIN_STRIDES = 1.5

#: Trunk joints (H36M order) whose common motion is the reference point of the relative coordinates.
_TRUNK = (0, 1, 4, 7, 8, 11, 14)

def _common_mode(xy, ok, fps, noise, trunk, offset_hz=3.0, k=4.0):
    """Per-frame image motion shared by the trunk joints (camera shake, the athlete's travel).

    A zoomed-in broadcast camera shakes: a random walk of 0.01 deg per frame moves
    the whole athlete by several pixels from frame to frame at a narrow field of
    view.  That motion is common to all joints and is not posture; left in the
    joints' relative tracks (as with a low-passed trunk reference) each joint's
    smoother takes it for noise and removes it a little differently, which
    distorts the posture.  On the benchmark suite the per-frame reference took the
    knee-angle error with exact cameras from 3.05 to 2.84 deg and MPJPE from 2.74
    to 2.57 cm.  The reference is not low-passed on the way out either: the per-frame
    cameras see the same shake (a 10 Hz low-pass cost 0.02 deg, 2 Hz 1.0 deg).

    Every trunk joint's offset from the plain trunk mean, low-passed at ``offset_hz``,
    is its slowly changing place on the body; subtracting it turns each joint into
    an estimate of the common point, and their mean (joints more than ``k`` noise
    sd from the frame's median left out: outliers, swaps) is the reference.  A
    missing trunk joint then leaves the reference where it was, instead of moving
    the mean by its offset.
    """
    T = xy[:, _TRUNK]
    okT = ok[:, _TRUNK]
    F = len(xy)
    scale = max(2.0 * noise, 1.0) if np.isfinite(noise) else 1.0
    tol = k * max(noise if np.isfinite(noise) else 1.0, 0.5)
    ref = trunk
    # twice: the offsets are first read against the plain mean, which jumps where a trunk
    # joint is missing, then against the common reference of the first pass
    for _ in range(2):
        dev = np.where(okT[..., None], T - ref[:, None], np.nan)
        cols = hampel_columns(dev.reshape(F, -1), 4, 3.0, min_scale=scale)
        for k in range(cols.shape[1]):  # gaps filled; a column never seen is 0
            x = fill_gaps(cols[:, k], F)
            cols[:, k] = np.where(np.isfinite(x), x, np.nanmedian(x)) if np.isfinite(x).any() else 0.0
        off = butterworth_columns(cols, fps, offset_hz).reshape(dev.shape)
        est = np.where(okT[..., None], T - off, np.nan)  # (F, 7, 2): each joint's view of the common point
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # frames without any trunk joint
            med = np.nanmedian(est, axis=1)
            d = np.linalg.norm(est - med[:, None], axis=-1)
            keep = np.isfinite(d) & (d <= tol)
            new = np.nanmean(np.where(keep[..., None], est, np.nan), axis=1)
        new = np.where(np.isfinite(new), new, med)
        ref = np.column_stack([fill_gaps(new[:, c], F) for c in range(2)])
        ref = np.where(np.isfinite(ref), ref, trunk)
    return ref


def _relative_tracks(kp, fps, noise):
    """Keypoints relative to the trunk's common motion (:func:`_common_mode`), divided by a
    slowly varying body scale (zoom does not read as a change of posture).

    Returns ``(rel, ref, scale, rel_clean)`` -- ``rel_clean`` with outliers removed (NaN),
    for timing estimates -- or None when the trunk or the body scale is not seen often enough.
    """
    F = len(kp)
    xy = kp[..., :2]
    ok = np.all(np.isfinite(xy), -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames without any trunk joint
        trunk = np.nanmean(np.where(ok[:, _TRUNK, None], xy[:, _TRUNK], np.nan), axis=1)  # (F, 2)
        # body scale: hip-to-neck and hip-to-shoulder distances, heavily smoothed
        span = np.nanmean(np.stack([np.linalg.norm(xy[:, 9] - xy[:, 0], axis=-1),
                                    np.linalg.norm(xy[:, 11] - xy[:, 4], axis=-1),
                                    np.linalg.norm(xy[:, 14] - xy[:, 1], axis=-1)], 1), axis=1)
    if np.isfinite(trunk).all(1).sum() < F // 2:
        return None
    trunk = np.column_stack([fill_gaps(trunk[:, c], F) for c in range(2)])
    ref = _common_mode(xy, ok, fps, noise, trunk)
    span = fill_gaps(span, F)
    if not np.isfinite(span).any() or np.nanmedian(span) <= 0:
        return None
    span = np.where(np.isfinite(span), span, np.nanmedian(span))
    scale = butterworth(median_filter(span, size=int(fps) | 1, mode="nearest"), fps, 0.5)
    rel = (xy - ref[:, None]) / scale[:, None, None]
    # the stride timing comes from outlier-free tracks (one wild detection would otherwise
    # dominate the pattern match)
    sn_med = float(np.median(noise / scale)) if np.isfinite(noise) else 0.0
    rel_t = hampel_columns(rel.reshape(F, -1), 4, 3.0, min_scale=max(2 * sn_med, 1e-3)).reshape(rel.shape)
    return rel, ref, scale, rel_t


def stride_lags(keypoints_px, fps, min_strides=MIN_STRIDES):
    """Per-frame lag (frames, fractional) to the same phase one stride later, from the
    whole-body 2D pattern; None when the clip shows fewer than ``min_strides`` repeating
    strides.  Frames without a partner one stride later are NaN.
    """
    kp = np.asarray(keypoints_px, float)
    F = len(kp)
    if kp.ndim != 3 or kp.shape[1] != 17 or F < 20:
        return None
    tracks = _relative_tracks(kp, fps, noise_model(kp)[0])
    return None if tracks is None else _lags_of(tracks[3], fps, min_strides)


def pattern_mismatch(keypoints_px, fps, lags):
    """Mean squared difference of the whole-body 2-D pattern (the outlier-free, trunk-relative
    tracks :func:`stride_lags` matches) with itself ``lag`` frames later, for each of ``lags``
    (rounded to whole frames; body-scale units); NaN where it cannot be measured."""
    kp = np.asarray(keypoints_px, float)
    out = np.full(len(lags), np.nan)
    if kp.ndim != 3 or kp.shape[1] != 17 or len(kp) < 20:
        return out
    tracks = _relative_tracks(kp, fps, noise_model(kp)[0])
    if tracks is None:
        return out
    y = tracks[3].reshape(len(kp), -1)
    for i, lag in enumerate(lags):
        L = int(np.rint(float(lag))) if np.isfinite(lag) else 0
        if 0 < L < len(y):
            out[i] = _lag_mismatch(y, L)
    return out


def _lag_mismatch(y, L):
    """Mean squared difference of the rows of ``y`` (F, D) with those ``L`` frames later (NaN with
    10 finite differences or fewer)."""
    diff = y[L:] - y[:-L]
    ok = np.isfinite(diff)
    return float(np.mean(diff[ok] ** 2)) if ok.sum() > 10 else float("nan")


def _lags_of(rel_t, fps, min_strides):
    """Local stride lags of outlier-free relative tracks, or None without repeating strides."""
    T0 = stride_period_frames(rel_t, fps)
    if not np.isfinite(T0) or len(rel_t) < min_strides * T0:
        return None
    return _local_lags(rel_t.reshape(len(rel_t), -1), T0)


def stride_period_frames(rel, fps, min_s=0.45, max_s=1.6):
    """Stride period (frames, fractional) of pelvis-relative keypoints: the lag that best
    repeats the whole-body pattern (mean squared difference, parabolic refinement).

    Returns NaN when the clip is shorter than 1.5 periods or shows no clear repetition.
    """
    F = len(rel)
    y = rel.reshape(F, -1)
    lags = np.arange(max(2, int(min_s * fps)), min(int(max_s * fps), int(F / 1.5)) + 1)
    if len(lags) < 3:
        return float("nan")
    d = np.array([_lag_mismatch(y, L) for L in lags])
    if not np.isfinite(d).any():
        return float("nan")
    i = int(np.nanargmin(d))
    # two or three strides repeat the pattern as well as one does, and sampling the lag in
    # whole frames can favour a multiple (at 31.05 frames per stride, lag 62 lands nearer to
    # two periods than 31 to one): take the shortest sub-multiple whose own dip comes close
    for k in (3, 2):
        near = np.flatnonzero(np.abs(lags - lags[i] / k) <= 1.5)
        if len(near) and np.isfinite(d[near]).any():
            c = int(near[np.nanargmin(d[near])])
            if 0 < c < i and d[c] <= 1.5 * d[i] and d[c] < 0.5 * np.nanmax(d[:c]):
                i = c
                break
    # a repeating pattern: an interior minimum well below the mismatch at shorter lags
    # (for running, the step lag swaps left and right); drifting tracks grow with the lag
    if not (0 < i < len(lags) - 1 and d[i] < 0.5 * np.nanmax(d[:i])):
        return float("nan")
    if np.all(np.isfinite(d[i - 1:i + 2])):
        den = d[i - 1] - 2 * d[i] + d[i + 1]
        off = 0.5 * (d[i - 1] - d[i + 1]) / den if den > 0 else 0.0
        return float(lags[i] + np.clip(off, -0.5, 0.5))
    return float(lags[i])


def _local_lags(y, T0, half_window=6, search=3.0, step=0.1):
    """Per-frame lag (frames) to the same stride phase one stride later: windowed search
    around ``T0`` (the stride time varies from stride to stride), median-smoothed."""
    F = len(y)
    cand = np.arange(T0 - search, T0 + search + 1e-9, step)
    t = np.arange(F, dtype=float)
    cost = np.full((len(cand), F), np.inf)
    g = np.exp(-0.5 * (np.arange(-half_window, half_window + 1) / (half_window / 2)) ** 2)
    for i, L in enumerate(cand):
        pos = t + L
        k = np.floor(pos).astype(int)
        a = pos - k
        ok = k + 1 < F
        diff = np.full(y.shape, np.nan)
        diff[ok] = y[ok] - ((1 - a[ok, None]) * y[k[ok]] + a[ok, None] * y[k[ok] + 1])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # frames without a partner
            e = np.nanmean(diff**2, axis=1)
        valid = np.isfinite(e)
        num = np.convolve(np.where(valid, e, 0.0), g, mode="same")
        den = np.convolve(valid.astype(float), g, mode="same")
        with np.errstate(invalid="ignore", divide="ignore"):
            cost[i] = np.where(den > 0.5 * g.sum(), num / den, np.inf)
    best = cand[np.argmin(cost, axis=0)]
    has = np.isfinite(cost).any(0)
    lag = np.where(has, best, np.nan)
    if np.isfinite(lag).sum() >= 3:
        lag = median_filter(np.where(np.isfinite(lag), lag, T0), size=2 * half_window + 1, mode="nearest")
        lag[~has] = np.nan
    return lag


def _coupling(lag, rows=None):
    """Sparse operator ``(R x)_i = x_t - x(t + lag_t)`` (linear interpolation) over the frames
    with a partner one stride later; returns ``(R, has)``, ``has`` marking those frames.
    ``rows``: the ties' ``(cols, vals, has)`` from :func:`probreg.filtering.banded._tie_rows`, when
    the caller has them already."""
    from scipy import sparse

    cols, vals, has = _tie_rows(lag) if rows is None else rows
    m = len(cols)
    R = sparse.csr_matrix((vals.T.ravel(), (np.tile(np.arange(m), 3), cols.T.ravel())), shape=(m, len(lag)))
    return R, has


def _smoothness(F, fps, cutoff_hz):
    """Second-difference penalty (relative to a unit data weight) with its half-power point at
    ``cutoff_hz``."""
    from scipy import sparse

    D2 = sparse.diags([np.ones(F - 2), -2 * np.ones(F - 2), np.ones(F - 2)], [0, 1, 2], shape=(F - 2, F))
    wc = 2 * np.pi * cutoff_hz / fps
    return (D2.T @ D2) / (2 - 2 * np.cos(min(wc, np.pi))) ** 2


def _ar1_precision(F, rho):
    """Precision of unit-variance AR(1) noise: tridiag(-rho, 1 + rho^2, -rho) / (1 - rho^2)."""
    from scipy import sparse

    diag = np.full(F, 1 + rho**2)
    diag[[0, -1]] = 1.0
    return sparse.diags([diag, np.full(F - 1, -rho), np.full(F - 1, -rho)], [0, 1, -1]) / (1 - rho**2)


#: systems up to this size are solved by a dense Cholesky factorisation (LAPACK), larger ones by
#: sparse LU: for a clip of a few hundred frames the dense path is several times faster than
#: SuperLU with its per-call overhead, for long clips the sparse one scales (measured: 250 frames)
DENSE_MAX = 600


class _SPDSolver:
    """Solves ``A x = b`` for a symmetric positive definite ``A``, sparse or dense (when small: banded
    Cholesky for a banded ``A``, else dense Cholesky; larger: sparse LU; a matrix that is not
    numerically positive definite falls back to LU).

    ``band``: the number of sub-diagonals of ``A`` when known (else found from ``A``).
    Raises ``RuntimeError`` (as ``splu``) when ``A`` is singular."""

    def __init__(self, A, band=None):
        from scipy import sparse

        n = A.shape[0]
        self._lu = self._cho = self._band = None
        if n <= DENSE_MAX:
            from scipy.linalg import LinAlgError, cho_factor, cholesky_banded

            D = A.toarray() if sparse.issparse(A) else np.asarray(A)
            # the systems are banded (smoothness: 2 neighbours; the stride tie: one stride): a
            # banded Cholesky costs n u^2 instead of n^3 / 3 (identical to rounding)
            if band is None:
                rows, cols = np.nonzero(D)
                band = int(np.max(np.abs(rows - cols))) if len(rows) else 0
            u = int(band)
            if u < n // 3:
                ab = np.zeros((u + 1, n))
                for k in range(u + 1):
                    ab[k, :n - k] = np.diagonal(D, -k)
                try:
                    self._band = cholesky_banded(ab, lower=True, check_finite=False)
                    return
                except LinAlgError:
                    pass
            try:
                self._cho = cho_factor(D, lower=True, check_finite=False)
                return
            except LinAlgError:
                pass
        from scipy.sparse.linalg import splu

        self._lu = splu(sparse.csc_matrix(A))

    def solve(self, b):
        if self._band is not None:
            from scipy.linalg import cho_solve_banded

            return cho_solve_banded((self._band, True), b, check_finite=False)
        if self._cho is not None:
            from scipy.linalg import cho_solve

            return cho_solve(self._cho, b, check_finite=False)
        return self._lu.solve(b)


def periodic_smooth_series(y, lag, fps, rho=0.0, smooth_cutoff_hz=14.0, lag_sd_frames=0.35,
                           min_sv=0.5, iters=4):
    """Cross-stride smoothing of one scalar series whose noise level is unknown.

    The model of :func:`periodic_smooth` for a single series (e.g. a lifted knee
    angle): ``y_t = x_t + e_t`` with AR(1) noise ``e`` of lag-1 correlation
    ``rho`` and unknown sd ``s_n``; the prior couples ``x_t`` to the same phase one
    stride later (variance ``2 s_v^2 + (v_t lag_sd)^2``) and penalises second
    differences (half-power point ``smooth_cutoff_hz``).  ``s_n`` and the
    stride-to-stride variability ``s_v`` are estimated alternately: ``s_n^2`` as
    the residual's AR(1) quadratic form over its degrees of freedom
    (``n - tr(S)``, S the smoother's hat matrix), ``s_v^2`` from the repeat
    differences of the data minus the noise's share (floored at ``min_sv``).

    Parameters
    ----------
    y : ndarray (F,)
        NaN = missing (filled by the model).
    lag : ndarray (F,)
        From :func:`stride_lags`.

    Returns
    -------
    x : ndarray (F,)
    info : dict
        ``noise_sd``, ``stride_sd``.

    >>> rng = np.random.default_rng(3)
    >>> t = np.arange(300); truth = 40 + 35 * np.sin(2 * np.pi * t / 34.0)
    >>> y = truth + rng.normal(0, 5, 300)
    >>> x, info = periodic_smooth_series(y, np.full(300, 34.0), 50.0, rho=0.0)
    >>> bool(np.mean(np.abs(x - truth)) < 0.5 * np.mean(np.abs(y - truth)))
    True
    >>> bool(abs(info["noise_sd"] - 5) < 1)
    True
    """
    y = np.asarray(y, float)
    F = len(y)
    ok = np.isfinite(y)
    if ok.sum() < 10 or lag is None:
        return y.copy(), {"noise_sd": float("nan"), "stride_sd": float("nan")}
    t = np.arange(F)
    wc = 2 * np.pi * smooth_cutoff_hz / fps
    system = SeriesSystem(ok, lag, rho, p2_scale=1.0 / (2 - 2 * np.cos(min(wc, np.pi))) ** 2)
    yi = np.interp(t, t[ok], y[ok])
    y0 = np.where(ok, y, 0.0)
    rep = system.tie(yi)
    sel = ok[system.has]
    x = yi
    # start: all repeat differences read as noise
    sn2 = max(float(np.mean(rep[sel] ** 2)) / 2, 1e-6) if sel.any() else float(np.var(yi))
    sv2 = min_sv**2
    for _ in range(iters):
        sv2, cvar = system.stride_tie_variance(rep, sel, x, sn2, sv2, min_sv, lag_sd_frames)
        # scaled by sn2: (Qm + sn2 * prior) x = Qm y, whose hat matrix is (...)^-1 Qm
        try:
            x, edf = system.solve(y0, sn2, cvar)
        except np.linalg.LinAlgError:  # singular: leave the series as it is
            return y.copy(), {"noise_sd": float("nan"), "stride_sd": float("nan")}
        sn2 = system.noise_variance(y, x, ok, edf)
    return x, {"noise_sd": float(np.sqrt(sn2)), "stride_sd": float(np.sqrt(sv2))}


def _robust_fit(y, okj, pb, Q, sn2, rs2, robust_iters, outlier_k, w=None):
    """One joint's penalised least-squares fit (both coordinates) with IRLS outlier weights.

    ``y`` (F, 2) relative track, ``pb`` the coupling + smoothness precision in lower band storage
    (:func:`_prior_band`), ``Q`` the AR(1) noise precision, ``sn2`` (F,) noise variance, ``rs2``
    (F,) or None its relative per-detection factor, ``w`` starting outlier weights.  Returns the
    fit (F, 2) and the last weights."""
    from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

    y0 = np.where(okj[:, None], y, 0.0)
    w = okj.astype(float) if w is None else w
    var = sn2 if rs2 is None else sn2 * rs2
    # banded throughout: the prior (one stride wide) in band storage, the data term
    # tridiagonal (AR(1) noise precision); the same system as the sparse one, without its
    # per-call overhead
    qd, qo = Q.diagonal(), Q.diagonal(-1)
    for it in range(robust_iters + 1):
        # data term with the AR(1) noise precision (tridiagonal), missing frames left out
        sq = np.sqrt(w / var)
        ab = pb.copy()
        ab[0] += sq * sq * qd
        ab[1, :-1] += sq[1:] * sq[:-1] * qo
        sy = sq[:, None] * y0
        rhs = qd[:, None] * sy
        rhs[:-1] += qo[:, None] * sy[1:]
        rhs[1:] += qo[:, None] * sy[:-1]
        rhs *= sq[:, None]
        try:
            x = cho_solve_banded((cholesky_banded(ab, lower=True, check_finite=False), True), rhs,
                                 check_finite=False)  # both coordinates at once
        except LinAlgError:  # not numerically positive definite: the general solver
            from scipy import sparse

            W = sparse.diags(sq) @ Q @ sparse.diags(sq)
            x = _SPDSolver(W + _band_matrix(pb)).solve(W @ y0)
        if it == robust_iters:
            break
        # detector outliers and left/right swaps: redescending (Cauchy-type) weights on the
        # standardised residual, so one wild detection does not drag its neighbours
        r = np.linalg.norm(y - x, axis=-1) / np.sqrt(sn2)
        w = np.where(okj, 1.0 / (1.0 + (np.nan_to_num(r) / outlier_k) ** 4), 0.0)
    return x, w


def score_noise_scale(keypoints_px, fitted_px, noise_px, floor=0.1, outlier_cap=25.0, min_spread=0.02):
    """Per-detection noise scale from the detector's confidence, learned from the clip itself.

    A pose detector's confidence says something about how far a detection is off,
    but how much differs between detectors (and between joints of one detector).
    Each joint's scores are divided by that joint's median score, and the squared
    residuals of a first smoothing pass (``keypoints - fitted``, per coordinate,
    capped at ``outlier_cap`` times their median) are regressed on that relative
    score by isotonic regression (variance never rises with the score), pooled over
    joints.  A detector whose confidence carries no information gives a flat fit,
    i.e. (nearly) equal weights.

    Returns
    -------
    ndarray (F, J) or None
        Noise sd of every detection relative to ``noise_px`` (the smoother's data
        weight is divided by its square); None when the clip has no usable scores
        (missing, or all equal within ``min_spread``).

    >>> rng = np.random.default_rng(0)
    >>> F = 400; score = rng.uniform(0.5, 1.0, (F, 17))
    >>> sd = 1.0 + 8.0 * (1.0 - score)          # low score, large error
    >>> truth = np.zeros((F, 17, 2)); err = rng.normal(0, 1, (F, 17, 2)) * sd[..., None]
    >>> kp = np.concatenate([truth + err, score[..., None]], -1)
    >>> rel = score_noise_scale(kp, truth, noise_px=float(np.sqrt(np.mean(sd ** 2))))
    >>> bool(np.corrcoef(rel.ravel(), sd.ravel())[0, 1] > 0.9)
    True
    """
    from scipy.optimize import isotonic_regression

    kp = np.asarray(keypoints_px, float)
    if kp.shape[-1] < 3 or not np.isfinite(noise_px) or noise_px <= 0:
        return None
    s = kp[..., 2]
    r2 = np.sum((kp[..., :2] - np.asarray(fitted_px, float)[..., :2]) ** 2, -1) / 2
    ok = np.isfinite(r2) & np.isfinite(s) & (s > 0)
    if ok.sum() < 50:
        return None
    with np.errstate(invalid="ignore"):
        med = np.array([np.median(s[ok[:, j], j]) if ok[:, j].any() else np.nan for j in range(s.shape[1])])
        rs = s / med[None]
    ok &= np.isfinite(rs)
    x, y = rs[ok], r2[ok]
    if np.percentile(x, 90) - np.percentile(x, 10) < min_spread:
        return None
    y = np.minimum(y, outlier_cap * np.median(y))
    order = np.argsort(-x)  # falling score: variance may only rise
    v = np.empty_like(y)
    v[order] = isotonic_regression(y[order], increasing=True).x
    v = np.maximum(v, floor * np.mean(y))
    rel = np.ones(s.shape)
    rel[ok] = np.sqrt(v) / noise_px
    return rel


def periodic_smooth(keypoints_px, fps, noise_px=None, noise_rho=None, smooth_cutoff_hz=7.0,
                    lag_sd_frames=0.35, min_strides=MIN_STRIDES, robust_iters=3, outlier_k=10.0, fill_max_gap=10,
                    rel_sd=None, score_weights=True, ankle_cutoff_hz=10.0):
    """Cross-stride smoothing of keypoint tracks: running repeats itself, noise does not.

    A runner's stride repeats with small stride-to-stride changes, while
    detector noise is new in every frame.  Each joint's track relative to the
    trunk's per-frame common motion (camera shake included, :func:`_common_mode`)
    is estimated by penalised least squares::

        sum_t |x_t - y_t|^2 / s_n^2  +  sum_t |x_t - x(t + tau_t)|^2 / s_c,t^2  +  smoothness

    with ``tau_t`` the local stride period (frames; found by matching the
    whole-body pattern, it follows stride-time changes) and ``x(t + tau_t)``
    linearly interpolated.  ``s_n`` is the detection noise; the coupling
    variance ``s_c,t^2 = 2 s_v^2 + (v_t * lag_sd)^2`` holds the joint's own
    stride-to-stride variability ``s_v`` (estimated from the clip: repeat
    differences minus twice the noise) and the timing uncertainty, which
    matters where the joint moves fast (``v_t``: its speed), so fast phases
    are coupled loosely and the true stride-to-stride differences survive.
    The smoothness term is a second-difference penalty with its half-power
    point at ``smooth_cutoff_hz``.  Relative coordinates are divided by a
    slowly varying body scale so that zoom does not read as a change of
    posture.

    Parameters
    ----------
    keypoints_px : ndarray (F, J, 3)
        Gap-filled keypoints (NaN = missing; missing frames are filled by the
        prior and set back to NaN).
    fps : float
    noise_px, noise_rho : float, optional
        Detection noise (px) and its frame-to-frame correlation (AR(1)); estimated
        with :func:`noise_model` when not given.  The data term uses the AR(1)
        precision, so correlated noise is not mistaken for motion.

    robust_iters, outlier_k : int, float
        Iteratively reweighted fits: a detection whose residual exceeds about
        ``outlier_k`` noise standard deviations is down-weighted (weight
        ``1 / (1 + (r / k)^4)``), so detector outliers and left/right swaps need no
        separate rejection step (a running-median test would also cut the fast
        turns of the ankles at touchdown).
    fill_max_gap : int
        Missing runs up to this length are filled by the model (the same phase of
        the neighbouring strides, not a straight line); longer runs stay NaN.
    smooth_cutoff_hz : float or array (J,)
        Half-power point of the smoothness term (per joint if an array).
    ankle_cutoff_hz : float or None
        The ankles' own (None: ``smooth_cutoff_hz``).  The ankle is the fastest joint of
        a runner (its swing turns sharply at toe-off and touchdown); at 7 Hz the
        smoothness term flattened those turns.  10 Hz for the ankles took the knee-angle
        error with exact cameras from 3.47 to 3.17 deg on the benchmark suite, with
        MPJPE unchanged (2.77 -> 2.76 cm); 10 Hz for every joint, or for the wrists
        too, made MPJPE worse.
    rel_sd : ndarray (F, J), optional
        Noise sd of every detection relative to ``noise_px`` (given: used as is).
    score_weights : bool
        Without ``rel_sd``: fit once with equal weights, learn from the residuals
        how the detector's confidence relates to its error
        (:func:`score_noise_scale`) and fit again with those per-detection
        weights.  On the benchmark suite (confidence falls with the detection
        error, as for a real detector) this cut the keypoint error after
        smoothing from 5.38 to 4.88 px and the knee-angle error of the lifting
        with exact cameras from 3.92 to 3.49 deg when it was introduced (current
        numbers: ``reports/bench_lifting.md``).

    Returns
    -------
    ndarray (F, J, 3) or None
        None when the clip shows fewer than ``min_strides`` repeating strides
        (too short, or not running): the caller falls back to a plain low-pass.
        Joints detected in fewer than half the frames are NaN (not smoothed); the
        score channel is passed through.
    """
    kp = np.asarray(keypoints_px, float)
    F, nj = kp.shape[:2]
    if nj != 17 or F < 20:
        return None
    if noise_px is None or noise_rho is None:
        est_sd, est_rho = noise_model(kp)
        noise_px = est_sd if noise_px is None else noise_px
        noise_rho = est_rho if noise_rho is None else noise_rho
    noise = float(noise_px)
    rho = float(np.clip(noise_rho, 0.0, 0.9))
    if not np.isfinite(noise) or noise <= 0:
        return None
    xy = kp[..., :2]
    ok = np.all(np.isfinite(xy), -1)
    tracks = _relative_tracks(kp, fps, noise)
    if tracks is None:
        return None
    rel, ref, scale, rel_t = tracks
    lag = _lags_of(rel_t, fps, min_strides)
    if lag is None:
        return None
    sn = noise / scale  # noise sd per frame in relative units
    t = np.arange(F)
    rows = _tie_rows(lag)
    R, has = _coupling(lag, rows)
    Q = _ar1_precision(F, rho)
    sn2_all = sn**2
    cut = np.array(np.broadcast_to(np.asarray(smooth_cutoff_hz, float), (17,)))
    if ankle_cutoff_hz is not None:
        cut[[3, 6]] = ankle_cutoff_hz  # H36M r_ankle, l_ankle
    # smoothness relative to the mean data weight, one matrix per distinct cut-off
    P2s = {c: lower_band(_smoothness(F, fps, c).multiply(np.mean(1.0 / sn2_all))) for c in set(cut.tolist())}
    ties = _BandTerm(*rows[:2], F)  # every joint's stride ties: the same rows
    out = np.full_like(kp, np.nan)
    out[..., 2:] = kp[..., 2:]
    short_gap = np.zeros((F, 17), bool)
    for j in range(17):
        gap = ~ok[:, j]
        short_gap[:, j] = gap & np.isfinite(fill_gaps(np.where(gap, np.nan, 0.0), fill_max_gap))
    fits = {}
    # speed (relative units per frame) from a light low-pass, for the timing term: every joint's
    # low-pass in one pass
    lows = _lowpass_series(np.where(ok[..., None], rel, np.nan), fps, 8.0)
    for j in range(17):
        y = rel[:, j]
        okj = ok[:, j]
        if okj.sum() < F // 2:
            continue
        yl = lows[:, j]
        yl = np.column_stack([np.interp(t, t[okj], yl[okj, c]) for c in range(2)])
        vel = np.linalg.norm(np.gradient(yl, axis=0), axis=-1)
        # the joint's stride-to-stride variability from its repeat differences
        yi = np.column_stack([np.interp(t, t[okj], y[okj, c]) for c in range(2)])
        timing = (vel[has] * lag_sd_frames) ** 2 / 2  # per coordinate
        rep = R @ yi  # per coordinate: var = 2 s_v^2 + 2 s_n^2 + timing
        sel = okj[has]
        if sel.any():
            sv2 = float(np.mean(np.sum(rep[sel] ** 2, -1) / 2 - timing[sel] - 2 * sn2_all[has][sel])) / 2
        else:  # no stride pair with data: the tie across strides no tighter than the track's own spread
            sv2 = float(np.mean(np.var(yi, axis=0)))
        sv2 = max(sv2, 0.05 * float(np.median(sn2_all)))
        cvar = 2 * sv2 + timing
        prior = _prior_band(ties, cvar, P2s[float(cut[j])])
        rs2 = None if rel_sd is None else np.nan_to_num(np.asarray(rel_sd, float)[:, j], nan=1.0) ** 2
        x, w = _robust_fit(y, okj, prior, Q, sn2_all, rs2, robust_iters, outlier_k)
        fits[j] = (prior, w)
        out[:, j, :2] = x * scale[:, None] + ref
    if score_weights and rel_sd is None and fits:
        # second pass: the detector's confidence tells which detections are good
        rel2 = score_noise_scale(kp, out, noise)
        if rel2 is not None:
            for j, (prior, w) in fits.items():
                # outliers are already down-weighted: one refit and one update of those weights
                x, _ = _robust_fit(rel[:, j], ok[:, j], prior, Q, sn2_all, rel2[:, j] ** 2, min(robust_iters, 1),
                                   outlier_k, w=w)
                out[:, j, :2] = x * scale[:, None] + ref
    for j in fits:
        out[~(ok[:, j] | short_gap[:, j]), j] = np.nan
    return out
