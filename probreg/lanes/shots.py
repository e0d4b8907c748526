"""Camera cuts: where a broadcast clip switches from one camera to another.

The whole method rests on one static camera per clip (one height selects the member of every
frame's family).  A broadcast edit cuts between cameras -- a main-stand camera, a rail camera, a
finish-line camera -- and a clip cut from it easily spans a cut.  Taken as one camera, the two
shots' lanes pull the height between two cameras that both exist, and the result can be wrong
by tens of degrees while every per-frame check passes (measured: a cut from a 9 m camera 30 m
away to an 11 m camera 40 m away gave a knee error of 38 deg with verdict ``ok``).

A cut changes the picture's content at once; a pan, a zoom or the athlete moving change it
little from one frame to the next.  The measure is the change of the frame's colour
distribution: the total variation distance between the normalised 8x8x8 BGR histograms of
consecutive frames (:func:`colour_histogram`, :func:`histogram_change`), 0 for identical
distributions and 1 for disjoint ones.  Within a shot it stays small (on tuning twins of the
held-out set, seeds 7501-7520, at most 0.034; on the benchmark's ``run_a`` 0.017; checked on the
ten independent validation clips, pans, zooms, 25 and 50 fps: at most 0.028); a cut between two
differently framed views moved 0.08-0.25 of the mass on probreg's renders.  A frame is a cut when
its change exceeds both :data:`CUT_MIN_CHANGE` (0.05, about 1.5 times the largest within-shot
change of the tuning clips) and :data:`CUT_LOCAL_RATIO` (6) times the median change of the
frames around it (a clip whose every frame changes a lot, e.g. strong flicker, does not cut
at every frame).  The phase-correlation response of the lane tracker is no cut signal: on
continuous validation shots it falls to -0.2.

Gradual transitions (dissolves, wipes) spread the change over many frames and are not found;
nor is a cut between two cameras whose pictures have the same colours.  The clip model's own
checks (``lanes_agree_frames``, bone lengths, the bands) remain behind this one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["colour_histogram", "histogram_change", "find_cuts", "shot_ranges", "ShotSplit", "split_shots",
           "restrict_clip", "is_shot_option",
           "CUT_MIN_CHANGE", "CUT_LOCAL_RATIO"]

#: the smallest colour change (total variation distance of consecutive frames' histograms) that
#: is a cut: about 1.5 times the largest change within a shot on the tuning twins (0.034)
CUT_MIN_CHANGE = 0.05
#: a cut's change is at least this many times the median change of the frames around it
CUT_LOCAL_RATIO = 6.0
#: frames on either side whose median change is the local level
CUT_WINDOW = 12
#: pixels sampled across the image for the histogram (a coarse grid is enough for a colour
#: distribution: every 4th pixel of a 1080p frame, ~0.55 ms)
_SAMPLE_WIDTH = 480


def colour_histogram(img):
    """The normalised 8x8x8 histogram of a BGR image (512 bins summing to 1), from every
    ``n``-th pixel of every ``n``-th row (about 480 pixels across; a sparser grid made the
    within-shot changes twice as large); None for an image that is not 8-bit 3-channel.

    >>> img = np.zeros((100, 200, 3), np.uint8); img[:, 100:] = (0, 0, 255)
    >>> h = colour_histogram(img)
    >>> h.shape, float(h.sum()), int((h > 0).sum())
    ((512,), 1.0, 2)
    """
    import cv2

    if img is None or getattr(img, "ndim", 0) != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or not img.size:
        return None
    n = max(1, img.shape[1] // _SAMPLE_WIDTH)
    # every n-th pixel of every n-th row; the nearest-neighbour resize takes that sample at half
    # the cost of slicing and copying it (1080p: 0.55 ms against 1.0 ms)
    size = (-(-img.shape[1] // n), -(-img.shape[0] // n))
    small = img if n == 1 else cv2.resize(img, size, interpolation=cv2.INTER_NEAREST)
    h = cv2.calcHist([small], [0, 1, 2], None, [8, 8, 8], [0, 256, 0, 256, 0, 256]).ravel().astype(float)
    return h / max(h.sum(), 1.0)


def histogram_change(h0, h1):
    """Total variation distance of two normalised histograms (0: the same colours, 1: none in
    common); NaN when either is missing.

    >>> a = np.array([0.5, 0.5, 0.0]); b = np.array([0.0, 0.5, 0.5])
    >>> histogram_change(a, b), histogram_change(a, a), histogram_change(a, None)
    (0.5, 0.0, nan)
    """
    if h0 is None or h1 is None:
        return float("nan")
    return float(0.5 * np.abs(np.asarray(h0) - np.asarray(h1)).sum())


def find_cuts(change, min_change=CUT_MIN_CHANGE, local_ratio=CUT_LOCAL_RATIO, window=CUT_WINDOW):
    """Frames that start a new shot: ``change[i]`` (frame ``i`` against frame ``i - 1``; NaN where
    unknown) above ``min_change`` and above ``local_ratio`` times the median change of the frames
    within ``window`` on either side (the frame itself left out).

    >>> c = np.full(60, 0.004); c[0] = np.nan; c[25] = 0.2
    >>> find_cuts(c)
    [25]
    >>> c[40] = 0.03  # a large change, but below the floor: a fast pan, not a cut
    >>> find_cuts(c)
    [25]
    >>> find_cuts(np.full(60, 0.08))  # everything changes a lot: no frame stands out
    []
    """
    c = np.asarray(change, float)
    cuts = []
    for i in np.flatnonzero(np.isfinite(c) & (c > min_change)):
        around = np.r_[c[max(0, i - window):i], c[i + 1:i + 1 + window]]
        around = around[np.isfinite(around)]
        level = float(np.median(around)) if around.size else 0.0
        if c[i] > local_ratio * level:
            cuts.append(int(i))
    return cuts


def shot_ranges(n_frames, cuts):
    """``[(start, stop), ...]`` of the shots between the cuts (``stop`` exclusive).

    >>> shot_ranges(100, [30, 70])
    [(0, 30), (30, 70), (70, 100)]
    >>> shot_ranges(5, [])
    [(0, 5)]
    """
    edges = [0, *sorted(c for c in cuts if 0 < c < n_frames), n_frames]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


@dataclass(frozen=True)
class ShotSplit:
    """The shots of a clip and the one estimated.

    ``cuts``: frames that start a new shot; ``ranges``: the shots' ``(start, stop)``; ``chosen``:
    the index of the shot estimated (None: the clip as one camera, ``--shot all``); ``how``:
    ``"only"`` (no cut), ``"longest"``, ``"given"`` or ``"all"``; ``change_max`` and ``step_max``:
    the largest colour change and lane step (:mod:`probreg.calibration.cuts`) within the frames
    estimated (how close a cut came to being found there); ``vetoed``: colour cuts the lanes
    showed to be one camera.
    """

    cuts: tuple = ()
    ranges: tuple = ()
    chosen: int | None = 0
    how: str = "only"
    change_max: float = float("nan")
    step_max: float = float("nan")
    vetoed: tuple = ()

    @property
    def frames(self):
        """``(start, stop)`` of the frames estimated (all of them when there is no choice)."""
        if self.chosen is None:
            return (self.ranges[0][0], self.ranges[-1][1]) if self.ranges else (0, 0)
        return self.ranges[self.chosen]

    @property
    def split(self):
        """Whether frames are left out (a cut, and one shot estimated)."""
        return bool(self.cuts) and self.chosen is not None

    def to_dict(self):
        def num(v):
            return None if not np.isfinite(v) else round(float(v), 4)

        return {"cuts": list(self.cuts), "ranges": [list(r) for r in self.ranges], "chosen": self.chosen,
                "how": self.how, "frames_estimated": list(self.frames), "change_max": num(self.change_max),
                "step_max": num(self.step_max), "vetoed_colour_cuts": list(self.vetoed)}

    def note(self):
        """The input note of a clip whose shots were split.

        >>> ShotSplit(cuts=(120,), ranges=((0, 120), (120, 240)), chosen=1, how="longest").note()
        'camera cut at frame 120: 2 shots; estimated shot 1 (frames 120-239, the longest); the other frames have status other_shot (--shot N picks another, --shot all takes the clip as one camera)'
        """
        a, b = self.frames
        many = "s" if len(self.cuts) > 1 else ""
        return (f"camera cut{many} at frame{many} {', '.join(map(str, self.cuts))}: "
                f"{len(self.ranges)} shots; estimated shot {self.chosen} (frames {a}-{b - 1}"
                f"{', the longest' if self.how == 'longest' else ''}); the other frames have status other_shot "
                "(--shot N picks another, --shot all takes the clip as one camera)")


def is_shot_option(value):
    """Whether ``value`` is a ``--shot``: ``"longest"``, ``"all"`` or a shot's number (0-based).

    >>> [is_shot_option(v) for v in ("longest", "all", "2", 2, "first", "-1")]
    [True, True, True, True, False, False]
    """
    return str(value) in ("longest", "all") or str(value).isdigit()


def split_shots(change, n_frames, shot="longest", cuts=None, steps=None, vetoed=(), lanes=None):
    """The :class:`ShotSplit` of a clip from its frames' colour changes (``cuts``, when given, are
    the clip's cuts found otherwise, e.g. :func:`probreg.calibration.cuts.find_clip_cuts`, with
    ``steps`` the lane steps behind them).

    ``shot``: ``"longest"`` (the shot with the most frames that show lanes, ``lanes`` a bool per
    frame; without ``lanes``, or among equal ones, the longest; the first of equal ones), ``"all"``
    (the clip as one camera, whatever the cuts), or a shot's index (0-based, as in ``ranges``).

    >>> c = np.full(100, 0.003); c[0] = np.nan; c[30] = 0.3
    >>> s = split_shots(c, 100)
    >>> s.cuts, s.ranges, s.chosen, s.frames, s.split
    ((30,), ((0, 30), (30, 100)), 1, (30, 100), True)
    >>> split_shots(c, 100, shot=0).frames, split_shots(c, 100, shot="all").split
    ((0, 30), False)
    >>> split_shots(c, 100, lanes=np.arange(100) < 40).frames  # the long shot shows no lanes after frame 39
    (0, 30)
    >>> split_shots(c, 100, shot=5)
    Traceback (most recent call last):
    ...
    ValueError: --shot 5: the clip has 2 shot(s) (cuts at frames 30), numbered from 0
    """
    change = np.asarray(change, float)
    cuts = tuple(find_cuts(change) if cuts is None else sorted(int(c) for c in cuts))
    ranges = tuple(shot_ranges(n_frames, cuts))
    if shot == "all":
        chosen, how = None, "all"
    elif shot == "longest":
        seen = np.ones(n_frames, bool) if lanes is None else np.asarray(lanes, bool)
        keys = [(int(seen[a:b].sum()), b - a) for a, b in ranges]
        chosen, how = (max(range(len(keys)), key=lambda k: (keys[k], -k)) if keys else 0), ("longest" if cuts else "only")
    else:
        if not is_shot_option(shot):
            raise ValueError(f"--shot must be 'longest', 'all' or a shot's number, got {shot!r}")
        chosen = int(shot)
        if chosen >= len(ranges):
            raise ValueError(f"--shot {shot}: the clip has {len(ranges)} shot(s)"
                             + (f" (cuts at frames {', '.join(map(str, cuts))})" if cuts else "")
                             + ", numbered from 0")
        how = "given" if cuts else "only"
    a, b = ranges[chosen] if chosen is not None and ranges else (0, n_frames)

    def largest(x):  # over the frames estimated (a frame's value compares it with the one before)
        x = np.asarray(x, float)[a + 1:b] if x is not None and b > a + 1 else np.array([])
        x = x[np.isfinite(x)]
        return float(x.max()) if x.size else float("nan")

    return ShotSplit(cuts=cuts, ranges=ranges, chosen=chosen, how=how, change_max=largest(change),
                     step_max=largest(steps), vetoed=tuple(int(v) for v in vetoed))


def restrict_clip(clip, split: ShotSplit):
    """The clip with the 2D keypoints of the frames outside the estimated shot removed (NaN) and a
    note saying so; the clip itself when nothing is left out.

    Raises ``ValueError`` when the estimated shot has fewer frames with a detected athlete than a
    clip needs (:func:`probreg.io.clip.athlete_frames`).
    """
    from dataclasses import replace

    from ..io.clip import MIN_ATHLETE_FRAMES, MIN_ATHLETE_JOINTS, athlete_frames

    if split is None or not split.split:
        return clip
    a, b = split.frames
    kp = None if clip.keypoints_px is None else np.array(clip.keypoints_px, float, copy=True)
    if kp is not None:
        if (seen := athlete_frames(kp[a:b])) < MIN_ATHLETE_FRAMES:
            raise ValueError(f"{clip.path}: the shot estimated (frames {a}-{b - 1}) has only {seen} frames with a "
                             f"detected athlete (at least {MIN_ATHLETE_JOINTS} joints; {MIN_ATHLETE_FRAMES} "
                             f"needed); camera cuts at frames "
                             f"{', '.join(map(str, split.cuts))}: choose another shot with --shot")
        kp[:a] = np.nan
        kp[b:] = np.nan
    return replace(clip, keypoints_px=kp, notes=(*clip.notes, split.note()))
