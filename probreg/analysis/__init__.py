"""Kinematics from lifted joints: touchdowns, gait cycles, cycle-normalised curves and the gait
summary (cadence, step length, contact time, speed).  Pure functions of joints and contacts;
the inference stage propagates them over posterior draws.
"""

from .kinematics import (
    GAIT_FIELDS,
    cycle_curves,
    gait_cycles,
    gait_summary,
    mean_cycle_curve,
    normalise_cycle,
    step_time_s,
    touchdowns,
)

__all__ = [
    "touchdowns", "gait_cycles", "normalise_cycle", "cycle_curves", "mean_cycle_curve", "gait_summary", "GAIT_FIELDS",
    "step_time_s",
]
