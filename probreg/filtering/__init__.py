"""Cleaning of a clip's 2D keypoints before lifting: noise estimates, outlier and gap handling,
and cross-stride smoothing that uses the repetition of running strides
(:func:`clean_keypoints` chooses the method from the clip's noise).
"""

from .basic import (
    NOISE_FLOOR_LEG_FRAC,
    NOISE_FLOOR_PX,
    butterworth,
    butterworth_columns,
    fill_gaps,
    hampel,
    hampel_columns,
    keypoint_noise_px,
    keypoints_noisy,
    leg_length_px,
    noise_model,
)
from .clean import clean_keypoints, detection_status
from .identity import relabel_left_right
from .pair import periodic_smooth_pair
from .periodic import (
    pattern_mismatch,
    periodic_smooth,
    periodic_smooth_series,
    score_noise_scale,
    stride_lags,
    stride_period_frames,
)

__all__ = [
    "hampel", "hampel_columns", "fill_gaps", "butterworth", "butterworth_columns", "clean_keypoints", "detection_status", "keypoint_noise_px", "noise_model",
    "keypoints_noisy", "leg_length_px", "NOISE_FLOOR_PX", "NOISE_FLOOR_LEG_FRAC",
    "periodic_smooth", "periodic_smooth_pair", "periodic_smooth_series", "score_noise_scale", "stride_lags",
    "pattern_mismatch", "stride_period_frames", "relabel_left_right",
]
