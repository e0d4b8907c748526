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
tops are: geometrically closer points just below the lowest top, and the tops' quantiles above it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["height_grid"]

#: relative distances below the lowest frame top at which extra grid points go
BELOW_TOP = (0.06, 0.04, 0.025, 0.015, 0.008, 0.004, 0.0015)
#: quantiles of the frames' tops that become grid points
TOP_QUANTILES = (0.0, 0.1, 0.25, 0.5, 0.75, 0.9)


def height_grid(lo, hi, n, tops=None, min_rel_step=2e-4):
    """Grid of camera heights in ``[lo, hi]``: ``n`` geometric points, refined near the frames'
    branch tops ``tops`` (the highest camera of every calibrated frame's branch).

    Points closer than ``min_rel_step`` (relative) to a kept neighbour are dropped, and the
    geometric points above the refined zone are left out where the refined points replace them.

    >>> g = height_grid(2.0, 26.0, 36)
    >>> len(g), float(g[0]), float(g[-1])
    (36, 2.0, 26.0)
    >>> tops = np.array([25.5, 25.6, 25.9, 26.0])
    >>> r = height_grid(2.0, 26.0, 36, tops)
    >>> bool(np.all(np.diff(r) > 0)), float(r[0]), float(r[-1])
    (True, 2.0, 26.0)
    >>> below = r[r < 25.5]                     # the step just below the lowest top is fine now
    >>> bool(25.5 - below[-1] < 0.05), bool(np.max(np.diff(r[r >= 0.94 * 25.5])) < 0.55)
    (True, True)
    """
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"height grid needs 0 < lo < hi, got {lo}, {hi}")
    grid = np.geomspace(lo, hi, int(n))
    tops = np.asarray([] if tops is None else tops, float)
    tops = tops[np.isfinite(tops) & (tops > lo) & (tops <= hi)]
    if len(tops):
        t_lo = float(np.min(tops))
        start = t_lo * (1 - BELOW_TOP[0])
        extra = np.r_[t_lo * (1 - np.asarray(BELOW_TOP)), np.quantile(tops, TOP_QUANTILES)]
        grid = np.r_[grid[(grid < start) | (grid == hi)], extra[(extra > lo) & (extra < hi)]]
    grid = np.unique(grid)
    keep = [0]
    for i in range(1, len(grid)):
        if grid[i] > grid[keep[-1]] * (1 + min_rel_step):
            keep.append(i)
    if keep[-1] != len(grid) - 1:
        keep[-1] = len(grid) - 1  # the top itself stays
    return grid[keep]
