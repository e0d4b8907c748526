"""Finding and measuring lane lines in one image.

A white-line response (morphological top-hat of the per-pixel minimum over B, G, R: white is
bright in every channel, the red track and the green infield are not) at reduced resolution,
``cv2.HoughLinesP`` segments, merging of collinear segments, and sub-pixel re-measurement of
every rough line at full resolution (background-subtracted luma centroids of short
perpendicular pixel runs), with a robust straight fit and its sagitta (bends are rejected).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from .mask import _near_capsules
from .types import _fit_line, _line_from_moments, _moments

__all__ = []


_TRIPLE_KERNEL = np.ones((1, 3), np.uint8)

def _white_response(gray_min, tophat_px):
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (tophat_px, tophat_px))
    return cv2.morphologyEx(gray_min, cv2.MORPH_TOPHAT, k)


@functools.lru_cache(maxsize=8)
def _vote_selection(shape, fraction):
    """A fixed pseudo-random 0/255 mask selecting ``fraction`` of the pixels (same every call)."""
    rng = np.random.default_rng(20231)
    return np.where(rng.random(shape) < fraction, 255, 0).astype(np.uint8)


def _segments(img_bgr, cfg):
    h, w = img_bgr.shape[:2]
    scale = min(1.0, cfg.work_width_px / w)
    small = cv2.resize(img_bgr, (int(round(w * scale)), int(round(h * scale))),
                       interpolation=cv2.INTER_AREA) if scale < 1 else img_bgr
    # minimum of B, G, R per pixel: an erosion across each interleaved (B, G, R) triple,
    # read at the G positions (one pass, no channel split)
    gmin = np.ascontiguousarray(
        cv2.erode(small.reshape(small.shape[0], -1), _TRIPLE_KERNEL, borderType=cv2.BORDER_REPLICATE)[:, 1::3])
    resp = _white_response(gmin, cfg.tophat_px)
    _, mask = cv2.threshold(resp, cfg.threshold, 255, cv2.THRESH_BINARY)
    # thin wide lines to their ridge (local maximum across rows or across columns): the
    # Hough transform's cost grows with the number of points, its result does not improve
    r = resp
    ridge = np.zeros(r.shape, bool)
    ridge[1:-1, :] = (r[1:-1] >= r[:-2]) & (r[1:-1] > r[2:])
    ridge[:, 1:-1] |= (r[:, 1:-1] >= r[:, :-2]) & (r[:, 1:-1] > r[:, 2:])
    mask = cv2.bitwise_and(mask, mask, mask=ridge.view(np.uint8))
    n_mask = int(np.count_nonzero(mask))
    frac = float(np.clip(cfg.hough_point_fraction, 0.0, 1.0))
    threshold = cfg.hough_threshold
    if frac < 1.0:
        mask = cv2.bitwise_and(mask, _vote_selection(mask.shape, frac))
        threshold = max(2, int(round(threshold * frac)))
    segs = cv2.HoughLinesP(mask, 1, np.radians(cfg.hough_theta_deg), threshold,
                           minLineLength=cfg.min_length_frac * small.shape[1], maxLineGap=cfg.max_gap_px)
    if segs is None:
        return np.zeros((0, 4)), n_mask
    segs = segs.reshape(-1, 4).astype(float) / scale
    if len(segs) > cfg.max_segments:
        keep = np.argsort(-np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]))[:cfg.max_segments]
        segs = segs[keep]
    return segs, n_mask


def _merge_segments(segs, cfg):
    """Greedy clustering of collinear segments; returns a list of endpoint arrays."""
    if len(segs) == 0:
        return []
    lengths = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    order = np.argsort(-lengths)
    clusters = []  # [line, endpoint arrays, moments]
    cos_tol = np.cos(np.radians(cfg.merge_angle_deg))
    for i in order:
        p = segs[i].reshape(2, 2)
        d = (p[1] - p[0]) / max(lengths[i], 1e-9)
        mom = _moments(p)
        placed = False
        for c in clusters:
            line = c[0]
            if abs(d[0] * line[1] - d[1] * line[0]) < cos_tol:  # |d . line direction|
                continue
            if max(abs(p[0] @ line[:2] + line[2]), abs(p[1] @ line[:2] + line[2])) < cfg.merge_dist_px:
                c[1].append(p)
                c[2] = c[2] + mom
                c[0] = _line_from_moments(*c[2])
                placed = True
                break
        if not placed:
            clusters.append([_line_from_moments(*mom), [p], mom])
    return [np.concatenate(c[1]) for c in clusters]


#: BGR weights of the luma (Rec. 601) in which lines are measured: JPEG and broadcast codecs keep
#: luma at full resolution, while the colour channels are subsampled and shifted (the minimum of
#: B, G, R, which finds white lines best, moves a measured centre by ~0.01 px after JPEG)
_LUMA_BGR = np.array([0.114, 0.587, 0.299], np.float32)

def _measure_lines(image_bgr, endpoint_sets, cfg, exclude=None):
    """Sub-pixel centre points along rough lines: luma centroids across the line on the pixel grid.

    Every ``profile_step_px`` along a rough line, the pixels of one image column (a line
    closer to horizontal) or row (closer to vertical) within ``profile_half_px`` of it
    are read without interpolation, and their background-subtracted centroid is the line
    centre there.  The discrete centroid of a blurred line is free of the sub-pixel
    "pixel locking" that interpolated, resampled profiles show (the ~0.5 px-periodic bias
    of a centroid over bilinear samples does not average out along lines whose slope
    barely changes, e.g. a camera square-on to the straight, and it tilts them); the
    centre of a straight band's cross-section in a column lies on its centre line, so the
    points need no correction.  Profiles that reach into the capsules ``exclude``
    (:func:`athlete_mask`) are dropped.  Returns one (N_i, 2) array (or None when too
    little is seen) per line.
    """
    h, w = image_bgr.shape[:2]
    # per line: reading direction, profile half-width and the columns (rows) it crosses;
    # lines alike in both are measured in one batch (one gather, one centroid pass)
    pixels = image_bgr.reshape(-1, 3)  # flat indexing: a 1-D gather is faster than a 2-D one
    plans, groups = [], {}
    crowded = _crowded(endpoint_sets, 2 * cfg.profile_half_px)
    for k, endpoints in enumerate(endpoint_sets):
        endpoints = np.asarray(endpoints, float)
        a, b, c = _fit_line(endpoints)
        horizontal = bool(abs(b) >= abs(a))  # normal mostly vertical: read columns
        ax, nrm = (0, b) if horizontal else (1, a)
        lo, hi = endpoints[:, ax].min(), endpoints[:, ax].max()
        major = np.arange(np.ceil(lo), hi, cfg.profile_step_px)
        if len(major) == 0:
            plans.append(None)
            continue
        # the predicted crossing of each column (row), and the pixels around it
        pred = -((a * major if horizontal else b * major) + c) / nrm
        half = int(np.ceil(cfg.profile_half_px / abs(nrm)))
        plans.append((major, np.round(pred).astype(np.int64)))
        groups.setdefault((horizontal, half), []).append(k)
    points, ok_all = [None] * len(plans), [None] * len(plans)
    for (horizontal, half), members in groups.items():
        major = np.concatenate([plans[k][0] for k in members])
        base = np.concatenate([plans[k][1] for k in members])
        offs = np.arange(-half, half + 1)
        minor = base[:, None] + offs[None, :]
        major_i = np.broadcast_to(major.astype(np.int64)[:, None], minor.shape)
        X, Y = (major_i, minor) if horizontal else (minor, major_i)
        inside = (X.min(1) >= 0) & (Y.min(1) >= 0) & (X.max(1) <= w - 1) & (Y.max(1) <= h - 1)
        flat_idx = (np.clip(Y, 0, h - 1) * w + np.clip(X, 0, w - 1)).ravel()
        prof = np.take(pixels, flat_idx, axis=0).reshape(minor.shape + (3,)) @ _LUMA_BGR
        counts = [len(plans[k][0]) for k in members]
        line_id = np.repeat(np.arange(len(members)), counts)
        off, ok = _profile_centroids(prof, offs.astype(float), cfg.threshold * 0.6, line_id, major,
                                     crowded=np.repeat(crowded[members], counts))
        ok &= inside
        ax = 0 if horizontal else 1
        pts = np.empty((len(major), 2))
        pts[:, ax] = major
        pts[:, 1 - ax] = base + off
        if exclude is not None:
            ok &= ~_near_capsules(pts, exclude, cfg.profile_half_px)
        splits = np.cumsum([len(plans[k][0]) for k in members])[:-1]
        for k, p_k, ok_k in zip(members, np.split(pts, splits), np.split(ok, splits)):
            points[k], ok_all[k] = p_k, ok_k
    return [None if plan is None or ok_all[k].sum() < 4 else points[k][ok_all[k]]
            for k, plan in enumerate(plans)]


def _crowded(endpoint_sets, reach_px, min_px=3.0, max_angle_deg=5.0):
    """Whether each rough line has a near-parallel neighbour closer than ``reach_px`` at its
    midpoint (one within ``min_px`` is a duplicate of it, not a neighbour): its profiles may
    hold another line.

    >>> seg = lambda y: np.array([[0.0, y], [500.0, y + 5.0]])
    >>> _crowded([seg(0), seg(9), seg(60), seg(61)], 20).tolist()
    [True, True, False, False]
    """
    n = len(endpoint_sets)
    if n < 2:
        return np.zeros(n, bool)
    lines = np.array([_fit_line(np.asarray(e, float)) for e in endpoint_sets])
    mids = np.array([np.asarray(e, float).mean(0) for e in endpoint_sets])
    dist = np.abs(mids @ lines[:, :2].T + lines[:, 2][None, :])  # (k, j): midpoint k to line j
    parallel = np.abs(lines[:, :2] @ lines[:, :2].T) > np.cos(np.radians(max_angle_deg))
    near = parallel & (dist > min_px) & (dist < reach_px)
    np.fill_diagonal(near, False)
    return near.any(1)


def _profile_centroids(prof, offs, min_contrast, line_id=None, along=None, crowded=None):
    """Background-subtracted centroids of bright lines in profiles (N, M) sampled at ``offs``.

    The background is taken per side of the peak (the two sides may differ: infield and
    track), from the outer two samples.  The centroid runs over the contiguous stretch
    around the peak above 15 % of its contrast (a neighbouring line must not pull it),
    widened by one sample on each side and kept unclipped there, so that cutting the
    blurred flanks at a threshold does not lock the centre to the pixel grid.

    Lines closer together than the profile is long (the far lanes of a low, grazing camera:
    8-10 px apart in a 21 px profile) put several peaks in one profile.  Peaks are the local
    maxima with a prominence (height above the higher of the lowest points between them and
    the neighbouring maxima) of at least a quarter of the profile's largest; the line
    measured is the peak nearest the rough line, not the brightest one (taking the brightest,
    neighbouring columns jumped between two lines and the fitted line came out between them).
    A rough line halfway between two lines still meets both: with ``line_id`` (N,) (which
    line each profile belongs to) the peaks are chosen again, nearest the median offset of
    that line's first choices, so that all its profiles take the same line; with ``along``
    (N,) (each profile's position along its line) twice more, nearest a straight line fitted
    to the choices (a rough line slightly tilted against the lines it crosses).
    Towards a neighbouring peak the stretch stops at the valley between them, and that side's
    background is the valley's level (the outer samples lie on the neighbour, or beyond it on
    another surface: the infield next to the innermost line).  A profile with one peak is
    measured as before, and so is every profile not marked ``crowded`` (N,) (a rough line
    without a near-parallel neighbour within two profile half-widths, :func:`_crowded`; all
    are when it is not given).

    Returns the offsets (N,) and whether each profile saw a line (contrast above
    ``min_contrast``, widened stretch inside the profile).

    >>> prof = np.array([[10, 10, 10, 60, 110, 60, 10, 10.0]])
    >>> off, ok = _profile_centroids(prof, np.arange(8.0) - 4, 20)
    >>> float(off[0]), bool(ok[0])
    (0.0, True)
    >>> # two lines 4 samples apart, the brighter one farther from the rough line (offset 0)
    >>> prof = np.array([[10, 10, 40, 90, 40, 10, 60, 140, 60, 10, 10.0]])
    >>> off, ok = _profile_centroids(prof, np.arange(11.0) - 4, 20)
    >>> float(off[0]), bool(ok[0])
    (-1.0, True)
    """
    n_side = 2
    N, M = prof.shape
    if crowded is not None:
        crowded = np.asarray(crowded, bool)
        if not crowded.all():
            # most profiles have no neighbouring line: their centroids take the short path, the
            # crowded ones (whole lines: their line_id and along go with them) the full one
            off, ok = _single_peak_centroids(prof, offs, min_contrast)
            if crowded.any():
                c = np.flatnonzero(crowded)
                off[c], ok[c] = _profile_centroids(prof[c], offs, min_contrast,
                                                   None if line_id is None else np.asarray(line_id)[c],
                                                   None if along is None else np.asarray(along)[c])
            return off, ok
    cols = np.arange(M)[None, :]
    # local maxima (the first sample of a flat top, as argmax takes it) and their prominence
    is_max = np.zeros(prof.shape, bool)
    is_max[:, 1:-1] = (prof[:, 1:-1] > prof[:, :-2]) & (prof[:, 1:-1] >= prof[:, 2:])
    # the brightest sample is the one peak unless another maximum reaches a quarter of its height
    # above the lower outer level, or it lies at the profile's end (most profiles have neither):
    # only the others need the prominences
    floor = np.minimum(prof[:, :n_side].mean(1), prof[:, -n_side:].mean(1))[:, None]
    bright = np.argmax(prof, axis=1)
    cand = cols == bright[:, None]
    n_strong = np.sum(is_max & (prof - floor >= 0.25 * (prof.max(1, keepdims=True) - floor)), 1)
    crowded = np.ones(N, bool) if crowded is None else np.asarray(crowded, bool)
    multi = np.flatnonzero(crowded & ((n_strong >= 2) | ((n_strong >= 1) & ~is_max[np.arange(N), bright])))
    if len(multi):
        pm, mm = prof[multi], is_max[multi]
        dip_l, dip_r = np.empty_like(pm), np.empty_like(pm)
        run_l, run_r = pm[:, 0].copy(), pm[:, -1].copy()
        for c in range(M):  # lowest point since the previous maximum, from either side
            dip_l[:, c] = run_l
            run_l = np.where(mm[:, c], pm[:, c], np.minimum(run_l, pm[:, c]))
            dip_r[:, M - 1 - c] = run_r
            run_r = np.where(mm[:, M - 1 - c], pm[:, M - 1 - c], np.minimum(run_r, pm[:, M - 1 - c]))
        prom = np.where(mm, pm - np.maximum(dip_l, dip_r), -np.inf)
        cand[multi] = mm & (prom >= 0.25 * prom.max(1, keepdims=True))
    am = np.where(cand, np.abs(offs)[None, :], np.inf).argmin(1)
    if line_id is not None and len(multi):
        # each line's majority: the median offset of its first choices, then the nearest peak to it
        line_id = np.asarray(line_id)
        target = np.zeros(N)
        lines = np.unique(line_id[multi])  # lines with a profile that has a choice
        for it in range(1 if along is None else 3):
            for k in lines:
                seen = (line_id == k) & cand.any(1)
                if not seen.any():
                    continue
                if it == 0 or seen.sum() < 3:
                    target[line_id == k] = np.median(offs[am[seen]])
                else:
                    coef = np.polyfit(along[seen], offs[am[seen]], 1)
                    target[line_id == k] = np.polyval(coef, along[line_id == k])
            am = np.where(cand, np.abs(offs[None, :] - target[:, None]), np.inf).argmin(1)
    am = np.where(cand.any(1), am, np.argmax(prof, axis=1))[:, None]
    # the nearest other peak on each side, and the valley between it and the chosen one
    nb_l = np.where(cand & (cols < am), cols, -1).max(1)[:, None]
    nb_r = np.where(cand & (cols > am), cols, M).min(1)[:, None]
    val_l = np.where((cols > nb_l) & (cols < am), prof, np.inf).argmin(1)[:, None]
    val_r = np.where((cols > am) & (cols < nb_r), prof, np.inf).argmin(1)[:, None]
    outer_l, outer_r = prof[:, :n_side].mean(1)[:, None], prof[:, -n_side:].mean(1)[:, None]
    low_l, low_r = np.take_along_axis(prof, val_l, 1), np.take_along_axis(prof, val_r, 1)
    top = np.take_along_axis(prof, am, 1)
    # a neighbour also where the profile rises again towards its end (a line cut by the
    # profile's end: its outer samples are no background), provided the valley before it is
    # down at the other side's background level
    cr = crowded[:, None]
    has_l = (nb_l >= 0) | (cr & (outer_l - low_l >= 0.25 * (top - low_l))
                           & (low_l - np.minimum(outer_r, low_r) <= 0.15 * (top - low_l)))
    has_r = (nb_r < M) | (cr & (outer_r - low_r >= 0.25 * (top - low_r))
                          & (low_r - np.minimum(outer_l, low_l) <= 0.15 * (top - low_r)))
    left_bg = np.where(has_l, low_l, outer_l)
    right_bg = np.where(has_r, low_r, outer_r)
    return _stretch_centroids(prof, offs, min_contrast, am, top, left_bg, right_bg, (has_l, has_r, val_l, val_r))


def _stretch_centroids(prof, offs, min_contrast, am, top, left_bg, right_bg, valleys=None):
    """The last step of :func:`_profile_centroids`: the centroid over the stretch around the chosen
    peak ``am`` (N, 1) at level ``top`` (N, 1) above the backgrounds ``left_bg`` and ``right_bg``
    (N, 1), and whether it saw a line.  ``valleys`` ``(has_l, has_r, val_l, val_r)`` stop the
    stretch at the valley towards a neighbouring line (where ``has_*``)."""
    M = prof.shape[1]
    cols = np.arange(M)[None, :]
    base = np.where(cols < am, left_bg, right_bg)
    peak = (top - np.minimum(left_bg, right_bg))[:, 0]
    # weights ~ line coverage on both sides: normalise by the contrast on each side
    wts = (prof - base) / np.maximum(top - base, 1e-6) * peak[:, None]
    low = wts <= 0.15 * peak[:, None]
    left = np.where(low & (cols < am), cols, -1).max(1) - 1
    right = np.where(low & (cols > am), cols, M).min(1) + 1
    if valleys is not None:
        has_l, has_r, val_l, val_r = valleys
        left = np.where(has_l[:, 0], np.maximum(left, val_l[:, 0] - 1), left)
        right = np.where(has_r[:, 0], np.minimum(right, val_r[:, 0] + 1), right)
    wts = np.where((cols > left[:, None]) & (cols < right[:, None]), wts, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        off = (wts * offs).sum(1) / wts.sum(1)
    ok = (peak > min_contrast) & (left >= 0) & (right <= M - 1) & np.isfinite(off)
    return off, ok


def _single_peak_centroids(prof, offs, min_contrast, n_side=2):
    """:func:`_profile_centroids` of profiles (N, M) none of which is ``crowded``: the brightest
    sample is the peak, each side's background its outer ``n_side`` samples.  The same numbers, to
    the bit, as the full function gives those rows (the same operations on them, without the
    neighbours' search that a profile with one line never uses).

    >>> prof = np.array([[10, 10, 10, 60, 110, 60, 10, 10.0], [10, 10, 60, 110, 60, 10, 10, 10.0]])
    >>> offs = np.arange(8.0) - 4
    >>> [a.tolist() for a in _single_peak_centroids(prof, offs, 20)]
    [[0.0, -1.0], [True, True]]
    >>> all(np.array_equal(a, b) for a, b in zip(_single_peak_centroids(prof, offs, 20),
    ...                                          _profile_centroids(prof, offs, 20)))
    True
    """
    am = np.argmax(prof, axis=1)[:, None]
    outer_l, outer_r = prof[:, :n_side].mean(1)[:, None], prof[:, -n_side:].mean(1)[:, None]
    return _stretch_centroids(prof, offs, min_contrast, am, np.take_along_axis(prof, am, 1), outer_l, outer_r)


def _median(x):
    """Median of a 1-D array (``np.partition``; avoids ``np.median``'s overhead on small arrays)."""
    n = len(x)
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return 0.5 * float(part[k - 1] + part[k])


def _robust_fit(points, iters=3, min_scale_px=0.1, degree=3):
    """Line fit that drops points beyond 3.5 robust sd (MAD, at least ``min_scale_px``) of a
    smooth curve through them.

    A clean line's centres scatter by ~0.05 px; where the athlete's legs or shadow
    cross it they move by 0.2-1 px, which a coarser floor would keep.  The outliers are
    judged against a polynomial of ``degree`` in the position along the line when the line is
    bent (the polynomial's residuals scatter less than half as much as the straight line's),
    else against the straight line: a lane line bent by the lens deviates from its chord by
    several px at the ends of a wide view, and judged against a straight line those ends
    were dropped, which straightened the support and hid the lens from the plumb-line
    evidence (k1 came out ~5 % low on a 35 deg, k1 = +0.2 view).  Returns the straight
    total-least-squares line of the kept points and the mask.
    """
    line = _fit_line(points)
    keep = np.ones(len(points), bool)
    n = line[:2]
    t = points @ np.array([-n[1], n[0]])
    t = (t - t.mean()) / max(np.ptp(t) / 2, 1e-9)
    V = np.vander(t, degree + 1) if len(points) > 2 * (degree + 1) else None
    if V is not None:
        # the curve only where the line is bent: its residuals must scatter less than half as
        # much as the straight line's (a straight line is judged against itself, as before)
        r = points @ line[:2] + line[2]
        rc = r - V @ np.linalg.lstsq(V, r, rcond=None)[0]
        if not 1.4826 * _median(np.abs(rc)) < 0.5 * max(1.4826 * _median(np.abs(r)), min_scale_px):
            V = None
    for _ in range(iters):
        r = points @ line[:2] + line[2]
        if V is not None:
            coef = np.linalg.lstsq(V[keep], r[keep], rcond=None)[0]
            r = r - V @ coef
        r = np.abs(r)
        s = max(1.4826 * _median(r[keep]), min_scale_px)
        new_keep = r < 3.5 * s
        if np.array_equal(new_keep, keep):
            break  # the same points again: the same line
        keep = new_keep
        if keep.sum() < 4:
            break
        line = _fit_line(points[keep])
    return line, keep


def _sagitta(points, line, with_residual=False):
    """Largest deviation of a quadratic fit from the straight line (px): curvature measure.

    With ``with_residual`` also the RMS residual (px) of the quadratic fit: a
    clean curve (a bend's arc) has a small one, clutter a large one.
    """
    n = line[:2]
    d = np.array([-n[1], n[0]])
    t = points @ d
    r = points @ n + line[2]
    if np.ptp(t) < 1e-6:
        return (0.0, 0.0) if with_residual else 0.0
    tt = (t - t.mean()) / (np.ptp(t) / 2)
    V = np.column_stack([tt * tt, tt, np.ones_like(tt)])
    coef = np.linalg.solve(V.T @ V, V.T @ r)  # quadratic least squares (well conditioned: tt in [-1, 1])
    if with_residual:
        return abs(coef[0]), float(np.sqrt(np.mean((V @ coef - r) ** 2)))
    return abs(coef[0])  # quadratic term at the ends of the support


def _ridge_widths(image_bgr, point_sets, max_profiles=24, half_px=6):
    """RMS width (px, across the line) of each measured line's bright ridge: the median over up to
    ``max_profiles`` of its support points of the luma profile's second moment about its centroid.

    Each profile (an image column for a line closer to horizontal, a row otherwise, ``half_px``
    either side of the point) is read from its brightest sample within a pixel of the point
    outwards, while above 15 % of the peak's contrast over that side's own background (its outer
    two samples: a line on the infield's edge has a darker surface on one side), and not up a
    neighbouring line the profile resolves (once it has dipped below half the contrast).  One
    painted line is as wide as its paint and the blur (at most 0.8 px on probreg's renders of far
    lines, 1.2-2.7 px on the seed paper's frames); two lines the blur has merged into one ridge
    are as wide as about half their distance (1.2-2.0 px where probreg's renders merge them).
    All lines' profiles are read and walked in one batch.  NaN for a line without a readable
    profile.

    >>> img = np.full((40, 60, 3), 60, np.uint8)
    >>> img[10, :] = 220                                   # one thin line
    >>> for r, v in zip(range(23, 30), (120, 180, 215, 220, 215, 180, 120)):
    ...     img[r, :] = v                                  # two lines blurred into one ridge
    >>> w = _ridge_widths(img, [np.column_stack([np.arange(5.0, 55), np.full(50, 10.0)]),
    ...                         np.column_stack([np.arange(5.0, 55), np.full(50, 26.0)])])
    >>> [round(float(v), 2) for v in w]
    [0.0, 1.68]
    """
    h, w = image_bgr.shape[:2]
    offs = np.arange(-half_px, half_px + 1)
    flat, owner = [], []
    for k, pts in enumerate(point_sets):
        pts = np.asarray(pts, float)
        pts = pts[np.all(np.isfinite(pts), 1)]
        if len(pts) < 2:
            continue
        pts = pts[np.linspace(0, len(pts) - 1, min(max_profiles, len(pts))).round().astype(int)]
        a, b, _ = _fit_line(pts)
        ax = 0 if abs(b) >= abs(a) else 1  # read columns (x fixed) for a line closer to horizontal
        major = np.round(pts[:, ax]).astype(np.int64)
        minor = np.round(pts[:, 1 - ax]).astype(np.int64)[:, None] + offs[None, :]
        ok = (major >= 0) & (major <= (w if ax == 0 else h) - 1) & (minor[:, 0] >= 0) & \
             (minor[:, -1] <= (h if ax == 0 else w) - 1)
        major, minor = major[ok, None], minor[ok]
        flat.append((minor * w + major) if ax == 0 else (major * w + minor))
        owner.append(np.full(len(minor), k))
    out = np.full(len(point_sets), np.nan)
    if not flat or not sum(len(f) for f in flat):
        return out
    idx, owner = np.concatenate(flat), np.concatenate(owner)
    prof = np.take(image_bgr.reshape(-1, 3), idx.ravel(), axis=0).reshape(idx.shape + (3,)) @ _LUMA_BGR
    n, m = prof.shape
    rows, cols = np.arange(n), np.arange(m)[None, :]
    mid = half_px + np.argmax(prof[:, half_px - 1:half_px + 2], 1) - 1
    top = prof[rows, mid]
    sides = (prof[:, :2].mean(1), prof[:, -2:].mean(1))
    base = np.where(cols < mid[:, None], sides[0][:, None], sides[1][:, None])
    inside = cols == mid[:, None]
    for step, b in zip((-1, 1), sides):  # outwards from the peak
        level, half = b + 0.15 * (top - b), b + 0.5 * (top - b)
        cur, alive, low = mid.copy(), np.ones(n, bool), top.copy()
        for _ in range(half_px):
            nxt = np.clip(cur + step, 0, m - 1)
            nv = prof[rows, nxt]
            alive &= (nxt != cur) & (nv > level) & ((nv <= prof[rows, cur]) | (low > half))
            inside[rows[alive], nxt[alive]] = True
            low = np.where(alive, np.minimum(low, nv), low)
            cur = np.where(alive, nxt, cur)
    wts = np.where(inside, np.maximum(prof - base, 0.0), 0.0)
    tot = wts.sum(1)
    good = (top > sides[0]) & (top > sides[1]) & (tot > 0)
    tot = np.where(good, tot, 1.0)
    c = (wts * offs).sum(1) / tot
    rms = np.sqrt((wts * (offs[None, :] - c[:, None]) ** 2).sum(1) / tot)
    for k in np.unique(owner[good]):
        out[k] = float(np.median(rms[good & (owner == k)]))
    return out
