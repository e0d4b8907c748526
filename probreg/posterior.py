"""The Bayesian clip model: posterior over the one-DOF calibration and the limb lengths.

Parameters (one clip, one static camera):

``log_height``
    log of the camera height (m): selects the family member in every frame.
``stature``
    the athlete's stature (m).
``m_<segment>``
    multipliers of the anthropometric segment proportions (thigh, shank,
    upper arm, forearm, trunk, hip width, shoulder width); segment length =
    stature x proportion x multiplier.

Likelihood (every term a function of the height; the limb terms also of the lengths):

* static camera: the family members at one height must share one camera
  position; the spread of their lateral positions over the clip (lane-line
  evidence that survives the per-frame one-DOF freedom) is scored with a
  Student-t;
* the ground-contact trajectory: the Kalman filter's marginal
  log-likelihood of the contact points (a runner's path is smooth; a wrong
  height stretches and bends it);
* planted feet: a foot in mid-stance (:data:`STANCE_WINDOW` of its contact)
  stands still on the track, but family members at a wrong height disagree
  on where a ground point is from frame to frame (the position along the
  track is free in each frame, and a panning camera sees it shift
  differently at every height), so planted ankles seem to slide.  The
  median slide over the clip's contacts, as a fraction of the running speed,
  is scored with a Gaussian whose sd adds :data:`STILLNESS_SYS_SD` (the slide
  left at the true height: contact timing, keypoint noise, real ankle
  motion) to the median's standard error;
* keypoints: the limb lengths measured in the sagittal plane at this height
  (the quantity the ray-sphere misses of the lifting depend on: a limb whose
  sphere is smaller than its keypoints' in-plane distance is missed) against
  the parameter lengths, with the measurement's standard error.

The height-dependent statistics are precomputed on a grid of heights and
interpolated, so the log-probability is vectorised over walkers and costs
microseconds; ``emcee`` runs until the chain is 50 integrated
autocorrelation times long (or a budget is spent).  Every kept draw is then
*propagated*: cameras at its height, ground track, lifting with its limb
lengths and with detector noise re-simulated (parametric bootstrap of the
keypoints), giving joint and angle samples and so credible bands.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .filtering import clean_keypoints, noise_model, score_noise_scale, stride_lags
from .kinematics import _runs, gait_summary
from .lifting import CameraArrays, LiftConfig, estimate_segments, lift
from .priors import SEGMENT_PROPORTIONS, ModelPriors
from .registration import (ClipRegistration, _zoom_outliers, athlete_ground_track, glitch_vote,
                           lane_anchor_shift)
from .skeleton import ANGLE_NAMES, JOINT_INDEX
from .trajectory import fit_ground_track

__all__ = ["ClipModel", "SamplerSettings", "noise_model", "PARAM_NAMES", "angle_bands", "STILLNESS_SYS_SD",
           "STANCE_WINDOW", "stance_window", "BAND_SCALE", "BAND_CURVATURE_S2", "angle_curvature", "gait_intervals", "GAIT_BAND_SCALE",
           "NONNEGATIVE_GAIT_SUFFIXES"]

#: Part of every detected contact (fractions of its length) in which the ankle is taken
#: to stand still.  Real runners' ankles are not still at the ends of a contact: in the
#: CMU running mocap (``shared/data/mocap``, 7 clips, 4 subjects) the ankle moves 1-2 cm
#: forward from heel strike to foot flat (first ~15 % of stance; 5 cm for the jogger)
#: and rises with the heel from ~45 %; in between it slides by 0.019 of the running
#: speed (median of 18 contacts; sd 0.04), i.e. well inside :data:`STILLNESS_SYS_SD`.
#: Skipping the first 15 % also skips the 1-3 frames by which detected contacts tend to
#: start early (late swing, where the ankle still moves).
STANCE_WINDOW = (0.15, 0.45)


def stance_window(a, b, window=STANCE_WINDOW):
    """Frames ``(first, n)`` of the planted part (fractions ``window``) of a contact that
    runs over frames ``a`` to ``b - 1``; at least two frames.

    >>> stance_window(10, 31)  # a 21-frame contact: frames 13-19
    (13, 7)
    """
    i0 = int(round(window[0] * (b - a)))
    return int(a) + i0, max(2, int(round(window[1] * (b - a))) - i0 + 1)

#: Systematic sd of the planted-foot slide (fraction of the running speed) at the true
#: camera height.  One per cent of height moves the slide by ~0.025, so alone the term
#: places the height to ~3 %, independent of the stature prior.  Chosen with
#: :data:`STANCE_WINDOW` on the 14 suite clips and the 8 held-out clips of ``bench
#: band-calibration`` (seeds 901-908) together: a grid approximation of the posterior gave
#: a height error of 3.3 % and 20 of 22 height intervals holding the truth, against 4.1 %
#: and 19 of 22 with 0.12 and the first half of stance (the previous choice); 0.06
#: narrows further but starts losing coverage.
STILLNESS_SYS_SD = 0.08

#: Curvature weight (s^2) of the bands of the cross-stride smoothed angles: the smoothing's bias
#: grows with the curvature of the angle curve (about half the squared smoothing time times the
#: second derivative), which the bootstrap cannot show.  Chosen on held-out synthetic clips
#: (``probreg bench band-calibration``): among 0-0.0015 s^2 it evens out the per-clip knee
#: coverage most (mean distance from 90 %: 6.3 points without, 3.0 with it; fast runners,
#: whose curves bend most, were under-covered) at 7 % more width.
BAND_CURVATURE_S2 = 0.001

#: Scale of the bootstrap deviations per angle family, fitted with the curvature term above
#: for 90 % pooled coverage on the held-out clips of ``probreg bench band-calibration``; the
#: trunk lean is not smoothed across strides and gets no curvature term.
BAND_SCALE = {"knee": 1.30, "hip": 1.44, "elbow": 1.90, "trunk_lean": 1.39}


def angle_curvature(series, fps):
    """Second derivative (deg/s^2) of an angle series, from differences over ~40 ms.

    NaN where the series or a neighbour is missing; the ends take their nearest value.

    >>> t = np.arange(50) / 50.0
    >>> bool(np.allclose(angle_curvature(3.0 * (50 * t) ** 2 / 2500, 50.0), 6.0))
    True
    """
    x = np.asarray(series, float)
    lag = max(1, int(round(0.04 * fps)))
    c = np.full(x.shape, np.nan)
    if len(x) > 2 * lag:
        c[lag:-lag] = (x[2 * lag:] - 2 * x[lag:-lag] + x[:-2 * lag]) * (fps / lag) ** 2
        c[:lag], c[-lag:] = c[lag], c[-lag - 1]
    return c


def _band_family(name):
    return name if name == "trunk_lean" else name.rsplit("_", 1)[0]


def angle_bands(angles_point, angles_noisy, fps=None, lo=5.0, hi=95.0, inflation=None):
    """Per-frame median and band of every angle.

    The median is that of the point liftings (no re-simulated noise, which would add its
    own bias).  Each side of the band is ``sqrt((k d)^2 + (a c)^2)``: ``d`` the bootstrap's
    deviation from its own median (5th or 95th percentile), ``k`` the angle family's scale
    (:data:`BAND_SCALE`), ``c`` the curvature of the median curve (:func:`angle_curvature`)
    and ``a`` :data:`BAND_CURVATURE_S2` (0 for the trunk lean; the term is left out where
    the curvature cannot be computed, or when ``fps`` is None).  ``inflation`` = a number
    scales every bootstrap band by it and leaves the curvature out (1.0: the raw bootstrap
    band, for calibration studies).

    Returns
    -------
    dict name -> (median, lo, hi), each (F,)
    """
    import warnings

    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for name, pts in angles_point.items():
            med = np.nanmedian(pts, 0)
            noisy = angles_noisy[name]
            centre = np.nanmedian(noisy, 0)
            dev_lo = centre - np.nanpercentile(noisy, lo, 0)
            dev_hi = np.nanpercentile(noisy, hi, 0) - centre
            fam = _band_family(name)
            if inflation is not None:
                k, bias = float(inflation), 0.0
            else:
                k = BAND_SCALE.get(fam, max(BAND_SCALE.values()))
                a = 0.0 if fam == "trunk_lean" or fps is None else BAND_CURVATURE_S2
                bias = a * np.abs(angle_curvature(med, fps)) if a > 0 else 0.0
                bias = np.where(np.isfinite(bias), bias, 0.0)
            out[name] = (med, med - np.hypot(k * dev_lo, bias), med + np.hypot(k * dev_hi, bias))
    return out


#: Scale of the bootstrap deviations of the gait numbers, fitted on held-out synthetic clips
#: for 90 % coverage over all clips and numbers (``probreg bench band-calibration``).
GAIT_BAND_SCALE = 2.25

#: Name endings of the gait numbers that cannot be negative (their intervals stop at zero).
NONNEGATIVE_GAIT_SUFFIXES = ("_spm", "_m", "_mps", "_s")


def gait_intervals(gait_point, gait_noisy, lo=5.0, hi=95.0, inflation=None):
    """Median and 90 % interval of every gait number.

    The median is that of the point liftings; each side of the interval is the bootstrap
    liftings' deviation from their own median (contacts detected anew on re-noised
    keypoints: step timing varies there and only there) scaled by ``inflation`` (default
    :data:`GAIT_BAND_SCALE`).

    Numbers that cannot be negative (rates, lengths, speeds, times: names ending in
    ``_spm``, ``_m``, ``_mps``, ``_s``) have their lower bound cut at zero; a widened
    interval of a short, uncertain contact time once reached -0.013 s.

    >>> g = gait_intervals({"cadence_spm": np.full(9, 170.0)},
    ...                    {"cadence_spm": 170.0 + np.linspace(-4.0, 4.0, 9)}, inflation=1.0)
    >>> [round(float(x), 1) for x in g["cadence_spm"]]
    [170.0, 166.4, 173.6]
    >>> g = gait_intervals({"contact_time_s": np.full(9, 0.05)},
    ...                    {"contact_time_s": 0.05 + np.linspace(-0.04, 0.04, 9)}, inflation=2.0)
    >>> [round(float(x), 3) for x in g["contact_time_s"]]
    [0.05, 0.0, 0.122]
    """
    import warnings

    k = GAIT_BAND_SCALE if inflation is None else float(inflation)
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for name, v in gait_point.items():
            med = float(np.nanmedian(v))
            w = np.asarray(gait_noisy.get(name, v), float)
            c = np.nanmedian(w)
            low = med - k * (c - np.nanpercentile(w, lo))
            if name.endswith(NONNEGATIVE_GAIT_SUFFIXES):
                low = max(low, 0.0)
            out[name] = (med, low, med + k * (np.nanpercentile(w, hi) - c))
    return out


SEGMENTS = ("thigh", "shank", "upper_arm", "forearm", "trunk", "hip_width", "shoulder_width")
OBSERVED_SEGMENTS = ("thigh", "shank", "upper_arm", "forearm", "trunk")
PARAM_NAMES = ["log_height", "stature"] + [f"m_{s}" for s in SEGMENTS]


@dataclass(frozen=True)
class SamplerSettings:
    """Sampling budget and propagation size."""

    n_walkers: int = 24
    tau_multiple: float = 50.0
    max_steps: int = 8000
    chunk: int = 250
    burn_in: int = 200
    n_draws: int = 60
    bootstrap_noise: bool = True
    seed: int = 0


class ClipModel:
    """Posterior of one clip: built from a registration and the (raw) keypoints.

    Parameters
    ----------
    registration : ClipRegistration
    keypoints_px : ndarray (F, 17, 3)
        Raw H36M keypoints (NaN = missing).
    fps : float
    athlete_lane : int or None
    priors : ModelPriors
    dist : array_like (5,), optional
        Known lens distortion.
    n_grid : int
        Heights on which the height-dependent statistics are precomputed.
    track_weight : float
        Weight of the ground-track filter's (per-contact) log-likelihood.  Its
        absolute values depend on unmodelled effects (foot placement, detector
        noise in depth), so it enters damped; 1 uses it at face value.

    Raises
    ------
    ValueError
        If no frame has lanes, or no height of the prior's range gives cameras.
    """

    def __init__(self, registration: ClipRegistration, keypoints_px, fps, athlete_lane=None,
                 priors: ModelPriors = ModelPriors(), dist=None, n_grid=36, branch="narrow",
                 track_weight=0.2):
        t0 = time.perf_counter()
        self.reg = registration
        self.fps = float(fps)
        self.priors = priors
        self.dist = None if dist is None else np.asarray(dist, float)
        self.athlete_lane = athlete_lane
        self.raw = np.asarray(keypoints_px, float)
        self.kp = clean_keypoints(self.raw, self.fps)
        self.noise_sd, self.noise_rho = noise_model(self.raw)
        self.F = len(self.kp)
        # stride timing for the cross-stride angle smoothing of every lifting (None: no
        # repeating strides, or keypoints too clean to need it -- as in lift()'s "auto")
        noisy = not np.isfinite(self.noise_sd) or self.noise_sd > LiftConfig().noise_floor_px
        self.stride_lag = stride_lags(self.kp, self.fps) if noisy else None
        self.branch = branch
        self.track_weight = float(track_weight)
        self.max_gap_frames = 25
        self._build_branches()
        if not self.valid.any():
            raise ValueError("no frame has a usable calibration family (no lanes found)")
        lo, hi = self.height_range
        plo, phi = priors.camera_height.interval(0.998)
        g_lo, g_hi = max(lo, plo), min(hi, phi)
        if not g_hi > g_lo:
            raise ValueError(f"the prior's camera heights ({plo:.1f}-{phi:.1f} m) do not overlap the "
                             f"heights the lanes allow ({lo:.1f}-{hi:.1f} m)")
        self.h_ref = float(np.clip(priors.camera_height.centre(), g_lo, g_hi))
        self._fix_offsets()
        self.grid = np.geomspace(g_lo, g_hi, n_grid)
        # two passes: contacts and lane offsets detected at a wrong height are wrong (a 50 %
        # error distorts the cast feet), so the first pass finds a reference height from
        # the limb lengths and the static camera alone, the second scores every term there
        self._precompute()
        theta = np.column_stack([np.log(self.grid), np.full(n_grid, priors.stature.centre()),
                                 np.ones((n_grid, len(SEGMENTS)))])
        saved = self.track_weight
        self.track_weight = 0.0
        lp = self.log_prob(theta)
        self.track_weight = saved
        if np.isfinite(lp).any():
            self.h_ref = float(self.grid[int(np.nanargmax(np.where(np.isfinite(lp), lp, -np.inf)))])
        self._fix_offsets(final=True)
        self._precompute()
        self.timings = {"precompute_s": time.perf_counter() - t0}

    # ------------------------------------------------------------------ cameras as a function of h
    def _build_branches(self, n=500):
        """Per frame: the family on a dense focal grid, restricted to one branch, as arrays."""
        fams = self.reg.sequence.families
        self.valid = np.array([f is not None for f in fams])
        self.inconsistent = np.zeros(self.F, bool)  # lanes found, family off the zoom path
        w = self.reg.image_size[0]
        self.logf = np.full((self.F, n), np.nan)
        self.h = np.full((self.F, n), np.nan)
        self.y = np.full((self.F, n), np.nan)
        self.R = np.full((self.F, n, 3, 3), np.nan)
        self.pp = np.tile([(self.reg.image_size[0] - 1) / 2, (self.reg.image_size[1] - 1) / 2], (self.F, 1))
        self.flip = np.zeros(self.F, bool)
        lo, hi = np.inf, -np.inf
        from .camera import focal_from_fov

        fgrid = np.geomspace(focal_from_fov(150.0, w), focal_from_fov(0.3, w), n)
        frames = [i for i, fam in enumerate(fams) if fam is not None]
        if self.dist is not None and np.any(self.dist):
            # every member undistorts the frame's lines anew (~1 ms each): frames go to the cores
            k = max(1, min(_default_workers(), len(frames)))
            parts = _fork_map(lambda idx: {i: self._members(i, fams[i], fgrid) for i in idx},
                              [frames[j::k] for j in range(k)])
            members = {i: m for part in parts for i, m in part.items()}
        else:
            members = {i: self._members(i, fams[i], fgrid) for i in frames}
        for i in frames:
            fam = fams[i]
            m = members[i]
            ok = m["valid"] & np.isfinite(m["height_m"])
            if ok.sum() < 3:
                self.valid[i] = False
                continue
            hh = np.where(ok, m["height_m"], np.nan)
            k = int(np.nanargmax(hh))
            sl = slice(k, n) if self.branch == "narrow" else slice(0, k + 1)
            self.logf[i, sl] = np.log(fgrid[sl])
            self.h[i, sl] = hh[sl]
            self.y[i, sl] = m["y_m"][sl]
            self.R[i, sl] = m["R"][sl]
            self.pp[i] = fam.principal_point
            self.flip[i] = bool(np.median(m["index_flipped"][ok]))
            seg = hh[sl]
            lo, hi = min(lo, np.nanmin(seg)), max(hi, np.nanmax(seg))
        self.height_range = (lo, hi)
        self.valid_lanes = self.valid.copy()
        self._glitches = None

    def _members(self, i, fam, fgrid):
        """Members of frame ``i``'s family at the focal lengths ``fgrid`` (lines undistorted
        with each member's own focal length when the lens distortion is given)."""
        if self.dist is None or not np.any(self.dist):
            return fam.members(fgrid)
        from .registration import undistorted_members

        lo, hi = self.priors.camera_height.interval(0.998)
        return undistorted_members(self.reg.frame_lanes[i], fam, fgrid, self.dist, self.reg.forward_px,
                                   self.reg.lane_width_m, height_window=(lo / 1.5, hi * 1.5),
                                   branch=self.branch)

    def _member_at(self, i, height_m):
        """Grid members of frame ``i``'s branch that bracket ``height_m``: ``(ia, ib, t)`` to
        interpolate linearly (``t`` from ``ia`` to ``ib``), or None when out of its reach."""
        hh = self.h[i]
        ok = np.isfinite(hh)
        if ok.sum() < 2:
            return None
        hv = hh[ok]
        order = np.argsort(hv)
        hs = hv[order]
        if not hs[0] <= height_m <= hs[-1]:
            return None
        j = int(np.clip(np.searchsorted(hs, height_m), 1, len(hs) - 1))
        a, b = order[j - 1], order[j]
        t = (height_m - hv[a]) / (hv[b] - hv[a]) if hv[b] != hv[a] else 0.0
        idx = np.flatnonzero(ok)
        return idx[a], idx[b], t

    def _focal_at(self, height_m):
        """(F,) focal length of every frame's own member at ``height_m`` (NaN: none)."""
        out = np.full(self.F, np.nan)
        for i in np.flatnonzero(self.valid_lanes):
            at = self._member_at(i, height_m)
            if at is not None:
                ia, ib, t = at
                out[i] = np.exp(self.logf[i, ia] + t * (self.logf[i, ib] - self.logf[i, ia]))
        return out

    def cameras_at(self, height_m, offsets=None):
        """Per-frame cameras of the family member at ``height_m`` as CameraArrays."""
        F = self.F
        valid = self.valid.copy()
        f = np.full(F, np.nan)
        y = np.full(F, np.nan)
        R = np.full((F, 3, 3), np.nan)
        for i in np.flatnonzero(self.valid):
            at = self._member_at(i, height_m)
            if at is None:
                valid[i] = False
                continue
            ia, ib, t = at
            f[i] = np.exp(self.logf[i, ia] + t * (self.logf[i, ib] - self.logf[i, ia]))
            y[i] = self.y[i, ia] + t * (self.y[i, ib] - self.y[i, ia])
            Rm = self.R[i, ia] + t * (self.R[i, ib] - self.R[i, ia])
            u, _, vt = np.linalg.svd(Rm)
            R[i] = u @ vt  # nearest rotation
        off = self.offsets if offsets is None else offsets
        y = y - self.reg.lane_width_m * off
        # frames without lanes between frames with lanes: the camera moves smoothly, so
        # bridge them (zoom, lateral position and rotation interpolated in time)
        self.gap_distance = np.zeros(F)
        ok = np.flatnonzero(valid)
        if len(ok) >= 2:
            for i in range(ok[0] + 1, ok[-1]):
                if valid[i]:
                    continue
                a, b = ok[ok < i][-1], ok[ok > i][0]
                if b - a > self.max_gap_frames:
                    continue
                t = (i - a) / (b - a)
                f[i] = np.exp((1 - t) * np.log(f[a]) + t * np.log(f[b]))
                y[i] = (1 - t) * y[a] + t * y[b]
                u, _, vt = np.linalg.svd((1 - t) * R[a] + t * R[b])
                R[i] = u @ vt
                valid[i] = True
                self.gap_distance[i] = min(i - a, b - i)
        C = np.column_stack([np.zeros(F), y, np.full(F, height_m)])
        C[~valid] = np.nan
        return CameraArrays(valid=valid, C=C, R=R, focal_px=f, principal_px=self.pp,
                            dist=np.zeros(5) if self.dist is None else self.dist)

    def _fix_offsets(self, final=False):
        """Lane-index offsets (frame to frame and to the athlete's lane) at the reference height."""
        reg = self.reg
        seq = reg.sequence
        seq.branch = self.branch
        # frames with a wrong family (a spurious or misplaced line) are bridged from their
        # neighbours like frames without lanes: those off the clip's zoom path at every height
        # and, once the reference height is settled (``final``), those off it at that height
        # (removing them at a first guess far from the truth would make that guess look
        # consistent)
        self.valid = self.valid_lanes.copy()
        self.inconsistent[:] = False
        # judged on the model's own families (with a lens, those of the undistorted lines)
        if self._glitches is None:
            self._glitches = glitch_vote(self._focal_at, self.valid_lanes)
        odd = set(self._glitches)
        if final:
            odd |= set(_zoom_outliers(self._focal_at(self.h_ref)))
        odd = sorted(i for i in odd if self.valid[i])
        if odd and len(odd) < self.valid.sum() - 2:
            self.valid[odd] = False
            self.inconsistent[odd] = True
        self.offsets = np.asarray(reg.track_offsets(seq, self.h_ref), int)
        cams = self.cameras_at(self.h_ref, offsets=self.offsets)
        self.offsets = self.offsets + lane_anchor_shift(athlete_ground_track(_as_list(cams), self.kp),
                                                        self.athlete_lane, reg.lane_width_m)

    # ------------------------------------------------------------------ likelihood on a grid
    def _precompute(self):
        G = len(self.grid)
        self.ll_track = np.full(G, -np.inf)
        self.ll_static = np.full(G, -np.inf)
        self.seg_obs = {s: np.full(G, np.nan) for s in OBSERVED_SEGMENTS}
        self.seg_se = {s: np.full(G, np.nan) for s in OBSERVED_SEGMENTS}
        # contacts are detected once (reference height) so every hypothesis is scored on the
        # same measurements; the filter's noise scales with the hypothesis (scale ~ height)
        ref = fit_ground_track(self.cameras_at(self.h_ref), self.kp, self.fps)
        self.contacts = ref.contacts
        self.stance_windows = self._stance_windows()
        slides = np.full((G, len(self.stance_windows)), np.nan)
        n_frames = max(int(self.valid.sum()), 1)
        for g, h in enumerate(self.grid):
            cams = self.cameras_at(h)
            if cams.valid.sum() < 3:
                continue
            tr = fit_ground_track(cams, self.kp, self.fps, contacts=self.contacts,
                                  config=self._track_config(cams))
            # tempered to one contact's worth: the filter's innovations are not independent
            # (the same feet, seen through one camera path), and its value under wrong
            # heights is dominated by unmodelled effects; undamped it would swamp every
            # other term by hundreds of nats
            n_meas = max(len(tr.contact_points_m), 1)
            self.ll_track[g] = tr.log_likelihood / n_meas if np.isfinite(tr.log_likelihood) else -1e3
            # static camera: one lateral position for all frames.  Residuals relative to the
            # camera-athlete distance (scale-free), Student-t (nu = 4) with scale 0.3 %,
            # tempered for the correlation of neighbouring frames (~10 frames)
            ys = cams.C[cams.valid, 1]
            dist = np.abs(np.median(ys) - np.nanmedian(tr.position_m[:, 1]))
            resid = (ys - np.median(ys)) / max(dist, 1.0)
            # a frame with lanes whose family has no member at this height (h beyond the
            # frame's branch) counts like a frame 10 % off the common position: otherwise a
            # height reached by a few odd frames only would be scored on those frames alone
            no_member = self.valid & ~(cams.valid & (self.gap_distance == 0))
            per_frame = -2.5 * np.log1p((resid / 0.003) ** 2 / 4)
            off_frame = -2.5 * np.log1p((0.1 / 0.003) ** 2 / 4)
            self.ll_static[g] = float(np.sum(per_frame) + off_frame * no_member.sum()) * (
                min(1.0, 25.0 / n_frames) if n_frames > 25 else 1.0) * 2.5
            self._segment_stats(g, cams, tr)
            slides[g] = self._slides(cams, tr)
        self._score_slides(slides)

    def _stance_windows(self):
        """``(side, first, n)``: the foot-flat part of every whole contact
        (fractions :data:`STANCE_WINDOW` of the detected contact)."""
        return [(side, *stance_window(a, b)) for side in (0, 1) for a, b in _runs(self.contacts[:, side])
                if a > 0 and b < self.F and b - a >= 3]  # a contact cut by the clip has no known phase

    def _slides(self, cams, tr):
        """Along-track velocity of each planted ankle (mid-stance, windows
        ``self.stance_windows``) as a fraction of the running speed, for the cameras ``cams``:
        (K,), NaN where unmeasured.

        The ankle is cast onto the athlete's vertical plane
        (:func:`probreg.trajectory.sagittal_ankle_points`), where its along-track position
        does not move when the ankle rises (on the ground plane it would)."""
        from .trajectory import sagittal_ankle_points

        win = self.stance_windows
        out = np.full(len(win), np.nan)
        if not win or tr.status != "ok":
            return out
        x = sagittal_ankle_points(cams, self.kp, tr)[..., 0]
        with np.errstate(invalid="ignore"):
            v_run = float(np.nanmedian(tr.velocity_mps[:, 0]))
        if not np.isfinite(v_run) or abs(v_run) < 0.5:
            return out
        for k, (side, a, n) in enumerate(win):
            xs = x[a:a + n, side]
            ok = np.isfinite(xs)
            if ok.sum() >= 2:
                out[k] = np.polyfit(np.flatnonzero(ok).astype(float), xs[ok], 1)[0] * self.fps / v_run
        return out

    def _score_slides(self, slides):
        """``ll_still`` on the grid from the per-contact slides (G, K)."""
        self.ll_still = np.zeros(len(self.grid))
        self.slide_median = np.full(len(self.grid), np.nan)
        rows = np.isfinite(slides).any(axis=1)  # heights with cameras and a track
        K = slides.shape[1]
        n_ok = np.isfinite(slides).sum(axis=1)
        if K < 4 or not rows.any():
            return  # too few whole contacts: no evidence
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            # a height that sees fewer than half the contacts is not scored on the few it sees
            med = np.where(n_ok >= max(4, K / 2), np.nanmedian(slides, axis=1), np.nan)
            # the median's scatter, measured once (at the reference height) for every hypothesis
            g0 = int(np.argmin(np.abs(np.log(self.grid / self.h_ref))))
            mad = 1.4826 * np.nanmedian(np.abs(slides[g0] - np.nanmedian(slides[g0])))
        if not np.isfinite(mad):
            return
        sd = float(np.hypot(1.2533 * mad / np.sqrt(max(n_ok[g0], 1)), STILLNESS_SYS_SD))
        self.slide_median = med
        # a height where the slide cannot be measured counts as a slide of the running speed
        self.ll_still = np.where(np.isfinite(med), -0.5 * (med / sd) ** 2, -0.5 * (1.0 / sd) ** 2)

    def _track_config(self, cams):
        """Contact-point noise for this hypothesis: foot placement plus the keypoint noise cast
        onto the ground (across the track it is magnified by the camera's grazing view)."""
        from .trajectory import TrackConfig

        ok = cams.valid
        if not ok.any() or not np.isfinite(self.noise_sd):
            return TrackConfig()
        pel = self.kp[:, JOINT_INDEX["pelvis"], :2]
        from .lifting import pixel_rays

        rays = pixel_rays(cams, pel[:, None, :])[:, 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            t = -cams.C[:, 2] / rays[:, 2]
            depth = np.nanmedian(t)
            sin_tilt = np.nanmedian(np.abs(rays[:, 2]))
            f = np.nanmedian(cams.focal_px)
        along = self.noise_sd * depth / f
        across = along / max(sin_tilt, 0.02)
        base = TrackConfig()
        return TrackConfig(contact_std_m=(float(np.hypot(base.contact_std_m[0], along)),
                                          float(np.hypot(base.contact_std_m[1], across))))

    def _segment_stats(self, g, cams, tr):
        from .lifting import _plane_hits, pixel_rays
        from .skeleton import SEGMENT_BONES

        J = JOINT_INDEX
        point = np.column_stack([tr.position_m, np.zeros(self.F)])
        P = _plane_hits(cams.C, pixel_rays(cams, self.kp[..., :2]), point, tr.left)
        depth = np.linalg.norm(P[:, J["pelvis"]] - cams.C, axis=-1)
        sd_m = np.nanmedian(self.noise_sd * depth / cams.focal_px) if np.isfinite(self.noise_sd) else 0.0
        for s in OBSERVED_SEGMENTS:
            lens = np.concatenate([np.linalg.norm(P[:, J[b]] - P[:, J[a]], axis=-1) for a, b in SEGMENT_BONES[s]])
            lens = lens[np.isfinite(lens)]
            if len(lens) < 10:
                continue
            obs = float(np.percentile(lens, 60))
            # remove the length that keypoint noise adds to a distance (2 joints, 2-D)
            obs = float(np.sqrt(max(obs**2 - 2 * sd_m**2, (0.5 * obs) ** 2)))
            mad = 1.4826 * np.median(np.abs(lens - np.median(lens)))
            n_eff = max(len(lens) / 10.0, 1.0)  # frames are strongly correlated
            self.seg_obs[s][g] = obs
            self.seg_se[s][g] = float(np.hypot(mad / np.sqrt(n_eff), 0.02 * obs))

    def _interp(self, arr, log_h):
        return np.interp(log_h, np.log(self.grid), arr, left=np.nan, right=np.nan)

    # ------------------------------------------------------------------ the log-probability
    def lengths(self, theta):
        """Segment lengths (m) of parameter vectors (W, D): dict seg -> (W,)."""
        theta = np.atleast_2d(theta)
        st = theta[:, 1]
        return {s: st * SEGMENT_PROPORTIONS[s] * theta[:, 2 + k] for k, s in enumerate(SEGMENTS)}

    def log_prior(self, theta):
        theta = np.atleast_2d(theta)
        h = np.exp(theta[:, 0])
        lp = self.priors.camera_height.logpdf(h) + theta[:, 0]  # Jacobian of h = exp(log h)
        lp = lp + self.priors.stature.logpdf(theta[:, 1])
        sd = self.priors.proportion_sd
        lp = lp + np.sum(-0.5 * ((theta[:, 2:] - 1.0) / sd) ** 2, axis=1)
        lp = np.where((theta[:, 1] > 0.5) & np.all(theta[:, 2:] > 0.5, axis=1), lp, -np.inf)
        return lp

    def log_likelihood(self, theta):
        theta = np.atleast_2d(theta)
        lh = theta[:, 0]
        with np.errstate(invalid="ignore"):
            ll = (self.track_weight * self._interp(self.ll_track, lh) + self._interp(self.ll_static, lh)
                  + self._interp(self.ll_still, lh))
        L = self.lengths(theta)
        for s in OBSERVED_SEGMENTS:
            if not np.isfinite(self.seg_obs[s]).any():
                continue  # never seen in this clip: the prior alone speaks
            obs = self._interp(self.seg_obs[s], lh)
            se = self._interp(self.seg_se[s], lh)
            # a height at which a seen segment cannot be measured is not a free pass
            ll = ll - 0.5 * ((obs - L[s]) / se) ** 2 - np.log(se)
        return np.where(np.isfinite(ll), ll, -np.inf)

    def log_prob(self, theta):
        """Vectorised log-posterior: theta (W, D) -> (W,)."""
        lp = self.log_prior(theta)
        out = np.full(len(lp), -np.inf)
        ok = np.isfinite(lp)
        if ok.any():
            out[ok] = lp[ok] + self.log_likelihood(np.atleast_2d(theta)[ok])
        return np.where(np.isfinite(out), out, -np.inf)

    # ------------------------------------------------------------------ sampling
    def initial_walkers(self, n, rng):
        """Walkers around the best grid height with lengths at their observed values."""
        theta_grid = []
        for g, h in enumerate(self.grid):
            st = self.priors.stature.centre()
            th = np.r_[np.log(h), st, np.ones(len(SEGMENTS))]
            theta_grid.append(th)
        lp = self.log_prob(np.array(theta_grid))
        g = int(np.nanargmax(np.where(np.isfinite(lp), lp, -np.inf)))
        base = theta_grid[g]
        # stature from the observed thigh + shank at that height, if available
        obs = np.nanmean([self.seg_obs[s][g] / SEGMENT_PROPORTIONS[s] for s in ("thigh", "shank")])
        if np.isfinite(obs):
            base[1] = obs
        step = np.log(self.grid[1] / self.grid[0]) if len(self.grid) > 1 else 0.05
        scale = np.r_[step, 0.02, np.full(len(SEGMENTS), 0.02)]
        p0 = base + rng.normal(0, 1, (n, len(base))) * scale
        # every walker must start where the posterior is positive
        for _ in range(50):
            bad = ~np.isfinite(self.log_prob(p0))
            if not bad.any():
                break
            p0[bad] = base + rng.normal(0, 1, (bad.sum(), len(base))) * scale * 0.5
        return p0

    def sample(self, settings: SamplerSettings = SamplerSettings(), progress=None):
        """Run emcee; returns (chain after burn-in, log-probs, acceptance, tau, diagnostics)."""
        import emcee

        rng = np.random.default_rng(settings.seed)
        D = len(PARAM_NAMES)
        if settings.n_walkers < 2 * D:
            raise ValueError(f"emcee's stretch move needs at least {2 * D} walkers for {D} parameters, "
                             f"got {settings.n_walkers}")
        p0 = self.initial_walkers(settings.n_walkers, rng)
        sampler = emcee.EnsembleSampler(settings.n_walkers, D, self.log_prob, vectorize=True)
        sampler.random_state = np.random.RandomState(settings.seed).get_state()  # reproducible moves
        t0 = time.perf_counter()
        state = sampler.run_mcmc(p0, settings.burn_in, progress=False, skip_initial_state_check=True)
        sampler.reset()
        tau = np.full(D, np.inf)
        steps = 0
        while steps < settings.max_steps:
            state = sampler.run_mcmc(state, settings.chunk, progress=False, skip_initial_state_check=True)
            steps += settings.chunk
            tau = sampler.get_autocorr_time(tol=0)
            if np.all(np.isfinite(tau)) and steps >= settings.tau_multiple * np.max(tau):
                break
        self.timings["sampling_s"] = time.perf_counter() - t0
        self.sampler = sampler
        return sampler, tau

    # ------------------------------------------------------------------ propagation
    def propagate(self, draws, rng, bootstrap_noise=True, config: LiftConfig = LiftConfig(), workers=None):
        """Lift the clip for every draw.

        Each draw is lifted twice: from the cleaned keypoints (the draw's *point*
        lifting: calibration and limb-length uncertainty) and from the cleaned
        keypoints plus re-simulated detector noise, cleaned again exactly as the
        data were (parametric bootstrap: adds the detector noise).  Both liftings
        smooth the hip, knee and elbow angles across strides as :func:`lift` does for
        noisy clips (with the clip's stride timing, found once).

        Every draw has its own random stream (spawned from ``rng``), so the result
        does not depend on ``workers``: draws are shared out over that many forked
        processes (default: the machine's cores, at most 4; 1, or a platform without
        ``fork``, runs them here).

        Returns
        -------
        dict
            ``joints`` (S, F, 17, 3) and ``angles`` {name: (S, F)} with noise;
            ``joints_point``, ``angles_point`` without; ``gait_point`` {name: (S,)} from
            the point liftings, ``gait`` from the noisy ones (contacts detected anew).
        """
        t0 = time.perf_counter()
        S = len(draws)
        cross = config.cross_stride_angles
        cross = self.stride_lag is not None if cross == "auto" else bool(cross)
        cfg = LiftConfig(**{**config.__dict__, "smooth_cutoff_hz": None, "cross_stride_angles": cross})
        L = self.lengths(draws)
        seeds = rng.integers(0, 2**63 - 1, size=S)
        with_noise = bootstrap_noise and np.isfinite(self.noise_sd) and self.noise_sd > 0
        job = (draws, L, seeds, cfg, with_noise, self._joint_noise_scale() if with_noise else None)
        workers = max(1, min(_default_workers() if workers is None else int(workers), S))
        chunks = [list(range(S))[k::workers] for k in range(workers)]
        parts = _fork_map(lambda idx: self._propagate_draws(idx, *job), chunks)
        out = {"joints": np.full((S, self.F, 17, 3), np.nan, np.float32),
               "joints_point": np.full((S, self.F, 17, 3), np.nan, np.float32),
               "angles": {k: np.full((S, self.F), np.nan) for k in ANGLE_NAMES},
               "angles_point": {k: np.full((S, self.F), np.nan) for k in ANGLE_NAMES},
               "gait": {}, "gait_point": {}}
        for part in parts:
            for s, res in part.items():
                for key in ("joints", "joints_point"):
                    out[key][s] = res[key]
                for key in ("angles", "angles_point"):
                    for k in ANGLE_NAMES:
                        out[key][k][s] = res[key][k]
                for key in ("gait", "gait_point"):
                    for k, v in res[key].items():
                        out[key].setdefault(k, np.full(S, np.nan))[s] = v
        self.timings["propagation_s"] = time.perf_counter() - t0
        return out

    def _propagate_draws(self, indices, draws, L, seeds, cfg, with_noise, per_joint):
        """The liftings of some draws: {draw index: {joints, joints_point, angles, angles_point, gait}}."""
        out = {}
        for s in indices:
            rng = np.random.default_rng(int(seeds[s]))
            h = float(np.exp(draws[s, 0]))
            cams = self._jitter_bridged(self.cameras_at(h), rng)
            seg = {k: float(v[s]) for k, v in L.items()}
            variants = [("_point", self.kp)]
            if with_noise:
                noisy = self.kp.copy()
                noisy[..., :2] += (_ar1_noise(rng, self.kp.shape[:2] + (2,), self.noise_sd, self.noise_rho)
                                   * per_joint[..., None])
                variants.append(("", clean_keypoints(noisy, self.fps)))
            res_s = {}
            for suffix, kp in variants:
                # the same contacts for every draw (detected once on the cleaned keypoints)
                tr = fit_ground_track(cams, kp, self.fps, contacts=self.contacts)
                res = lift(cams, kp, self.fps, segments_m=seg, track=tr, config=cfg, stride_lag=self.stride_lag)
                a = res.angles_deg()
                res_s["joints" + suffix] = res.joints_track_m.astype(np.float32)
                res_s["angles" + suffix] = a
                if suffix == "_point":
                    res_s["gait_point"] = dict(gait_summary(res.track, a, self.fps))
                else:
                    # the timing of the steps comes from the contacts: in the bootstrap they are
                    # detected anew on the re-noised keypoints, so cadence and contact times vary
                    res_s["gait"] = dict(gait_summary(fit_ground_track(cams, kp, self.fps), a, self.fps))
            if not with_noise:
                res_s["joints"], res_s["angles"] = res_s["joints_point"], res_s["angles_point"]
                res_s["gait"] = res_s["gait_point"]
            out[s] = res_s
        return out

    def _jitter_bridged(self, cams, rng, deg_per_frame=0.01, zoom_per_frame=0.002):
        """Uncertainty of bridged frames (no lanes): random pan/tilt and zoom growing with the
        distance to the nearest frame with lanes, so their bands widen where evidence is missing."""
        d = self.gap_distance
        if not np.any(d > 0):
            return cams
        R = cams.R.copy()
        f = cams.focal_px.copy()
        for i in np.flatnonzero(d > 0):
            a = np.radians(deg_per_frame * d[i]) * rng.standard_normal(2)
            ca, sa, cb, sb = np.cos(a[0]), np.sin(a[0]), np.cos(a[1]), np.sin(a[1])
            pan = np.array([[ca, 0, -sa], [0, 1, 0], [sa, 0, ca]])
            tilt = np.array([[1, 0, 0], [0, cb, -sb], [0, sb, cb]])
            R[i] = tilt @ pan @ R[i]
            f[i] *= np.exp(zoom_per_frame * d[i] * rng.standard_normal())
        return CameraArrays(valid=cams.valid, C=cams.C, R=R, focal_px=f, principal_px=cams.principal_px,
                            dist=cams.dist)

    def _joint_noise_scale(self):
        """Relative noise sd of every detection (F, 17) for the bootstrap (trunk = 1).

        Each joint's level comes from its residuals after cleaning; within a joint,
        detections are scaled by what their confidence says about their error
        (:func:`probreg.filtering.score_noise_scale`, normalised to unit RMS per
        joint), so the re-simulated noise relates to the scores as the data's does
        and the cleaning of the bootstrap copies weights them as it weighted the data."""
        resid = self.raw[..., :2] - self.kp[..., :2]
        rms = np.sqrt(np.nanmean(resid**2, axis=(0, 2)))
        trunk = np.nanmean(rms[[JOINT_INDEX["pelvis"], JOINT_INDEX["spine"], JOINT_INDEX["thorax"]]])
        scale = rms / trunk if np.isfinite(trunk) and trunk > 0 else np.ones(17)
        scale = np.where(np.isfinite(scale), np.clip(scale, 0.5, 3.0), 1.0)
        out = np.tile(scale, (self.F, 1))
        rel = score_noise_scale(self.raw, self.kp, self.noise_sd)
        if rel is not None:
            with np.errstate(invalid="ignore"):
                unit = rel / np.sqrt(np.nanmean(rel**2, axis=0))[None]
            out = out * np.where(np.isfinite(unit), unit, 1.0)
        return out


#: the function forked workers run on their chunk (set only while a pool runs)
_FORKED = None


def _default_workers():
    import os

    return min(os.cpu_count() or 1, 4)


def _forked_chunk(indices):
    from threadpoolctl import threadpool_limits

    # the workers already use every core: BLAS threads inside them only compete (4x slower)
    with threadpool_limits(limits=1):
        return _FORKED(indices)


def _fork_map(func, chunks):
    """``[func(chunk) for chunk in chunks]``, on one forked process per chunk when there are
    several and the platform forks (the workers inherit ``func`` and its data; only the
    chunks and the results are pickled), else here, as also when processes are not allowed."""
    import multiprocessing as mp

    global _FORKED
    if len(chunks) > 1 and "fork" in mp.get_all_start_methods():
        _FORKED = func
        try:
            with mp.get_context("fork").Pool(len(chunks)) as pool:
                return pool.map(_forked_chunk, chunks)
        except OSError:  # no processes allowed here (sandbox, limits)
            pass
        finally:
            _FORKED = None
    return [func(c) for c in chunks]


def _ar1_noise(rng, shape, sd, rho):
    """AR(1) noise along axis 0 with marginal sd ``sd``."""
    e = rng.standard_normal(shape)
    out = np.empty(shape)
    out[0] = e[0]
    c = np.sqrt(1 - rho**2)
    for t in range(1, shape[0]):
        out[t] = rho * out[t - 1] + c * e[t]
    return out * sd


def _as_list(cams: CameraArrays):
    """CameraArrays -> list of Camera/None (for functions that take Camera objects)."""
    from .camera import Camera

    out = []
    for i in range(len(cams.valid)):
        if not cams.valid[i]:
            out.append(None)
            continue
        f = cams.focal_px[i]
        K = np.array([[f, 0, cams.principal_px[i, 0]], [0, f, cams.principal_px[i, 1]], [0, 0, 1.0]])
        out.append(Camera(K=K, R=cams.R[i], C=cams.C[i], dist=cams.dist))
    return out

