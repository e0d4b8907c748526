"""Ground contacts and the athlete's line of travel: ray-cast feet, Kalman filter, RTS smoother.

A foot in contact is momentarily still on the ground: its ankle, cast onto
the plane of the ankle height, stops moving while the athlete runs on.  A
swinging ankle cast onto that plane lands beyond the athlete and moves at
about twice the running speed.  Each contact gives one point; a
constant-velocity Kalman filter with an RTS smoother (``filterpy``) over
those points yields the athlete's ground track in every frame, flight phases
included, with a covariance, the running direction ``f`` and so the sagittal
plane.  The filter's log-likelihood measures how smooth a runner's path this
camera hypothesis implies (the Bayesian model uses it).
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..geometry import JOINT_INDEX
from .kalman import forward_pass_batch, gated_forward_pass, rts_backward, rts_backward_batch

__all__ = ["GroundTrack", "TrackConfig", "camera_track_config", "cast_ankles", "detect_contacts", "fit_ground_track",
           "fit_ground_tracks", "sagittal_ankle_points", "sagittal_ankle_height", "gate_contacts_by_height",
           "gated_forward_pass", "rts_backward"]


@dataclass(frozen=True)
class TrackConfig:
    """Noise model of the ground-track filter.

    Attributes
    ----------
    accel_std_mps2 : (float, float)
        Process noise (white acceleration) along and across the track: a runner
        on a straight changes speed a little and drifts laterally even less.
    contact_std_m : (float, float)
        Scatter of a contact point about the athlete's track at mid-stance, along
        (foot placement ahead of or behind the centre of mass) and across (after
        removing half the step width, estimated from the clip's left and right contacts).
    contact_speed_frac : float
        A cast ankle slower than this fraction of the running speed is in contact.
    min_contact_frames : int
    max_gap_s : float
        Two contacts of one foot closer in time than this are one stance: a foot
        cannot swing through in 0.1 s (a runner's swing takes 0.25 s or more), and a
        stance split in two gives two footprints at one place a few frames apart,
        which read as the athlete standing still.
    contact_height_margin_m : float or None
        Height gate on the ends of each detected contact: frames where the ankle, cast onto
        the athlete's vertical sagittal plane, is more than this above its median height in
        contact are cut from the start and end of the contact.  In late swing a runner
        pulls the foot back towards the ground speed (foot retraction), so the speed test
        alone takes the last frames before touchdown (ankle still ~0.2 m up) for contact;
        this made contacts 50-80 ms too long for high and telephoto views.  0.06 m was
        chosen on the benchmark suite (``reports/bench_posterior.md``); None disables it.
    max_rejected_run : int
        Contacts whose innovation fails the filter's 4-sigma gate are skipped, but after
        this many in a row the next one re-starts the filter from it (position and
        velocity as uncertain as at the start): once the filter's velocity is wrong,
        every later footprint fails the gate, and without a restart the track coasts at
        that velocity to the end of the clip.
    """

    accel_std_mps2: tuple = (1.5, 0.6)
    contact_std_m: tuple = (0.10, 0.03)
    contact_speed_frac: float = 0.35
    min_contact_frames: int = 2
    max_gap_s: float = 0.1
    contact_height_margin_m: float | None = 0.06
    max_rejected_run: int = 2


def camera_track_config(cams, pelvis_px, noise_px):
    """Contact-point noise of the ground-track filter under one camera hypothesis: the foot
    placement of :class:`TrackConfig` plus the keypoint noise (``noise_px``, per coordinate) cast
    onto the ground, across the track magnified by the camera's grazing view.

    ``cams``: per-frame :class:`~probreg.geometry.CameraArrays`; ``pelvis_px`` (F, 2).  Where it
    cannot be computed (no camera, no pelvis in a frame that has one, unknown noise) the default
    :class:`TrackConfig`.
    """
    from ..geometry import pixel_rays

    base = TrackConfig()
    if not np.any(cams.valid) or not np.isfinite(noise_px):
        return base
    rays = pixel_rays(cams, np.asarray(pelvis_px, float)[:, None, :])[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all NaN: no pelvis where there are cameras
        depth = np.nanmedian(-cams.C[:, 2] / rays[:, 2])
        sin_tilt = np.nanmedian(np.abs(rays[:, 2]))
        along = noise_px * depth / np.nanmedian(cams.focal_px)
    across = along / max(sin_tilt, 0.02)
    if not (np.isfinite(along) and np.isfinite(across)):
        return base
    return TrackConfig(contact_std_m=(float(np.hypot(base.contact_std_m[0], along)),
                                      float(np.hypot(base.contact_std_m[1], across))))


#: largest heading (deg) of a runner's track from the straight's direction ``+x``: a runner keeps to
#: the lane (a lane change over a few strides, as when the 800 m breaks, turns the track by ~5-10 deg)
MAX_HEADING_DEG = 20.0


@dataclass(frozen=True)
class GroundTrack:
    """The athlete's ground track (track frame, metres).

    Attributes
    ----------
    position_m, velocity_mps : ndarray, shape (F, 2)
        Smoothed ``(x, y)`` and its rate.
    cov : ndarray, shape (F, 4, 4)
        Covariance of ``(x, vx, y, vy)``.
    contacts : ndarray of bool, shape (F, 2)
        ``[left, right]`` foot on the ground.
    contact_points_m : ndarray, shape (K, 4)
        ``(frame, side, x, y)`` of every contact (side 0 = left, 1 = right).
    log_likelihood : float
        Sum of the filter's measurement log-likelihoods.
    status : str
        ``ok`` or the reason the track is a fallback (``few_contacts``, ``no_feet``).
    half_step_m : float
        Half the lateral distance between left and right footprints.
    """

    position_m: np.ndarray
    velocity_mps: np.ndarray
    cov: np.ndarray
    contacts: np.ndarray
    contact_points_m: np.ndarray
    log_likelihood: float
    status: str = "ok"
    half_step_m: float = 0.0

    @property
    def forward(self):
        """Unit running direction per frame, shape (F, 3) (horizontal): the track's heading, or
        the straight's direction ``+x`` where the heading is more than :data:`MAX_HEADING_DEG` from
        it (:meth:`off_heading`)."""
        v = self.velocity_mps
        n = np.linalg.norm(v, axis=1, keepdims=True)
        f = np.where(n > 1e-6, v / np.maximum(n, 1e-12), [1.0, 0.0])
        f = np.where(self.off_heading()[:, None], [1.0, 0.0], f)
        return np.column_stack([f, np.zeros(len(f))])

    def off_heading(self):
        """Frames (F,) whose track heading is more than :data:`MAX_HEADING_DEG` from ``+x``.

        The track frame's ``x`` is the running direction on the straight (``CLIP_FORMAT.md``), and
        a runner keeps to the lane, so such a heading is the filter's, not the athlete's: a track
        run backwards or sideways from contacts too few or too noisy to give its velocity (a
        low grazing view, where a pixel moves a cast foot metres along the ray).  Reversed, the
        running direction would turn every hip angle and the trunk lean into their negatives.

        >>> nan = np.full((3, 4, 4), np.nan)
        >>> tr = GroundTrack(np.zeros((3, 2)), np.array([[7.0, 0.2], [-9.0, 0.1], [0.5, 3.0]]), nan,
        ...                  np.zeros((3, 2), bool), np.zeros((0, 4)), 0.0)
        >>> tr.off_heading().tolist(), tr.forward[:, 0].round(3).tolist()
        ([False, True, True], [1.0, 1.0, 1.0])
        """
        v = np.asarray(self.velocity_mps, float)
        with np.errstate(invalid="ignore"):
            return v[:, 0] < math.cos(math.radians(MAX_HEADING_DEG)) * np.hypot(v[:, 0], v[:, 1])

    @property
    def left(self):
        """Unit left direction per frame (``z x f``), the sagittal plane's normal, shape (F, 3)."""
        f = self.forward
        return np.column_stack([-f[:, 1], f[:, 0], np.zeros(len(f))])


def _rays(cameras, pts_px):
    """Per-frame rays: origins (F, 3) and unit directions (F, K, 3); NaN where no camera.

    ``cameras`` is a list of Camera/None or a :class:`probreg.lifting.CameraArrays`.
    """
    from ..geometry import CameraArrays, camera_arrays, pixel_rays

    arr = cameras if isinstance(cameras, CameraArrays) else camera_arrays(cameras)
    return arr.C, pixel_rays(arr, pts_px)


def cast_ankles(cameras, keypoints_px, ankle_height_m=0.07):
    """Ankles ``[left, right]`` cast onto the plane ``z = ankle_height_m``: (F, 2, 3), NaN if missing."""
    kp = np.asarray(keypoints_px, float)[:, [JOINT_INDEX["l_ankle"], JOINT_INDEX["r_ankle"]], :2]
    o, d = _rays(cameras, kp)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (ankle_height_m - o[:, None, 2]) / d[..., 2]
    t = np.where(t > 0, t, np.nan)
    return o[:, None, :] + t[..., None] * d


def detect_contacts(ankles_m, fps, config: TrackConfig = TrackConfig(), camera_xy=None):
    """Contact flags ``[left, right]`` (F, 2) from the along-track speed of the cast ankles.

    Only the component along the running direction is used: across the track
    (in depth, for a broadcast camera) a cast point inherits the keypoint noise
    amplified by the grazing view of the ground, along the track it does not.

    With the camera's ground position ``camera_xy`` (F, 2), the along-track speed
    is read from the ankle's motion *across the viewing ray* only (divided by the
    share of the running direction across the ray).  Along the ray a cast point
    also moves when the ankle merely rises or sinks (by ``dz / tan(elevation)``),
    which for a low camera looking obliquely along the straight is metres per
    second during stance and hides every contact.  Frames seen nearly along the
    running direction (share < 0.3) keep the plain along-track speed.
    """
    F = len(ankles_m)
    xy = ankles_m[..., :2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN frames stay NaN
        body = np.nanmean(xy, axis=1)
    ok = np.all(np.isfinite(body), -1)
    direction = np.array([1.0, 0.0])
    if ok.sum() >= 2:
        d = body[np.flatnonzero(ok)[-1]] - body[np.flatnonzero(ok)[0]]
        if np.linalg.norm(d) > 1e-6:
            direction = d / np.linalg.norm(d)
    along = xy @ direction  # (F, 2)
    # 5-frame smoothed central difference (nan-aware): speed along the track
    speed = np.full((F, 2), np.nan)
    if F >= 5:
        speed[2:-2] = (along[4:] - along[:-4]) * fps / 4
    elif F >= 3:
        speed[1:-1] = (along[2:] - along[:-2]) * fps / 2
    if camera_xy is not None and F >= 5:
        ray = xy - np.asarray(camera_xy, float)[:, None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            ray = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
            across = np.stack([-ray[..., 1], ray[..., 0]], -1)  # (F, 2, 2): unit, across the ray
            share = across @ direction  # running direction's component across the ray
            vel = np.full((F, 2, 2), np.nan)
            vel[2:-2] = (xy[4:] - xy[:-4]) * fps / 4
            est = np.sum(vel * across, -1) / share
        use = np.isfinite(est) & (np.abs(share) >= 0.3)
        speed = np.where(use, est, speed)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # no finite speed at all: NaN, the default below
        run = np.nanmedian(np.abs(np.diff(body @ direction))) * fps if ok.sum() > 1 else np.nan
        run = np.nanmedian(np.abs(speed)) if not np.isfinite(run) else run
    thr = config.contact_speed_frac * run if np.isfinite(run) and run > 0.5 else 1.0
    with np.errstate(invalid="ignore"):
        contact = np.abs(speed) < thr
    out = np.zeros((F, 2), bool)
    max_gap = int(np.floor(config.max_gap_s * fps))
    for s in (0, 1):
        edges = np.diff(np.concatenate([[0], contact[:, s].astype(int), [0]]))
        runs = list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))
        merged = []
        for a, b in runs:  # one stance split by a few noisy frames is still one stance
            if merged and a - merged[-1][1] <= max_gap:
                merged[-1] = (merged[-1][0], b)
            else:
                merged.append((a, b))
        for a, b in merged:
            if b - a >= config.min_contact_frames:
                out[a:b, s] = True
    return out


def fit_ground_track(cameras, keypoints_px, fps, ankle_height_m=0.07, config: TrackConfig = TrackConfig(),
                     contacts=None):
    """Contacts and the Kalman/RTS-smoothed ground track of the athlete.

    Parameters
    ----------
    cameras : list of Camera or None (length F), or CameraArrays
    keypoints_px : ndarray, shape (F, 17, 3)
        H36M-17 keypoints; NaN = missing.
    fps : float
    ankle_height_m : float
        Height of the ankle joint centre above the ground in stance.
    contacts : ndarray of bool (F, 2), optional
        Fixed contact flags (e.g. detected once for a reference camera), so that
        the filter sees the same measurements under every camera hypothesis.

    Returns
    -------
    GroundTrack
    """
    from ..geometry import CameraArrays, camera_arrays

    if not isinstance(cameras, CameraArrays):  # stacked once, used three times below
        cameras = camera_arrays(cameras)
    F = len(keypoints_px)
    ankles = cast_ankles(cameras, keypoints_px, ankle_height_m)
    if contacts is not None:
        return _track_from_contacts(ankles, np.asarray(contacts, bool), fps, config)
    contacts = detect_contacts(ankles, fps, config, camera_xy=_rays(cameras, np.zeros((F, 0, 2)))[0][:, :2])
    first = _track_from_contacts(ankles, contacts, fps, config)
    if config.contact_height_margin_m is None or first.status != "ok":
        return first
    z = sagittal_ankle_height(cameras, keypoints_px, first)
    gated = gate_contacts_by_height(contacts, z, config.contact_height_margin_m, config.min_contact_frames)
    if np.array_equal(gated, contacts) or not gated.any():
        return first
    return _track_from_contacts(ankles, gated, fps, config)


def sagittal_ankle_points(cameras, keypoints_px, track: GroundTrack):
    """Ankles ``[left, right]`` cast onto the athlete's vertical plane: (F, 2, 3), NaN where missing.

    The plane is the track's line of travel shifted by half the step width to the foot's
    side (left feet land left of it).  A broadcast camera sees this plane nearly face-on,
    so the cast point's height tells a foot in late swing (0.2 m up) from a foot on the
    ground, which the ground plane cannot do, and its along-track position does not move
    when the ankle merely rises.
    """
    kp = np.asarray(keypoints_px, float)[:, [JOINT_INDEX["l_ankle"], JOINT_INDEX["r_ankle"]], :2]
    o, d = _rays(cameras, kp)
    y0 = track.position_m[:, 1][:, None] + np.array([1.0, -1.0]) * track.half_step_m
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (y0 - o[:, None, 1]) / d[..., 1]
        P = o[:, None, :] + t[..., None] * d
    return np.where((np.isfinite(t) & (t > 0))[..., None], P, np.nan)


def sagittal_ankle_height(cameras, keypoints_px, track: GroundTrack):
    """Height (m) of each ankle ``[left, right]`` on the athlete's vertical plane
    (:func:`sagittal_ankle_points`): (F, 2), NaN where missing."""
    return sagittal_ankle_points(cameras, keypoints_px, track)[..., 2]


def gate_contacts_by_height(contacts, height_m, margin_m, min_frames=2):
    """Cut frames from the start and end of every contact while the ankle is too high.

    ``height_m`` (F, 2) is the ankle height (e.g. :func:`sagittal_ankle_height`); a frame
    is too high when it exceeds the median height over all contact frames by more than
    ``margin_m``.  Frames inside a contact are kept (a noisy frame does not split a
    stance); contacts left shorter than ``min_frames`` are dropped.

    >>> c = np.array([[0, 1, 1, 1, 1, 1, 0]] * 2, bool).T
    >>> z = np.array([[0.3, 0.2, 0.07, 0.3, 0.08, 0.09, 0.3]] * 2).T
    >>> gate_contacts_by_height(c, z, 0.05)[:, 0].astype(int).tolist()
    [0, 0, 1, 1, 1, 1, 0]
    """
    c = np.asarray(contacts, bool)
    z = np.asarray(height_m, float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = np.nanmedian(z[c]) if c.any() else np.nan
    if not np.isfinite(ref):
        return c.copy()
    high = np.nan_to_num(z, nan=-np.inf) > ref + margin_m  # a missing height does not cut
    out = np.zeros_like(c)
    for s in range(c.shape[1]):
        for a, b in _runs(c[:, s]):
            while a < b and high[a, s]:
                a += 1
            while b > a and high[b - 1, s]:
                b -= 1
            if b - a >= min_frames:
                out[a:b, s] = True
    return out


@dataclass(frozen=True)
class _TrackSetup:
    """What the ground-track filter of one hypothesis runs on (:func:`_track_setup`)."""

    meas: dict  # frame -> 2-D measurement
    R: np.ndarray  # (2, 2) measurement covariance
    x0: np.ndarray  # (4,) start state [x, vx, y, vy]
    P0: np.ndarray  # (4,) start variances
    cps: np.ndarray
    status: str
    half_step: float
    dt: float
    F: np.ndarray
    Q: np.ndarray

    @property
    def first(self):
        return min(self.meas)

    def track(self, xs, Ps, loglik, contacts):
        return GroundTrack(position_m=xs[:, [0, 2]], velocity_mps=xs[:, [1, 3]], cov=Ps, contacts=contacts,
                           contact_points_m=self.cps, log_likelihood=loglik, status=self.status,
                           half_step_m=self.half_step)


@functools.lru_cache(maxsize=16)
def _motion_model(fps, accel_std_mps2):
    """``(dt, F, Q)`` of the ground track's two constant-velocity axes (read-only arrays, made
    once per frame rate and process noise)."""
    from filterpy.common import Q_discrete_white_noise

    dt = 1.0 / fps
    Q = np.zeros((4, 4))
    Q[:2, :2] = Q_discrete_white_noise(2, dt=dt, var=accel_std_mps2[0] ** 2)
    Q[2:, 2:] = Q_discrete_white_noise(2, dt=dt, var=accel_std_mps2[1] ** 2)
    F = np.kron(np.eye(2), np.array([[1.0, dt], [0.0, 1.0]]))
    F.flags.writeable = Q.flags.writeable = False
    return dt, F, Q


def _track_setup(ankles, contacts, fps, config, cps=None):
    """The measurements, noise and start of the ground-track filter from cast ankles (F, 2, 3)
    and fixed contact flags (``cps``: their contact points when known): a :class:`_TrackSetup`,
    or the finished all-NaN :class:`GroundTrack` when there is nothing to measure."""
    F = len(ankles)
    cps = _contact_points_many([ankles], contacts)[0] if cps is None else cps
    if len(cps) >= 3:
        # athletes keep to their lane: a "contact" far off the clip's median lateral position
        # is a swinging foot cast beyond the athlete, not a footprint
        off = np.abs(cps[:, 3] - np.median(cps[:, 3]))
        cps = cps[off < max(0.5, 4 * 1.4826 * np.median(off))]
    status = "ok"
    R_meas = np.diag(np.square(np.asarray(config.contact_std_m)))
    # left feet land left of the line of travel, right feet right of it: remove half the
    # step width (estimated from the clip) so that contacts measure the centre line
    half_step = 0.0
    lat = np.array([0.0, 1.0])  # on the straight the athlete runs along x: lateral is y
    if len(cps) >= 2 and (cps[:, 1] == 0).any() and (cps[:, 1] == 1).any():
        off = cps[:, 2:] @ lat
        half_step = 0.5 * (np.median(off[cps[:, 1] == 0]) - np.median(off[cps[:, 1] == 1]))
        half_step = float(np.clip(half_step, 0.0, 0.25))
        centred = cps[:, 2:] - np.where(cps[:, 1:2] == 0, 1.0, -1.0) * half_step * lat
    else:
        centred = cps[:, 2:]
    meas = {int(round(c[0])): p for c, p in zip(cps, centred)}
    if len(cps) < 2:
        # fallback: per-frame mean of the cast ankles, heavily de-weighted
        status = "few_contacts" if np.isfinite(ankles).any() else "no_feet"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            body = np.nanmean(ankles[..., :2], axis=1) if np.isfinite(ankles).any() else np.full((F, 2), np.nan)
        meas = {i: body[i] for i in range(F) if np.all(np.isfinite(body[i]))}
        R_meas = np.diag([0.5**2, 0.3**2])
    keys = sorted(meas)
    if not keys:
        nan = np.full((F, 2), np.nan)
        return GroundTrack(nan, nan, np.full((F, 4, 4), np.nan), contacts, cps, -np.inf, "no_feet")
    dt, Fm, Q = _motion_model(float(fps), tuple(config.accel_std_mps2))
    # initial state from the first measurements
    if len(keys) >= 2:
        k0, k1 = keys[0], keys[-1]
        v0 = (meas[k1] - meas[k0]) / max((k1 - k0) * dt, dt)
    else:
        v0 = np.zeros(2)
    v0[1] = 0.0  # athletes follow their lane: start with no lateral velocity
    p0 = meas[keys[0]] - v0 * keys[0] * dt
    # the lateral start is the footprints' median, as uncertain as their spread: started on
    # the first footprint (a swinging foot taken for a contact, say), the filter would gate
    # out every true footprint after it and keep the athlete in the wrong place
    lat0 = np.array([meas[k][1] for k in keys])
    p0[1] = float(np.median(lat0))
    sd0 = 1.4826 * float(np.median(np.abs(lat0 - p0[1]))) if len(keys) >= 3 else 0.7
    return _TrackSetup(meas=meas, R=R_meas, x0=np.array([p0[0], v0[0], p0[1], v0[1]]),
                       P0=np.array([4.0, 4.0, float(np.clip(sd0, 0.05, 0.7)) ** 2, 0.1**2]), cps=cps,
                       status=status, half_step=half_step, dt=dt, F=Fm, Q=Q)


def _track_from_contacts(ankles, contacts, fps, config):
    """The Kalman/RTS ground track from cast ankles (F, 2, 3) and fixed contact flags."""
    from filterpy.kalman import KalmanFilter

    setup = _track_setup(ankles, contacts, fps, config)
    if isinstance(setup, GroundTrack):
        return setup
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.H, kf.Q, kf.R = setup.F, np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]]), setup.Q, setup.R
    kf.x, kf.P = setup.x0, np.diag(setup.P0)
    xs, Ps, loglik = gated_forward_pass(kf, setup.meas, len(ankles), first=setup.first,
                                        max_rejected_run=config.max_rejected_run)
    xs, Ps = rts_backward(xs, Ps, setup.F, setup.Q)
    return setup.track(xs, Ps, loglik, contacts)


def fit_ground_tracks(cameras, keypoints_px, fps, contacts, configs=None, ankle_height_m=0.07):
    """:func:`fit_ground_track` with fixed ``contacts`` for many hypotheses at once: a list of
    :class:`GroundTrack`, the ``h``-th exactly (to the bit) ``fit_ground_track(cameras[h],
    keypoints_px[h], fps, ankle_height_m, configs[h], contacts)``.

    ``cameras`` and ``keypoints_px`` are sequences of one clip's per-frame cameras (e.g. the cameras
    of every posterior draw or grid height) and keypoints, ``configs`` their :class:`TrackConfig`
    (default: the default for all).  The contacts' points, the Kalman filter and the RTS smoother
    run for all hypotheses together (:func:`probreg.lifting.kalman.forward_pass_batch`,
    :func:`~probreg.lifting.kalman.rts_backward_batch`): one loop over the frames instead of one
    per hypothesis."""
    from ..geometry import CameraArrays, camera_arrays

    configs = [TrackConfig()] * len(cameras) if configs is None else list(configs)
    if not len(cameras) == len(keypoints_px) == len(configs):
        raise ValueError("fit_ground_tracks needs as many keypoint arrays and configs as camera sets")
    if contacts is None:  # each hypothesis detects its own: nothing in common to batch
        return [fit_ground_track(c, k, fps, ankle_height_m, cfg) for c, k, cfg in zip(cameras, keypoints_px, configs)]
    contacts = np.asarray(contacts, bool)
    ankles = [cast_ankles(c if isinstance(c, CameraArrays) else camera_arrays(c), k, ankle_height_m)
              for c, k in zip(cameras, keypoints_px)]
    setups = [_track_setup(a, contacts, fps, cfg, cps=cps)
              for a, cfg, cps in zip(ankles, configs, _contact_points_many(ankles, contacts))]
    out = [s if isinstance(s, GroundTrack) else None for s in setups]
    groups = {}
    for h, s in enumerate(setups):
        if not isinstance(s, GroundTrack):
            groups.setdefault((s.Q.tobytes(), int(configs[h].max_rejected_run)), []).append(h)
    for (_, max_run), idx in groups.items():
        S = [setups[h] for h in idx]
        n = len(ankles[idx[0]])
        z, measured = np.zeros((len(S), n, 2)), np.zeros((len(S), n), bool)
        for g, s in enumerate(S):
            frames = list(s.meas)
            z[g, frames] = [s.meas[k] for k in frames]
            measured[g, frames] = True
        Q = S[0].Q
        xs, Ps, ll = forward_pass_batch(
            np.array([s.x0 for s in S]), np.array([[s.P0[0], 0.0, s.P0[1], s.P0[2], 0.0, s.P0[3]] for s in S]),
            np.array([np.diag(s.R) for s in S]), S[0].dt, ((Q[0, 0], Q[0, 1], Q[1, 1]), (Q[2, 2], Q[2, 3], Q[3, 3])),
            z, measured, np.array([s.first for s in S]), max_rejected_run=max_run)
        xs, Ps = rts_backward_batch(xs, Ps, S[0].F, Q)
        for g, h in enumerate(idx):
            out[h] = S[g].track(xs[g], Ps[g], float(ll[g]), contacts)
    return out


def _contact_points_many(ankles, contacts):
    """The footprints of several hypotheses' cast ankles (a list of (F, 2, 3)) under the same
    contact flags (F, 2): a list of (K_h, 4) arrays ``(run centre frame, side, x, y)`` in the order
    of the centres, one row per contact run with a finite ankle.  Each footprint is the median of
    the run's first half (the foot-flat part: later the heel rises, and the raised ankle, cast onto
    the ankle-height plane, lands beyond the foot), over its frames with a finite ankle."""
    runs = []
    for s in (0, 1):
        for a, b in _runs(contacts[:, s]):
            runs.append(((a + b - 1) / 2, s, a, a + max(1, (b - a + 1) // 2)))
    runs.sort()  # by centre, then side (no two runs share both)
    feet = np.stack([np.asarray(a, float)[..., :2] for a in ankles]) if ankles else np.zeros((0, 0, 2, 2))
    pts = [[] for _ in ankles]
    for centre, s, lo, hi in runs:
        run = feet[:, lo:hi, s]  # (H, m, 2)
        ok = np.all(np.isfinite(run), -1)
        whole = ok.all(1)
        if whole.any():
            for h, (x, y) in zip(np.flatnonzero(whole), np.median(run[whole], axis=1)):
                pts[h].append((centre, s, x, y))
        for h in np.flatnonzero(~whole & ok.any(1)):
            x, y = np.median(run[h][ok[h]], axis=0)
            pts[h].append((centre, s, x, y))
    return [np.array(p, float).reshape(-1, 4) for p in pts]


def _runs(flags):
    edges = np.diff(np.concatenate([[0], np.asarray(flags, int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))
