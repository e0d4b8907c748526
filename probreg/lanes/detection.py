"""Lane detection in one frame: rough lines, the shared vanishing point, the ordered pencil.

An exhaustive pair search finds the vanishing point that most long lines share (robust to
the athlete, kerbs and stray marks); pieces of one bent line are joined, and a missing line
in the middle is found from the projective spacing fit when at least four lines are seen.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from ..geometry import cross3
from .measure import (
    _measure_lines,
    _median,
    _merge_segments,
    _ridge_widths,
    _robust_fit,
    _sagitta,
    _segments,
)
from .types import (
    FrameLanes,
    LaneDetectorConfig,
    LaneLine,
    _fit_line,
    _from_unit,
    _to_unit,
)
from .undistort import _undistort_px
from .vanishing import (
    _pencil_coordinate,
    _refine_vp,
    _spacing_residual_px,
    assign_line_indices,
    lines_through_point,
)

__all__ = ["detect_lanes", "merged_lines_note"]


# --------------------------------------------------------------------------- main entry
def detect_lanes(image_bgr, config: LaneDetectorConfig = LaneDetectorConfig(), frame=None,
                 dist=None, focal_px=None, exclude=None):
    """Detect the lane lines of the straight and their vanishing point in one frame.

    Parameters
    ----------
    image_bgr : ndarray, shape (H, W, 3), uint8, or None
    config : LaneDetectorConfig
    frame : int, optional
        Frame index stored in the result.
    dist : array_like (5,), optional
        Known or hypothesised lens distortion; with ``focal_px`` the support points are
        undistorted before the lines and the vanishing point are fitted.
    focal_px : float, optional
    exclude : ndarray (S, 5), optional
        Image regions whose line evidence is ignored, as capsules (:func:`athlete_mask`).

    Returns
    -------
    FrameLanes
        Never raises for bad image content; see :data:`STATUSES`.
    """
    if image_bgr is None or not hasattr(image_bgr, "shape") or image_bgr.ndim != 3 or image_bgr.size == 0:
        return FrameLanes(status="bad_image", frame=frame)
    fl = _detect(image_bgr, config, frame, dist, focal_px, exclude)
    if fl.ok or not config.low_contrast_threshold:
        return fl
    low = low_contrast_threshold(image_bgr, config)
    if low >= config.threshold:
        return fl
    faint = _detect(image_bgr, replace(config, threshold=low), frame, dist, focal_px, exclude)
    if not faint.ok:
        return fl
    return replace(faint, extra={**faint.extra, "low_contrast_threshold": low})


def merged_lines_note(frame_lanes):
    """The input note about frames whose far lane lines merged into one ridge, left out
    (:func:`_merged_ends`), or None.

    >>> merged_lines_note([FrameLanes(status="ok", frame=6, extra={"merged_lines": 1}), FrameLanes(status="no_lines")])
    'the far lane lines merge into one ridge in 1 frame(s) (first: frame 6): that ridge is left out, the nearer lines used'
    """
    merged = [fl.frame for fl in frame_lanes if fl.extra.get("merged_lines")]
    return (f"the far lane lines merge into one ridge in {len(merged)} frame(s) (first: frame {merged[0]}): that ridge "
            "is left out, the nearer lines used") if merged else None


def low_contrast_threshold(image_bgr, config: LaneDetectorConfig = LaneDetectorConfig()):
    """Threshold of the white-line response for faint lines: ``low_contrast_snr`` times the
    response's noise sd (from the median absolute difference of neighbouring pixels of the
    per-pixel channel minimum at working resolution), at least ``low_contrast_threshold``.

    >>> rng = np.random.default_rng(0)
    >>> quiet = np.clip(rng.normal(100, 2.0, (200, 400, 3)), 0, 255).astype(np.uint8)
    >>> noisy = np.clip(rng.normal(100, 6.0, (200, 400, 3)), 0, 255).astype(np.uint8)
    >>> low_contrast_threshold(quiet), low_contrast_threshold(noisy) > 20
    (12, True)
    """
    h, w = image_bgr.shape[:2]
    scale = min(1.0, config.work_width_px / w)
    small = cv2.resize(image_bgr, (int(round(w * scale)), int(round(h * scale))),
                       interpolation=cv2.INTER_AREA) if scale < 1 else image_bgr
    g = small.min(axis=2).astype(np.float32)
    d = np.abs(np.diff(g, axis=1)).ravel()
    sd = 1.4826 * float(np.median(d)) / np.sqrt(2.0)
    return int(max(config.low_contrast_threshold, np.ceil(config.low_contrast_snr * sd)))


def _detect(image_bgr, config, frame, dist, focal_px, exclude):
    h, w = image_bgr.shape[:2]
    size = (w, h)
    segs, n_mask = _segments(image_bgr, config)
    if len(segs) == 0:
        return FrameLanes(status="no_lines", image_size=size, frame=frame, extra={"mask_px": n_mask})
    candidates, (n_curved, curved_len) = _measure_candidates(image_bgr, _merge_segments(segs, config), config,
                                                         exclude=exclude)
    # merge candidates that turned out to be the same line after re-measurement
    candidates = _dedupe(candidates, config)
    fl = FrameLanes(status="no_lines", image_size=size, frame=frame, n_curved=n_curved,
                    extra={"curved_length_px": curved_len})
    if len(candidates) < 2:
        return replace(fl, status="no_straight" if n_curved >= 2 else
                       ("too_few_lines" if candidates or n_curved else "no_lines"))
    if dist is not None and focal_px is not None and np.any(dist):
        candidates = [(_fit_line(p), p, L) for _, p, L in
                      ((c[0], _undistort_px(c[1], dist, focal_px, size), c[2]) for c in candidates)]
        fl = replace(fl, undistorted=True)
        image_bgr = None  # the support points are no longer where the image shows them
    return _pencil_from_candidates(candidates, fl, config, image_bgr)


def _measure_candidates(image_bgr, endpoint_sets, config, distinct=False, exclude=None):
    """Sub-pixel measurement of rough lines (longest first); curved ones are counted, not kept.

    All lines are measured in one batch.  With ``distinct=False`` a cluster lying on an
    already measured line is dropped as a duplicate; ``distinct=True`` (lines known to be
    different, e.g. followed from the previous frame) keeps every one.  Returns the
    candidates ``(line, points, length)`` and ``(number, total length)`` of curved ones.
    """
    candidates, measured = [], []
    n_curved, curved_length = 0, 0.0
    order = sorted(endpoint_sets, key=lambda e: -np.ptp(e, axis=0).max())
    # all profiles in one batch (one remap); duplicates are rare and dropped afterwards
    batch = _measure_lines(image_bgr, order, config, exclude)
    for k, ep in enumerate(order):
        # a cluster lying on an already measured line is a duplicate
        if not distinct and any(np.max(np.abs(ep @ m[:2] + m[2])) < 3.0 for m in measured):
            continue
        pts = batch[k]
        if pts is None or len(pts) < 6:
            continue
        line, keep = _robust_fit(pts)
        pts = pts[keep]
        if len(pts) < 6:
            continue
        length = np.ptp(pts @ np.array([-line[1], line[0]]))
        sag, quad_rms = _sagitta(pts, line, with_residual=True)
        # a bend's arc curves far more than lens distortion bends a lane line
        # (curvature ~ 8 sagitta / length^2: bends >= 4e-5 / px, distorted straight lines <= 2e-5)
        if sag > config.curved_sagitta_px and 8 * sag / length**2 > config.curved_curvature_per_px:
            if quad_rms < 0.35 and length > 150:  # a clean arc is bend evidence; clutter is not
                n_curved += 1
                curved_length += length
            continue
        candidates.append((line, pts, length))
        measured.append(line)
    return candidates, (n_curved, curved_length)


def _image_chord(line, image_size):
    """The two points where a line leaves the image rectangle, shape (2, 2) (None if outside)."""
    w, h = image_size
    a, b, c = line
    pts = []
    if abs(b) > 1e-12:
        for x in (0.0, w - 1.0):
            y = -(a * x + c) / b
            if 0 <= y <= h - 1:
                pts.append((x, y))
    if abs(a) > 1e-12:
        for y in (0.0, h - 1.0):
            x = -(b * y + c) / a
            if 0 <= x <= w - 1:
                pts.append((x, y))
    if len(pts) < 2:
        return None
    pts = np.array(pts)
    d = np.array([-b, a])
    t = pts @ d
    return pts[[np.argmin(t), np.argmax(t)]]


def _dedupe(cands, cfg):
    out = []
    cos_tol = np.cos(np.radians(cfg.merge_angle_deg))
    reach = 2.0 + np.sin(np.radians(cfg.merge_angle_deg)) * 4000.0  # bound for a near-parallel duplicate
    for line, pts, L in sorted(cands, key=lambda c: -c[2]):
        mid = pts[len(pts) // 2]
        for k, (l2, p2, L2) in enumerate(out):
            if abs(line[:2] @ l2[:2]) > cos_tol and abs(mid @ l2[:2] + l2[2]) < reach and \
                    _median(np.abs(pts @ l2[:2] + l2[2])) < 2.0:
                allp = np.concatenate([p2, pts])
                out[k] = (_fit_line(allp), allp, L2 + L)
                break
        else:
            out.append((line, pts, L))
    return out


def _drop_mixed(cands, frac, reach=20.0):
    """The candidates without the lines that mix neighbours: a candidate whose support scatters
    (RMS about a quadratic along it: a line bent by the lens is smooth) by more than ``frac`` of
    the distance from its midpoint to the nearest other candidate line took its points from
    several lines.  Where lines crowd together (a low grazing camera's far lanes, 8-10 px
    apart) a rough line can cross them and its profiles pick a different line in each stretch:
    the fit lies between them with a scatter of a few px, which a clean line (~0.1-0.5 px)
    never has; its index and position would corrupt the lane spacing that the calibration
    rests on.  Only lines closer than ``reach`` px to another one are judged (those whose
    profiles can hold a neighbour).

    >>> line = lambda y: np.array([0.0, 1.0, -y])
    >>> xs = np.arange(0.0, 100.0, 5.0)
    >>> clean = [(line(y), np.column_stack([xs, y + 0.1 * np.sin(xs)]), 100.0) for y in (10.0, 20.0, 30.0)]
    >>> mixed = (line(25.0), np.column_stack([xs, np.where(xs < 50, 20.0, 30.0)]), 100.0)
    >>> [float(c[0][2]) for c in _drop_mixed(clean + [mixed], 0.1)]
    [-10.0, -20.0, -30.0]
    """
    if len(cands) < 2 or not frac:
        return cands
    lines = np.array([c[0] for c in cands])
    keep = []
    for k, (line, pts, _) in enumerate(cands):
        mid = pts.mean(0)
        others = np.delete(lines, k, axis=0)
        gap = float(np.min(np.abs(others[:, :2] @ mid + others[:, 2])))
        # the scatter only where a neighbour is near enough to be mixed in
        keep.append(gap >= reach or _sagitta(pts, line, with_residual=True)[1] <= frac * gap)
    return [c for c, ok in zip(cands, keep) if ok]


def _pencil_from_candidates(cands, fl, cfg, image=None):
    """The frame's ordered pencil of lane lines from its measured candidates (``FrameLanes``).
    With ``image`` (the frame the candidates were measured in), lines at either end of the
    pencil that are two lines merged into one ridge are left out (:func:`_merged_ends`)."""
    cands = _drop_mixed(cands, cfg.max_rms_gap_frac, 2 * cfg.profile_half_px)
    if len(cands) < 2:
        return replace(fl, status="too_few_lines")
    size = fl.image_size
    mids = np.array([p.mean(0) for _, p, _ in cands])
    lines = np.array([c[0] for c in cands])
    lengths = np.array([L for _, _, L in cands])
    n = len(cands)
    ii, jj = np.triu_indices(n, 1)
    vps = cross3(lines[ii], lines[jj])  # (P, 3) candidate vanishing points
    # angle between every line and the direction from its midpoint to every candidate
    dirs = np.stack([-lines[:, 1], lines[:, 0]], -1)  # (n, 2)
    to_vp = vps[:, None, :2] - mids[None] * vps[:, None, 2:3]  # (P, n, 2)
    nrm = np.linalg.norm(to_vp, axis=-1)
    cosang = np.abs(np.sum(to_vp * dirs[None], -1)) / np.maximum(nrm, 1e-300)
    inlier = (cosang > np.cos(np.radians(cfg.vp_inlier_deg))) | (nrm < 1e-9)
    count = inlier.sum(1)
    score = inlier @ lengths + count  # the longest support (many short pieces of clutter or of a bend lose)
    if len(score) == 0:
        return replace(fl, status="too_few_lines")
    p = int(np.argmax(score))
    best = (vps[p], list(np.flatnonzero(inlier[p])))
    if len(best[1]) < cfg.min_lines:
        status = "no_straight" if fl.n_curved >= 2 and len(best[1]) < 2 else "too_few_lines"
        return replace(fl, status=status)
    vp, inl = best
    if fl.extra.get("curved_length_px", 0.0) > lengths[inl].sum():
        # more curved line evidence than straight: a bend, whose short chords can mimic a pencil
        return replace(fl, status="no_straight")
    sets = [cands[k][1] for k in inl]
    v_unit, cov, sigma = _refine_vp(sets, _to_unit(vp, size), size)
    lines_px, res = lines_through_point(sets, v_unit, size)
    coord = _pencil_coordinate(lines_px, v_unit, size)
    joined = _join_pieces(sets, lines_px, coord)
    if len(joined) < len(sets):
        sets = joined
        if len(sets) < cfg.min_lines:
            return replace(fl, status="too_few_lines")
        v_unit, cov, sigma = _refine_vp(sets, v_unit, size)
        lines_px, res = lines_through_point(sets, v_unit, size)
        coord = _pencil_coordinate(lines_px, v_unit, size)
    order = np.argsort(coord)
    # canonical direction (the sign of the homogeneous vanishing point is arbitrary, so the
    # angular order may run either way): the first line is the one nearer the image top
    # (or, for near-vertical lines, the left edge) where it passes the image centre
    c0 = np.array([(size[0] - 1) / 2, (size[1] - 1) / 2, 1.0])
    nrm = lines_px[:, :2].mean(0)
    nrm = nrm * (1 if (abs(nrm[1]) >= abs(nrm[0]) and nrm[1] > 0) or
                 (abs(nrm[1]) < abs(nrm[0]) and nrm[0] > 0) else -1)
    offs = -(lines_px @ c0) * np.sign(lines_px[:, :2] @ nrm)  # signed position along nrm
    if offs[order[-1]] < offs[order[0]]:
        order = order[::-1]
    if not (np.all(np.isfinite(coord)) and np.all(np.isfinite(v_unit))):
        # a degenerate pencil (lines merging into one, e.g. a grazing view): no lane geometry
        return replace(fl, status="too_few_lines", extra={**fl.extra, "degenerate_pencil": True})

    def without(drop):
        # the pencil again without the lines at positions ``drop`` of ``order``: the vanishing
        # point, the lines through it, their order and indices
        keep = np.delete(order, drop)  # the other lines, in their order
        kept = [sets[k] for k in np.sort(keep)]
        v, cv, sg = _refine_vp(kept, v_unit, size)
        lp, rs = lines_through_point(kept, v, size)
        co = _pencil_coordinate(lp, v, size)
        od = np.searchsorted(np.sort(keep), keep)  # the same order, in the new sets' numbering
        return (kept, v, cv, sg, lp, rs, co, od, *assign_line_indices(co[od], cfg.max_missing_lines))

    idx, spacing = assign_line_indices(coord[order], cfg.max_missing_lines)
    merged = _merged_ends([sets[o] for o in order], image) if image is not None else []
    if merged:
        # the farthest lines blurred into one ridge between them (a low grazing camera): left
        # out, the nearer lines carry the pencil, and the frame says so
        fl = replace(fl, extra={**fl.extra, "merged_lines": len(merged)})
        if len(order) - len(merged) < cfg.min_lines:
            return replace(fl, status="too_few_lines")
        sets, v_unit, cov, sigma, lines_px, res, coord, order, idx, spacing = without(merged)
    while (drop := _off_comb(coord[order], idx, spacing, cfg.max_missing_lines)) is not None:
        # a line off the lanes' equally spaced comb (the infield's edge, a far kerb) shifted
        # every index; without it, the vanishing point and the lines again
        sets, v_unit, cov, sigma, lines_px, res, coord, order, idx, spacing = without(drop)
    lanes = tuple(LaneLine(line=lines_px[o], points_px=sets[o], rms_px=float(np.sqrt(np.mean(res[o] ** 2))),
                           index=int(k)) for o, k in zip(order, idx))
    spacing_px = (_spacing_residual_px(lanes, coord[order], idx, v_unit, size) if len(lanes) >= 4
                  else float("nan"))
    return replace(fl, status="ok", lines=lanes, vanishing_point=_from_unit(v_unit, size), vp_cov=cov,
                   spacing_residual_px=spacing_px, extra={"vp_unit": v_unit, "vp_sigma_px": sigma,
                                                        **({"merged_lines": len(merged)} if merged else {})})


#: comb misfit (RMS, in units of the mean step per index) above which :func:`_off_comb` looks
#: for a line to drop: twice the largest misfit of a clean frame on the tuning clips (0.1-2.3 %
#: over grazing, stand, steep and lens views); a merged pair of far lines gives 3-9 %
COMB_MISFIT_FRAC = 0.05


#: a line at an end of the pencil whose ridge is this many times as wide as its neighbour's is two
#: lines merged into one (:func:`_merged_ends`)
MERGED_WIDTH_RATIO = 2.5
#: ... and at least this wide (RMS, px): narrower ridges are the blur's, whatever their ratio
MERGED_MIN_WIDTH_PX = 1.0
#: ... and nearer its neighbour than this (px): two lines the blur merges are a few px apart, and where
#: lines crowd that much the next one found is within a few steps (lines between may be missed)
MERGED_MAX_GAP_PX = 40.0


def _merged_ends(sets, image, ratio=MERGED_WIDTH_RATIO, min_px=MERGED_MIN_WIDTH_PX):
    """Positions (in ``sets``' order across the track) of lines at either end of the pencil that
    are two lines blurred into one ridge, to be left out.

    Where a low grazing camera sees the far lanes 5-6 px apart, the blur can merge the two
    farthest lines into one clean ridge between them: a line 1-2 px off the nearer of them, which
    the comb of equally spaced lines absorbs when it fits within a few per cent (:func:`_off_comb`),
    and which then moves the frame's family (on a held-out grazing clip in a race, a third of the
    frames had one: the camera came out 3.8 times too high).  Its width gives it away: one
    painted line is as wide as its paint and the blur, and the paint of a farther line is never
    wider than that of a nearer one; two merged lines are as wide as about half their distance.
    The line at an end whose ridge (:func:`probreg.lanes.measure._ridge_widths`) is ``ratio``
    times as wide as its neighbour's and at least ``min_px`` wide is left out, and the new end
    judged again while three lines are left to judge; only ends within :data:`MERGED_MAX_GAP_PX`
    of their neighbour are judged (widths are read only then).  On probreg's grazing renders
    single lines measured 0.8 px at most (median 0.6) and merged pairs 1.2-2.0 px; neighbouring
    lines of steep, wide, stand and long-lens views were within a factor 1.31 of each other, and
    on the seed paper's frames (1.2-2.7 px) no end line was 1.45 times as wide as its neighbour.

    >>> img = np.full((60, 80, 3), 60, np.uint8)
    >>> for y in (10, 20, 31, 43):
    ...     img[y] = 220                                    # four single lines
    >>> for r, v in zip(range(49, 56), (120, 180, 215, 220, 215, 180, 120)):
    ...     img[r] = v                                      # and two merged into one ridge
    >>> line = lambda y: np.column_stack([np.arange(5.0, 75), np.full(70, float(y))])
    >>> _merged_ends([line(y) for y in (10, 20, 31, 43, 52)], img)
    [4]
    >>> _merged_ends([line(y) for y in (10, 20, 31, 43)], img)
    []
    """
    keep, out, widths = list(range(len(sets))), [], {}
    while len(keep) >= 3:
        # only a line near its neighbour can be a merged pair the profile holds (a pair the blur
        # merges is a few px apart, its neighbour within a few of its widths)
        ends = [(e, nb) for e, nb in ((keep[0], keep[1]), (keep[-1], keep[-2]))
                if abs(np.r_[np.mean(sets[e], 0), 1.0] @ _fit_line(sets[nb])) < MERGED_MAX_GAP_PX]
        need = sorted({k for pair in ends for k in pair} - widths.keys())
        if need:  # the widths not read yet, in one batch
            widths.update(zip(need, _ridge_widths(image, [sets[k] for k in need])))
        drop = next((e for e, nb in ends if widths[e] >= min_px and widths[e] > ratio * widths[nb]), None)
        if drop is None:
            break
        out.append(drop)
        keep.remove(drop)
    return sorted(out)


def _off_comb(coord, idx, resid, max_missing, frac=COMB_MISFIT_FRAC):
    """Position (in ``coord``'s order) of a line to drop from a pencil whose lines an equally
    spaced comb does not fit, or None.

    Lane lines are equally spaced on the ground, so their pencil coordinates follow a 1-D
    projective map of their indices (:func:`assign_line_indices`).  When the misfit ``resid``
    exceeds ``frac`` of the mean step per index, every line is left out in turn; the one
    whose absence brings the misfit below that bound, and to less than half, is dropped (five
    lines at least: four still check the comb).  On a low grazing tuning clip a straight edge
    300 px above the lanes (the infield's far edge) joined the pencil as line 0 and put every
    lane one index off.  On another (seed 10039) the two farthest lines, 5 px apart, were
    measured as one clean line between them (0.18 px support scatter): 40 % of the local step
    off the comb, 7 % of the mean step in the clip's RMS misfit, under the former bound of 10 %;
    the families then held no camera near the true one and the posterior put the camera 188 %
    too high.  With the bound at 5 % the merged line is left out where that halves the misfit
    (frames 30 and 50 of that clip); where it does not (frames 0 and 10) it stays.

    >>> t = 100.0 / (1 + 0.05 * np.arange(8.0))      # eight equally spaced lines in perspective
    >>> idx, r = assign_line_indices(t)
    >>> _off_comb(t, idx, r, 2) is None
    True
    >>> t2 = np.r_[160.0, t]                         # and an edge above them
    >>> idx2, r2 = assign_line_indices(t2)
    >>> int(_off_comb(t2, idx2, r2, 2))
    0
    >>> t3 = np.r_[t[:-2], t[-2:].mean()]               # the two farthest lines merged into one
    >>> idx3, r3 = assign_line_indices(t3)
    >>> int(_off_comb(t3, idx3, r3, 2)) == len(t3) - 1, _off_comb(t3, idx3, r3, 2, frac=0.1) is None
    (True, True)
    """
    n = len(coord)
    if n < 5 or not np.isfinite(resid):
        return None
    step = abs(coord[-1] - coord[0]) / max(idx[-1] - idx[0], 1)
    if not resid > frac * step:
        return None
    best, best_r = None, resid
    for j in range(n):
        c = np.delete(coord, j)
        i2, r2 = assign_line_indices(c, max_missing)
        step2 = abs(c[-1] - c[0]) / max(i2[-1] - i2[0], 1)
        if r2 < best_r and r2 <= frac * step2 and r2 < 0.5 * resid:
            best, best_r = j, r2
    return best


def _join_pieces(sets, lines_px, coord, max_frac=0.2, max_overlap=0.5):
    """Support-point sets of the pencil with the pieces of one lane line joined.

    A lane line bent by a distorting lens (or partly hidden) can reach the pencil as
    two straight pieces, one after the other along the line.  Their pencil
    coordinates nearly coincide (within ``max_frac`` of the typical spacing of
    neighbouring lines) while distinct lane lines are a whole spacing apart; a kerb
    or a second line close beside a lane line runs alongside it instead, so pieces
    whose extents along the line overlap by more than ``max_overlap`` of the shorter
    one are not joined.

    >>> pts = lambda y0, x0, x1: np.column_stack([np.arange(x0, x1, 10.0), y0 + 0.1 * np.arange(x0, x1, 10.0)])
    >>> sets = [pts(100, 0, 1000), pts(200, 0, 500), pts(200.4, 500, 1000), pts(300, 0, 1000)]
    >>> lines = np.array([[-0.1, 1, -y] for y in (100, 200, 200.4, 300)]) / np.hypot(0.1, 1)
    >>> [len(p) for p in _join_pieces(sets, lines, np.array([0.0, 1.0, 1.004, 2.0]))]
    [100, 100, 100]
    """
    n = len(sets)
    if n < 3:
        return sets
    order = np.argsort(coord)
    gaps = np.diff(np.asarray(coord, float)[order])
    big = gaps[gaps > 0.25 * np.median(gaps)]
    if not len(big):
        return sets
    tol = max_frac * float(np.median(big))
    groups = [[order[0]]]
    for k, g in zip(order[1:], gaps):
        if g < tol and all(_overlap(sets[k], sets[j], lines_px[j]) <= max_overlap for j in groups[-1]):
            groups[-1].append(k)
        else:
            groups.append([k])
    if len(groups) == n:
        return sets
    return [np.concatenate([sets[j] for j in grp]) if len(grp) > 1 else sets[grp[0]] for grp in groups]


def _overlap(pts_a, pts_b, line):
    """Overlap of two point sets' extents along ``line``, as a fraction of the shorter extent."""
    d = np.array([-line[1], line[0]])
    ta, tb = pts_a @ d, pts_b @ d
    inter = min(ta.max(), tb.max()) - max(ta.min(), tb.min())
    shorter = max(min(np.ptp(ta), np.ptp(tb)), 1e-9)
    return max(inter, 0.0) / shorter

