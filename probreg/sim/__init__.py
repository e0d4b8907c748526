"""Simulation for tests, benchmarks and ``probreg synth``: a parametric running-gait model, a
broadcast camera operator, detector noise, and a renderer of the track.  The estimation stages
never import it.
"""

from .render import (
    RenderStyle,
    finish_image,
    lane_line_polygons,
    render_background,
    render_frame,
    render_runner,
)
from .runner import (
    STYLES,
    Anthropometry,
    GaitParams,
    RunnerMotion,
    contact_time_s,
    gait_for_style,
    simulate_runner,
    step_frequency_hz,
)
from .synth import (
    PRESETS,
    SUITES,
    CameraSetup,
    DetectorNoise,
    SynthClip,
    SynthConfig,
    config_from_preset,
    noisy_keypoints,
    simulate_broadcast_cameras,
    synthesize,
    write_clip,
    write_suite,
)

__all__ = [
    "Anthropometry", "GaitParams", "RunnerMotion", "STYLES", "gait_for_style", "simulate_runner",
    "step_frequency_hz", "contact_time_s", "CameraSetup", "DetectorNoise", "SynthConfig",
    "SynthClip", "PRESETS", "SUITES", "config_from_preset", "simulate_broadcast_cameras",
    "noisy_keypoints", "synthesize", "write_clip", "write_suite", "RenderStyle",
    "render_background", "render_runner", "render_frame", "finish_image", "lane_line_polygons",
]
