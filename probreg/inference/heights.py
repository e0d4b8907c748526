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

__all__ = ["height_grid"]

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
