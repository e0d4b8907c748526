"""Ray-cast 3D lifting of an H36M-17 skeleton with known per-frame cameras (seed paper, Sec. 3.3).

* The pelvis, spine, thorax, neck and head rays are cast into the athlete's
  sagittal plane (the vertical plane of the Kalman-smoothed ground track).
* Hips and shoulders lie on spheres of half the hip / shoulder width around
  the pelvis / thorax, on their own side of the sagittal plane.
* Each limb joint is found where its ray meets a sphere of limb-length
  radius around its parent: two solutions per joint, four per two-segment
  chain (hip-knee-ankle, shoulder-elbow-wrist).  When a ray misses its sphere
  the closest point is taken and the miss distance reported.
* The candidates are chosen for the whole clip at once by dynamic programming
  (Viterbi) over frames: range-of-motion penalties per frame plus a penalty on
  joint jumps between frames.

Everything is vectorised over frames; the per-frame loop left is the Viterbi
recursion over four states per chain.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..filtering import (
    NOISE_FLOOR_LEG_FRAC,
    NOISE_FLOOR_PX,
    clean_keypoints,
    keypoints_noisy,
    noise_model,
    stride_lags,
)
from ..geometry import (
    JOINT_INDEX,
    SEGMENT_BONES,
    CameraArrays,
    camera_arrays,
    joint_angles,
    pixel_rays,
)
from .angles import smooth_angles_across_strides
from .trajectory import GroundTrack, fit_ground_track

__all__ = ["LiftConfig", "LiftResult", "estimate_segments", "implausible_segments", "lift", "lift_many",
           "smooth_angles_across_strides", "ANTHROPOMETRIC_RATIOS"]


J = JOINT_INDEX

CHAINS = {  # name: (root, mid, end, segment of root->mid, segment of mid->end)
    "leg_r": ("r_hip", "r_knee", "r_ankle", "thigh", "shank"),
    "leg_l": ("l_hip", "l_knee", "l_ankle", "thigh", "shank"),
    "arm_r": ("r_shoulder", "r_elbow", "r_wrist", "upper_arm", "forearm"),
    "arm_l": ("l_shoulder", "l_elbow", "l_wrist", "upper_arm", "forearm"),
}

#: Widths relative to the trunk (pelvis-thorax) length when they cannot be measured
#: (Winter 2009 proportions: hip-joint separation 0.10 H, biacromial ~0.21 H, trunk 0.288 H).
ANTHROPOMETRIC_RATIOS = {"hip_width": 0.10 / 0.288, "shoulder_width": 0.207 / 0.288}

@dataclass(frozen=True)
class LiftConfig:
    """Costs of the candidate selection (dimensionless, ~ squared standard scores)."""

    joint_speed_std_mps: float = 4.0   # relative to the pelvis, between frames
    rom_penalty: float = 50.0
    length_std_m: float = 0.015       # limb-length sphere, soft
    knee_flex_tol: float = 0.15        # sin of the allowed hyperextension
    elbow_flex_tol: float = 0.25
    hip_range_deg: tuple = (-60.0, 140.0)
    # Knee/ankle and elbow/wrist off their limb's sagittal plane: the CMU running mocap in
    # shared/data shows sd 3.7 cm (knee), 5.5 cm (ankle), 4.3 cm (elbow), 3.7 cm (wrist);
    # arms get more room for styles that swing them across the body.
    leg_lateral_std_m: float = 0.04
    arm_lateral_std_m: float = 0.08
    # Expected offset of the wrist from the elbow towards the body midline.  In a side view
    # the wrist's two ray-sphere solutions mirror each other in depth about the elbow, so
    # this prior picks the branch: forearms point towards the midline (CMU running mocap in
    # shared/data, 14 arms: wrist 3.7 cm medial of the elbow on average, medial in ~75 % of
    # frames).  Measuring the wrist's offset from the shoulder with a zero mean instead
    # picked the mirror branch for arms that cross the body (synthetic odd-arms clip, true
    # cameras: right elbow 17.8 -> 9.3 deg; other clips unchanged, 2.89 -> 2.88 deg).
    forearm_medial_offset_m: float = 0.037
    # Expected offsets of the knee medial of the hip and of the ankle medial of the knee (the
    # mean of the CMU running mocap in shared/data, 14 legs: 2.1 cm, range 0.4-4.4, and 1.7 cm,
    # range 0.1-4.0; `probreg bench realism` section e).  Centring the legs' plane term there
    # rather than on the plane (0.2.0.dev24), with the true cameras and limb lengths: exact 2D
    # knee 1.25 -> 1.15 deg, hip 1.06 -> 0.85 deg on 30 tuning twins (7501-7530), noisy 2D knee
    # 3.72 -> 3.69, hip 2.89 -> 2.69; validation clips (checked) noisy knee 2.99 -> 2.97, hip
    # 2.36 -> 2.28, exact knee 0.73 -> 0.43 (docs/method.md, "Limb joints off their rays").
    knee_medial_offset_m: float = 0.021
    ankle_medial_offset_m: float = 0.017
    min_score: float = 0.3
    ankle_height_m: float = 0.07
    smooth_cutoff_hz: float | str | None = "auto"  # keypoint low-pass before lifting (None: off)
    # cross-stride smoothing of the lifted hip, knee and elbow angles (True / False / "auto":
    # when the keypoints are cleaned here and are noisy); see :func:`smooth_angles_across_strides`
    cross_stride_angles: bool | str = "auto"
    # frame-to-frame correlation assumed for the angle noise in that smoothing: 0 (white) beat
    # 0.25/0.5/0.75 for knee, hip and elbow on the suite (knee 3.08 vs 3.17 deg with exact
    # cameras) and on held-out clips (3.08 vs 3.17; elbow 2.96 vs 3.43)
    angle_noise_rho: float = 0.0
    angle_smooth_cutoff_hz: float = 14.0
    # left and right sides of each angle smoothed together, tied half a stride apart, their
    # asymmetry sd floored at this (deg; None: each side alone).  Knee error with the true
    # cameras on the 30 tuning clips 3.60 -> 3.31 deg (3.30 with 2 rounds); the floor is the most symmetric
    # runner's of the CMU running mocap (probreg.filtering.pair)
    left_right_min_sd_deg: float | None = 2.0
    # keypoints count as noisy (cleaned, angles smoothed across strides) above this noise (px),
    # or above this fraction of the legs' image length when that is less
    # (:func:`probreg.filtering.keypoints_noisy`; None: the pixel floor alone)
    noise_floor_px: float = NOISE_FLOOR_PX
    noise_floor_leg_frac: float | None = NOISE_FLOOR_LEG_FRAC


@dataclass(frozen=True)
class LiftResult:
    """A lifted clip.

    Attributes
    ----------
    joints_track_m : ndarray, shape (F, 17, 3)
        NaN where a joint could not be lifted.
    status : list of str
        Per frame: ``ok``, ``partial`` (some joints missing), ``interpolated`` (no detection
        in this frame; bridged from its neighbours), ``no_camera``, ``no_detection``.
    miss_m : ndarray, shape (F, 17)
        Signed distance of each sphere-cast joint from its limb-length sphere (0 = on it;
        NaN = not cast): for hips and shoulders the ray's miss distance, for limb joints
        the residual of the sphere-and-plane fit.
    track : GroundTrack
    segments_m : dict
    """

    joints_track_m: np.ndarray
    status: list
    miss_m: np.ndarray
    track: GroundTrack
    segments_m: dict
    extra: dict = field(default_factory=dict)

    def angles_deg(self):
        """Joint angles (CLIP_FORMAT) with ``f`` = the smoothed running direction per frame."""
        return joint_angles(self.joints_track_m, forward=self.track.forward)


def _plane_hits(origins, dirs, point, normal):
    """Rays (F,K,3) from origins (F,3) meet planes (point (F,3), normal (F,3)): points (F,K,3)."""
    num = np.sum((point - origins) * normal, -1)[:, None]
    den = np.sum(dirs * normal[:, None, :], -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = num / den
    t = np.where(t > 0, t, np.nan)
    return origins[:, None, :] + t[..., None] * dirs


def _sphere_hits(origins, dirs, centres, radius):
    """Both ray-sphere solutions (F, 2, 3) and miss distances (F,), vectorised."""
    oc = centres - origins
    tm = np.sum(oc * dirs, -1)
    d2 = np.sum(oc * oc, -1) - tm**2
    h2 = radius**2 - d2
    h = np.sqrt(np.clip(h2, 0, None))
    miss = np.where(h2 < 0, np.sqrt(np.clip(d2, 0, None)) - radius, 0.0)
    sols = origins[:, None, :] + (tm[:, None] + np.array([-1.0, 1.0])[None, :] * h[:, None])[..., None] * dirs[:, None, :]
    return sols, miss


def _side_pick(sols, centre, left, sign):
    """Of two candidates pick the one on side ``sign`` (+1 left, -1 right) of the sagittal plane."""
    side = np.sum((sols - centre[:, None, :]) * left[:, None, :], -1) * sign
    k = np.argmax(side, axis=1)
    return sols[np.arange(len(sols)), k]


def estimate_segments(cameras, keypoints_px, track: GroundTrack | None = None, fps=50.0, percentile=50):
    """Limb lengths (m) from the clip itself: joints cast into the sagittal plane.

    The athlete's limbs move mostly in sagittal planes, so casting both ends
    of a limb into the mid-sagittal plane gives its length foreshortened only
    when it leaves that plane; the ``percentile``-th percentile over the clip
    is taken, by default the median.  Foreshortening is small for every
    segment but the forearm, while the keypoints' noise spreads the cast
    lengths both ways, so a higher percentile reads the limbs long: until
    0.2.0.dev41 the 60th, +1.5 % (thigh) and +1.8 % (shank) on 24 tuning
    clips with their true cameras, the median -0.1 % and -0.1 %
    (``docs/method.md``, "The limbs seen at a height").  Widths, which a side
    view cannot measure, follow from the trunk length with
    :data:`ANTHROPOMETRIC_RATIOS`.
    """
    kp = np.asarray(keypoints_px, float)
    cams = cameras if isinstance(cameras, CameraArrays) else camera_arrays(cameras)
    if track is None:
        track = fit_ground_track(cams, kp, fps)
    point = np.column_stack([track.position_m, np.zeros(len(kp))])
    rays = pixel_rays(cams, kp[..., :2])
    P = _plane_hits(cams.C, rays, point, track.left)
    out = {}
    for seg, pairs in SEGMENT_BONES.items():
        if seg in ANTHROPOMETRIC_RATIOS:
            continue
        lens = np.concatenate([np.linalg.norm(P[:, J[b]] - P[:, J[a]], axis=-1) for a, b in pairs])
        lens = lens[np.isfinite(lens)]
        out[seg] = float(np.percentile(lens, percentile)) if len(lens) else float("nan")
    # the trunk line is in the plane: its median is unbiased
    tr = np.linalg.norm(P[:, J["thorax"]] - P[:, J["pelvis"]], axis=-1)
    tr = tr[np.isfinite(tr)]
    if len(tr):
        out["trunk"] = float(np.median(tr))
    for seg, ratio in ANTHROPOMETRIC_RATIOS.items():
        out[seg] = ratio * out.get("trunk", np.nan)
    return out


def _refine_on_ray(origins, dirs, root, length, normal, t0, sd_len, sd_lat, iters=6, offset=0.0):
    """Depth along each ray that best meets both the limb-length sphere around ``root`` and
    the limb's sagittal plane (through ``root``, normal ``normal``): Gauss-Newton on

    ``((|q| - L) / sd_len)^2 + ((q . n - offset) / sd_lat)^2``,  ``q = o + t d - root``.

    With exact keypoints the sphere term is met exactly; with noisy ones it stops the
    depth from running away where a ray grazes its sphere (the limb almost parallel to
    the image plane), which is where the pure ray-sphere solution is ill-conditioned.
    Returns points (F, 3) and the sphere misfit ``|q| - L`` (F,); ``t0`` (and ``root``)
    may carry leading axes (several starts at once), which the results then have too.
    """
    t = t0.copy()
    dn = np.sum(dirs * normal, -1)
    for _ in range(iters):
        q = origins + t[..., None] * dirs - root
        nq = np.linalg.norm(q, axis=-1)
        qd = np.sum(q * dirs, -1) / np.maximum(nq, 1e-9)
        r1 = (nq - length) / sd_len
        r2 = (np.sum(q * normal, -1) - offset) / sd_lat
        j1 = qd / sd_len
        j2 = dn / sd_lat
        step = (r1 * j1 + r2 * j2) / np.maximum(j1 * j1 + j2 * j2, 1e-12)
        t = t - step
    q = origins + t[..., None] * dirs - root
    return origins + t[..., None] * dirs, np.linalg.norm(q, axis=-1) - length


def _chain_candidates(origins, rays, root, L1, L2, i_mid, i_end, normal, sd_len, sd_lat, offsets=(0.0, 0.0)):
    """Four candidate (mid, end) pairs per frame: (F, 4, 2, 3), and misfits (F, 4).

    Each joint starts from both ray-sphere solutions (the closest point when the ray
    misses) and is refined against sphere and sagittal plane together; ``offsets`` are the
    middle joint's expected offset from the root's plane and the end joint's from the middle's
    (along ``normal``).
    """
    F = len(origins)
    cands = np.empty((F, 4, 2, 3))
    misfit = np.empty((F, 4))

    def starts(d, centre, L):
        oc = centre - origins
        tm = np.sum(oc * d, -1)
        h = np.sqrt(np.clip(L**2 - (np.sum(oc * oc, -1) - tm**2), 0, None))
        return tm - h, tm + h

    d_mid, d_end = rays[:, i_mid], rays[:, i_end]
    # both starts of the middle joint refined at once (leading axis a), then both starts of
    # the end joint from each of them (axes b, a)
    mid, m1 = _refine_on_ray(origins, d_mid, root, L1, normal, np.stack(starts(d_mid, root, L1)),
                             sd_len, sd_lat, offset=offsets[0])  # (2, F, 3), (2, F)
    end, m2 = _refine_on_ray(origins, d_end, mid, L2, normal, np.stack(starts(d_end, mid, L2)),
                             sd_len, sd_lat, offset=offsets[1])  # (2, 2, F, 3), (2, 2, F)
    for a in range(2):
        for b in range(2):
            cands[:, 2 * a + b, 0] = mid[a]
            cands[:, 2 * a + b, 1] = end[b, a]
            misfit[:, 2 * a + b] = np.abs(m1[a]) + np.abs(m2[b, a])
    return cands, misfit


def _viterbi(emission, transition):
    """Min-cost state paths, batched over leading axes (the four limb chains at once).

    emission (..., F, S); transition (..., F-1, S, S), cost from s' to s.  Returns the
    paths (..., F).  The recursion over frames is the one loop left; batching the chains
    runs it once instead of four times.
    """
    em = np.moveaxis(np.asarray(emission, float), -2, 0)  # (F, ..., S)
    tr = np.moveaxis(np.asarray(transition, float), -3, 0)  # (F-1, ..., S, S)
    F = em.shape[0]
    cost = em[0].copy()
    back = np.zeros(em.shape, np.intp)
    for t in range(1, F):
        tot = cost[..., :, None] + tr[t - 1]  # (..., S', S)
        back[t] = np.argmin(tot, axis=-2)
        cost = np.min(tot, axis=-2) + em[t]
    path = np.empty(em.shape[:-1], np.intp)  # (F, ...)
    path[-1] = np.argmin(cost, axis=-1)
    # backtrack with the batch axes flattened: a plain fancy index per frame
    flat_back = back.reshape(F, -1, back.shape[-1])
    flat_path = path.reshape(F, -1)
    rows = np.arange(flat_back.shape[1])
    for t in range(F - 1, 0, -1):
        flat_path[t - 1] = flat_back[t, rows, flat_path[t]]
    return np.moveaxis(flat_path.reshape(path.shape), 0, -1)


#: the segment lengths the lifting uses (its spheres' radii)
LIFTED_SEGMENTS = ("hip_width", "shoulder_width", "thigh", "shank", "upper_arm", "forearm")


def _given_segments(segments_m):
    """The user's segment lengths as floats, checked: known names, positive finite metres.

    >>> _given_segments({"thigh": "0.45"})
    {'thigh': 0.45}
    >>> _given_segments({"thigh": -1})
    Traceback (most recent call last):
    ...
    ValueError: segment length 'thigh' must be a positive length in metres, got -1
    """
    if segments_m is None:
        return {}
    if not isinstance(segments_m, dict):
        raise ValueError(f"segment lengths must be a mapping of segment name to metres, got {type(segments_m).__name__}")
    unknown = sorted(set(segments_m) - set(SEGMENT_BONES))
    if unknown:
        raise ValueError(f"unknown segment(s) {', '.join(map(repr, unknown))}; known: {', '.join(SEGMENT_BONES)}")
    out = {}
    for k, v in segments_m.items():
        try:
            x = float("nan") if isinstance(v, bool) else float(v)  # true is no length (float() reads 1.0)
        except (TypeError, ValueError):
            x = float("nan")
        if not (np.isfinite(x) and x > 0):  # no upper bound: posterior draws may be absurd, not wrong input
            raise ValueError(f"segment length {k!r} must be a positive length in metres, got {v!r}")
        out[k] = x
    return out


#: thigh and shank lengths (m) of adults 1.50-2.10 m tall (Winter 2009: about 0.245 of the
#: stature each, 0.37-0.51 m), widened by about a third either way
HUMAN_LEG_SEGMENT_M = (0.25, 0.70)


def implausible_segments(segments_m):
    """The leg segments of ``segments_m`` no adult runner has, as short strings (empty: none).

    Estimated from the clip, such lengths mean cameras that do not fit it (another clip's, a
    wrong scale): every 3D number of the lifting is then off by the same factor.

    >>> implausible_segments({"thigh": 0.45, "shank": 0.44})
    []
    >>> implausible_segments({"thigh": 0.027, "shank": None})
    ['thigh 0.027 m']
    """
    lo, hi = HUMAN_LEG_SEGMENT_M
    return [f"{k} {v:.3g} m" for k in ("thigh", "shank")
            if (v := segments_m.get(k)) is not None and np.isfinite(v) and not lo <= v <= hi]


def lift(cameras, keypoints_px, fps=50.0, segments_m=None, track: GroundTrack | None = None,
         config: LiftConfig = LiftConfig(), stride_lag=None):
    """Lift 2D keypoints to 3D joints in the track frame.

    Parameters
    ----------
    cameras : list of Camera or None (length F), or CameraArrays
    keypoints_px : array_like, shape (F, 17, 3)
        H36M-17 ``(x, y, score)``; NaN or low-score joints are missing.
    fps : float
    segments_m : dict, optional
        Segment lengths (m) keyed as :data:`probreg.geometry.skeleton.SEGMENT_BONES`; those not
        given are estimated from the clip (:func:`estimate_segments`).
    track : GroundTrack, optional
        Precomputed ground track (else fitted here).
    config : LiftConfig
    stride_lag : ndarray (F,), optional
        Stride lag per frame for the cross-stride angle smoothing
        (:func:`probreg.filtering.stride_lags`); computed from the keypoints when needed.

    Returns
    -------
    LiftResult
        ``extra["angle_noise"]``: per smoothed angle, the estimated noise and
        stride-to-stride sd (degrees), when the cross-stride angle smoothing ran.

    Raises
    ------
    ValueError
        If the keypoints do not have shape (F, 17, 2|3) or the camera count differs, or a given
        segment length is unknown, not positive or not a number.
    """
    return lift_many([(cameras, keypoints_px, segments_m, track)], fps, config, stride_lag)[0]


#: frames x liftings cast in one batch by :func:`lift_many` (bounds its memory: about 1 kB a row)
BATCH_ROWS = 20000


def lift_many(jobs, fps=50.0, config: LiftConfig = LiftConfig(), stride_lag=None):
    """:func:`lift` of several liftings at once, each exactly as :func:`lift` gives it.

    ``jobs``: a sequence of ``(cameras, keypoints_px, segments_m, track)``, one per lifting (e.g.
    the posterior draws of a clip, each with its own cameras, limb lengths, keypoints and ground
    track); ``fps``, ``config`` and ``stride_lag`` are shared.  Returns their :class:`LiftResult`
    in order.

    The ray casting, the limb chains' candidates and the Viterbi recursion run over all liftings
    of one length at once: the frames of every lifting are rows of one array, and the recursion's
    loop over frames runs once for all of them instead of once per lifting (a clip's posterior
    draws: ``reports/bench_speed.md``).  Each lifting's keypoint cleaning, segment estimate, ground
    track and cross-stride angle smoothing remain its own.

    >>> from probreg.geometry import Camera
    >>> cam = Camera.look_at([0.0, -30.0, 5.0], [0.0, 0.0, 1.0], fov_deg=20.0)
    >>> kp = np.full((3, 17, 3), np.nan)
    >>> [r.status for r in lift_many([([cam] * 3, kp, None, None)] * 2)]
    [['no_detection', 'no_detection', 'no_detection'], ['no_detection', 'no_detection', 'no_detection']]
    """
    preps = [_prepare(cams, kp, fps, seg, track, config) for cams, kp, seg, track in jobs]
    cast = [None] * len(preps)
    by_length = {}
    for i, p in enumerate(preps):
        by_length.setdefault(p["F"], []).append(i)
    for F, idx in by_length.items():
        step = max(1, BATCH_ROWS // max(F, 1))
        for a in range(0, len(idx), step):
            part = idx[a:a + step]
            joints, miss = _cast([preps[i] for i in part], fps, config)
            for k, i in enumerate(part):
                cast[i] = (joints[k].copy(), miss[k].copy())
    return [_finish(p, joints, miss, fps, config, stride_lag) for p, (joints, miss) in zip(preps, cast)]


def _prepare(cameras, keypoints_px, fps, segments_m, track, config):
    """One lifting's inputs checked and made ready for :func:`_cast` (keypoints cleaned as the
    config says, cameras as arrays, the ground track, segment lengths, rays)."""
    kp = np.array(keypoints_px, float)
    if kp.ndim != 3 or kp.shape[1] != 17 or kp.shape[2] not in (2, 3):
        raise ValueError(f"keypoints must have shape (F, 17, 3), got {kp.shape}")
    if kp.shape[2] == 2:
        kp = np.concatenate([kp, np.ones(kp.shape[:2] + (1,))], -1)
    kp[kp[..., 2] < config.min_score] = np.nan
    kp[~np.all(np.isfinite(kp), -1)] = np.nan
    raw_missing = ~np.all(np.isfinite(kp), -1)
    cross = config.cross_stride_angles
    if cross == "auto":  # the same rule as the cross-stride keypoint cleaning
        cross = config.smooth_cutoff_hz == "auto" and keypoints_noisy(kp, noise_model(kp)[0], config.noise_floor_px,
                                                                      config.noise_floor_leg_frac)
    if config.smooth_cutoff_hz is not None:
        kp = clean_keypoints(kp, fps, cutoff_hz=config.smooth_cutoff_hz, noise_floor_px=config.noise_floor_px,
                             noise_floor_leg_frac=config.noise_floor_leg_frac)
    F = len(kp)
    cams = cameras if isinstance(cameras, CameraArrays) else camera_arrays(cameras)
    if len(cams.valid) != F:
        raise ValueError(f"{len(cams.valid)} cameras for {F} frames of keypoints")
    if track is None:
        track = fit_ground_track(cams, kp, fps, ankle_height_m=config.ankle_height_m)
    seg = _given_segments(segments_m)
    if not set(LIFTED_SEGMENTS) <= set(seg):  # the lengths not given are estimated from the clip
        seg = {**estimate_segments(cams, kp, track, fps), **seg}
    return {"F": F, "kp": kp, "raw_missing": raw_missing, "cross": cross, "cams": cams, "track": track,
            "seg": seg, "rays": (rays := pixel_rays(cams, kp[..., :2])), "missing": ~np.all(np.isfinite(rays), -1),
            "left": track.left, "fwd": track.forward}


def _cast(preps, fps, config):
    """The ray casting of liftings of one length ``F`` (from :func:`_prepare`), all at once:
    joints (N, F, 17, 3) and sphere misfits (N, F, 17).  Every step is per frame except the
    frame-to-frame costs and the Viterbi recursion, which run per lifting along its own frames."""
    N, F = len(preps), preps[0]["F"]
    origins = np.concatenate([p["cams"].C for p in preps])  # rows: lifting by lifting, frame by frame
    rays = np.concatenate([p["rays"] for p in preps])  # (N F, 17, 3), NaN where missing
    left = np.concatenate([p["left"] for p in preps])
    fwd = np.concatenate([p["fwd"] for p in preps])
    point = np.concatenate([np.column_stack([p["track"].position_m, np.zeros(F)]) for p in preps])
    seg = {k: np.repeat(np.array([p["seg"][k] for p in preps], float), F) for k in LIFTED_SEGMENTS}
    joints = np.full((N * F, 17, 3), np.nan)
    miss = np.full((N * F, 17), np.nan)
    # mid-sagittal joints
    mids = [J[n] for n in ("pelvis", "spine", "thorax", "neck", "head")]
    joints[:, mids] = _plane_hits(origins, rays[:, mids], point, left)
    # hips and shoulders on their side of the plane
    for centre, (rj, lj), width in (("pelvis", ("r_hip", "l_hip"), "hip_width"),
                                     ("thorax", ("r_shoulder", "l_shoulder"), "shoulder_width")):
        c = joints[:, J[centre]]
        for name, sign in ((rj, -1.0), (lj, 1.0)):
            sols, m = _sphere_hits(origins, rays[:, J[name]], c, seg[width] / 2)
            joints[:, J[name]] = _side_pick(sols, c, left, sign)
            miss[:, J[name]] = m
    # limb chains: candidates, then Viterbi over each lifting's frames
    lean = np.arctan2(np.sum((joints[:, J["thorax"]] - joints[:, J["pelvis"]]) * fwd, -1),
                      (joints[:, J["thorax"]] - joints[:, J["pelvis"]])[:, 2])
    pelvis = joints[:, J["pelvis"]]
    sig = config.joint_speed_std_mps / fps
    pending = []
    for name, (root, mid, end, s1, s2) in CHAINS.items():
        r = joints[:, J[root]]
        arm = name.startswith("arm")
        lat_std = config.arm_lateral_std_m if arm else config.leg_lateral_std_m
        medial = -1.0 if name.endswith("_l") else 1.0  # along ``left``: the midline is right of a left limb
        # a leg's knee and ankle sit medially: their expected offsets (knee from hip, ankle from knee)
        offs = (0.0, 0.0) if arm else (medial * config.knee_medial_offset_m, medial * config.ankle_medial_offset_m)
        cands, cmiss = _chain_candidates(origins, rays, r, seg[s1], seg[s2], J[mid], J[end], left,
                                         config.length_std_m, lat_std, offsets=offs)
        u = cands[:, :, 0] - r[:, None]  # root -> mid
        v = cands[:, :, 1] - cands[:, :, 0]  # mid -> end
        bend = np.sum(np.cross(u, v) * left[:, None], -1) / (seg[s1] * seg[s2])[:, None]  # sin of signed flexion
        e = (cmiss / config.length_std_m) ** 2
        # limbs swing in the sagittal plane through their root: the mirror solution of a
        # ray-sphere pair lies across the body (the camera looks roughly along the plane normal)
        lateral = np.sum((cands - r[:, None, None, :]) * left[:, None, None, :], -1)  # (N F, 4, 2)
        if arm:  # the wrist from the elbow
            lateral = np.stack([lateral[..., 0],
                                lateral[..., 1] - lateral[..., 0] - medial * config.forearm_medial_offset_m], -1)
        else:
            lateral = lateral - np.array([offs[0], offs[0] + offs[1]])
        e += np.sum(lateral**2, -1) / lat_std**2
        if name.startswith("leg"):
            e += config.rom_penalty * (bend < -config.knee_flex_tol)
            hip = np.degrees(np.arctan2(np.sum(u * fwd[:, None], -1), -u[..., 2]) + lean[:, None])
            lo, hi = config.hip_range_deg
            e += config.rom_penalty * ((hip < lo) | (hip > hi))
            e += config.rom_penalty * (cands[:, :, 1, 2] < -0.05)  # ankle below the ground
        else:
            e += config.rom_penalty * (bend > config.elbow_flex_tol)  # elbows flex forward
        e = np.where(np.isfinite(e), e, 0.0)
        rel = (cands - pelvis[:, None, None, :]).reshape(N, F, 4, 2, 3)
        d = rel[:, 1:, None, :, :, :] - rel[:, :-1, :, None, :, :]  # (N, F-1, S', S, 2, 3)
        T = np.sum(d**2, axis=(-1, -2)) / (2 * sig**2)
        T = np.where(np.isfinite(T), T, 0.0)
        pending.append((cands, e.reshape(N, F, 4), T, r, mid, end, s1, s2))
    paths = _viterbi(np.stack([p[1] for p in pending]), np.stack([p[2] for p in pending]))  # (chains, N, F)
    rows = np.arange(N * F)
    for (cands, _, _, r, mid, end, s1, s2), path in zip(pending, paths):
        chosen = cands[rows, path.reshape(-1)]
        joints[:, J[mid]] = chosen[:, 0]
        joints[:, J[end]] = chosen[:, 1]
        miss[:, J[mid]] = np.linalg.norm(chosen[:, 0] - r, axis=-1) - seg[s1]
        miss[:, J[end]] = np.linalg.norm(chosen[:, 1] - chosen[:, 0], axis=-1) - seg[s2]
    # a joint whose ray is missing stays missing (no candidate is invented)
    joints[np.concatenate([p["missing"] for p in preps])] = np.nan
    return joints.reshape(N, F, 17, 3), miss.reshape(N, F, 17)


def _finish(p, joints, miss, fps, config, stride_lag):
    """One lifting's result from its cast joints: the cross-stride angle smoothing (when the
    config asks for it) and the per-frame status."""
    F = p["F"]
    extra = {}
    if p["cross"]:
        lag = stride_lag if stride_lag is not None else stride_lags(p["kp"], fps)
        if lag is not None:
            joints, extra["angle_noise"] = smooth_angles_across_strides(
                joints, p["fwd"], lag, fps, rho=config.angle_noise_rho, smooth_cutoff_hz=config.angle_smooth_cutoff_hz,
                pair_min_sd=config.left_right_min_sd_deg)
    # per-frame status, the first that applies (whole-array tests, then one pick per frame)
    raw_missing, missing = p["raw_missing"], p["missing"]
    all_raw = raw_missing.reshape(F, -1).all(1)
    tests = [~p["cams"].valid, all_raw & missing.reshape(F, -1).all(1), np.isnan(joints).reshape(F, -1).any(1), all_raw]
    names = np.array(["no_camera", "no_detection", "partial", "interpolated", "ok"], object)
    status = names[np.argmax(np.column_stack(tests + [np.ones(F, bool)]), axis=1)].tolist()
    return LiftResult(joints_track_m=joints, status=status, miss_m=miss, track=p["track"], segments_m=p["seg"],
                      extra=extra)
