"""A 3D running-gait model: anthropometry, running styles, and H36M-17 motion.

The model is kinematic.  Knee flexion and thigh angle follow smooth periodic
curves over the gait cycle, shaped by key values from the running-biomechanics
literature; the pelvis is then *placed* so that the stance ankle never moves
(foot-flat stance) and flights are ballistic.  By construction the segment
lengths are exactly constant and the stance foot does not slide.

Sources
-------
* Segment proportions of stature H: Drillis & Contini (1966) as tabulated in
  Winter, *Biomechanics and Motor Control of Human Movement*, 4th ed. (2009),
  Fig. 4.1: thigh 0.245 H, shank 0.246 H, upper arm 0.186 H, forearm 0.146 H,
  shoulder width 0.259 H, hip-joint height 0.530 H, shoulder height 0.818 H,
  ankle height 0.039 H.  Hip-joint-centre separation 0.10 H (the CMU mocap in
  ``shared/data/mocap`` shows 0.177 m at about 1.75 m).
* Step frequency and contact time against speed: approximate values read from
  Dorn, Schache & Pandy (2012), J. Exp. Biol. 215:1944-1956 (3.5-9 m/s), with
  a 2.5 m/s jogging anchor from the CMU jogging clips (2.5-2.6 steps/s).
* Joint-angle key values (knee about 20 deg at touchdown, 35-45 deg peak in
  stance, 90-130 deg peak in swing rising with speed; hip extension 10-25 deg at
  toe-off, peak flexion 35-80 deg): Novacheck (1998), Gait & Posture 7:77-95,
  Fig. 6-8.  Arm swing and trunk lean (5-15 deg forward, more when faster):
  same source and Hinrichs (1987) for arm swing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from ..geometry import JOINT_INDEX

__all__ = ["Anthropometry", "GaitParams", "RunnerMotion", "STYLES", "gait_for_style", "simulate_runner", "step_frequency_hz", "contact_time_s"]


G_MPS2 = 9.81

# (speed m/s, step frequency steps/s, contact time s); see module docstring
_SPEED_TABLE = np.array([
    [2.5, 2.58, 0.31],
    [3.5, 2.78, 0.27],
    [5.2, 2.92, 0.20],
    [7.0, 3.16, 0.16],
    [8.95, 3.70, 0.12],
])

# proportions of stature (Winter 2009 / Drillis & Contini 1966)
_PROPORTIONS = {
    "thigh": 0.245, "shank": 0.246, "upper_arm": 0.186, "forearm": 0.146,
    "hip_width": 0.100, "shoulder_width": 0.259 * 0.8, "trunk": 0.818 - 0.530,
    "neck": 0.05, "head": 0.10, "ankle_height": 0.039, "ankle_to_ball": 0.075,
}

def step_frequency_hz(speed_mps):
    """Typical step frequency (steps/s) at a running speed (linear interpolation of the table).

    >>> round(float(step_frequency_hz(3.5)), 2)
    2.78
    """
    return np.interp(speed_mps, _SPEED_TABLE[:, 0], _SPEED_TABLE[:, 1])


def contact_time_s(speed_mps):
    """Typical ground-contact time (s) at a running speed.

    >>> round(float(contact_time_s(7.0)), 2)
    0.16
    """
    return np.interp(speed_mps, _SPEED_TABLE[:, 0], _SPEED_TABLE[:, 2])


@dataclass(frozen=True)
class Anthropometry:
    """Segment lengths of one athlete (metres)."""

    stature_m: float
    thigh_m: float
    shank_m: float
    upper_arm_m: float
    forearm_m: float
    hip_width_m: float
    shoulder_width_m: float
    trunk_m: float
    neck_m: float
    head_m: float
    ankle_height_m: float
    ankle_to_ball_m: float

    @classmethod
    def from_stature(cls, stature_m, rng=None, variation=0.03):
        """Proportional anthropometry, optionally with individual variation.

        Parameters
        ----------
        stature_m : float
            Standing height, 1.0-2.5 m.
        rng : numpy.random.Generator, optional
            Source of the individual variation; none without it.
        variation : float
            Relative standard deviation of each proportion.

        Raises
        ------
        ValueError
            If the stature is not plausible.

        Examples
        --------
        >>> round(Anthropometry.from_stature(1.8).thigh_m, 3)
        0.441
        """
        if not np.isfinite(stature_m) or not 1.0 <= stature_m <= 2.5:
            raise ValueError(f"stature must lie in [1.0, 2.5] m, got {stature_m}")
        values = {}
        for name, p in _PROPORTIONS.items():
            scale = 1.0 if rng is None else float(np.clip(1 + variation * rng.standard_normal(), 0.85, 1.15))
            values[f"{name}_m"] = p * stature_m * scale
        return cls(stature_m=float(stature_m), **values)

    def segments_m(self):
        """Segment lengths keyed as :data:`probreg.geometry.skeleton.SEGMENT_BONES`."""
        return {"thigh": self.thigh_m, "shank": self.shank_m, "upper_arm": self.upper_arm_m,
                "forearm": self.forearm_m, "hip_width": self.hip_width_m,
                "shoulder_width": self.shoulder_width_m, "trunk": self.trunk_m,
                "neck": self.neck_m, "head": self.head_m}


@dataclass(frozen=True)
class GaitParams:
    """Parameters of one running style at one speed (angles in degrees)."""

    speed_mps: float
    step_freq_hz: float
    contact_time_s: float
    knee_td_deg: float = 20.0
    knee_stance_peak_deg: float = 42.0
    knee_to_deg: float = 18.0
    knee_swing_peak_deg: float = 105.0
    thigh_td_deg: float = 25.0
    thigh_to_deg: float = -22.0
    thigh_swing_peak_deg: float = 45.0
    trunk_lean_deg: float = 8.0
    arm_swing_deg: float = 35.0
    arm_mean_deg: float = 5.0
    elbow_deg: float = 85.0
    elbow_swing_deg: float = 15.0
    arm_cross_deg: float = 5.0
    pelvis_yaw_deg: float = 5.0
    heel_rise_deg: float = 40.0
    lateral_drift_m: float = 0.05
    # legs off the sagittal plane: the knee medial of the hip, the ankle medial of the knee (m, with
    # the segment vertical), plus a stride-periodic part peaking in mid-stance.  CMU running mocap
    # in shared/data (14 legs): knee 0.4-4.4 cm medial (mean 2.1), ankle 0.1-4.0 cm medial of the
    # knee (mean 1.7), within-clip sd 2-3.4 cm (mean 2.7) (`probreg bench realism`, section e).  Until
    # 0.2.0.dev24 every generated leg swung in its sagittal plane.
    knee_medial_m: float = 0.021
    ankle_medial_m: float = 0.017
    leg_medial_swing_m: float = 0.038
    # stride-to-stride variability (applied when the simulation has an rng), set so that the
    # generated runner matches the CMU running mocap in shared/data on the same measure (sd of
    # the angle curve one stride apart, / sqrt 2: knee 2.1 deg, hip 1.7 deg; deviations
    # decorrelate within ~0.1 s; `probreg bench realism`, section c).  The amplitudes below are
    # larger than those numbers because deviations fade out around touchdown and toe-off.
    # Stride-time CV of about 2 % is typical of healthy runners (e.g. Jordan, Challis & Newell
    # 2006; Meardon et al. 2011).
    stride_var_knee_deg: float = 3.4
    stride_var_thigh_deg: float = 2.6
    stride_var_slow_deg: float = 1.5
    stride_var_arm_deg: float = 2.0
    step_time_cv: float = 0.02

    def __post_init__(self):
        if not (0 < self.speed_mps <= 12):
            raise ValueError(f"running speed must lie in (0, 12] m/s, got {self.speed_mps}")
        if self.step_freq_hz <= 0 or self.contact_time_s <= 0:
            raise ValueError("step frequency and contact time must be positive")
        if self.contact_time_s >= 0.95 / self.step_freq_hz:
            raise ValueError("contact time leaves no flight phase; that is walking, not running")

    def to_dict(self):
        return asdict(self)


def _base_gait(speed_mps):
    """Literature-shaped defaults at a speed (Novacheck 1998; Dorn et al. 2012)."""
    v = float(speed_mps)
    return GaitParams(
        speed_mps=v, step_freq_hz=float(step_frequency_hz(v)), contact_time_s=float(contact_time_s(v)),
        knee_td_deg=float(np.interp(v, [3, 9], [27, 18])),
        knee_stance_peak_deg=float(np.interp(v, [3, 9], [45, 38])),
        knee_to_deg=float(np.interp(v, [3, 9], [20, 22])),
        knee_swing_peak_deg=float(np.interp(v, [3, 5, 9], [105, 112, 128])),
        thigh_swing_peak_deg=float(np.interp(v, [3, 9], [38, 65])),
        trunk_lean_deg=float(np.interp(v, [3, 9], [6, 12])),
        arm_swing_deg=float(np.interp(v, [3, 9], [28, 55])),
        elbow_deg=float(np.interp(v, [3, 9], [90, 80])),
    )


def _jog(v):
    return _base_gait(v)


def _long_step(v):
    g = _base_gait(v)
    return replace(g, step_freq_hz=g.step_freq_hz * 0.85, contact_time_s=g.contact_time_s * 1.05,
                   thigh_swing_peak_deg=g.thigh_swing_peak_deg + 8, knee_td_deg=g.knee_td_deg - 4)


def _high_knee(v):
    g = _base_gait(v)
    return replace(g, step_freq_hz=g.step_freq_hz * 1.08, thigh_swing_peak_deg=80.0,
                   knee_swing_peak_deg=135.0, trunk_lean_deg=3.0)


def _odd_arms(v):
    g = _base_gait(v)
    return replace(g, arm_cross_deg=35.0, arm_swing_deg=g.arm_swing_deg * 0.6, elbow_deg=110.0,
                   elbow_swing_deg=30.0, arm_mean_deg=20.0)


#: Running styles like the seed paper's: name -> (speed range m/s, gait factory).
STYLES = {
    "jog": ((2.6, 3.4), _jog),
    "run": ((4.0, 5.2), _base_gait),
    "fast": ((6.5, 8.5), _base_gait),
    "long_step": ((4.5, 5.5), _long_step),
    "high_knee": ((3.5, 4.5), _high_knee),
    "odd_arms": ((4.0, 5.0), _odd_arms),
}

def gait_for_style(style, rng=None, speed_mps=None):
    """Gait parameters for a named style, with a speed drawn from its range.

    Raises
    ------
    ValueError
        For an unknown style.

    >>> gait_for_style("fast", speed_mps=8.0).speed_mps
    8.0
    """
    if style not in STYLES:
        raise ValueError(f"unknown running style {style!r}; choose from {sorted(STYLES)}")
    (lo, hi), factory = STYLES[style]
    if speed_mps is None:
        speed_mps = 0.5 * (lo + hi) if rng is None else float(rng.uniform(lo, hi))
    g = factory(speed_mps)
    if rng is not None:  # this runner's legs off the sagittal plane (the mocap's range, see GaitParams),
        # from a stream of their own: ``rng`` is not advanced, so every other draw is as before
        own = np.random.Generator(rng.bit_generator.jumped())
        g = replace(g, knee_medial_m=float(own.uniform(0.0, 0.045)), ankle_medial_m=float(own.uniform(0.0, 0.045)),
                    leg_medial_swing_m=float(own.uniform(0.025, 0.05)))
    return g


@dataclass(frozen=True)
class RunnerMotion:
    """Simulated motion.

    Attributes
    ----------
    joints_track_m : ndarray, shape (F, 17, 3)
    contacts : ndarray of bool, shape (F, 2)
        ``[left, right]`` foot on the ground.
    times_s : ndarray, shape (F,)
    anthropometry : Anthropometry
    gait : GaitParams
    touchdowns : list of (time_s, side, ankle_track_m)
    contact_points_track_m : ndarray, shape (F, 2, 3)
        Ball of the foot ``[left, right]`` while that foot is on the ground
        (NaN in the air): the point that must not slide.
    """

    joints_track_m: np.ndarray
    contacts: np.ndarray
    times_s: np.ndarray
    anthropometry: Anthropometry
    gait: GaitParams
    touchdowns: list = field(default_factory=list)
    contact_points_track_m: np.ndarray = None


def _periodic_pchip(knots):
    """Periodic monotone-cubic curve through (phase, value) knots on [0, 1)."""
    knots = np.asarray(sorted(knots), float)
    ph = np.concatenate([knots[:, 0] - 1, knots[:, 0], knots[:, 0] + 1])
    val = np.tile(knots[:, 1], 3)
    curve = PchipInterpolator(ph, val)
    return lambda phase: curve(np.mod(phase, 1.0))


class _LegCurves:
    """Knee flexion and thigh angle (rad) of one leg over the stride phase (0 = touchdown)."""

    def __init__(self, g: GaitParams, thigh_scale: float):
        stride_s = 2.0 / g.step_freq_hz
        beta = g.contact_time_s / stride_s  # duty factor
        sw = 1.0 - beta
        self.beta = beta
        kmin = max(g.knee_td_deg - 5.0, 3.0)
        self.knee = _periodic_pchip([
            (0.0, g.knee_td_deg), (0.4 * beta, g.knee_stance_peak_deg), (beta, g.knee_to_deg),
            (beta + 0.48 * sw, g.knee_swing_peak_deg), (beta + 0.9 * sw, kmin)])
        td, to = g.thigh_td_deg * thigh_scale, g.thigh_to_deg * thigh_scale
        self.thigh = _periodic_pchip([
            (0.0, td), (beta, to), (beta + 0.12 * sw, to - 4.0),
            (beta + 0.80 * sw, max(g.thigh_swing_peak_deg, td + 3.0))])

    def angles_rad(self, phase):
        return np.radians(self.thigh(phase)), np.radians(self.knee(phase))


def _leg_rel(thigh_rad, knee_rad, a: Anthropometry):
    """Ankle relative to hip in the sagittal plane: (forward, up)."""
    fwd = a.thigh_m * np.sin(thigh_rad) + a.shank_m * np.sin(thigh_rad - knee_rad)
    up = -(a.thigh_m * np.cos(thigh_rad) + a.shank_m * np.cos(thigh_rad - knee_rad))
    return fwd, up


def _stance_travel(g, a, scale):
    c = _LegCurves(g, scale)
    f0, _ = _leg_rel(*c.angles_rad(0.0), a)
    f1, _ = _leg_rel(*c.angles_rad(c.beta), a)
    return f0 - f1 + _heel_rise(1.0, g, a)[0]


def _heel_rise(stance_fraction, g, a):
    """Ankle displacement (forward, up) from its foot-flat position while the heel
    rises about the ball of the foot in late stance (heel-off at mid-stance)."""
    p = np.clip((np.asarray(stance_fraction, float) - 0.5) / 0.5, 0.0, 1.0)
    rho = np.radians(g.heel_rise_deg) * p * p * (3 - 2 * p)  # smoothstep
    d, h = a.ankle_to_ball_m, a.ankle_height_m
    r, phi0 = np.hypot(d, h), np.pi - np.arctan2(h, d)
    return d + r * np.cos(phi0 - rho), r * np.sin(phi0 - rho) - h


def _smooth_noise(rng, times, sd, length_s):
    """A stationary Gaussian process (squared-exponential kernel) sampled at ``times``."""
    if sd <= 0:
        return np.zeros(len(times))
    dt = min(0.005, length_s / 4)
    grid = np.arange(times[0] - 4 * length_s, times[-1] + 4 * length_s + dt, dt)
    # convolving white noise with a Gaussian of width l / sqrt(2) gives an SE kernel of length l
    w = length_s / np.sqrt(2)
    k = np.exp(-0.5 * (np.arange(-4 * w, 4 * w + dt, dt) / w) ** 2)
    k /= np.sqrt(np.sum(k**2))
    x = np.convolve(rng.standard_normal(len(grid)), k, mode="same")
    return sd * np.interp(times, grid, x)


def _deviations(rng, t0, t1, g):
    """Per-leg stride-to-stride deviations (rad) of thigh and knee and of the arm swing and
    elbow, as functions of time: a fast part (decorrelates within ~0.1 s) and a slow one."""
    times = np.arange(t0, t1 + 0.01, 0.005)
    out = {}
    for side in (0, 1):
        for name, sd in (("thigh", g.stride_var_thigh_deg), ("knee", g.stride_var_knee_deg),
                         ("arm", g.stride_var_arm_deg), ("elbow", g.stride_var_arm_deg)):
            out[name, side, "fast"] = np.radians(_smooth_noise(rng, times, sd, 0.06))
            out[name, side, "slow"] = np.radians(_smooth_noise(rng, times, g.stride_var_slow_deg, 0.5))

    def dev(t, name, side, phase=None, beta=None):
        d = np.interp(t, times, out[name, side, "fast"] + out[name, side, "slow"])
        if phase is not None:
            # touchdown and toe-off follow the template (the pelvis's ballistic flight is
            # fixed by them): deviations fade in and out around both events, so that the
            # swing foot clears the ground and the stance foot stays put
            p = np.mod(phase, 1.0)
            # (in phase units, scaled by the width of each fade: 0.1 after touchdown and
            # around toe-off, 0.25 before touchdown, where the foot descends to the ground)
            dist = np.minimum(np.minimum(p / 0.1, (1.0 - p) / 0.25), np.abs(p - beta) / 0.1)
            x = np.clip(dist, 0.0, 1.0)
            d = d * x * x * (3 - 2 * x)
        return d

    return dev


def _clearance_flexion(hip, thigh_rad, knee_rad, swing, a, floor_m=0.035):
    """Extra swing-knee flexion (rad) that keeps the swing ankle at least ``floor_m`` above the
    ground (the stride-to-stride deviations of the stance leg can lower the pelvis), smoothed
    over time as a runner would flex the knee for toe clearance."""
    extra = np.zeros(len(knee_rad))
    steps = np.radians(np.arange(0.0, 40.5, 0.5))
    z = hip[:, None, 2] - a.thigh_m * np.cos(thigh_rad)[:, None] \
        - a.shank_m * np.cos(thigh_rad[:, None] - knee_rad[:, None] - steps[None])
    low = swing & (z[:, 0] < floor_m)
    if not low.any():
        return extra
    ok = z >= floor_m
    first = np.where(ok.any(1), np.argmax(ok, 1), len(steps) - 1)
    extra[low] = steps[first[low]]
    extra = gaussian_filter1d(maximum_filter1d(extra, 5), 1.0)
    return np.where(swing, extra, 0.0)


def simulate_runner(anthropometry, gait, n_frames, fps=50.0, rng=None, start_x_m=0.0,
                    lane_y_m=-3.05, start_phase=0.0):
    """Simulate a runner on the straight, running in ``+x`` along ``y = lane_y_m``.

    Parameters
    ----------
    anthropometry : Anthropometry
    gait : GaitParams
    n_frames : int
    fps : float
    rng : numpy.random.Generator, optional
        Drives the lateral drift and the stride-to-stride variability (step times and
        joint-angle deviations, see :class:`GaitParams`); none without it (every stride
        is then identical).
    start_x_m, lane_y_m : float
        Pelvis position at the first frame (x) and the line of travel (y).
    start_phase : float
        Right-leg stride phase at the first frame, in [0, 1).

    Returns
    -------
    RunnerMotion

    Raises
    ------
    ValueError
        For non-positive frame counts or frame rates.

    Examples
    --------
    >>> m = simulate_runner(Anthropometry.from_stature(1.8), gait_for_style("run"), 100)
    >>> m.joints_track_m.shape, m.contacts.shape
    ((100, 17, 3), (100, 2))
    """
    if int(n_frames) <= 0 or not fps > 0:
        raise ValueError("n_frames and fps must be positive")
    a, g = anthropometry, gait
    # choose the thigh-angle scale so that the hip travels speed * contact time over the stance
    target = g.speed_mps * g.contact_time_s
    scales = np.linspace(0.8, 1.3, 51)
    travels = np.array([_stance_travel(g, a, s) for s in scales])
    scale = float(np.interp(target, travels, scales))
    if target > travels[-1] or target < travels[0]:
        # out of reach of plausible leg angles: let the contact time follow the geometry
        scale = float(np.clip(scale, scales[0], scales[-1]))
        g = replace(g, contact_time_s=float(_stance_travel(g, a, scale) / g.speed_mps))
    curves = _LegCurves(g, scale)
    step_s = 1.0 / g.step_freq_hz
    stride_s = 2 * step_s
    tc = g.contact_time_s
    travel = _stance_travel(g, a, scale)
    v_flight = (g.speed_mps * step_s - travel) / (step_s - tc)

    times = np.arange(int(n_frames)) / fps
    t_first = -(start_phase % 1.0) * stride_s - stride_s  # a right touchdown before the clip
    n_steps = int(np.ceil((times[-1] - t_first) / (0.9 * step_s))) + 3
    drift_knots = np.cumsum((rng.standard_normal(n_steps) if rng is not None else np.zeros(n_steps))
                            * g.lateral_drift_m / 3)
    drift_knots -= drift_knots[min(2, n_steps - 1)]
    # touchdown times: step durations vary from step to step (contact time in proportion)
    jitter = rng.standard_normal(n_steps) if rng is not None else np.zeros(n_steps)
    steps = step_s * np.clip(1.0 + g.step_time_cv * jitter, 0.8, 1.2)
    t_tds = t_first + np.concatenate([[0.0], np.cumsum(steps)])  # n_steps + 1 touchdowns
    dev = _deviations(rng, t_first, t_tds[-1], g) if rng is not None else None
    knots_t = [t_tds[0::2], t_tds[1::2]]  # right touchdowns (phase 0, 1, ...), left ones

    def phase_of(t, side):  # side 0 = right, 1 = left; piecewise linear between touchdowns
        kt = knots_t[side]
        ph = np.arange(len(kt), dtype=float)
        t = np.asarray(t, float)
        before = ph[0] + (t - kt[0]) / stride_s
        after = ph[-1] + (t - kt[-1]) / stride_s
        return np.where(t < kt[0], before, np.where(t > kt[-1], after, np.interp(t, kt, ph)))

    def leg_angles(t, side):
        ph = phase_of(t, side)
        th, kn = curves.angles_rad(ph)
        if dev is not None:
            th = th + dev(t, "thigh", side, ph, curves.beta)
            kn = np.maximum(kn + dev(t, "knee", side, ph, curves.beta), np.radians(1.0))
        return th, kn

    def hip_offset(t, side):
        # pelvic yaw: the hip of the swinging leg comes forward (Novacheck 1998)
        psi = np.radians(g.pelvis_yaw_deg) * np.cos(2 * np.pi * (phase_of(t, 0) - 0.95))
        lateral = (-0.5 if side == 0 else 0.5) * a.hip_width_m
        return np.stack([-lateral * np.sin(psi), lateral * np.cos(psi)], -1)  # (x, y)

    def leg_vectors(t, side, th=None, kn=None):
        """Hip -> knee and knee -> ankle (n, 3): the sagittal leg turned medially about the
        forward axis (the right leg's medial side is +y)."""
        ph = phase_of(t, side)
        if th is None:
            th, kn = leg_angles(t, side)
        swing = g.leg_medial_swing_m * np.cos(2 * np.pi * (ph - 0.15))
        vecs = []
        for length, ang, medial in ((a.thigh_m, th, g.knee_medial_m), (a.shank_m, th - kn, g.ankle_medial_m)):
            phi = np.arcsin(np.clip((medial + swing) / length, -0.5, 0.5)) * (1.0 if side == 0 else -1.0)
            down = length * np.cos(ang)
            vecs.append(np.stack([length * np.sin(ang), down * np.sin(phi), -down * np.cos(phi)], -1))
        return vecs

    def ankle_rel(t, side):
        v1, v2 = leg_vectors(np.atleast_1d(t), side)
        return (v1 + v2)[0] if np.ndim(t) == 0 else v1 + v2

    def leg_height(t, side):
        return -ankle_rel(t, side)[2]

    pelvis = np.full((len(times), 3), np.nan)
    stance_side = np.full(len(times), -1)
    balls = np.full((len(times), 2, 3), np.nan)  # ball of the stance foot, [right, left]
    touchdowns = []
    # pelvis at the first touchdown
    p_td = np.array([start_x_m - g.speed_mps * (0 - t_first), lane_y_m,
                     a.ankle_height_m + leg_height(t_tds[0], 0)])
    for k in range(n_steps):
        side = k % 2
        t_td, t_next = t_tds[k], t_tds[k + 1]
        tc_k = tc * (t_next - t_td) / step_s
        t_to = t_td + tc_k
        off = hip_offset(t_td, side)
        rel = ankle_rel(t_td, side)
        ankle = np.array([p_td[0] + off[0] + rel[0], p_td[1] + off[1] + rel[1], a.ankle_height_m])
        touchdowns.append((t_td, "right" if side == 0 else "left", ankle))
        # stance: the pelvis is placed so that the ankle stays put
        sel = (times >= t_td) & (times < t_to)
        if np.any(sel):
            ts = times[sel]
            f, lat, u = ankle_rel(ts, side).T
            o = hip_offset(ts, side)
            hx, hz = _heel_rise((ts - t_td) / tc_k, g, a)
            pelvis[sel] = np.stack([ankle[0] + hx - f - o[:, 0], ankle[1] - lat - o[:, 1],
                                    a.ankle_height_m + hz - u], -1)
            balls[sel, side] = ankle + [a.ankle_to_ball_m, 0.0, -a.ankle_height_m]
            stance_side[sel] = side
        # pelvis at toe-off
        f, lat, u = ankle_rel(t_to, side)
        o = hip_offset(t_to, side)
        hx, hz = _heel_rise(1.0, g, a)
        p_to = np.array([ankle[0] + hx - f - o[0], ankle[1] - lat - o[1], a.ankle_height_m + hz - u])
        # flight: ballistic in z, constant velocity in x, linear drift in y
        t_fl = t_next - t_to
        p_next = np.array([p_to[0] + v_flight * t_fl, lane_y_m + drift_knots[min(k + 1, n_steps - 1)],
                           a.ankle_height_m + leg_height(t_next, 1 - side)])
        vz0 = (p_next[2] - p_to[2] + 0.5 * G_MPS2 * t_fl**2) / t_fl
        sel = (times >= t_to) & (times < t_next)
        if np.any(sel):
            dt = times[sel] - t_to
            pelvis[sel] = np.stack([p_to[0] + v_flight * dt,
                                    p_to[1] + (p_next[1] - p_to[1]) * dt / t_fl,
                                    p_to[2] + vz0 * dt - 0.5 * G_MPS2 * dt**2], -1)
        p_td = p_next

    joints = np.zeros((len(times), 17, 3))
    J = JOINT_INDEX
    joints[:, J["pelvis"]] = pelvis
    for side, prefix in ((0, "r"), (1, "l")):
        o = hip_offset(times, side)
        hip = pelvis + np.concatenate([o, np.zeros((len(times), 1))], -1)
        th, kn = leg_angles(times, side)
        if dev is not None:
            kn = kn + _clearance_flexion(hip, th, kn, stance_side != side, a)
        v1, v2 = leg_vectors(times, side, th, kn)
        knee = hip + v1
        ankle = knee + v2
        joints[:, J[f"{prefix}_hip"]] = hip
        joints[:, J[f"{prefix}_knee"]] = knee
        joints[:, J[f"{prefix}_ankle"]] = ankle
    _upper_body(joints, times, phase_of, a, g, dev)
    contacts = np.stack([stance_side == 1, stance_side == 0], -1)
    return RunnerMotion(joints_track_m=joints, contacts=contacts, times_s=times,
                        anthropometry=a, gait=g, touchdowns=touchdowns,
                        contact_points_track_m=balls[:, ::-1])


def _upper_body(joints, times, phase_of, a, g, dev=None):
    J = JOINT_INDEX
    pelvis = joints[:, J["pelvis"]]
    phr = phase_of(times, 0)
    lean = np.radians(g.trunk_lean_deg + 1.5 * np.sin(4 * np.pi * phr))
    up = np.stack([np.sin(lean), np.zeros_like(lean), np.cos(lean)], -1)  # trunk line
    ahead = np.stack([np.cos(lean), np.zeros_like(lean), -np.sin(lean)], -1)  # forward, normal to trunk
    thorax = pelvis + a.trunk_m * up
    joints[:, J["thorax"]] = thorax
    joints[:, J["spine"]] = pelvis + 0.5 * a.trunk_m * up
    head_lean = 0.5 * lean
    up_head = np.stack([np.sin(head_lean), np.zeros_like(lean), np.cos(head_lean)], -1)
    joints[:, J["neck"]] = thorax + a.neck_m * up_head
    joints[:, J["head"]] = joints[:, J["neck"]] + a.head_m * up_head
    # shoulders counter-rotate against the pelvis
    chi = -1.5 * np.radians(g.pelvis_yaw_deg) * np.cos(2 * np.pi * (phr - 0.95))
    left_dir = np.stack([-np.sin(chi), np.cos(chi), np.zeros_like(chi)], -1)
    for side, prefix, sign in ((0, "r", -1.0), (1, "l", 1.0)):
        shoulder = thorax + sign * 0.5 * a.shoulder_width_m * left_dir
        ph = phase_of(times, side)
        # the arm is forward when the same-side thigh is back (around toe-off)
        alpha = np.radians(g.arm_mean_deg + g.arm_swing_deg * np.cos(2 * np.pi * (ph - 0.45)))
        elbow_flex = np.radians(g.elbow_deg + g.elbow_swing_deg * np.cos(2 * np.pi * (ph - 0.45)))
        if dev is not None:
            alpha = alpha + dev(times, "arm", side)
            elbow_flex = elbow_flex + dev(times, "elbow", side)
        cross = np.radians(g.arm_cross_deg) * (0.5 + 0.5 * np.cos(2 * np.pi * (ph - 0.45)))
        inward = -sign * left_dir  # towards the body midline
        upper = -up * np.cos(alpha)[:, None] + ahead * np.sin(alpha)[:, None]
        upper = upper * np.cos(cross)[:, None] + inward * np.sin(cross)[:, None] * 0.5
        upper /= np.linalg.norm(upper, axis=-1, keepdims=True)
        beta = alpha + elbow_flex
        fore = -up * np.cos(beta)[:, None] + ahead * np.sin(beta)[:, None]
        fore = fore + inward * np.sin(cross)[:, None]
        fore /= np.linalg.norm(fore, axis=-1, keepdims=True)
        elbow = shoulder + a.upper_arm_m * upper
        joints[:, J[f"{prefix}_shoulder"]] = shoulder
        joints[:, J[f"{prefix}_elbow"]] = elbow
        joints[:, J[f"{prefix}_wrist"]] = elbow + a.forearm_m * fore
