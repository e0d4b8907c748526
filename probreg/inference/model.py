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
  Student-t with a scale of 0.3 % of the camera-athlete distance, or the
  members' own frame-to-frame jitter at that height where the family amplifies
  the lane noise beyond it (:mod:`probreg.inference.static`);
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
  the parameter lengths, with the measurement's standard error (normalised
  relative to the measured length: both scale with the height).

The height-dependent statistics are precomputed on a grid of heights and
interpolated, so the log-probability is vectorised over walkers and costs
microseconds; ``emcee`` (differential-evolution moves, :mod:`probreg.inference.sampling`) runs
until the chain is 50 integrated autocorrelation times long (or a budget is spent).  Every kept draw is then
*propagated*: cameras at its height, ground track, lifting with its limb
lengths and with detector noise re-simulated (parametric bootstrap of the
keypoints), giving joint and angle samples and so credible bands.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..calibration.family import members_on_grid
from ..calibration.registration import (
    ClipRegistration,
    _zoom_outliers,
    athlete_ground_track,
    glitch_vote,
    lane_anchor_shift,
)
from ..filtering import clean_keypoints, keypoints_noisy, noise_model, relabel_left_right, stride_lags
from ..geometry import JOINT_INDEX, SEGMENT_BONES
from ..geometry.rays import CameraArrays, _as_list
from ..lifting import LiftConfig
from ..lifting.trajectory import _runs, camera_track_config, fit_ground_track, fit_ground_tracks
from .bands import stance_window
from .camera_path import CameraPath, along_path
from .heights import (HEIGHT_SYSTEMATIC_SD, height_grid, identity_height, lens_conflict, limb_consistency,
                      smear_log_likelihood, term_conflict)
from .priors import SEGMENT_PROPORTIONS, ModelPriors
from .parallel import default_workers, fork_map
from .propagation import DrawPropagation
from .sampling import EmceeSampling, SamplerSettings
from .static import member_jitter, score_static

__all__ = ["ClipModel", "SamplerSettings", "PARAM_NAMES", "STILLNESS_SYS_SD", "NoCalibrationError"]


class NoCalibrationError(ValueError):
    """The clip cannot be calibrated (``reason``: ``"no_family"``, no lanes of the straight;
    ``"no_plausible_height"`` or ``"no_finite_posterior"``, lanes that allow no camera the
    priors admit); :func:`probreg.pipeline.run_clip` writes an ``"uncalibrated"`` result."""

    def __init__(self, message, reason="no_family"):
        super().__init__(message)
        self.reason = reason


#: Systematic sd of the planted-foot slide (fraction of the running speed) at the true
#: camera height.  One per cent of height moves the slide by ~0.025, so alone the term
#: places the height to ~3 %, independent of the stature prior.  Chosen with
#: :data:`STANCE_WINDOW` on the 14 suite clips and the 8 held-out clips of ``bench
#: band-calibration`` (seeds 901-908) together: a grid approximation of the posterior gave
#: a height error of 3.3 % and 20 of 22 height intervals holding the truth, against 4.1 %
#: and 19 of 22 with 0.12 and the first half of stance (the previous choice); 0.06
#: narrows further but starts losing coverage.
STILLNESS_SYS_SD = 0.08


SEGMENTS = ("thigh", "shank", "upper_arm", "forearm", "trunk", "hip_width", "shoulder_width")

OBSERVED_SEGMENTS = ("thigh", "shank", "upper_arm", "forearm", "trunk")

PARAM_NAMES = ["log_height", "stature"] + [f"m_{s}" for s in SEGMENTS]

class ClipModel(DrawPropagation, EmceeSampling):
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
        Known lens distortion (the pipeline gives a known ``k1`` alone as a sharp ``lens`` prior).
    lens : LensModel, optional
        The lens from the lanes (:class:`probreg.calibration.lens.LensModel`): the lines are
        already undistorted with its ``kappa_star``; ``k1`` is the last parameter (prior
        ``lens.prior``, likelihood the plumb-line evidence at ``k1 (r_ref / f_ref(h))**2``).
    n_grid : int
        Heights (geometric) of the precomputed height-dependent statistics.
    track_weight : float
        Weight of the ground-track filter's (per-contact) log-likelihood.  Its
        absolute values depend on unmodelled effects (foot placement, detector
        noise in depth), so it enters damped; 1 uses it at face value.
    height_systematic_sd : float
        Systematic allowance (sd of log height) of the height-only terms (0: off; the default
        :data:`probreg.inference.heights.HEIGHT_SYSTEMATIC_SD`).
    limb_consistency_weight : float
        Weight of :func:`probreg.inference.heights.limb_consistency` (0: off).

    Raises ``ValueError`` if no frame has lanes, or no height of the prior's range gives cameras.
    """

    def __init__(self, registration: ClipRegistration, keypoints_px, fps, athlete_lane=None,
                 priors: ModelPriors = ModelPriors(), dist=None, n_grid=36, branch="narrow",
                 track_weight=0.2, lens=None, height_systematic_sd=HEIGHT_SYSTEMATIC_SD,
                 limb_consistency_weight=1.0):
        t0 = time.perf_counter()
        self.height_systematic_sd = float(height_systematic_sd)
        if not (np.isfinite(self.height_systematic_sd) and self.height_systematic_sd >= 0):
            raise ValueError(f"height_systematic_sd must be a finite number >= 0, got {height_systematic_sd!r}")
        self.reg = registration
        self.lens = lens
        if lens is not None and dist is not None and np.any(dist):
            raise ValueError("a clip model takes a known lens (dist) or an inferred one (lens), not both")
        self.fps = float(fps)
        self.priors = priors
        self.dist = None if dist is None else np.asarray(dist, float)
        self.athlete_lane = athlete_lane
        self.raw = np.asarray(keypoints_px, float)  # the detector's labels: a swap stays in the noise
        self.noise_sd, self.noise_rho = noise_model(self.raw)
        relabelled, self.exchanged = relabel_left_right(self.raw, self.noise_sd)  # legs set right (run.json)
        self.kp = clean_keypoints(relabelled, self.fps, relabel=False)
        self.F = len(self.kp)
        # stride timing for the cross-stride angle smoothing of every lifting (None: no
        # repeating strides, or keypoints too clean to need it -- as in lift()'s "auto")
        cfg = LiftConfig()
        noisy = keypoints_noisy(self.raw, self.noise_sd, cfg.noise_floor_px, cfg.noise_floor_leg_frac)
        self.stride_lag = stride_lags(self.kp, self.fps) if noisy else None
        self.branch = branch
        self.track_weight = float(track_weight)
        self.limb_consistency_weight = float(limb_consistency_weight)
        self.max_gap_frames = 25
        self.camera_path = None
        self._build_branches()
        if not self.valid.any():
            raise NoCalibrationError(f"no frame has a usable calibration family on the {branch} branch "
                                     "(no lanes found, or, with a lens given, none of its cameras "
                                     "straightens the lines)")
        lo, hi = self.height_range
        plo, phi = priors.camera_height.interval(0.998)
        g_lo, g_hi = max(lo, plo), min(hi, phi)
        if not g_hi > g_lo:
            # lanes that allow no plausible camera (e.g. spurious lines of a grazing view) calibrate nothing
            raise NoCalibrationError(f"the prior's camera heights ({plo:.1f}-{phi:.1f} m) do not overlap the "
                                     f"heights the lanes allow ({lo:.1f}-{hi:.1f} m)", "no_plausible_height")
        self.h_ref = float(np.clip(priors.camera_height.centre(), g_lo, g_hi))
        self._id_range = (g_lo, g_hi)
        self._fix_offsets()
        # refined below the frames' branch tops (probreg.inference.heights)
        self.grid = height_grid(g_lo, g_hi, n_grid, np.nanmax(self.h[self.valid], axis=1))
        # two passes: contacts and lane offsets detected at a wrong height are wrong (a 50 %
        # error distorts the cast feet), so the first pass finds a reference height from
        # the limb lengths and the static camera alone, the second scores every term there
        self._precompute()
        saved = self.track_weight
        self.track_weight = 0.0
        lp = self._grid_log_prob()[1]
        self.track_weight = saved
        if np.isfinite(lp).any():
            self.h_ref = float(self.grid[int(np.nanargmax(np.where(np.isfinite(lp), lp, -np.inf)))])
        self._fix_offsets(final=True)
        self._precompute()
        if not np.isfinite(self._grid_log_prob()[1]).any():
            # e.g. a grazing view whose few calibrated frames give no limb lengths at any height
            raise NoCalibrationError("no camera height the lanes allow gives a finite posterior (no limb "
                                     "lengths or no consistent camera at any height)", "no_finite_posterior")
        # do the height-only terms tell one story? (tempered by temper_height_terms, after the branch choice)
        self.height_conflict, self.height_temper = term_conflict(self.grid, self._height_term_curves()), 1.0
        self.timings = {"precompute_s": time.perf_counter() - t0}

    @property
    def param_names(self):
        """Names of the posterior's parameters (``k1`` last when the lens is inferred)."""
        return PARAM_NAMES + (["k1"] if self.lens is not None else [])

    def given_lens_conflict(self):
        """A given lens's plumb-line term against the height terms (:func:`.heights.lens_conflict`), or None."""
        if self.lens is None or self.lens.given_k1 is None:
            return None
        x, ll = self._height_terms()
        with np.errstate(invalid="ignore", divide="ignore"):
            z = self.lens.evidence.log_likelihood(self.lens.evidence.kappa_of(self.lens.given_k1, self.f_ref_grid))
        return lens_conflict(x, ll, self._interp(z, x))

    def k1_at(self, height_m):
        """``k1`` the lines' undistortion implies at ``height_m`` (the family's reference focal
        length there); 0 without an inferred lens."""
        if self.lens is None:
            return np.zeros_like(np.asarray(height_m, float))
        f = np.exp(self._interp(np.log(self.f_ref_grid), np.log(height_m)))
        return self.lens.evidence.k1_of(self.lens.kappa_star, f)

    # ------------------------------------------------------------------ cameras as a function of h
    def _build_branches(self, n=500):
        """Per frame: the family on a dense focal grid, restricted to one branch, as arrays."""
        fams = self.reg.sequence.families
        self.valid = np.array([f is not None for f in fams])
        self.inconsistent = np.zeros(self.F, bool)  # lanes found, family off the zoom path
        w = self.reg.image_size[0]
        self.logf, self.h, self.y = (np.full((self.F, n), np.nan) for _ in range(3))
        self.R = np.full((self.F, n, 3, 3), np.nan)
        self.pp = np.tile([(self.reg.image_size[0] - 1) / 2, (self.reg.image_size[1] - 1) / 2], (self.F, 1))
        self.flip = np.zeros(self.F, bool)
        lo, hi = np.inf, -np.inf
        from ..geometry import focal_from_fov

        fgrid = np.geomspace(focal_from_fov(150.0, w), focal_from_fov(0.3, w), n)
        frames = [i for i, fam in enumerate(fams) if fam is not None]
        if self.dist is not None and np.any(self.dist):
            # every member undistorts the frame's lines anew (~1 ms each): frames go to the cores
            k = max(1, min(default_workers(), len(frames)))
            parts = fork_map(lambda idx: {i: self._members(i, fams[i], fgrid) for i in idx},
                              [frames[j::k] for j in range(k)])
            members = {i: m for part in parts for i, m in part.items()}
        else:
            members = members_on_grid({i: fams[i] for i in frames}, fgrid)
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
        """Members of frame ``i``'s family at the focal lengths ``fgrid``, its lines undistorted
        with each member's own focal length (the lens distortion is given)."""
        from ..calibration import undistorted_members

        lo, hi = self.priors.camera_height.interval(0.998)
        return undistorted_members(self.reg.frame_lanes[i], fam, fgrid, self.dist, self.reg.forward_px,
                                   self.reg.lane_width_m, height_window=(lo / 1.5, hi * 1.5),
                                   branch=self.branch)

    def _sorted_heights(self):
        """Per frame, its branch's grid heights in increasing order (``+inf`` padded) and their
        grid indices: (F, n) each, computed once (the branch grids do not change)."""
        if getattr(self, "_hs_cache", None) is None or self._hs_cache[0] is not self.h:
            hh = np.where(np.isfinite(self.h), self.h, np.inf)
            order = np.argsort(hh, axis=1, kind="stable")
            self._hs_cache = (self.h, np.take_along_axis(hh, order, axis=1), order,
                              np.isfinite(self.h).sum(axis=1))
        return self._hs_cache[1:]

    def _brackets(self, height_m):
        """Grid members of every frame's branch that bracket ``height_m``, to interpolate
        linearly: grid indices ``ia``, ``ib`` (F,), the weight ``t`` from ``ia`` to ``ib`` and
        whether the frame reaches ``height_m`` (at least two grid members and ``height_m``
        within their heights)."""
        hs, order, n_ok = self._sorted_heights()
        F = len(hs)
        j = np.clip((hs < height_m).sum(axis=1), 1, np.maximum(n_ok - 1, 1))
        rows = np.arange(F)
        ha, hb = hs[rows, j - 1], hs[rows, j]
        last = hs[rows, np.maximum(n_ok - 1, 0)]
        ok = (n_ok >= 2) & (hs[:, 0] <= height_m) & (height_m <= last)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(hb != ha, (height_m - ha) / (hb - ha), 0.0)
        return order[rows, j - 1], order[rows, j], np.where(ok, t, 0.0), ok

    def _focal_at(self, height_m):
        """(F,) focal length of every frame's own member at ``height_m`` (NaN: none)."""
        ia, ib, t, ok = self._brackets(height_m)
        ok &= self.valid_lanes
        rows = np.arange(self.F)
        with np.errstate(invalid="ignore"):
            lf = self.logf[rows, ia] + t * (self.logf[rows, ib] - self.logf[rows, ia])
        return np.where(ok, np.exp(lf), np.nan)

    def member_sensitivity(self, height_m, rel=0.01):
        """How weakly the height fixes the camera: the median over calibrated frames of
        ``|d log f / d log h|`` at ``height_m`` (central difference over +-``rel``), about 1 for a
        broadcast camera, growing without bound towards the top of the family (a frame that
        loses its member within the step counts as infinite); NaN without calibrated frames."""
        up, down = self._focal_at(height_m * (1 + rel)), self._focal_at(height_m / (1 + rel))
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.abs(np.log(up) - np.log(down)) / (2 * np.log1p(rel))
        frames = self.valid & np.isfinite(self._focal_at(height_m))
        if not frames.any():
            return float("nan")
        return float(np.median(np.where(np.isfinite(s[frames]), s[frames], np.inf)))

    def cameras_at(self, height_m, offsets=None, smooth=True):
        """Per-frame cameras of the family member at ``height_m`` as CameraArrays, their path
        smoothed in time when it is noisy (:class:`probreg.inference.camera_path.CameraPath`;
        ``smooth`` False: each frame's own member)."""
        F = self.F
        ia, ib, t, reach = self._brackets(height_m)
        valid = self.valid & reach
        f = np.full(F, np.nan)
        y = np.full(F, np.nan)
        R = np.full((F, 3, 3), np.nan)
        v = np.flatnonzero(valid)
        if len(v):
            a, b, tv = ia[v], ib[v], t[v]
            f[v] = np.exp(self.logf[v, a] + tv * (self.logf[v, b] - self.logf[v, a]))
            y[v] = self.y[v, a] + tv * (self.y[v, b] - self.y[v, a])
            Rm = self.R[v, a] + tv[:, None, None] * (self.R[v, b] - self.R[v, a])
            u, _, vt = np.linalg.svd(Rm)
            R[v] = u @ vt  # nearest rotations
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
        if self.lens is not None:
            dist = np.array([self.lens.camera_k1(f), 0.0, 0.0, 0.0, 0.0])  # f: NaN without valid frames
        else:
            dist = np.zeros(5) if self.dist is None else self.dist
        cams = CameraArrays(valid=valid, C=C, R=R, focal_px=f, principal_px=self.pp, dist=dist)
        return along_path(self.camera_path, cams) if smooth else cams

    def _fix_offsets(self, final=False):
        """Lane-index offsets (frame to frame and to the athlete's lane) at the reference height, or the
        nearest well-conditioned one (:func:`probreg.inference.heights.identity_height`)."""
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
        lo, hi = self._id_range  # where the lines' identities are settled
        h_id = self._identity_h = identity_height(np.geomspace(lo, hi, 17), self.member_sensitivity, lambda h: int(
            np.isfinite(self._focal_at(h)[self.valid]).sum()), self.h_ref)
        self.offsets = np.asarray(reg.track_offsets(seq, h_id), int)
        cams = self.cameras_at(h_id, offsets=self.offsets, smooth=False)
        self.offsets = self.offsets + lane_anchor_shift(athlete_ground_track(_as_list(cams), self.kp),
                                                        self.athlete_lane, reg.lane_width_m)
        # the path's noise, measured where the lines' identities are settled (every height's
        # cameras are then smoothed as much as that noise asks: probreg.inference.camera_path;
        # the anchor's shift of all offsets by whole lanes does not change it)
        self.camera_path = CameraPath.from_cameras(cams, self.gap_distance == 0)

    # ------------------------------------------------------------------ likelihood on a grid
    def _precompute(self):
        G = len(self.grid)
        self._precompute_id = getattr(self, "_precompute_id", 0) + 1
        self.ll_track = np.full(G, -np.inf)
        self.seg_obs = {s: np.full(G, np.nan) for s in OBSERVED_SEGMENTS}
        self.seg_se = {s: np.full(G, np.nan) for s in OBSERVED_SEGMENTS}
        self.seg_spread, self.seg_measured = ({s: np.full(G, v) for s in OBSERVED_SEGMENTS} for v in (np.nan, 0.0))
        J, fin = JOINT_INDEX, np.isfinite(self.kp[..., 0])
        self.seg_count = {s: int(sum(np.sum(fin[:, J[a]] & fin[:, J[b]]) for a, b in SEGMENT_BONES[s]))
                          for s in OBSERVED_SEGMENTS}
        # contacts are detected once (reference height) so every hypothesis is scored on the
        # same measurements; the filter's noise scales with the hypothesis (scale ~ height)
        self.contacts = fit_ground_track(self.cameras_at(self.h_ref), self.kp, self.fps).contacts
        self.stance_windows = self._stance_windows()
        slides = np.full((G, len(self.stance_windows)), np.nan)
        n_frames = max(int(self.valid.sum()), 1)
        static_parts = {}
        # the clip's reference focal length (zoom ratios removed) at every grid height
        self.f_ref_grid, self.speed_grid = np.full(G, np.nan), np.full(G, np.nan)  # and the athlete's speed
        zoom = self.lens.evidence.zoom if self.lens is not None else np.ones(self.F)
        pelvis = self.kp[:, JOINT_INDEX["pelvis"], :2]
        scored = {}  # grid index -> (each frame's own member, the members along the path, frames bridged)
        for g, h in enumerate(self.grid):
            raw = self.cameras_at(h, smooth=False)  # each frame's own member: the static term's spread
            cams = along_path(self.camera_path, raw)
            if cams.valid.any():
                self.f_ref_grid[g] = float(np.nanmedian(cams.focal_px[cams.valid] / zoom[cams.valid]))
            if cams.valid.sum() >= 3:  # (cameras_at sets gap_distance anew for every height)
                scored[g] = raw, cams, self.gap_distance
        tracks = fit_ground_tracks([c for _, c, _ in scored.values()], [self.kp] * len(scored), self.fps, self.contacts,
                                   [camera_track_config(c, pelvis, self.noise_sd) for _, c, _ in scored.values()])
        for (g, (raw, cams, gap)), tr in zip(scored.items(), tracks):  # every height's track from one filter pass
            # tempered to one contact's worth: the filter's innovations are not independent
            # (the same feet, seen through one camera path), and its value under wrong
            # heights is dominated by unmodelled effects; undamped it would swamp every
            # other term by hundreds of nats
            n_meas = max(len(tr.contact_points_m), 1)
            v = np.linalg.norm(tr.velocity_mps, axis=-1)  # no finite speed: NaN, no penalty
            self.speed_grid[g] = np.median(v[np.isfinite(v)]) if np.isfinite(v).any() else np.nan
            self.ll_track[g] = tr.log_likelihood / n_meas if np.isfinite(tr.log_likelihood) else -1e3
            # static camera: one lateral position for all frames (residuals relative to the
            # camera-athlete distance, scored once every height is seen: probreg.inference.static)
            ys = raw.C[raw.valid, 1]
            with warnings.catch_warnings():  # no track where this height has cameras: from the track's y = 0
                warnings.simplefilter("ignore", RuntimeWarning)
                lateral = np.nanmedian(tr.position_m[:, 1])
            dist = max(float(np.abs(np.median(ys) - (lateral if np.isfinite(lateral) else 0.0))), 1.0)
            # a frame with lanes whose family has no member at this height (h beyond the
            # frame's branch) counts like a frame 10 % off the common position: otherwise a
            # height reached by a few odd frames only would be scored on those frames alone
            no_member = self.valid & ~(raw.valid & (gap == 0))
            static_parts[g] = ((ys - np.median(ys)) / dist, int(no_member.sum()),
                               member_jitter(raw.C[:, 1], raw.valid & (gap == 0), dist))
            self._segment_stats(g, cams, tr)
            slides[g] = self._slides(cams, tr)
        self.ll_static = score_static(static_parts, len(self.grid), n_frames)[0]
        self.ll_limbs = self.limb_consistency_weight * limb_consistency(self.seg_spread, self.seg_count,
                                                                        measured=self.seg_measured, frames=self.F)
        self._score_slides(slides)

    def _stance_windows(self):
        """``(side, first, n)``: the foot-flat part of every whole contact (:data:`STANCE_WINDOW`)."""
        return [(side, *stance_window(a, b)) for side in (0, 1) for a, b in _runs(self.contacts[:, side])
                if a > 0 and b < self.F and b - a >= 3]  # a contact cut by the clip has no known phase

    def _slides(self, cams, tr):
        """Along-track velocity of each planted ankle (mid-stance, windows
        ``self.stance_windows``) as a fraction of the running speed, for the cameras ``cams``:
        (K,), NaN where unmeasured.

        The ankle is cast onto the athlete's vertical plane
        (:func:`probreg.lifting.trajectory.sagittal_ankle_points`), where its along-track position
        does not move when the ankle rises (on the ground plane it would)."""
        from ..lifting import sagittal_ankle_points

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

    def _segment_stats(self, g, cams, tr):
        from ..geometry import pixel_rays
        from ..lifting.raycast import _plane_hits

        J = JOINT_INDEX
        point = np.column_stack([tr.position_m, np.zeros(self.F)])
        P = _plane_hits(cams.C, pixel_rays(cams, self.kp[..., :2]), point, tr.left)
        depth = np.linalg.norm(P[:, J["pelvis"]] - cams.C, axis=-1)
        with warnings.catch_warnings():  # no pelvis in front of the camera in any frame: no noise term
            warnings.simplefilter("ignore", RuntimeWarning)
            sd_m = np.nanmedian(self.noise_sd * depth / cams.focal_px) if np.isfinite(self.noise_sd) else 0.0
        sd_m = float(sd_m) if np.isfinite(sd_m) else 0.0
        for s in OBSERVED_SEGMENTS:
            lens = np.concatenate([np.linalg.norm(P[:, J[b]] - P[:, J[a]], axis=-1) for a, b in SEGMENT_BONES[s]])
            lens = lens[np.isfinite(lens) & (lens > 0)]  # joints at one point measure no length
            if len(lens) < 10:
                continue
            med = float(np.median(lens))  # unbiased, not a percentile (docs/method.md: "The limbs seen at a height")
            # remove the length that keypoint noise adds to a distance (2 joints, 2-D)
            obs = float(np.sqrt(max(med**2 - 2 * sd_m**2, (0.5 * med) ** 2)))
            mad = 1.4826 * np.median(np.abs(lens - med))
            n_eff = max(len(lens) / 10.0, 1.0)  # frames are strongly correlated
            self.seg_obs[s][g] = obs
            self.seg_se[s][g] = float(np.hypot(mad / np.sqrt(n_eff), 0.02 * obs))
            self.seg_spread[s][g], self.seg_measured[s][g] = mad / max(med, 1e-9), len(lens)

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
        m = theta[:, 2:2 + len(SEGMENTS)]
        lp = lp + np.sum(-0.5 * ((m - 1.0) / sd) ** 2, axis=1)
        lp = np.where((theta[:, 1] > 0.5) & np.all(m > 0.5, axis=1), lp, -np.inf)
        if self.lens is not None:
            lp = lp + self.lens.prior.logpdf(theta[:, -1])
        return lp

    def _height_term_curves(self):
        """The height-only likelihood terms on the grid: name -> (G,)."""
        return {"ground_track": self.track_weight * self.ll_track, "static_camera": self.ll_static,
                "planted_feet": self.ll_still, "limb_consistency": self.ll_limbs}

    def temper_height_terms(self):
        """Temper the height-only terms by ``height_conflict["temper"]`` (1 unless they contradict
        each other: :func:`probreg.inference.heights.term_conflict`); returns the factor.  Done once
        the family branch is chosen: the branches' evidence compares the terms untempered."""
        self.height_temper = float(self.height_conflict["temper"])
        return self.height_temper

    def _height_terms(self):
        """The terms that depend on the camera height alone (ground track, static camera,
        planted feet, limbs' consistency: tempered by ``height_temper``; the running-speed prior),
        marginalised over the height's systematic allowance
        (:func:`probreg.inference.heights.smear_log_likelihood`): ``(log_grid, ll)``."""
        temper = getattr(self, "height_temper", 1.0)  # set once the model is built (1 while it is)
        key = (self.track_weight, self._precompute_id, temper)
        if getattr(self, "_height_cache", (None,))[0] != key:
            with np.errstate(invalid="ignore"):
                ll = temper * sum(self._height_term_curves().values())
                ll = ll + self.priors.running_speed_logpdf(self.speed_grid)  # a height-only prior term
            self._height_cache = (key, smear_log_likelihood(self.grid, ll, self.height_systematic_sd))
        return self._height_cache[1]

    def log_likelihood(self, theta):
        theta = np.atleast_2d(theta)
        lh = theta[:, 0]
        x, ll_h = self._height_terms()
        ll = np.interp(lh, x, ll_h, left=np.nan, right=np.nan)
        L = self.lengths(theta)
        for s in OBSERVED_SEGMENTS:
            if not np.isfinite(self.seg_obs[s]).any():
                continue  # never seen in this clip: the prior alone speaks
            obs = self._interp(self.seg_obs[s], lh)
            se = self._interp(self.seg_se[s], lh)
            # a height at which a seen segment cannot be measured is not a free pass
            # normalised in the image's terms: obs and se scale together with the height, and a
            # normaliser log(se) would add a spurious -log(h) per segment (heights pulled low)
            ll = ll - 0.5 * ((obs - L[s]) / se) ** 2 - np.log(se / obs)
        if self.lens is not None:
            # plumb-line evidence: the image-space distortion this k1 makes at this height's focal length
            with np.errstate(invalid="ignore"):
                f = np.exp(self._interp(np.log(self.f_ref_grid), lh))
                ll = ll + self.lens.evidence.log_likelihood(self.lens.evidence.kappa_of(theta[:, -1], f))
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
    def _grid_log_prob(self):
        """Parameter vectors at the grid heights (prior-centre stature, unit proportions, the
        lens's best ``k1``) and their log-posteriors."""
        theta_grid = []
        for h in self.grid:
            th = np.r_[np.log(h), self.priors.stature.centre(), np.ones(len(SEGMENTS))]
            if self.lens is not None:
                th = np.r_[th, float(self.k1_at(h))]
            theta_grid.append(th)
        return theta_grid, self.log_prob(np.array(theta_grid))
