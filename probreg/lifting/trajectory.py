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

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..geometry import JOINT_INDEX

__all__ = ["GroundTrack", "TrackConfig", "camera_track_config", "cast_ankles", "detect_contacts", "fit_ground_track",
           "sagittal_ankle_points", "sagittal_ankle_height", "gate_contacts_by_height", "gated_forward_pass", "rts_backward"]


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


def _contact_points(ankles_m, contacts):
    pts = []
    for s in (0, 1):
        c = contacts[:, s]
        edges = np.diff(np.concatenate([[0], c.astype(int), [0]]))
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            # the first half of the contact is foot-flat; later the heel rises and the
            # raised ankle, cast onto the ankle-height plane, lands beyond the foot
            run = ankles_m[a:a + max(1, (b - a + 1) // 2), s, :2]
            ok = np.all(np.isfinite(run), -1)
            if ok.any():
                x, y = np.median(run[ok], axis=0)
                pts.append(((a + b - 1) / 2, s, x, y))
    pts.sort()
    return np.array(pts, float).reshape(-1, 4)


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


def _track_from_contacts(ankles, contacts, fps, config):
    """The Kalman/RTS ground track from cast ankles (F, 2, 3) and fixed contact flags."""
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    F = len(ankles)
    cps = _contact_points(ankles, contacts)
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
    dt = 1.0 / fps
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F = np.kron(np.eye(2), np.array([[1.0, dt], [0.0, 1.0]]))
    kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    kf.Q = np.zeros((4, 4))
    kf.Q[:2, :2] = Q_discrete_white_noise(2, dt=dt, var=config.accel_std_mps2[0] ** 2)
    kf.Q[2:, 2:] = Q_discrete_white_noise(2, dt=dt, var=config.accel_std_mps2[1] ** 2)
    kf.R = R_meas
    keys = sorted(meas)
    if not keys:
        nan = np.full((F, 2), np.nan)
        return GroundTrack(nan, nan, np.full((F, 4, 4), np.nan), contacts, cps, -np.inf, "no_feet")
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
    kf.x = np.array([p0[0], v0[0], p0[1], v0[1]])
    kf.P = np.diag([4.0, 4.0, float(np.clip(sd0, 0.05, 0.7)) ** 2, 0.1**2])
    xs, Ps, loglik = gated_forward_pass(kf, meas, F, first=keys[0], max_rejected_run=config.max_rejected_run)
    xs, Ps = rts_backward(xs, Ps, kf.F, kf.Q)
    return GroundTrack(position_m=xs[:, [0, 2]], velocity_mps=xs[:, [1, 3]], cov=Ps, contacts=contacts,
                       contact_points_m=cps, log_likelihood=loglik, status=status, half_step_m=half_step)


def gated_forward_pass(kf, meas, n, first=None, max_rejected_run=2, gate=16.0):
    """The forward pass of the ground-track filter: ``(xs (n, 4), Ps (n, 4, 4), log_likelihood)``.

    ``kf`` is a ``filterpy`` ``KalmanFilter`` of two independent constant-velocity axes (state
    ``[x, vx, y, vy]``, ``H`` picking ``x`` and ``y``; ``F``, ``Q``, ``R`` and the start ``P``
    without cross-axis terms, as :func:`_track_from_contacts` builds it); ``meas`` maps a frame
    index to its 2-D measurement.  Each step is ``kf.predict()`` then, for a measured frame,
    ``kf.update(z)`` -- the same formulas (Joseph-form update) written per axis in scalars, which
    the block structure keeps exact (other models are refused) and which takes a seventh of the
    time of filterpy's calls (the filter runs for every posterior draw).  An innovation whose squared Mahalanobis length exceeds
    ``gate`` (chi-square, 2 dof, p ~ 3e-4) is not used, except on frame ``first``, but still
    costs its Gaussian log-density with the exponent capped at the gate, so that hypotheses
    cannot hide data; after ``max_rejected_run`` rejections in a row the filter, not the
    footprints, went astray: its covariance restarts from the start ``P`` and the measurement
    is taken.

    >>> from filterpy.common import Q_discrete_white_noise
    >>> from filterpy.kalman import KalmanFilter
    >>> kf = KalmanFilter(dim_x=4, dim_z=2); dt = 0.02
    >>> kf.F = np.kron(np.eye(2), np.array([[1.0, dt], [0.0, 1.0]])); kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    >>> kf.Q = np.zeros((4, 4)); kf.Q[:2, :2] = Q_discrete_white_noise(2, dt=dt, var=2.0)
    >>> kf.Q[2:, 2:] = Q_discrete_white_noise(2, dt=dt, var=0.4); kf.R = np.diag([0.01, 0.001])
    >>> kf.x = np.array([0.0, 9.0, 0.0, 0.0]); kf.P = np.diag([4.0, 4.0, 0.09, 0.01])
    >>> meas = {i: np.array([0.18 * i + 0.05 * np.sin(i), 0.02 * np.cos(i)]) for i in range(0, 40, 3)}
    >>> xs, Ps, _ = gated_forward_pass(kf, meas, 40, first=0)
    >>> ref = []
    >>> for i in range(40):
    ...     if i > 0: kf.predict()
    ...     if i in meas: kf.update(meas[i])
    ...     ref.append((kf.x.copy(), kf.P.copy()))
    >>> bool(np.allclose(xs, [r[0] for r in ref], rtol=1e-12, atol=1e-12)
    ...      and np.allclose(Ps, [r[1] for r in ref], rtol=1e-12, atol=1e-12))
    True
    """
    dt = float(kf.F[0, 1])
    pair = np.array([0, 0, 1, 1])
    cross = pair[:, None] != pair[None, :]
    if (not np.array_equal(kf.F, np.kron(np.eye(2), [[1.0, dt], [0.0, 1.0]]))
            or not np.array_equal(kf.H, [[1.0, 0, 0, 0], [0, 0, 1.0, 0]]) or np.any(np.asarray(kf.R)[[0, 1], [1, 0]])
            or np.any(np.asarray(kf.Q)[cross]) or np.any(np.asarray(kf.P)[cross])):
        raise ValueError("gated_forward_pass needs two independent constant-velocity axes (F, H, Q, R, P "
                         "as _track_from_contacts builds them)")
    q = [(float(kf.Q[o, o]), float(kf.Q[o, o + 1]), float(kf.Q[o + 1, o + 1])) for o in (0, 2)]
    r = (float(kf.R[0, 0]), float(kf.R[1, 1]))
    x0 = np.asarray(kf.x, float).ravel()
    P0 = np.asarray(kf.P, float)
    start = [(float(P0[o, o]), float(P0[o, o + 1]), float(P0[o + 1, o + 1])) for o in (0, 2)]
    px, vx, py, vy = (float(v) for v in x0)
    (ax, bx, cx), (ay, by, cy) = start
    (qx1, qx2, qx3), (qy1, qy2, qy3) = q
    rx, ry = r
    log_2pi_sq = 2.0 * math.log(2.0 * math.pi)
    states, covs = [], []
    loglik, run_rejected = 0.0, 0
    for i in range(n):
        if i > 0:  # predict: x = F x, P = F P F' + Q
            px, py = px + dt * vx, py + dt * vy
            ax, bx, cx = ax + dt * (2.0 * bx + dt * cx) + qx1, bx + dt * cx + qx2, cx + qx3
            ay, by, cy = ay + dt * (2.0 * by + dt * cy) + qy1, by + dt * cy + qy2, cy + qy3
        z = meas.get(i)
        if z is not None:
            zx, zy = float(z[0]), float(z[1])
            sx, sy = ax + rx, ay + ry
            ex, ey = zx - px, zy - py
            nis = ex * ex / sx + ey * ey / sy
            rejected = nis > gate and i != first
            loglik += -0.5 * (gate if rejected else nis) - 0.5 * (log_2pi_sq + math.log(sx * sy))
            take = not rejected
            if rejected:
                if run_rejected < max_rejected_run:
                    run_rejected += 1
                else:
                    (ax, bx, cx), (ay, by, cy) = start
                    sx, sy = ax + rx, ay + ry
                    take = True
            if take:
                run_rejected = 0
                k0, k1 = ax / sx, bx / sx
                px, vx = px + k0 * ex, vx + k1 * ex
                ax, bx, cx = ((1 - k0) ** 2 * ax + k0 * k0 * rx, (1 - k0) * (bx - k1 * ax) + k0 * k1 * rx,
                              cx - 2.0 * k1 * bx + k1 * k1 * (ax + rx))
                k0, k1 = ay / sy, by / sy
                py, vy = py + k0 * ey, vy + k1 * ey
                ay, by, cy = ((1 - k0) ** 2 * ay + k0 * k0 * ry, (1 - k0) * (by - k1 * ay) + k0 * k1 * ry,
                              cy - 2.0 * k1 * by + k1 * k1 * (ay + ry))
        states.append((px, vx, py, vy))
        covs.append((ax, bx, cx, ay, by, cy))
    xs = np.array(states, float).reshape(n, 4)
    c = np.array(covs, float).reshape(n, 6)
    Ps = np.zeros((n, 4, 4))
    for o, j in ((0, 0), (2, 3)):
        Ps[:, o, o], Ps[:, o, o + 1], Ps[:, o + 1, o + 1] = c[:, j], c[:, j + 1], c[:, j + 2]
        Ps[:, o + 1, o] = c[:, j + 1]
    return xs, Ps, loglik


def rts_backward(xs, Ps, F, Q):
    """The Rauch-Tung-Striebel backward pass of a time-invariant model: smoothed states and
    covariances from the filtered ones ``xs`` (n, d) and ``Ps`` (n, d, d).

    The recursion of ``filterpy``'s ``KalmanFilter.rts_smoother`` (same formulas, same order),
    with the predicted covariances and the smoother gains, which depend only on the filtered
    covariances, computed for all steps at once; only the two short recursions remain a loop.

    >>> from filterpy.kalman import KalmanFilter
    >>> kf = KalmanFilter(dim_x=2, dim_z=1)
    >>> kf.F = np.array([[1.0, 0.1], [0.0, 1.0]]); kf.H = np.array([[1.0, 0.0]])
    >>> kf.Q = np.diag([1e-3, 1e-2]); kf.R = np.array([[0.5]]); kf.x = np.zeros(2)
    >>> xs, Ps = np.zeros((30, 2)), np.zeros((30, 2, 2))
    >>> for i in range(30):
    ...     kf.predict(); kf.update(np.array([0.1 * i + np.sin(i)])); xs[i], Ps[i] = kf.x, kf.P
    >>> x_ref, P_ref, _, _ = kf.rts_smoother(xs, Ps)
    >>> x, P = rts_backward(xs, Ps, kf.F, kf.Q)
    >>> bool(np.allclose(x, x_ref, rtol=1e-12, atol=1e-12) and np.allclose(P, P_ref, rtol=1e-12, atol=1e-12))
    True
    """
    x, P = np.array(xs, float), np.array(Ps, float)
    if len(x) < 2:
        return x, P
    Pf = P[:-1]
    Pp = F @ Pf @ F.T + Q  # predicted covariance of step k + 1 from step k
    K = Pf @ F.T @ np.linalg.inv(Pp)
    a = x[:-1] - np.einsum("kij,kj->ki", K, x[:-1] @ F.T)  # x[k] + K (x_s[k + 1] - F x[k])
    B = Pf - K @ Pp @ np.swapaxes(K, 1, 2)  # P[k] + K (P_s[k + 1] - Pp) K'
    if _pairs_decoupled(F, Q, P):
        # independent 2-state axes (the ground track's x and y): the recursions in scalars, a
        # fifth of the small-matrix products' cost (this runs for every posterior draw)
        for i in range(0, x.shape[1], 2):
            _rts_pair(x, P, a, K, B, i, i + 1)
        return x, P
    for k in range(len(x) - 2, -1, -1):
        Kk = K[k]
        x[k] = a[k] + Kk @ x[k + 1]
        P[k] = B[k] + Kk @ P[k + 1] @ Kk.T
    return x, P


def _pairs_decoupled(F, Q, P):
    """Whether the states fall into independent pairs (0, 1), (2, 3), ...: no entry of ``F``,
    ``Q`` or any ``P`` couples two pairs."""
    d = F.shape[0]
    if d % 2 or d < 2:
        return False
    pair = np.arange(d) // 2
    cross = pair[:, None] != pair[None, :]
    return not (np.any(F[cross]) or np.any(Q[cross]) or np.any(P[:, cross]))


def _rts_pair(x, P, a, K, B, i, j):
    """The two backward recursions of :func:`rts_backward` for the decoupled state pair
    ``(i, j)``, in place (the same formulas, ``P`` kept symmetric)."""
    a0, a1 = a[:, i].tolist(), a[:, j].tolist()
    k00, k01, k10, k11 = (K[:, u, v].tolist() for u, v in ((i, i), (i, j), (j, i), (j, j)))
    b00, b01, b11 = (B[:, u, v].tolist() for u, v in ((i, i), (i, j), (j, j)))
    x0, x1 = float(x[-1, i]), float(x[-1, j])
    p, q, r = float(P[-1, i, i]), float(P[-1, i, j]), float(P[-1, j, j])
    n = len(x)
    xs0, xs1, ps, qs, rs = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    xs0[-1], xs1[-1], ps[-1], qs[-1], rs[-1] = x0, x1, p, q, r
    for k in range(n - 2, -1, -1):
        c00, c01, c10, c11 = k00[k], k01[k], k10[k], k11[k]
        x0, x1 = a0[k] + c00 * x0 + c01 * x1, a1[k] + c10 * x0 + c11 * x1
        m00, m01 = c00 * p + c01 * q, c00 * q + c01 * r  # K P
        m10, m11 = c10 * p + c11 * q, c10 * q + c11 * r
        p, q, r = b00[k] + m00 * c00 + m01 * c01, b01[k] + m00 * c10 + m01 * c11, b11[k] + m10 * c10 + m11 * c11
        xs0[k], xs1[k], ps[k], qs[k], rs[k] = x0, x1, p, q, r
    x[:, i], x[:, j] = xs0, xs1
    P[:, i, i], P[:, i, j], P[:, j, i], P[:, j, j] = ps, qs, qs, rs


def _runs(flags):
    edges = np.diff(np.concatenate([[0], np.asarray(flags, int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))
