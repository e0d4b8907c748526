"""The grid of camera heights on which the clip model's likelihood terms are precomputed.

Every frame's family branch ends at a highest camera (the fold where the narrow and the wide
branch meet).  A steep camera close to the track sits just below that fold, where the family's
focal length and tilt change fastest with the height, and the frames' tops differ a little (lane
measurement noise, pan and zoom).  A geometric grid from the lowest to the highest height the
lanes allow puts its last two points far apart there: the last one above nearly every frame's top
(no camera), the one before it well below the truth.  The likelihood, interpolated between grid
points, was then cut at the second last point and the posterior piled up against that edge with
an interval a few centimetres wide, metres away from the truth (four steep held-out clips,
0.3 % wide intervals 1.6-5 % below the true height).  So the grid is refined where the frames'
tops are: points closer and closer just below the tops' 10 % quantile (a few odd frames may end
far lower), and the tops' quantiles; every geometric point stays (dropping those above an odd
frame's low top once left a validation clip's grid with nothing between 8.8 and 26 m).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CONFLICT_P", "HEIGHT_SYSTEMATIC_SD", "LIMB_SPREAD_FLOOR", "height_grid", "identity_height",
           "height_terms_note", "limb_consistency", "smear_log_likelihood", "term_conflict"]

#: relative distances below the frames' typical lowest top (see :func:`height_grid`) at which
#: extra grid points go
BELOW_TOP = (0.06, 0.04, 0.025, 0.015, 0.008, 0.004, 0.0015)
#: quantiles of the frames' tops that become grid points
TOP_QUANTILES = (0.05, 0.1, 0.25, 0.5, 0.75, 0.9)
#: the quantile of the frames' tops below which the grid is refined: a few frames may end far
#: lower (an odd family), the static-camera term drops fast once more frames than that lose
#: their member
ANCHOR_QUANTILE = 0.1


def height_grid(lo, hi, n, tops=None, min_rel_step=2e-4):
    """Grid of camera heights in ``[lo, hi]``: ``n`` geometric points, refined near the frames'
    branch tops ``tops`` (the highest camera of every calibrated frame's branch): points
    :data:`BELOW_TOP` below their :data:`ANCHOR_QUANTILE` quantile, and their
    :data:`TOP_QUANTILES`.  The geometric points all stay (odd frames may end far below the
    others: the grid must not thin out anywhere).  Points closer than ``min_rel_step``
    (relative) to a kept neighbour are dropped.

    >>> g = height_grid(2.0, 26.0, 36)
    >>> len(g), float(g[0]), float(g[-1])
    (36, 2.0, 26.0)
    >>> tops = np.r_[8.8, np.linspace(25.5, 26.0, 30)]      # one odd frame ends at 8.8 m
    >>> r = height_grid(2.0, 26.0, 36, tops)
    >>> bool(np.all(np.diff(r) > 0)), float(r[0]), float(r[-1])
    (True, 2.0, 26.0)
    >>> bool(np.all(np.isin(g, r)))                          # every geometric point stays
    True
    >>> t10 = np.quantile(tops, 0.1)
    >>> below = r[r < t10]                                   # the step just below the tops is fine
    >>> bool(t10 - below[-1] < 0.002 * t10), bool(np.max(np.diff(r[r >= 0.94 * t10])) < 0.55)
    (True, True)
    """
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"height grid needs 0 < lo < hi, got {lo}, {hi}")
    grid = np.geomspace(lo, hi, int(n))
    tops = np.asarray([] if tops is None else tops, float)
    tops = tops[np.isfinite(tops) & (tops > lo) & (tops <= hi)]
    if len(tops):
        anchor = float(np.quantile(tops, ANCHOR_QUANTILE))
        extra = np.r_[anchor * (1 - np.asarray(BELOW_TOP)), np.quantile(tops, TOP_QUANTILES)]
        grid = np.r_[grid, extra[(extra > lo) & (extra < hi)]]
    grid = np.unique(grid)
    keep = [0]
    for i in range(1, len(grid)):
        if grid[i] > grid[keep[-1]] * (1 + min_rel_step):
            keep.append(i)
    if keep[-1] != len(grid) - 1:
        keep[-1] = len(grid) - 1  # the top itself stays
    return grid[keep]


#: Systematic allowance on the camera height (sd of log height) for what the lane geometry
#: itself cannot know: the real lane width (1.22 m +- 1 cm, ~0.5 %) and the track's lateral
#: slope (up to 1 %: ~0.6 % of height for a typical view), in quadrature ~0.8 %.  See
#: :func:`smear_log_likelihood`; 1.5 % was tried on the tuning set and let a near view drift
#: 11 % off unflagged (docs/method.md).
HEIGHT_SYSTEMATIC_SD = 0.008


def smear_log_likelihood(grid, ll, sd=HEIGHT_SYSTEMATIC_SD, step=None):
    """The camera-height terms ``ll`` (on ``grid``, linear between points in log height)
    marginalised over a systematic shift of log height, ``N(0, sd)``: returns
    ``(log_grid, ll_smeared)`` on a fine uniform grid of log height (step ``sd / 8``).

    The lanes fix the height through the family's geometry; near the fold the terms become
    spikes a few tenths of a percent wide, narrower than what the geometry's own assumptions
    (flat track, exact lane width) warrant.  The convolution leaves a term broader than ``sd``
    as it was and widens a spike to ``sd``; it keeps the term's integral, so an exact evidence
    would not move (the branches' Laplace estimate, :mod:`probreg.inference.evidence`, can:
    near the fold the widened terms are far from Gaussian).  Heights outside the grid count as
    no support.

    >>> g = np.geomspace(5.0, 40.0, 3000)
    >>> spike = -0.5 * (np.log(g / 20.0) / 0.001) ** 2         # 0.1 % wide
    >>> x, s = smear_log_likelihood(g, spike, sd=0.02)
    >>> w = np.exp(s - s.max()); m = np.sum(w * x) / w.sum()
    >>> round(float(np.exp(m)), 1), round(float(np.sqrt(np.sum(w * (x - m) ** 2) / w.sum())), 3)
    (20.0, 0.02)
    >>> broad = -0.5 * (np.log(g / 20.0) / 0.3) ** 2           # 30 % wide: unchanged
    >>> x, b = smear_log_likelihood(g, broad, sd=0.02)
    >>> bool(np.max(np.abs((b - b.max()) - (np.interp(x, np.log(g), broad) - broad.max()))[np.abs(x - np.log(20)) < 0.5]) < 0.01)
    True
    """
    from scipy.special import logsumexp

    grid, ll = np.asarray(grid, float), np.asarray(ll, float)
    log_g = np.log(grid)
    if sd <= 0 or len(grid) < 2:
        return log_g, ll
    step = sd / 8.0 if step is None else float(step)
    x = np.arange(log_g[0], log_g[-1] + 0.5 * step, step)
    x[-1] = min(x[-1], log_g[-1])
    fine = np.interp(x, log_g, np.where(np.isfinite(ll), ll, -1e300))
    fine[fine < -1e299] = -np.inf
    k = int(np.ceil(4 * sd / step))
    off = np.arange(-k, k + 1) * step
    w = np.exp(-0.5 * (off / sd) ** 2)
    w /= w.sum()
    padded = np.r_[np.full(k, -np.inf), fine, np.full(k, -np.inf)]
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * k + 1)
    with np.errstate(divide="ignore"):
        out = logsumexp(windows, b=w[::-1], axis=1)
    return x, out


#: relative spread of a segment's per-frame lengths below which the consistency term stops
#: rewarding (out-of-plane motion alone spreads a limb's sagittal length by a few per cent)
LIMB_SPREAD_FLOOR = 0.01

#: frames' worth of evidence the limbs' consistency term holds at most (0.2.0.dev29).  Its weight
#: grew with the clip's length without bound, the only height term that did (the track's is per
#: contact, the static camera's saturates at 25 frames, the planted feet's and the segments' have
#: systematic floors); the keypoints' bias that moves its minimum off the true height does not
#: average out over frames.  On 1000-frame clips the 90 % height interval shrank to half the width
#: of the same scene's first 250 frames and missed the truth on 4 of 7 (docs/method.md).  100 is the
#: length the intervals' scale (``STATIC_INTERVAL_SCALE``) was calibrated on.
LIMB_EVIDENCE_FRAMES = 100


def limb_consistency(spread, count, frames_per_sample=10.0, floor=LIMB_SPREAD_FLOOR, measured=None,
                     min_coverage=0.8, frames=None, max_frames=LIMB_EVIDENCE_FRAMES):
    """Log-likelihood on the height grid that every segment keeps one length through the clip.

    Under the right camera a limb cast onto the athlete's sagittal plane has about the same
    length in every frame; under a wrong member of the family the plane and the rays are off
    by amounts that change as the athlete crosses the view, and the lengths spread.  Near the
    family's fold (steep cameras close by) the lanes barely tell the heights apart, while the
    spread does: on a steep tuning clip the thigh's relative spread was 3.7 % at the true
    height and 8.5 % at 20 % below it.  With the per-frame lengths normal around the segment's
    length and their scale profiled out, each segment adds ``-n log(spread)``, where ``spread``
    (G,) is the robust relative spread at each grid height and ``n`` its number of lengths
    over ``frames_per_sample`` (neighbouring frames are strongly correlated).  ``n`` is the
    clip's, from its keypoints, the same at every height and on both branches of the family:
    the term's level compares them (a hypothesis must not gain by measuring fewer lengths).
    Heights where a segment cannot be measured get its worst spread, and so do heights where
    it is measured in fewer than ``min_coverage`` of the frames the best-covered height has
    (``measured``: dict segment -> (G,) number of lengths at each height): near the top of
    the family some frames have no camera, and a spread over the few frames left is not
    comparable (on a given-lens clip it fell from 8 % to 4-5 % with 15-30 of 100 frames, and
    pulled the height 6 % high).  Spreads below ``floor`` count as ``floor``.  A clip of more than
    ``max_frames`` ``frames`` counts as ``max_frames`` (every ``n`` scaled by their ratio,
    :data:`LIMB_EVIDENCE_FRAMES`): a longer clip measures the spread more finely, but not the bias
    its keypoints give it.

    ``spread``: dict segment -> (G,) array; ``count``: dict segment -> number of lengths the
    keypoints give.

    >>> sp = {"thigh": np.array([0.08, 0.04, 0.05, np.nan])}
    >>> n = {"thigh": 200}
    >>> np.round(limb_consistency(sp, n) - limb_consistency(sp, n)[1], 2)  # 20 x log(2) below at 0.08
    array([-13.86,   0.  ,  -4.46, -13.86])
    >>> few = {"thigh": np.array([200, 200, 60, 0])}  # a third height seen in 30 % of the frames
    >>> np.round(limb_consistency(sp, n, measured=few) - limb_consistency(sp, n)[1], 2)
    array([-13.86,   0.  , -13.86, -13.86])
    >>> np.round(limb_consistency(sp, n, frames=400) - limb_consistency(sp, n, frames=400)[1], 2)  # 100 of 400
    array([-3.47,  0.  , -1.12, -3.47])
    """
    cap = 1.0 if frames is None or frames <= max_frames else float(max_frames) / float(frames)
    total = None
    for s, sp in spread.items():
        sp = np.asarray(sp, float)
        ok = np.isfinite(sp)
        if measured is not None:
            m = np.asarray(measured[s], float)
            ok &= m >= min_coverage * np.max(m)
        if not ok.any():
            continue
        sp = np.maximum(np.where(ok, sp, np.max(sp[ok])), floor)
        n = max(cap * float(count[s]) / frames_per_sample, 1.0)
        total = -n * np.log(sp) if total is None else total - n * np.log(sp)
    if total is None:
        return np.zeros(len(next(iter(spread.values()), ())))
    return total


def identity_height(heights, sensitivity, coverage, h_ref, max_sensitivity=2.0, min_share=0.9):
    """The camera height at which the lane lines' identities are settled from frame to frame.

    A followed line that slips to its neighbour moves a frame's member sideways by exactly one
    lane at *every* height, so the identities can be checked at any height where the members are
    well conditioned.  Towards the top of the family (the fold) they are not: every member is
    hypersensitive to its lines, neighbouring frames' lateral positions differ by a large part
    of a lane and noise passes for a slip (and frames without a member there keep offset 0).
    The reference height ``h_ref`` (the best height of a first pass) can sit right there.

    Returned: ``h_ref`` when its members are well conditioned (``sensitivity``, ``|d log f /
    d log h|``, at most ``max_sensitivity``, and a member in at least ``min_share`` of the best
    ``coverage``), else the height of ``heights`` nearest to it (in log) that is; ``h_ref`` when
    none is.  ``sensitivity`` and ``coverage`` are functions of the height.

    >>> sens = lambda h: 1.0 if h < 20 else 8.0  # the fold near 20 m
    >>> cover = lambda h: 100 if h < 24 else 10
    >>> [identity_height([5.0, 10.0, 15.0, 22.0, 25.0], sens, cover, h) for h in (12.0, 22.0, 25.0)]
    [12.0, 15.0, 15.0]
    """
    def good(h, best):
        s = sensitivity(h)
        return np.isfinite(s) and s <= max_sensitivity and coverage(h) >= min_share * best

    cand = np.unique(np.r_[np.asarray(heights, float), h_ref])
    best = max(coverage(h) for h in cand)
    if good(h_ref, best):
        return float(h_ref)
    ok = [h for h in cand if good(h, best)]
    return float(min(ok, key=lambda h: abs(np.log(h / h_ref)))) if ok else float(h_ref)


#: tail probability below which the height-only terms count as contradicting each other
#: (:func:`term_conflict`)
CONFLICT_P = 1e-3


def term_conflict(grid, terms, p=CONFLICT_P):
    """Whether the height-only terms of a clip model tell one story, and how far to temper them.

    Each term (the static camera, the ground track, the planted feet, the limbs' consistency)
    is a log-likelihood of the camera height from its own evidence.  Where their sum peaks,
    each falls short of its own maximum by a deficit; were they consistent, locally quadratic
    measurements of one height, twice the deficits' sum would be chi-square with ``k - 1``
    degrees of freedom (``k`` terms that vary over the grid).  When that sum exceeds its
    ``1 - p`` quantile one term at least measures something its model does not hold (a wide
    distorted near view, ``lens_h09`` of the lens suite's held-out part, where it was found, so that
    clip is no longer held out for this: the static camera peaked at 5.8 m, the limbs and the planted
    feet at 9.7-10.3 m, the truth 9.9 m; their sum, 9.0 m, excluded the truth with a confident
    interval).  The terms are then tempered by the Birge ratio ``(k - 1) / (2 conflict)`` (the
    scale factor of a weighted mean of inconsistent measurements): their sum then has the spread
    its disagreement shows.  Below the threshold nothing changes (``temper`` 1).  The terms are
    not calibrated likelihoods (each is tempered by hand), so the check fires far more often than
    ``p`` says: on 6 of the 20 tuning twins (seeds 7501-7520), five of them grazing views, where the
    other terms (limb lengths, the stature prior) then set the height.  It is a widening, not a
    verdict reason: three of those six clips had knee errors of 3.2-4.0 deg and the height within
    7 %.

    ``terms``: name -> (G,) log-likelihood on ``grid`` (non-finite: no value at that height).
    Returns a dict: ``conflict_nats``, ``threshold_nats``, ``temper``, ``height_m`` (where the
    sum peaks), ``peaks_m`` and ``deficits_nats`` per informative term.

    >>> g = np.geomspace(4.0, 16.0, 200)
    >>> q = lambda h0, s: -0.5 * (np.log(g / h0) / s) ** 2
    >>> agree = term_conflict(g, {"a": q(8.0, 0.05), "b": q(8.3, 0.05), "c": np.zeros(200)})
    >>> agree["temper"], sorted(agree["peaks_m"])                  # c is flat: not a term
    (1.0, ['a', 'b'])
    >>> split = term_conflict(g, {"a": q(6.0, 0.03), "b": q(10.0, 0.03)})
    >>> round(split["height_m"], 1), round(split["conflict_nats"], 1), round(split["temper"], 4)  # 2 x 36 nats
    (7.8, 72.5, 0.0069)
    """
    from scipy.stats import chi2

    grid = np.asarray(grid, float)
    use = {k: np.asarray(v, float) for k, v in terms.items()}
    ok = np.all([np.isfinite(v) for v in use.values()], axis=0) if use else np.zeros(len(grid), bool)
    use = {k: v for k, v in use.items() if ok.any() and np.ptp(v[ok]) > 1e-9}
    out = {"conflict_nats": 0.0, "threshold_nats": float("nan"), "temper": 1.0, "height_m": float("nan"),
           "peaks_m": {}, "deficits_nats": {}}
    if len(use) < 2:
        return out
    idx = np.flatnonzero(ok)
    total = sum(v[idx] for v in use.values())
    j = idx[int(np.argmax(total))]
    deficits = {k: float(np.max(v[idx]) - v[j]) for k, v in use.items()}
    conflict = float(sum(deficits.values()))
    threshold = 0.5 * float(chi2.ppf(1.0 - p, len(use) - 1))
    out.update(conflict_nats=conflict, threshold_nats=threshold, height_m=float(grid[j]),
               peaks_m={k: float(grid[idx[int(np.argmax(v[idx]))]]) for k, v in use.items()},
               deficits_nats=deficits)
    if conflict > threshold:
        out["temper"] = 0.5 * (len(use) - 1) / conflict
    return out


def height_terms_note(conflict):
    """Words for height-only terms that contradict each other (``conflict``: :func:`term_conflict`):
    where each term alone puts the camera.

    >>> height_terms_note({"peaks_m": {"static_camera": 5.76, "limb_consistency": 9.74},
    ...                    "conflict_nats": 44.4, "threshold_nats": 8.1})
    'camera height terms disagree (static camera 5.76 m, limb consistency 9.74 m; 44.4 nats, limit 8.1)'
    """
    peaks = sorted(conflict["peaks_m"].items(), key=lambda kv: kv[1])
    return ("camera height terms disagree (" + ", ".join(f"{k.replace('_', ' ')} {v:.2f} m" for k, v in peaks)
            + f"; {conflict['conflict_nats']:.1f} nats, limit {conflict['threshold_nats']:.1f})")


#: tail probability below which a given lens counts as contradicting the clip's own height terms
#: (:func:`lens_conflict`); stricter than :data:`CONFLICT_P` because those terms are not
#: calibrated likelihoods and are biased on some close views (docs/method.md)
LENS_CONFLICT_P = 1e-4


def lens_conflict(log_grid, height_ll, lens_ll, p=LENS_CONFLICT_P):
    """Does a given lens agree with the clip's other evidence of the camera height?

    With ``k1`` known, the lane lines' curvature fixes the focal length and so the height
    (``lens_ll``: the plumb-line log-likelihood at each height); the height-only terms measure
    it on their own (``height_ll``, as the model sums them).  Where their sum peaks, each falls
    short of its own maximum; the deficits' sum, were both measurements of one height, would be
    half a chi-square with one degree of freedom.  Beyond its ``1 - p`` quantile the given lens
    and the clip tell different heights: a lens calibrated at another zoom, or another lens.
    None when either curve has no values.  Returns ``deficit_nats``, ``threshold_nats``,
    ``height_lens_m`` and ``height_other_m`` (where each peaks).

    >>> x = np.log(np.geomspace(3.0, 12.0, 300))
    >>> q = lambda h0, s: -0.5 * ((x - np.log(h0)) / s) ** 2
    >>> round(lens_conflict(x, q(6.0, 0.1), q(6.1, 0.01))["deficit_nats"], 2)
    0.01
    >>> c = lens_conflict(x, q(6.0, 0.1), q(9.0, 0.01))  # 4 sd of the other terms apart
    >>> [round(c[k], 2) for k in ("height_lens_m", "height_other_m", "deficit_nats", "threshold_nats")]
    [9.0, 5.99, 8.14, 7.57]
    """
    from scipy.stats import chi2

    h, z = np.asarray(height_ll, float), np.asarray(lens_ll, float)
    ok = np.isfinite(h) & np.isfinite(z)
    if ok.sum() < 3 or np.ptp(z[ok]) < 1e-9:
        return None
    x = np.asarray(log_grid, float)[ok]
    h, z = h[ok], z[ok]
    j = int(np.argmax(h + z))
    return {"deficit_nats": float(h.max() + z.max() - h[j] - z[j]), "threshold_nats": 0.5 * float(chi2.ppf(1 - p, 1)),
            "height_lens_m": float(np.exp(x[int(np.argmax(z))])), "height_other_m": float(np.exp(x[int(np.argmax(h))]))}
