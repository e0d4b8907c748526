"""Gait-level kinematics: touchdowns, gait cycles and time-normalised curves.

A gait cycle of one leg runs from one touchdown of that foot to the next
(0-100 % of the cycle), the convention of running biomechanics (Novacheck 1998).
"""

from __future__ import annotations

import numpy as np

__all__ = ["touchdowns", "gait_cycles", "normalise_cycle", "cycle_curves"]


def touchdowns(contact):
    """Frame indices where a boolean contact series switches from air to ground.

    >>> touchdowns([0, 0, 1, 1, 0, 1]).tolist()
    [2, 5]
    """
    c = np.asarray(contact, bool).astype(int)
    return np.flatnonzero(np.diff(c) == 1) + 1


def gait_cycles(contact):
    """``(start, end)`` frame pairs of complete cycles (touchdown to next touchdown).

    >>> gait_cycles([0, 1, 1, 0, 0, 1, 0, 0, 1])
    [(1, 5), (5, 8)]
    """
    td = touchdowns(contact)
    return [(int(a), int(b)) for a, b in zip(td[:-1], td[1:])]


def normalise_cycle(signal, start, end, n_points=101):
    """Resample ``signal[start:end+1]`` onto ``n_points`` equally spaced cycle percentages.

    >>> normalise_cycle(np.arange(11.0), 0, 10, 3).tolist()
    [0.0, 5.0, 10.0]
    """
    s = np.asarray(signal, float)[start:end + 1]
    x = np.linspace(0.0, 1.0, len(s))
    return np.interp(np.linspace(0.0, 1.0, n_points), x, s)


def cycle_curves(signal, contact, n_points=101):
    """All complete cycles of ``signal`` normalised to ``n_points``: shape (n_cycles, n_points)."""
    cyc = gait_cycles(contact)
    if not cyc:
        return np.zeros((0, n_points))
    return np.stack([normalise_cycle(signal, a, b, n_points) for a, b in cyc])
