"""The static-camera term of the clip model: one camera position for every frame.

The lanes leave each frame's camera one degree of freedom; at a hypothesised camera height every
frame has its own family member, and a static camera means their lateral positions agree.  The
term scores their spread at each height of the model's grid.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STATIC_FIXED_SCALE", "member_jitter", "score_static"]

#: Scale (fraction of the camera-athlete distance) of the residuals wherever the members'
#: frame-to-frame jitter (times the clip's noise ratio) is smaller, or cannot be measured.
STATIC_FIXED_SCALE = 0.003


def member_jitter(y_m, own, dist_m):
    """Frame-to-frame scatter of the members' lateral positions ``y_m`` (F,) over the frames
    ``own`` (with their own member), relative to the camera-athlete distance: robust sd of
    consecutive differences over sqrt 2, the lane noise as the family at this height amplifies
    it.  NaN with fewer than 5 pairs of consecutive frames.

    >>> rng = np.random.default_rng(0)
    >>> y = 50.0 + rng.normal(0, 0.1, 2000)
    >>> round(float(member_jitter(y, np.ones(2000, bool), 50.0)) / 0.002, 1)
    1.0
    """
    d = np.diff(np.where(own, y_m, np.nan))
    d = d[np.isfinite(d)]
    return 1.4826 * float(np.median(np.abs(d))) / np.sqrt(2) / dist_m if len(d) >= 5 else np.nan


def score_static(parts, n_grid, n_frames):
    """The static-camera log-likelihood on a grid of heights and the clip's noise ratio.

    ``parts``: grid index -> (relative residuals of the members' lateral positions from their
    median, number of frames without a member, :func:`member_jitter`); heights not in ``parts``
    (too few cameras) get ``-inf``.

    Student-t (nu = 4) residuals with the fixed scale :data:`STATIC_FIXED_SCALE`, or, where
    the family amplifies the lane noise beyond it, the members' own jitter at that height times
    one factor for the clip: the smallest ratio over the grid of the residuals' robust sd to the
    jitter (at least 1), returned as the noise ratio.  Towards the family's top every frame's
    member is hypersensitive to its lines and the members scatter far more than the fixed
    scale: there the term widens instead of scoring the true height below a lower one; noise
    that persists from frame to frame (followed lines), which the jitter misses, is measured
    where the members agree best.  Where the jitter is small the fixed scale keeps the term's
    absolute level, which compares the family's two branches.  A frame without a member counts
    like one 10 % off the common position.  Tempered for the correlation of neighbouring frames
    (~10 frames).

    >>> z = np.random.default_rng(1).normal(0, 1, 100)
    >>> noise = {g: (z * j, 0, j) for g, j in enumerate([0.004, 0.008, 0.016])}
    >>> ll, ratio = score_static(noise, 3, 100)  # noise amplified by the family: every height alike
    >>> bool(np.ptp(ll) < 1e-9), round(ratio, 1)
    (True, 1.0)
    >>> drift = dict(noise); drift[0] = (noise[0][0] + np.linspace(-0.04, 0.04, 100), 0, 0.004)
    >>> bool(score_static(drift, 3, 100)[0][0] < ll[0] - 100)  # a drifting camera is penalised
    True
    """
    ll = np.full(n_grid, -np.inf)
    ratios = [1.4826 * np.median(np.abs(r)) / j for r, _, j in parts.values()
              if np.isfinite(j) and j > 0 and len(r) >= 10]
    ratio = max(1.0, float(np.min(ratios))) if ratios else 1.0
    temper = (min(1.0, 25.0 / n_frames) if n_frames > 25 else 1.0) * 2.5
    for g, (resid, n_off, jit) in parts.items():
        sc = max(ratio * jit, STATIC_FIXED_SCALE) if np.isfinite(jit) else STATIC_FIXED_SCALE
        ll[g] = float(np.sum(-2.5 * np.log1p((resid / sc) ** 2 / 4))
                      - 2.5 * np.log1p((0.1 / sc) ** 2 / 4) * n_off) * temper
    return ll, ratio
