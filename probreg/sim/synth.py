"""Synthetic broadcast clips with ground truth: runner + broadcast camera + rendering + detector noise.

The seed paper rendered its benchmark in Unreal Engine 5; probreg ships this
generator instead so that every stage can be benchmarked against exact
ground truth.  A clip is fully determined by ``(preset, seed, n_frames)``.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from ..geometry import (
    JOINT_INDEX,
    JOINT_NAMES,
    STANDARD_TRACK,
    Camera,
    focal_from_fov,
    lane_center_y,
    look_at_rotation,
)
from ..io.clip import atomic_output_dir, write_json, write_keypoints_json
from .render import RenderStyle, finish_image, render_background, render_runner
from .runner import STYLES, Anthropometry, RunnerMotion, gait_for_style, simulate_runner

__all__ = ["CameraSetup", "DetectorNoise", "SynthConfig", "SynthClip", "Rival", "RIVAL_KITS", "rival_lanes", "simulate_rivals", "PRESETS", "SUITES", "config_from_preset", "simulate_broadcast_cameras", "noisy_keypoints", "synthesize", "write_clip", "write_suite"]


@dataclass(frozen=True)
class CameraSetup:
    """A static pan/tilt/zoom broadcast camera in the stands.

    Attributes
    ----------
    height_m : float
        Camera height above the track, 3-30 m.
    distance_m : float
        Horizontal distance across the track from the athlete's lane centre, 15-120 m.
    along_m : float
        Camera ``x`` relative to the athlete's position at mid-clip.
    infield : bool
        Camera on the infield side (``y > 0``) instead of the stands.
    athlete_height_px : float
        Zoom is set so that the athlete appears about this tall (clamped to the FOV range).
    fov_range_deg : (float, float)
        Allowed horizontal field of view.
    follow_lag_s : float
        Time constant of the operator following the athlete.
    jitter_deg : float
        Per-frame random-walk step of pan and tilt.
    offset_frac : (float, float)
        Framing offset of the athlete as a fraction of the image (x, y).
    roll_deg : float
    zoom_drift : float
        Relative amplitude of a slow zoom change over the clip.
    dist : tuple of 5 float
        OpenCV lens distortion.
    rail_frac : float
        A camera on a rail along the track (or a tracking vehicle): it moves along ``x`` at this
        share of the runner's mean speed, in the runner's direction (0: the static broadcast
        camera; 1: it keeps pace).  It is at ``along_m`` at mid-clip and keeps aiming at the
        runner.  probreg assumes a static camera: such a clip tests that it says so.
    """

    height_m: float = 12.0
    distance_m: float = 50.0
    along_m: float = -10.0
    infield: bool = False
    athlete_height_px: float = 300.0
    fov_range_deg: tuple = (2.0, 30.0)
    follow_lag_s: float = 0.15
    jitter_deg: float = 0.01
    offset_frac: tuple = (0.05, 0.03)
    roll_deg: float = 0.3
    zoom_drift: float = 0.03
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)
    rail_frac: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.height_m) and 0 < self.height_m <= 100):
            raise ValueError(f"camera height must lie in (0, 100] m, got {self.height_m}")
        if not (np.isfinite(self.distance_m) and self.distance_m > 2):
            raise ValueError(f"camera distance must exceed 2 m, got {self.distance_m}")
        lo, hi = self.fov_range_deg
        if not (0 < lo <= hi < 180):
            raise ValueError(f"field of view range must lie in (0, 180) degrees, got {self.fov_range_deg}")
        if self.athlete_height_px <= 0:
            raise ValueError("athlete height in pixels must be positive")
        if len(self.dist) != 5 or not np.all(np.isfinite(self.dist)):
            raise ValueError("dist must be 5 finite OpenCV coefficients [k1, k2, p1, p2, k3]")
        if not (np.isfinite(self.rail_frac) and 0 <= self.rail_frac <= 1.5):
            raise ValueError(f"rail_frac (share of the runner's speed) must lie in [0, 1.5], got {self.rail_frac}")


@dataclass(frozen=True)
class DetectorNoise:
    """Noise model of a 2D pose detector.

    The default Gaussian sigma of 4.7 px for a 300 px tall athlete (scaled with
    the athlete's size) follows the seed paper's measurement of a
    state-of-the-art 2D detector on its data (4.66 +- 0.87 px).

    Attributes
    ----------
    sigma_px : float
        Per-coordinate standard deviation for an athlete of ``ref_height_px``.
    ref_height_px : float
    temporal_corr : float
        AR(1) coefficient of the error from frame to frame.
    outlier_prob : float
        Per joint and frame: a gross error of 5-25 sigma.
    swap_prob : float
        Per frame: left and right legs (or arms) swapped.
    missing_frame_prob, missing_joint_prob : float
    """

    sigma_px: float = 4.7
    ref_height_px: float = 300.0
    temporal_corr: float = 0.5
    outlier_prob: float = 0.005
    swap_prob: float = 0.003
    missing_frame_prob: float = 0.01
    missing_joint_prob: float = 0.003

    def __post_init__(self):
        if self.sigma_px < 0 or self.ref_height_px <= 0:
            raise ValueError("noise sigma must be >= 0 and reference height > 0")
        for name in ("outlier_prob", "swap_prob", "missing_frame_prob", "missing_joint_prob"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must be a probability")
        if not 0 <= self.temporal_corr < 1:
            raise ValueError("temporal_corr must lie in [0, 1)")

    @classmethod
    def ideal(cls):
        return cls(sigma_px=0.0, outlier_prob=0.0, swap_prob=0.0, missing_frame_prob=0.0,
                   missing_joint_prob=0.0)


@dataclass(frozen=True)
class SynthConfig:
    """Everything that defines a synthetic clip (besides the seed)."""

    style: str = "run"
    stature_m: float = 1.78
    speed_mps: float | None = None
    n_frames: int = 250
    fps: float = 50.0
    image_size: tuple = (1920, 1080)
    athlete_lane: int = 4
    camera: CameraSetup = field(default_factory=CameraSetup)
    noise: DetectorNoise = field(default_factory=DetectorNoise)
    render: RenderStyle = field(default_factory=RenderStyle)
    mid_x_m: float = 45.0
    # other runners of the race in the lanes next to the athlete's (0: the athlete alone, as every
    # clip before 0.2.0.dev35 was); :func:`simulate_rivals`
    rivals: int = 0

    def __post_init__(self):
        if self.style not in STYLES:
            raise ValueError(f"unknown running style {self.style!r}; choose from {sorted(STYLES)}")
        if not 1.0 <= self.stature_m <= 2.5:
            raise ValueError(f"stature must lie in [1.0, 2.5] m, got {self.stature_m}")
        if int(self.n_frames) < 1:
            raise ValueError("a clip needs at least one frame")
        if not self.fps > 0:
            raise ValueError("fps must be positive")
        if not 1 <= self.athlete_lane <= STANDARD_TRACK.n_lanes:
            raise ValueError(f"athlete_lane must be 1..{STANDARD_TRACK.n_lanes}")
        if min(self.image_size) < 16:
            raise ValueError("image size too small")
        if not 0 <= int(self.rivals) < STANDARD_TRACK.n_lanes:
            raise ValueError(f"rivals must be 0..{STANDARD_TRACK.n_lanes - 1} (one runner per other lane)")


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def _sample_camera(rng, **fixed):
    base = dict(height_m=_u(rng, 6, 22), distance_m=_u(rng, 30, 90), along_m=_u(rng, -35, 35),
                athlete_height_px=_u(rng, 250, 450), roll_deg=_u(rng, -1.0, 1.0),
                offset_frac=(_u(rng, -0.12, 0.12), _u(rng, -0.08, 0.08)),
                jitter_deg=_u(rng, 0.003, 0.015), follow_lag_s=_u(rng, 0.08, 0.25),
                zoom_drift=_u(rng, 0.0, 0.06))
    base.update(fixed)
    return CameraSetup(**base)


def _preset(style=None, **camera):
    def make(rng):
        st = style or str(rng.choice(sorted(STYLES)))
        cam = {k: (v(rng) if callable(v) else v) for k, v in camera.items()}
        return dict(style=st, camera=_sample_camera(rng, **cam))
    return make


#: name -> factory(rng) -> SynthConfig overrides.  Mirrors the seed paper's variety.
PRESETS = {
    "default": _preset("run"),
    "jog": _preset("jog"),
    "run": _preset("run"),
    "fast": _preset("fast"),
    "long_step": _preset("long_step"),
    "high_knee": _preset("high_knee"),
    "odd_arms": _preset("odd_arms"),
    "tele": _preset(None, distance_m=lambda r: _u(r, 90, 120), athlete_height_px=lambda r: _u(r, 550, 700),
                    fov_range_deg=(1.8, 30.0)),
    "wide": _preset(None, distance_m=lambda r: _u(r, 15, 25), height_m=lambda r: _u(r, 4, 10),
                    athlete_height_px=lambda r: _u(r, 180, 260)),
    "high": _preset(None, height_m=lambda r: _u(r, 24, 30)),
    "low": _preset(None, height_m=lambda r: _u(r, 3, 5), distance_m=lambda r: _u(r, 15, 35)),
    "square": _preset(None, along_m=lambda r: _u(r, -1.0, 1.0), jitter_deg=0.002, follow_lag_s=0.05,
                      offset_frac=(0.0, 0.0)),
    "distorted": _preset(None, dist=lambda r: (_u(r, -0.12, -0.04), _u(r, 0.0, 0.05), 0.0, 0.0, 0.0),
                         athlete_height_px=lambda r: _u(r, 200, 300)),
    # a camera high up close to the track looking down steeply: its calibration lies on the
    # family's wide branch (probreg.inference.evidence)
    "steep_near": _preset(None, height_m=lambda r: _u(r, 18, 30), distance_m=lambda r: _u(r, 15, 30),
                          athlete_height_px=lambda r: _u(r, 250, 400)),
    # a broadcast zoom lens at its wide end, close to the track: |k1| 0.1-0.25, either sign
    # (the lens development set of issue 27; the held-out set's wide near views are separate)
    "wide_lens": _preset(None, distance_m=lambda r: _u(r, 10, 25), height_m=lambda r: _u(r, 3, 10),
                         athlete_height_px=lambda r: _u(r, 150, 250), fov_range_deg=(2.0, 35.0),
                         dist=lambda r: (float(r.choice([-1.0, 1.0])) * _u(r, 0.1, 0.25), 0.0, 0.0, 0.0, 0.0)),
}

#: Fixed clip suites: name -> list of (clip name, preset, seed).
SUITES = {
    "bench": [
        ("jog_a", "jog", 101), ("run_a", "run", 102), ("fast_a", "fast", 103),
        ("longstep_a", "long_step", 104), ("highknee_a", "high_knee", 105),
        ("oddarms_a", "odd_arms", 106), ("tele_a", "tele", 107), ("wide_a", "wide", 108),
        ("high_a", "high", 109), ("low_a", "low", 110), ("square_a", "square", 111),
        ("distorted_a", "distorted", 112), ("run_b", "run", 113), ("fast_b", "fast", 114),
    ],
    "mini": [("run_a", "run", 102), ("fast_a", "fast", 103), ("square_a", "square", 111)],
    # wide distorted near views for the lens (issue 27): developed on, unlike the held-out set
    "lens": [(f"lens_{k}", "wide_lens", 600 + k) for k in range(1, 9)],
    # the same set-ups, seeds fixed (2026-11-26) before any run on them: held out, never tuned on
    "lens_heldout": [(f"lens_h{k:02d}", "wide_lens", 650 + k) for k in range(1, 17)],
}

def config_from_preset(name, seed, n_frames=None, **overrides):
    """The :class:`SynthConfig` of a preset for a seed.

    Raises
    ------
    ValueError
        For an unknown preset.

    >>> config_from_preset("fast", 1).style
    'fast'
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose from {sorted(PRESETS)}")
    rng = np.random.default_rng([seed, 7919])
    kw = PRESETS[name](rng)
    kw.update(stature_m=_u(rng, 1.55, 2.0), athlete_lane=int(rng.integers(1, 9)),
              mid_x_m=_u(rng, 25, 65))
    if n_frames is not None:
        kw["n_frames"] = int(n_frames)
    kw.update(overrides)
    return SynthConfig(**kw)


def simulate_broadcast_cameras(setup: CameraSetup, motion: RunnerMotion, image_size, fps, rng,
                               lane_y_m, mid_x_m):
    """Per-frame cameras of a static broadcast camera following the runner.

    The camera centre is fixed (on a rail, ``setup.rail_frac > 0``, it moves along ``x`` at that
    share of the runner's mean speed, through its static position at mid-clip); pan/tilt follow
    the pelvis with a first-order lag, a random-walk jitter and a framing offset; zoom holds the
    athlete at about ``athlete_height_px`` with a slow drift.
    """
    w, h = image_size
    side = 1.0 if setup.infield else -1.0
    C = np.array([mid_x_m + setup.along_m, lane_y_m + side * setup.distance_m, setup.height_m])
    pelvis = motion.joints_track_m[:, JOINT_INDEX["pelvis"]]
    n = len(pelvis)
    target = pelvis.copy()
    target[:, 2] = 0.55 * motion.anthropometry.stature_m
    alpha = 1.0 - np.exp(-1.0 / (fps * max(setup.follow_lag_s, 1e-3)))
    smooth = np.empty_like(target)
    # first-order follow: in steady state the view trails the athlete by speed * lag
    velocity = (target[-1] - target[0]) / max((n - 1) / fps, 1e-9) if n > 1 else np.zeros(3)
    smooth[0] = target[0] - velocity * setup.follow_lag_s
    for i in range(1, n):
        smooth[i] = smooth[i - 1] + alpha * (target[i] - smooth[i - 1])
    depth = np.linalg.norm(smooth - C, axis=1)
    f0 = setup.athlete_height_px * float(np.median(depth)) / motion.anthropometry.stature_m
    lo, hi = setup.fov_range_deg
    f0 = float(np.clip(f0, focal_from_fov(hi, w), focal_from_fov(lo, w)))
    phase = rng.uniform(0, 2 * np.pi)
    t = np.arange(n) / fps
    focal = f0 * (1 + setup.zoom_drift * np.sin(2 * np.pi * t / max(t[-1] + 1 / fps, 1.0) + phase))
    focal = np.clip(focal, focal_from_fov(hi, w), focal_from_fov(lo, w))
    jitter = np.cumsum(rng.normal(0, setup.jitter_deg, (n, 2)), axis=0)
    centres = np.repeat(C[None], n, axis=0)
    centres[:, 0] += setup.rail_frac * velocity[0] * (t - t[(n - 1) // 2]) if n else 0.0
    cams = []
    for i in range(n):
        C = centres[i]
        R = look_at_rotation(C, smooth[i])
        # framing offset and jitter: rotate about the camera's own axes
        ox = np.arctan(setup.offset_frac[0] * w / focal[i]) + np.radians(jitter[i, 0])
        oy = np.arctan(setup.offset_frac[1] * h / focal[i]) + np.radians(jitter[i, 1])
        cy, sy, cx, sx = np.cos(ox), np.sin(ox), np.cos(oy), np.sin(oy)
        pan = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]])
        tilt = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        a = np.radians(setup.roll_deg)
        roll = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        Rf = roll @ tilt @ pan @ R
        K = np.array([[focal[i], 0, (w - 1) / 2], [0, focal[i], (h - 1) / 2], [0, 0, 1]])
        cams.append(Camera(K=K, R=Rf, C=C, dist=setup.dist, image_size=(w, h)))
    return cams


def noisy_keypoints(joints2d_px, athlete_height_px, noise: DetectorNoise, rng, far_side_left=None):
    """Detector-like 2D keypoints from ground-truth projections.

    Parameters
    ----------
    joints2d_px : ndarray, shape (F, 17, 2)
    athlete_height_px : ndarray, shape (F,)
        Apparent stature in pixels (noise scales with it).
    noise : DetectorNoise
    rng : numpy.random.Generator
    far_side_left : ndarray of bool, shape (F,), optional
        Whether the left side faces away from the camera (lower scores there).

    Returns
    -------
    ndarray, shape (F, 17, 3)
        ``(x, y, score)``, NaN for missing joints and frames.
    """
    gt = np.asarray(joints2d_px, float)
    n = len(gt)
    sigma = noise.sigma_px * np.asarray(athlete_height_px, float) / noise.ref_height_px
    # extremities are harder to localise than the trunk
    joint_scale = np.ones(17)
    for name in ("r_ankle", "l_ankle", "r_wrist", "l_wrist"):
        joint_scale[JOINT_INDEX[name]] = 1.25
    for name in ("pelvis", "spine", "thorax"):
        joint_scale[JOINT_INDEX[name]] = 0.8
    white = rng.standard_normal((n, 17, 2))
    err = np.empty_like(white)
    rho = noise.temporal_corr
    err[0] = white[0]
    for i in range(1, n):
        err[i] = rho * err[i - 1] + np.sqrt(1 - rho**2) * white[i]
    err *= sigma[:, None, None] * joint_scale[None, :, None]
    kp = gt + err
    z = np.linalg.norm(err, axis=-1) / np.maximum(sigma[:, None] * joint_scale, 1e-9)
    score = np.clip(0.97 - 0.08 * z + rng.normal(0, 0.02, (n, 17)), 0.05, 1.0)
    if far_side_left is not None:
        is_left = np.array([name.startswith("l_") for name in JOINT_NAMES])
        is_right = np.array([name.startswith("r_") for name in JOINT_NAMES])
        far = np.where(np.asarray(far_side_left)[:, None], is_left[None], is_right[None])
        score = np.where(far, score * 0.9, score)
    out = rng.random((n, 17)) < noise.outlier_prob
    if np.any(out):
        ang = rng.uniform(0, 2 * np.pi, out.sum())
        mag = rng.uniform(5, 25, out.sum()) * np.repeat(sigma[:, None], 17, 1)[out]
        kp[out] += np.stack([np.cos(ang), np.sin(ang)], -1) * mag[:, None]
        score[out] = rng.uniform(0.2, 0.7, out.sum())
    swap = rng.random(n) < noise.swap_prob
    pairs = [("r_hip", "l_hip"), ("r_knee", "l_knee"), ("r_ankle", "l_ankle")]
    for i in np.flatnonzero(swap):
        for a, b in pairs:
            ia, ib = JOINT_INDEX[a], JOINT_INDEX[b]
            kp[i, [ia, ib]] = kp[i, [ib, ia]]
    result = np.concatenate([kp, score[..., None]], -1)
    result[rng.random((n, 17)) < noise.missing_joint_prob] = np.nan
    result[rng.random(n) < noise.missing_frame_prob] = np.nan
    return result


@dataclass
class SynthClip:
    """A generated clip in memory (before writing)."""

    config: SynthConfig
    seed: int
    motion: RunnerMotion
    cameras: list
    joints2d_px: np.ndarray
    keypoints_px: np.ndarray
    athlete_height_px: np.ndarray
    lane_y_m: float
    preset: str | None = None
    rivals: tuple = ()


#: kits (shirt, shorts; BGR) and skin tones (BGR) of the other runners of a race: none is the
#: athlete's default kit (:class:`~probreg.sim.render.RenderStyle`)
RIVAL_KITS = (((40, 40, 190), (40, 40, 150)), ((170, 100, 30), (120, 60, 20)), ((40, 190, 220), (40, 90, 40)),
              ((35, 35, 35), (30, 30, 30)), ((60, 140, 50), (235, 235, 235)), ((30, 110, 230), (35, 35, 35)),
              ((150, 60, 140), (60, 40, 100)), ((235, 235, 235), (160, 40, 40)))
RIVAL_SKINS = ((120, 150, 200), (70, 100, 150), (45, 65, 100), (150, 180, 225))


@dataclass(frozen=True)
class Rival:
    """Another runner of the race: its lane, motion and look (``style``: its kit and skin)."""

    lane: int
    motion: RunnerMotion
    style: RenderStyle


def rival_lanes(athlete_lane, n, n_lanes=STANDARD_TRACK.n_lanes):
    """The lanes of ``n`` other runners: the nearest to the athlete's first, inside before outside.

    >>> rival_lanes(4, 3), rival_lanes(1, 3), rival_lanes(8, 2)
    ([3, 5, 2], [2, 3, 4], [7, 6])
    """
    order = sorted((ln for ln in range(1, n_lanes + 1) if ln != athlete_lane),
                   key=lambda ln: (abs(ln - athlete_lane), ln))
    return order[:n]


def simulate_rivals(config: SynthConfig, seed, motion: RunnerMotion, start_x_m):
    """``config.rivals`` other runners next to the athlete (:func:`rival_lanes`): the same running
    style, speeds within 3 % of the athlete's, 2.5 m ahead or behind at most (a close race, where
    they overlap the athlete in the image most), statures 1.60-1.95 m, a kit from
    :data:`RIVAL_KITS` and a skin tone from :data:`RIVAL_SKINS`.  Their random numbers are their
    own, so the athlete, the cameras and the keypoints are those of the clip without rivals.
    ``start_x_m``: where the athlete starts (the rivals start within 2.5 m of it)."""
    out = []
    for k, lane in enumerate(rival_lanes(config.athlete_lane, int(config.rivals))):
        rng = np.random.default_rng([int(seed), 611953, k])
        anthro = Anthropometry.from_stature(_u(rng, 1.60, 1.95), rng=rng)
        gait = gait_for_style(config.style, rng=rng, speed_mps=motion.gait.speed_mps * _u(rng, 0.97, 1.03))
        lane_y = float(lane_center_y(lane)) + rng.uniform(-0.15, 0.15)
        m = simulate_runner(anthro, gait, config.n_frames, config.fps, rng=rng,
                            start_x_m=start_x_m + _u(rng, -2.5, 2.5), lane_y_m=lane_y, start_phase=rng.uniform())
        shirt, shorts = RIVAL_KITS[int(rng.integers(len(RIVAL_KITS)))]
        skin = RIVAL_SKINS[int(rng.integers(len(RIVAL_SKINS)))]
        out.append(Rival(lane=lane, motion=m,
                         style=replace(config.render, shirt_bgr=shirt, shorts_bgr=shorts, skin_bgr=skin)))
    return tuple(out)


def synthesize(config: SynthConfig, seed=0, preset=None):
    """Simulate runner, cameras and keypoints (no images).

    Examples
    --------
    >>> clip = synthesize(config_from_preset("run", 3, n_frames=20), seed=3)
    >>> clip.keypoints_px.shape
    (20, 17, 3)
    """
    rng = np.random.default_rng([int(seed), 104729])
    anthro = Anthropometry.from_stature(config.stature_m, rng=rng)
    gait = gait_for_style(config.style, rng=rng, speed_mps=config.speed_mps)
    lane_y = float(lane_center_y(config.athlete_lane)) + rng.uniform(-0.15, 0.15)
    duration = config.n_frames / config.fps
    start_x = config.mid_x_m - gait.speed_mps * duration / 2
    motion = simulate_runner(anthro, gait, config.n_frames, config.fps, rng=rng, start_x_m=start_x,
                             lane_y_m=lane_y, start_phase=rng.uniform())
    cams = simulate_broadcast_cameras(config.camera, motion, config.image_size, config.fps, rng,
                                      lane_y, config.mid_x_m)
    j3 = motion.joints_track_m
    j2 = np.stack([c.project(j) for c, j in zip(cams, j3)])
    pel = j3[:, JOINT_INDEX["pelvis"]]
    depth = np.array([c.track_to_camera(p)[2] for c, p in zip(cams, pel)])
    height_px = np.array([c.focal_px for c in cams]) * anthro.stature_m / depth
    far_left = np.array([np.linalg.norm(j[JOINT_INDEX["l_hip"]] - c.C)
                         > np.linalg.norm(j[JOINT_INDEX["r_hip"]] - c.C) for c, j in zip(cams, j3)])
    kp = noisy_keypoints(j2, height_px, config.noise, rng, far_side_left=far_left)
    return SynthClip(config=config, seed=int(seed), motion=motion, cameras=cams, joints2d_px=j2,
                     keypoints_px=kp, athlete_height_px=height_px, lane_y_m=lane_y, preset=preset,
                     rivals=simulate_rivals(config, seed, motion, start_x) if config.rivals else ())


def _render_chunk(args):
    frames_dir, indices, cam_dicts, joints, stature, style, seeds, size, rivals = args
    for n, (i, cd, j, s) in enumerate(zip(indices, cam_dicts, joints, seeds)):
        cam = Camera.from_dict(cd, image_size=size)
        img = render_background(cam, style=style)
        runners = [(j, stature, style)] + [(rj[n], rs, rst) for rj, rs, rst in rivals]
        if len(runners) > 1:  # the farthest first: nearer runners hide those behind them
            pelvis = JOINT_INDEX["pelvis"]
            runners.sort(key=lambda r: -float(np.linalg.norm(r[0][pelvis] - cam.C)))
        for rj, rs, rst in runners:
            render_runner(img, cam, rj, rs, rst)
        img = finish_image(img, np.random.default_rng(s), style)
        ok = cv2.imwrite(str(Path(frames_dir) / f"{i:06d}.jpg"), img,
                         [cv2.IMWRITE_JPEG_QUALITY, int(style.jpeg_quality)])
        if not ok:
            raise OSError(f"could not write frame {i} to {frames_dir}")
    return len(indices)


def _render_all(clip: SynthClip, frames_dir: Path, jobs):
    cfg = clip.config
    n = cfg.n_frames
    seeds = np.random.SeedSequence([clip.seed, 15485863]).generate_state(n)
    cam_dicts = [c.to_dict() for c in clip.cameras]
    jobs = max(1, min(int(jobs or os.cpu_count() or 1), n))
    chunks = np.array_split(np.arange(n), jobs * 4 if jobs > 1 else 1)
    tasks = [(str(frames_dir), list(map(int, ch)), [cam_dicts[i] for i in ch],
              clip.motion.joints_track_m[ch], cfg.stature_m, cfg.render, list(seeds[ch]),
              cfg.image_size, [(r.motion.joints_track_m[ch], r.motion.anthropometry.stature_m, r.style)
                               for r in clip.rivals]) for ch in chunks if len(ch)]
    if jobs == 1:
        for t in tasks:
            _render_chunk(t)
        return
    with cf.ProcessPoolExecutor(jobs, mp_context=mp.get_context("fork")) as ex:
        list(ex.map(_render_chunk, tasks))


def write_clip(clip: SynthClip, out_dir, images=True, jobs=None, overwrite=False):
    """Write a clip folder (``CLIP_FORMAT.md``) atomically.

    Raises
    ------
    FileExistsError, PermissionError
        When the output folder cannot be (re)placed.
    """
    cfg = clip.config
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        gt = tmp / "groundtruth"
        gt.mkdir()
        if images:
            (tmp / "frames").mkdir()
            _render_all(clip, tmp / "frames", jobs)
        write_json(tmp / "clip.json", {
            "fps": cfg.fps, "image_size": list(cfg.image_size), "athlete_lane": cfg.athlete_lane,
            "lane_width_m": STANDARD_TRACK.lane_width_m, "n_frames": cfg.n_frames,
            "generator": {"name": "probreg.synth", "preset": clip.preset, "seed": clip.seed,
                          "style": cfg.style, **({"rivals": len(clip.rivals)} if clip.rivals else {})},
        })
        if clip.rivals:  # the other runners' truth: lanes, statures, kits and joints (R, F, 17, 3)
            np.save(gt / "rivals_joints3d.npy", np.stack([r.motion.joints_track_m for r in clip.rivals]))
            write_json(gt / "rivals.json", {"rivals": [
                {"lane": r.lane, "stature_m": r.motion.anthropometry.stature_m, "shirt_bgr": list(r.style.shirt_bgr),
                 "shorts_bgr": list(r.style.shorts_bgr), "skin_bgr": list(r.style.skin_bgr)} for r in clip.rivals]})
        write_keypoints_json(tmp / "keypoints2d.json", clip.keypoints_px)
        write_json(gt / "cameras.json", {"frames": [dict(frame=i, **c.to_dict())
                                                    for i, c in enumerate(clip.cameras)]})
        np.save(gt / "joints3d.npy", clip.motion.joints_track_m)
        np.save(gt / "joints2d.npy", clip.joints2d_px)
        np.save(gt / "contacts.npy", clip.motion.contacts)
        np.save(gt / "contact_points.npy", clip.motion.contact_points_track_m)
        a = clip.motion.anthropometry
        write_json(gt / "athlete.json", {
            "stature_m": a.stature_m, "segments_m": a.segments_m(),
            "ankle_height_m": a.ankle_height_m, "style": cfg.style,
            "gait": clip.motion.gait.to_dict(), "lane_y_m": clip.lane_y_m,
            "camera_setup": asdict(cfg.camera),
            "camera_height_m": float(clip.cameras[0].C[2]),
            "athlete_height_px": clip.athlete_height_px,
        })
    return out_dir


def write_suite(name, out_dir, images=True, n_frames=None, jobs=None, overwrite=False):
    """Write every clip of a fixed suite under ``out_dir/<clip name>``; returns the clip folders."""
    if name not in SUITES:
        raise ValueError(f"unknown suite {name!r}; choose from {sorted(SUITES)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for clip_name, preset, seed in SUITES[name]:
        cfg = config_from_preset(preset, seed, n_frames=n_frames)
        clip = synthesize(cfg, seed=seed, preset=preset)
        paths.append(write_clip(clip, out_dir / clip_name, images=images, jobs=jobs,
                                overwrite=overwrite))
    return paths
