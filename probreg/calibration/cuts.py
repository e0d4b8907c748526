"""Camera cuts from the lanes: consecutive frames of one static camera share a calibration family.

A static pan/tilt/zoom camera sees the lanes of every frame through one camera centre: as it
pans and zooms its frames' one-degree-of-freedom families change smoothly.  After a cut to
another camera the family jumps: the camera that a given focal length implies is suddenly at
another height.  Each frame's family is evaluated in closed form at a few fixed fields of view
(:data:`PROBE_FOV_DEG`, from a long lens to a wide one) and the log height of each member is
the frame's signature; the *step* at frame ``i`` is the median over those fields of view of the
change of the signature's median over the :data:`STEP_WINDOW` nearest frames with lanes before
``i`` to its median over those from ``i`` on, and it must persist: the smaller of that step and
the one over :data:`PERSIST_WINDOW` frames counts.  A cut is a step above :data:`GEOMETRIC_CUT`
(0.10: the family's camera 10 % higher or lower at every field of view) and above
:data:`GEOMETRIC_NOISE_RATIO` times the clip's own frame-to-frame noise, placed at the frame of
the largest change between consecutive frames within the step's plateau.  Window medians make a
single misread frame no cut, the longer window a few frames' excursion.

Measured (lanes at their raw per-frame values, before the vanishing-point smoother, which would
blur a cut): within continuous shots the step stayed at or below 0.031 on the ten independent
validation clips (pans, zooms, 25 fps, grazing and steep views, a distorted long lens), 0.05 on
tuning twins of the held-out set's stand, steep, wide and long-lens views and 0.002 on the
benchmark's ``run_a``; grazing cameras' crowded lines make their families 30-100 times noisier,
hence the noise-relative threshold.  Cuts between two cameras stepped by 0.2-1.5, also between two
views of the same rendered stadium that the colours do not tell apart.  ``probreg bench cuts``
(``reports/bench_cuts.md``): 18 of 20 cuts of a fixed-seed cut set found at their frame, none in
50 clips without a cut.

The colour change (:mod:`probreg.lanes.shots`) finds the cut's frame exactly and works where
one side of a cut has no lanes; the two are combined in :func:`find_clip_cuts`: where the lanes
can compare both sides of a frame they decide (a colour cut they see across with no more than
their typical step is the same camera: a flash, a graphic, lanes lost for a while), and the
colours decide where they cannot.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..lanes.shots import find_cuts

__all__ = ["PROBE_FOV_DEG", "GEOMETRIC_CUT", "GEOMETRIC_NOISE_RATIO", "STEP_WINDOW", "PERSIST_WINDOW", "STEP_REACH",
           "family_signature", "signature_noise", "persistent_steps",
           "family_steps", "geometric_cuts", "find_clip_cuts"]

#: horizontal fields of view (deg) at which every frame's family is evaluated (from the longest
#: broadcast lenses, ~1 deg, to wide ones; a lens far from every probe hardly moves the signature)
PROBE_FOV_DEG = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
#: a step (change of the log family height at fixed fields of view) above this is a cut ...
GEOMETRIC_CUT = 0.10
#: ... and above this many times the clip's median change from one frame with lanes to the next
#: (a grazing camera's crowded lines make its families 30-100x noisier than a stand camera's)
GEOMETRIC_NOISE_RATIO = 30.0
#: frames with lanes on either side whose median signature is compared
STEP_WINDOW = 5
#: ... and again over this many (as many as there are up to the clip's ends): a cut persists, while
#: a line entering the view can move a few frames' families by as much as a cut (held-out 9038:
#: three frames by 0.1, which five-frame windows took for a cut when the families settled back)
PERSIST_WINDOW = 15
#: how far (frames) a step looks for frames with lanes on either side
STEP_REACH = 100


def family_signature(families, image_size):
    """``(F, K)`` log heights (m) of every frame's family member at the fields of view
    :data:`PROBE_FOV_DEG` (NaN for a frame without a family or without a valid member there).

    ``families``: a :class:`~probreg.calibration.family.CalibrationFamily` or None per frame.
    """
    from .family import _members_batch

    fov = np.radians(np.asarray(PROBE_FOV_DEG, float))
    focal = float(image_size[0]) / (2.0 * np.tan(fov / 2.0))
    out = np.full((len(families), len(focal)), np.nan)
    groups = {}
    for i, fam in enumerate(families):
        if fam is not None:
            groups.setdefault(len(fam.lines), []).append(i)
    for idx in groups.values():  # the batch takes families with the same number of lines together
        mm = _members_batch([families[i] for i in idx], np.tile(focal, (len(idx), 1)))
        h = np.asarray(mm["height_m"], float)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[idx] = np.where(np.asarray(mm["valid"], bool) & (h > 0), np.log(np.where(h > 0, h, 1.0)), np.nan)
    return out


def family_steps(signature, window=STEP_WINDOW, reach=STEP_REACH):
    """``(F,)`` step of the signature at every frame: the ``window`` nearest frames with lanes
    before it against the ``window`` nearest from it on (within ``reach`` frames; NaN where a side
    has none), so that frames without lanes between two shots do not hide a change.  Every split
    of the frames with lanes is evaluated at once (sliding windows); a frame takes its split's
    step when its nearest frames with lanes on both sides lie within ``reach``.

    A camera that zooms or pans moves its signature steadily from frame to frame, and two windows'
    medians lie frames apart: each field of view's difference is corrected by the windows' own
    drift (the median signed change per frame between their consecutive frames with lanes) times
    the distance between the windows' centres, before the median over the fields of view.

    >>> sig = np.log(np.r_[np.full(20, 9.0), np.full(20, 12.0)])[:, None] * np.ones((1, 3))
    >>> s = family_steps(sig)
    >>> round(float(s[20]), 3), float(np.nanmax(s[:15])), bool(np.isnan(s[0]))
    (0.288, 0.0, True)
    >>> gap = sig.copy(); gap[15:25] = np.nan  # no lanes around the cut: the frames on either side compare
    >>> round(float(family_steps(gap)[18]), 3)
    0.288
    >>> zoom = np.linspace(0.0, 0.2, 40)[:, None] * np.ones((1, 3)); zoom[10:30] = np.nan
    >>> round(float(family_steps(zoom)[20]), 3)  # a steady zoom across a gap is no step
    0.0
    >>> cut = zoom.copy(); cut[30:] += 0.12; cut[10:30] = np.linspace(0, 0.2, 40)[10:30, None]
    >>> round(float(family_steps(cut, window=15)[30]), 3)  # nor does it eat into a cut's step
    0.12
    """
    sig = np.asarray(signature, float)
    F, K = sig.shape
    out = np.full(F, np.nan)
    rows = np.flatnonzero(np.isfinite(sig).any(axis=1))
    R = len(rows)
    if F < 2 or R == 0:
        return out
    w = int(window)
    # every split k of the frames with lanes (rows[:k] before, rows[k:] after), for all k at once:
    # windows over the NaN-padded compacted signature, their positions and their drift per frame
    from numpy.lib.stride_tricks import sliding_window_view as windows

    pad = np.full((w, K), np.nan)
    sc = np.concatenate([pad, sig[rows], pad])
    pos = np.concatenate([np.full(w, np.nan), rows.astype(float), np.full(w, np.nan)])
    rate = np.diff(sig[rows], axis=0) / np.diff(rows)[:, None] if R > 1 else np.empty((0, K))
    rc = np.concatenate([np.full((w, K), np.nan), rate, np.full((w, K), np.nan)])
    ks = np.arange(R + 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        wb = windows(sc, w, axis=0)[ks]  # (R+1, K, w): rows k-w .. k-1
        wa = windows(sc, w, axis=0)[ks + w]  # rows k .. k+w-1
        d = np.nanmedian(wa, axis=2) - np.nanmedian(wb, axis=2)
        centre = np.nanmedian(windows(pos, w)[ks + w], axis=1) - np.nanmedian(windows(pos, w)[ks], axis=1)
        # the drift pairs inside the two windows: pairs k-w .. k-2 and k .. k+w-2 (not the pair
        # that straddles the split)
        pairs = windows(rc, 2 * w - 1, axis=0)[ks].copy()  # (R+1, K, 2w-1): pairs k-w .. k+w-2
        pairs[:, :, w - 1] = np.nan
        r = np.nanmedian(pairs, axis=2)
        d = d - np.where(np.isfinite(r), r, 0.0) * centre[:, None]
        both = np.isfinite(wb).any(axis=2) & np.isfinite(wa).any(axis=2)
        step_k = np.nanmedian(np.where(both, np.abs(d), np.nan), axis=1)
    step_k[~both.any(axis=1)] = np.nan
    i = np.arange(1, F)
    k = np.searchsorted(rows, i)
    near_b = np.where(k > 0, i - rows[np.maximum(k - 1, 0)], np.iinfo(np.int64).max)
    near_a = np.where(k < R, rows[np.minimum(k, R - 1)] - i, np.iinfo(np.int64).max)
    ok = (k > 0) & (k < R) & (near_b <= reach) & (near_a < reach)
    out[1:] = np.where(ok, step_k[k], np.nan)
    return out


def _lane_changes(sig):
    """``(F,)`` change of each frame with lanes from the frame with lanes before it (median over the
    fields of view; NaN elsewhere)."""
    out = np.full(len(sig), np.nan)
    rows = np.flatnonzero(np.isfinite(sig).any(axis=1))
    if len(rows) > 1:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out[rows[1:]] = np.nanmedian(np.abs(sig[rows[1:]] - sig[rows[:-1]]), axis=1)
    return out


def signature_noise(signature):
    """The median change of the signature from one frame with lanes to the next (median over the
    fields of view): how much a frame's family moves by itself (0 with fewer than two frames).

    >>> round(signature_noise(np.array([[0.0], [0.01], [0.03], [np.nan], [0.04]])), 3)
    0.01
    """
    d = _lane_changes(np.asarray(signature, float))
    return float(np.nanmedian(d)) if np.isfinite(d).any() else 0.0


def geometric_cuts(signature, steps=None, threshold=None, window=STEP_WINDOW):
    """Frames that start a new camera by the lanes: each run of steps above ``threshold`` (runs
    closer than ``window`` frames merged) gives one cut, at the frame of the largest change of
    the signature from the frame before (or of the largest step where no two consecutive frames
    have lanes).  ``steps``: by default :func:`persistent_steps`; ``threshold``: by default
    :data:`GEOMETRIC_CUT` or :data:`GEOMETRIC_NOISE_RATIO` times :func:`signature_noise`, whichever
    is larger.

    >>> sig = np.log(np.r_[np.full(30, 9.0), np.full(30, 13.0)])[:, None] * np.ones((1, 3))
    >>> sig[10] += 0.5  # one misread frame: no cut
    >>> geometric_cuts(sig)
    [30]
    """
    sig = np.asarray(signature, float)
    steps = persistent_steps(sig) if steps is None else np.asarray(steps, float)
    if threshold is None:
        threshold = max(GEOMETRIC_CUT, GEOMETRIC_NOISE_RATIO * signature_noise(sig))
    above = np.flatnonzero(np.isfinite(steps) & (steps > threshold))
    if not above.size:
        return []
    runs, start = [], above[0]
    for a, b in zip(above[:-1], above[1:]):
        if b - a > window:
            runs.append((start, a))
            start = b
    runs.append((start, above[-1]))
    diff = _lane_changes(sig)
    cuts = []
    for a, b in runs:
        lo, hi = max(1, a - 1), min(len(sig) - 1, b + 1)
        d = diff[lo:hi + 1]
        j = lo + int(np.nanargmax(d)) if np.isfinite(d).any() else a + int(np.nanargmax(steps[a:b + 1]))
        cuts.append(int(j))
    return cuts


def persistent_steps(signature):
    """The smaller of the steps over :data:`STEP_WINDOW` and over :data:`PERSIST_WINDOW` frames with
    lanes (:func:`family_steps`): large only where the signature changes and stays changed.

    >>> sig = np.zeros((60, 3)); sig[30:] = 0.3; sig[10:13] = 0.3  # a cut at 30, an excursion at 10-12
    >>> s = persistent_steps(sig)
    >>> round(float(s[30]), 2), round(float(np.nanmax(s[5:20])), 2), round(float(np.nanmax(family_steps(sig)[5:20])), 2)
    (0.3, 0.0, 0.3)
    """
    return np.fmin(family_steps(signature, STEP_WINDOW), family_steps(signature, PERSIST_WINDOW))


def find_clip_cuts(colour_change, families, image_size):
    """The clip's camera cuts from both signals (see the module docstring): every geometric cut
    (moved to a colour cut within :data:`STEP_WINDOW` frames, which places it exactly), and every
    colour cut where the lanes cannot compare the two sides (no frame with lanes within
    :data:`STEP_REACH` frames on one side); a colour cut that the lanes see across with a step no
    larger than their typical one (half :data:`GEOMETRIC_CUT`, or three times the clip's median
    step) is the same camera (a flash, a graphic, lanes lost for a while).  Returns ``(cuts, info)`` with
    ``info``: the steps of every frame (``steps``; NaN within :data:`STEP_WINDOW` frames of a cut,
    where the windows straddle it) and colour cuts vetoed by the lanes (``vetoed``)."""
    sig = family_signature(families, image_size)
    steps = persistent_steps(sig)
    colour = find_cuts(colour_change)
    geo = geometric_cuts(sig, steps)
    finite = steps[np.isfinite(steps)]
    same = max(GEOMETRIC_CUT / 2, 3.0 * float(np.median(finite))) if finite.size else GEOMETRIC_CUT / 2
    cuts, vetoed = set(), []
    lanes = np.flatnonzero(np.isfinite(sig).any(axis=1))
    change = np.asarray(colour_change, float)
    for g in geo:
        near = [c for c in colour if abs(c - g) <= STEP_WINDOW]
        if near:  # the colours place it to the frame
            cuts.add(min(near, key=lambda c: abs(c - g)))
            continue
        # frames without lanes just before it: the cut lies among them, where the picture changes most
        prev = lanes[lanes < g]
        span = np.arange(prev[-1] + 1 if prev.size else 0, g + 1)
        inside = change[span] if span.size and span[-1] < len(change) else np.array([])
        cuts.add(int(span[int(np.nanargmax(inside))]) if np.isfinite(inside).any() else g)
    for c in colour:
        if c in cuts or any(abs(c - g) <= STEP_WINDOW for g in geo):
            continue
        if np.isfinite(steps[c]) and steps[c] <= same:
            vetoed.append(int(c))  # the nearest lanes on both sides show one camera
            continue
        cuts.add(int(c))
    away = steps.copy()  # a step's windows straddle a cut for STEP_WINDOW frames around it
    for c in cuts:
        away[max(0, c - STEP_WINDOW):c + STEP_WINDOW] = np.nan
    return sorted(cuts), {"steps": away, "vetoed": vetoed}
