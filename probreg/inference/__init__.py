"""The probabilistic layer: priors on camera height, stature and limb proportions
(:class:`ModelPriors`), the clip model whose posterior over the one-DOF calibration and limb
lengths ``emcee`` samples (:class:`ClipModel`), propagation of every kept draw through the
lifting, and credible bands for angles and gait numbers (:func:`angle_bands`).
"""

from .bands import (
    BAND_CURVATURE_S2,
    BAND_SCALE,
    GAIT_BAND_SCALE,
    NOISE_RATIO_POWER,
    NONNEGATIVE_GAIT_SUFFIXES,
    STANCE_WINDOW,
    STATIC_INTERVAL_SCALE,
    angle_bands,
    angle_curvature,
    bootstrap_noise_ratio,
    GAIT_CYCLE_ANGLES,
    gait_cycle_bands,
    gait_intervals,
    stance_window,
    static_interval,
)
from .model import (
    PARAM_NAMES,
    STILLNESS_SYS_SD,
    ClipModel,
)
from .sampling import MOVES, SamplerSettings
from .priors import SEGMENT_PROPORTIONS, LogNormalPrior, ModelPriors, NormalPrior, Prior
from .gait_check import gait_check, pattern_cadence_spm, speed_scatter, stance_slide
from .verdict import VerdictThresholds, bone_length_cv, clip_verdict, knee_band_width, posterior_modes

__all__ = [
    "VerdictThresholds", "clip_verdict", "bone_length_cv", "knee_band_width", "posterior_modes",
    "Prior", "NormalPrior", "LogNormalPrior", "ModelPriors", "SEGMENT_PROPORTIONS", "angle_bands",
    "STANCE_WINDOW", "stance_window", "BAND_SCALE", "angle_curvature", "gait_intervals",
    "GAIT_BAND_SCALE", "NONNEGATIVE_GAIT_SUFFIXES", "ClipModel", "SamplerSettings", "MOVES", "PARAM_NAMES",
    "STILLNESS_SYS_SD", "BAND_CURVATURE_S2", "GAIT_CYCLE_ANGLES", "gait_cycle_bands",
    "STATIC_INTERVAL_SCALE", "static_interval", "gait_check", "pattern_cadence_spm", "speed_scatter", "stance_slide",
]
