"""Following lane lines from frame to frame (a full detection every few frames).

Lines are re-measured around a prediction from the global image motion (phase correlation);
a followed line whose fit scatter jumps sends its frame back to full detection, and line
identities are kept across the clip.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from .detection import (
    _dedupe,
    _image_chord,
    _measure_candidates,
    _pencil_from_candidates,
    detect_lanes,
)
from .mask import athlete_mask, on_athlete_fraction
from .shots import colour_histogram, histogram_change
from .types import FrameLanes, LaneDetectorConfig

__all__ = ["track_lanes", "stitch_tracks"]


def track_lanes(frames, config: LaneDetectorConfig = LaneDetectorConfig(), keypoints_px=None, warmup=0):
    """Lanes of a frame sequence, following the lines from frame to frame.

    The broadcast camera moves smoothly, so each frame's lines are first
    re-measured around the previous frame's lines (no Hough transform); a full
    :func:`detect_lanes` runs on the first frame, every ``redetect_every``
    frames (to pick up lines entering the view), and whenever following loses
    a line or fails.

    Parameters
    ----------
    frames : iterable of (index, image or None)
    config : LaneDetectorConfig
    keypoints_px : ndarray (F, 17, 2 or 3), optional
        The athlete's 2-D keypoints by frame index: line evidence near the athlete
        (:func:`athlete_mask`) is ignored.
    warmup : int
        The first ``warmup`` frames only prepare the global motion and the colour change of the
        next one, as the frames before them would have in one pass over the whole sequence
        (they give no lanes): a sequence followed in parts (:func:`probreg.calibration.register_clip`)
        starts each later part two frames early, and its frames come out as from one pass.

    Returns
    -------
    list of FrameLanes
        Each with ``extra["colour_change"]``: the change of the frame's colour distribution from
        the previous frame's (:func:`probreg.lanes.shots.histogram_change`; NaN for the first
        frame and next to an unreadable one), the evidence for camera cuts.  With ``keypoints_px``, also
        ``extra["on_athlete"]``: :func:`on_athlete_fraction` of the frame's keypoints (NaN without
        an image or a pose), the evidence that the keypoints belong to these images.
    """
    out = []
    prev = last_ok = None
    next_id = 0
    prev_small = window = prev_hist = None
    for k, (i, img) in enumerate(frames, start=-int(warmup)):  # the warm-up frames' k are negative
        hist = colour_histogram(img)
        fl = None
        shift = np.zeros(2)
        small = None
        if img is not None and getattr(img, "ndim", 0) == 3 and img.size:
            # global image motion from the previous frame (phase correlation of a small grey
            # copy): predicts where the lines went when the camera pans or shakes
            scale = 320.0 / img.shape[1]
            step = max(1, img.shape[1] // 640)  # cheap pre-decimation; phase correlation is coarse anyway
            # decimate first, then grey: the colour conversion is per pixel, so this is the
            # same image at a ninth of the conversion's cost (1080p: ~1.7 -> ~0.4 ms)
            small = cv2.resize(cv2.cvtColor(_decimated(img, step), cv2.COLOR_BGR2GRAY),
                               (320, max(8, int(round(img.shape[0] * scale)))),
                               interpolation=cv2.INTER_AREA).astype(np.float32)
            if prev_small is not None and prev_small.shape == small.shape:
                if window is None or window.shape != small.shape:
                    window = cv2.createHanningWindow(small.shape[::-1], cv2.CV_32F)
                # each frame's image is windowed again as the next frame's previous one (OpenCV 4
                # did it in place; kept on every version: every known answer rests on it; the
                # warm-up frames of a later part replay it, so that parts equal one pass)
                (dx, dy), resp, small = _phase_correlate(prev_small, small, window)
                if resp > 0.05:
                    shift = np.array([dx, dy]) / scale
        if k < 0:  # a warm-up frame: its motion image and colours are the next frame's previous
            prev_small, prev_hist = small, hist
            continue
        exclude = (athlete_mask(keypoints_px[i]) if keypoints_px is not None and 0 <= i < len(keypoints_px)
                   else None)
        if prev is not None and prev.ok and small is not None and k % max(config.redetect_every, 1):
            size = (img.shape[1], img.shape[0])
            chords = [c for c in (_image_chord(_translate(ln.line, shift), size) for ln in prev.lines)
                      if c is not None]
            # faint lines found at a lower threshold are followed at that threshold
            low = prev.extra.get("low_contrast_threshold")
            cfg = config if low is None else replace(config, threshold=low)
            cands, (n_curved, curved_len) = _measure_candidates(img, chords, cfg, distinct=True,
                                                                exclude=exclude)
            if len(cands) >= max(config.min_lines, len(prev.lines) - 1):
                extra = {"curved_length_px": curved_len}
                if low is not None:
                    extra["low_contrast_threshold"] = low
                fl = _pencil_from_candidates(_dedupe(cands, cfg),
                                             FrameLanes(status="no_lines", image_size=size, frame=i,
                                                        n_curved=n_curved, extra=extra), cfg, img)
                if not fl.ok or len(fl.lines) < len(prev.lines) - 1 or \
                        max(ln.rms_px for ln in fl.lines) > _track_rms_bound(prev, config):
                    fl = None
        if fl is None:
            fl = detect_lanes(img, config, frame=i, exclude=exclude)
        if fl.ok:
            ref = prev if prev is not None else last_ok
            fl, next_id = _assign_track_ids(fl, ref, next_id, shift if ref is prev else np.zeros(2))
            last_ok = fl
        extra = {**fl.extra, "colour_change": histogram_change(prev_hist, hist)}
        if keypoints_px is not None and 0 <= i < len(keypoints_px):  # do the keypoints lie on the athlete?
            extra["on_athlete"] = on_athlete_fraction(img, keypoints_px[i])
        out.append(replace(fl, extra=extra))
        prev = fl if fl.ok else None
        prev_small, prev_hist = small, hist
    return out


def _phase_correlate(prev, cur, window):
    """``cv2.phaseCorrelate(prev, cur, window)`` as OpenCV 4 computes it on every OpenCV version:
    ``((dx, dy), response, cur after the call)``.

    OpenCV 4 multiplies both images by the window in place when their sizes are DFT-optimal (it
    pads a copy otherwise); OpenCV 5 leaves them as they are.  The lane step feeds each frame's
    image back as the next frame's previous one, so the in-place windowing changed its shift
    estimates (OpenCV 5.1: the tracked frames' line points moved by ~0.07 px, validation clip
    v08_tele's camera height from 4.70 % to 6.18 % off).  Here the windowing is done explicitly,
    and the call gets no window: the same numbers on OpenCV 4 and 5.

    >>> rng = np.random.default_rng(0)
    >>> a = rng.random((180, 320)).astype(np.float32); b = np.roll(a, 2, 1)
    >>> w = cv2.createHanningWindow((320, 180), cv2.CV_32F)
    >>> (dx, dy), resp, b_after = _phase_correlate(a, b, w)
    >>> round(dx, 2), round(dy, 2), bool(np.array_equal(b_after, b * w))  # 320 x 180 is DFT-optimal
    (2.0, -0.0, True)
    """
    a, b = prev * window, cur * window
    (dx, dy), resp = cv2.phaseCorrelate(a, b)
    optimal = all(cv2.getOptimalDFTSize(n) == n for n in cur.shape[:2])
    return (dx, dy), resp, (b if optimal else cur)


def _decimated(img, step):
    """``img[::step, ::step]`` as a contiguous image: a nearest-neighbour resize takes exactly those
    pixels when ``step`` divides both sides (at a tenth of the cost of copying the strided view:
    1080p, 0.1 ms against 1.2 ms), the copy otherwise.

    >>> img = np.arange(6 * 9 * 3, dtype=np.uint8).reshape(6, 9, 3)
    >>> bool(np.array_equal(_decimated(img, 3), img[::3, ::3]))
    True
    >>> bool(np.array_equal(_decimated(img[:5], 3), img[:5:3, ::3]))  # 5 rows: not a multiple of 3
    True
    """
    h, w = img.shape[:2]
    if step == 1:
        return img
    if h % step or w % step:
        return np.ascontiguousarray(img[::step, ::step])
    return cv2.resize(img, (w // step, h // step), interpolation=cv2.INTER_NEAREST)


def _track_rms_bound(prev, config):
    """Largest support scatter (px) accepted for a line followed from ``prev``.

    When the predicted position is off by a good part of the local line spacing
    (the far end of a low camera's view, where the lines crowd together, after a
    poor global-motion estimate), the intensity profiles jump between neighbouring
    lines and the fit's scatter grows from ~0.1 px to several px.

    >>> from probreg.lanes import FrameLanes, LaneDetectorConfig, LaneLine
    >>> prev = FrameLanes(status="ok", lines=(LaneLine(np.array([0.0, 1.0, -5.0]), np.zeros((2, 2)), 0.1),))
    >>> _track_rms_bound(prev, LaneDetectorConfig())
    0.5
    """
    worst = max((ln.rms_px for ln in prev.lines), default=0.0)
    return max(config.track_rms_px, config.track_rms_factor * worst)


def _translate(line, shift):
    """The image line moved by ``shift`` (px)."""
    return np.array([line[0], line[1], line[2] - line[0] * shift[0] - line[1] * shift[1]])


def _assign_track_ids(fl, ref, next_id, shift=(0.0, 0.0)):
    """Give each line of ``fl`` the id of the line of ``ref`` it continues (new ids otherwise).

    Both frames' lines are ordered across the track, so the correspondence is
    an index shift: the shift with the smallest mean distance between matched
    lines wins if that distance is well below the spacing of neighbouring
    lines (the camera moves by less than half a lane between frames).
    """
    ids = [None] * len(fl.lines)
    if ref is not None and ref.ok and len(ref.lines) >= 2:
        # a dozen points per line are plenty to tell which line continues which
        pts = [ln.points_px[:: max(1, len(ln.points_px) // 12)] for ln in fl.lines]
        ref_pts = [r.points_px[:: max(1, len(r.points_px) // 12)] for r in ref.lines]
        spacing = np.median([np.median(np.abs(a @ b.line[:2] + b.line[2]))
                             for a, b in zip(ref_pts[:-1], ref.lines[1:])])
        # the predicted image motion first; no motion when that finds no match (the
        # global-motion estimate can be fooled by the athlete, who stays in the middle
        # of a following camera's view)
        for motion in ([shift, (0.0, 0.0)] if np.any(np.asarray(shift) != 0) else [shift]):
            ref_lines = np.array([_translate(r.line, motion) for r in ref.lines])  # (m, 3)
            D = np.array([np.median(np.abs(p @ ref_lines[:, :2].T + ref_lines[:, 2]), axis=0) for p in pts])
            best, best_cost = None, np.inf
            n, m = D.shape
            for k_shift in range(-(n - 1), m):
                pairs = [(k, k + k_shift) for k in range(n) if 0 <= k + k_shift < m]
                if len(pairs) < min(2, n, m):
                    continue
                cost = float(np.mean([D[k, j] for k, j in pairs]))
                if cost < best_cost:
                    best, best_cost = pairs, cost
            if best is not None and best_cost < 0.35 * spacing:
                for k, j in best:
                    ids[k] = ref.lines[j].track_id
                break
    for k in range(len(ids)):
        if ids[k] is None:
            ids[k] = next_id
            next_id += 1
    lines = tuple(replace(ln, track_id=i) for ln, i in zip(fl.lines, ids))
    return replace(fl, lines=lines), next_id


def stitch_tracks(first, second):
    """``second`` (the lanes of the frames after ``first``, followed on their own) with its
    line identities continuing those of ``first``: the first calibrated frame of ``second`` is
    matched to the last one of ``first`` as consecutive frames are (:func:`_assign_track_ids`),
    lines new there (or in later frames) get ids ``first`` does not use.

    >>> from probreg.lanes import FrameLanes, LaneLine
    >>> def frame(ids, y0=0.0):
    ...     lines = tuple(LaneLine(np.array([0.0, 1.0, -(y0 + 100.0 * k)]),
    ...                            np.array([[x, y0 + 100.0 * k] for x in range(0, 500, 50)]), 0.1, track_id=i)
    ...                   for k, i in enumerate(ids))
    ...     return FrameLanes(status="ok", lines=lines)
    >>> out = stitch_tracks([frame([0, 1, 2])], [frame([0, 1, 2], y0=100.0), frame([0, 1, 2, 3], y0=100.0)])
    >>> [[ln.track_id for ln in fl.lines] for fl in out]
    [[1, 2, 3], [1, 2, 3, 4]]
    """
    used = [ln.track_id for fl in first for ln in fl.lines if ln.track_id is not None]
    next_id = max(used, default=-1) + 1
    ref = next((fl for fl in reversed(first) if fl.ok), None)
    head = next((fl for fl in second if fl.ok), None)
    mapping = {}
    if head is not None:
        matched, next_id = _assign_track_ids(head, ref, next_id)
        mapping = {a.track_id: b.track_id for a, b in zip(head.lines, matched.lines)}
    out = []
    for fl in second:
        lines = []
        for ln in fl.lines:
            if ln.track_id is not None and ln.track_id not in mapping:
                mapping[ln.track_id] = next_id
                next_id += 1
            lines.append(replace(ln, track_id=mapping.get(ln.track_id)))
        out.append(replace(fl, lines=tuple(lines)) if fl.lines else fl)
    return out
