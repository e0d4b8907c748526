"""The frames' zoom ratios for the plumb-line evidence (:mod:`probreg.calibration.lens`).

A frame that zooms sees the clip's lens as ``kappa_i = kappa / zoom_i**2``; the ratios come from
the lane families' focal lengths at one camera height, read where the families' series is regular
(:func:`_zoom_height`) or, with a strong lens, where one lens straightens every frame's lines best
(:func:`_zoom_by_lines`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

__all__ = []


#: camera heights (m) scanned for the frames' zoom ratios when the families at the prior's centre
#: height do not give a regular focal-length series (:func:`_zoom_ratios`): every broadcast position
ZOOM_SCAN_HEIGHTS_M = tuple(np.geomspace(2.0, 40.0, 14))
#: a frame-to-frame change of the focal length above this (log) is no zoom but a family that
#: folds over at that height (two members of very different focal length either side of it)
ZOOM_JUMP_LOG = 0.05
#: a series with at most this share of such jumps is regular (an odd misread frame, which the
#: running median of :func:`_zoom_ratios` drops)
ZOOM_JUMP_SHARE = 0.02


def _series_quality(f):
    """``(coverage, jumps, roughness)`` of a focal-length series: the share of frames with a
    member, the share of consecutive frame pairs whose focal length jumps by more than
    :data:`ZOOM_JUMP_LOG` (log), and the median absolute second difference of ``log f``.

    >>> f = np.r_[np.full(10, 1000.0), np.full(10, 60.0)]
    >>> cover, jumps, rough = _series_quality(f)
    >>> float(cover), round(float(jumps), 3), float(rough)
    (1.0, 0.053, 0.0)
    """
    ok = np.isfinite(f)
    g = np.log(np.where(ok, f, 1.0))
    d1 = np.abs(np.diff(g))[ok[1:] & ok[:-1]]
    d2 = np.abs(np.diff(g, 2))[ok[2:] & ok[1:-1] & ok[:-2]]
    return (float(ok.mean()) if len(f) else 0.0, float(np.mean(d1 > ZOOM_JUMP_LOG)) if len(d1) else 0.0,
            float(np.median(d2)) if len(d2) else np.inf)


def _zoom_height(reg, height_m):
    """The height at which the frames' zoom ratios are read, and its focal-length series:
    ``height_m`` when the series there is regular (members in 95 % of the frames with lanes or
    more, frame-to-frame jumps in at most :data:`ZOOM_JUMP_SHARE` of the pairs), else the
    regular height of :data:`ZOOM_SCAN_HEIGHTS_M` nearest to it (in log), else the height with
    the most members, then the fewest jumps, then the smoothest series.

    The family of a wide view's bent (still distorted) lines can end below a plausible height
    (no member there) or fold over near it (members of 600 and 6000 px in neighbouring frames,
    measured on a 29 deg view with ``k1 = 0.24``); ratios read there are noise, and a frame given
    a ratio of 0.1 is undistorted by a hundred times the clip's lens, which ruins the evidence.
    The ratios between frames still depend on the height: away from the camera's true height a
    family's focal length changes with the pan too (up to 20 % on wide near views read at 9 m for
    cameras 4-10 m high); :func:`_zoom_by_lines` lets the lines choose the height where that
    matters (a given lens)."""
    n_ok = max(sum(fl.ok for fl in reg.frame_lanes), 1) / max(len(reg.frame_lanes), 1)

    def regular(q):
        return q[0] >= 0.95 * n_ok and q[1] <= ZOOM_JUMP_SHARE

    f = reg.sequence.focal_at_height(height_m)
    if regular(_series_quality(f)):
        return float(height_m), f
    scan = [(h, reg.sequence.focal_at_height(h)) for h in ZOOM_SCAN_HEIGHTS_M]
    quality = [_series_quality(g) for _, g in scan]
    good = [k for k, q in enumerate(quality) if regular(q)]
    if good:
        k = min(good, key=lambda k: abs(np.log(scan[k][0] / height_m)))
        return float(scan[k][0]), scan[k][1]
    # nothing regular: the most members (to the hundredth), then the fewest jumps, then the
    # smoothest series, the given height first among equals
    scan.insert(0, (float(height_m), f))
    quality.insert(0, _series_quality(f))
    k = max(range(len(scan)), key=lambda k: (round(quality[k][0], 2), -quality[k][1], -quality[k][2], k == 0))
    return float(scan[k][0]), scan[k][1]


def _zoom_ratios(reg, height_m):
    """Each frame's focal length relative to the clip's median, from the families of the lines
    at ``height_m`` or, where those are not regular there, at another height
    (:func:`_zoom_height`), smoothed over time with a 25-frame running median; frames without a
    member get their neighbours' ratio.
    Also returns the reference (median) focal length (of the height used)."""
    return _ratios_of(_zoom_height(reg, height_m)[1])


def _ratios_of(f):
    """A focal-length series (F,) as zoom ratios to its median, smoothed over time, and that
    median (ones and NaN without any focal length)."""
    F = len(f)
    if not np.isfinite(f).any():
        return np.ones(F), float("nan")
    # a broadcast zoom changes smoothly; single frames' families scatter by several per cent
    # (near the family's highest member the focal length at a given height is ill-conditioned):
    # a running median over half a second of frames keeps the zoom and drops that scatter
    ok = np.isfinite(f)
    t = np.arange(F)
    g = np.interp(t, t[ok], np.log(f[ok]))
    g = median_filter(g, size=min(25, 2 * (F // 2) - 1) if F > 2 else 1, mode="nearest")
    ref = float(np.exp(np.median(g[ok])))
    return np.exp(g) / ref, ref


def _zoom_by_lines(reg, curvatures, height_m, nats_per_rss=np.inf, min_gain=2.0):
    """The frames' zoom ratios read at the height whose ratios let one lens straighten the lines
    best: ``(ratios, reference focal length, height)``.  When no height has a regular
    focal-length series or none beats the ratios of :func:`_zoom_ratios` by ``min_gain`` in
    log-likelihood (``nats_per_rss`` converts an RSS difference: the evidence's tempering over
    twice its points' variance), those are returned, with height None (a narrow view's lines
    carry no curvature to choose by).

    Away from the camera's true height, a family's focal lengths change from frame to frame
    with the pan (a camera following the athlete), not only with the zoom: on wide near
    views read at 9 m, ratios off by up to 20 % where the camera did not zoom at all.  A
    frame undistorted with a zoom ratio off by ``e`` is undistorted by ``(1 + e)**-2`` times the
    lens, and the clip's ``kappa`` became a compromise of those (5-12 % low on several wide
    views).  The lines themselves say which ratios are right: with the true ones a single
    ``kappa`` straightens every frame.  So each candidate height (``height_m`` and
    :data:`ZOOM_SCAN_HEIGHTS_M`, those with a regular series as in :func:`_zoom_height`) is
    scored by the summed plumb-line RSS at its best ``kappa`` (``curvatures`` from
    :func:`_frame_curvatures`: a closed form per height), and the lowest wins (the
    profile likelihood of the height the ratios are read at; the camera height itself is
    left to the clip model).  Around the best, :data:`ZOOM_REFINE` more heights towards each
    neighbour are scored (the scanned heights are 26 % apart).""" 
    ii, a, b = curvatures
    n_ok = max(sum(fl.ok for fl in reg.frame_lanes), 1) / max(len(reg.frame_lanes), 1)

    def score(h, series=None):  # series: the fallback height's (:func:`_zoom_height`), taken as it is
        f = reg.sequence.focal_at_height(h) if series is None else series
        cover, jumps, _ = _series_quality(f)
        if series is None and (cover < 0.95 * n_ok or jumps > ZOOM_JUMP_SHARE):
            return None
        ratios, ref = _ratios_of(f)
        w = 1.0 / ratios[ii] ** 2
        rss_drop = np.sum(b * w) ** 2 / (4.0 * np.sum(a * w * w))  # sum c - min RSS
        return (rss_drop, ratios, ref, float(h))

    base = score(*_zoom_height(reg, height_m))
    scan = sorted(set((float(height_m),) + tuple(float(h) for h in ZOOM_SCAN_HEIGHTS_M)))
    scored = [s for s in map(score, scan) if s is not None]
    if not scored:
        return base[1], base[2], None
    best = max(scored, key=lambda s: s[0])
    j = scan.index(best[3])
    lo, hi = scan[max(j - 1, 0)], scan[min(j + 1, len(scan) - 1)]
    extra = [s for s in map(score, np.geomspace(lo, hi, 2 * ZOOM_REFINE + 1)[1:-1]) if s is not None]
    best = max([best] + extra, key=lambda s: s[0])
    if (best[0] - base[0]) * nats_per_rss < min_gain:
        return base[1], base[2], None
    return best[1:]


#: heights scored between the best scanned height and each neighbour (:func:`_zoom_by_lines`)
ZOOM_REFINE = 2
#: the lines choose the zoom ratios' height only for a lens that moves the image corner by this
#: much (px): ratios off by 20 % change a frame's undistortion by 40 % of the lens, below a pixel
#: less than the choice can be trusted on (v01_far_side, 0.13 px: a height whose ratios were 43 %
#: off scored best, by the frames' own scatter)
ZOOM_SCAN_MIN_SHIFT_PX = 1.0
