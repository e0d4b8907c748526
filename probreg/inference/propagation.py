"""Propagation of posterior draws to joints and angles (re-lifting every kept draw)."""

from __future__ import annotations

import time
import warnings
from dataclasses import replace

import numpy as np

from ..analysis import gait_summary
from ..filtering import clean_keypoints, score_noise_scale, stride_lags
from ..geometry import ANGLE_NAMES, JOINT_INDEX, CameraArrays
from ..lifting import LiftConfig, fit_ground_track, fit_ground_tracks, lift_many
from ..lifting.raycast import BATCH_ROWS
from ..lifting.trajectory import camera_track_config
from .parallel import default_workers, fork_call, fork_map, stop_flag

__all__ = ["DrawPropagation"]


class DrawPropagation:
    """The propagation half of :class:`probreg.inference.ClipModel`: every kept draw is lifted
    again (cameras at its height, its limb lengths, re-simulated detector noise).

    Needs the clip model's ``cameras_at``, ``lengths``, keypoints (``kp``, ``raw``), noise model
    (``noise_sd``, ``noise_rho``), ``contacts``, ``stride_lag``, ``gap_distance`` and ``timings``."""

    def propagate(self, draws, rng, bootstrap_noise=True, config: LiftConfig = LiftConfig(), workers=None,
                  progress=None, draws_per_noise_copy=2, noise_copies=None, noise_copy_seeds=None):
        """Lift the clip for every draw.

        Each draw is lifted twice: from the cleaned keypoints (the draw's *point*
        lifting: calibration and limb-length uncertainty) and from the cleaned
        keypoints plus re-simulated detector noise, cleaned again exactly as the
        data were (parametric bootstrap: adds the detector noise).  Both liftings
        smooth the hip, knee and elbow angles across strides as :func:`lift` does for
        noisy clips (with the clip's stride timing, found once).

        The re-noised keypoints do not depend on the draw: ``draws_per_noise_copy`` draws share
        one noise copy (and its cleaning, the costly part of a bootstrap), draw ``s`` copy
        ``s mod K`` with ``K = ceil(S / draws_per_noise_copy)``; each draw is still lifted with
        its own camera and limbs (on ``run_a``, sharing by 2 moved the knee bands' mean width
        by less than their Monte Carlo noise, ``reports/bench_speed.md``; 1 gives every draw
        its own copy).

        ``noise_copies`` (a list from :meth:`bootstrap_copies`, made ahead, e.g. while the
        sampler runs) replaces the copies: draw ``s`` takes ``noise_copies[s mod len]``; an entry
        that is ``None`` (the sampler finished first) is made here from ``noise_copy_seeds``
        (the seeds the list was made from), the same copy as it would have been there.

        Every draw and every noise copy has its own random stream (spawned from ``rng``), so the result
        does not depend on ``workers``: draws are shared out over that many forked
        processes (default: the machine's cores, at most 4; 1, or a platform without
        ``fork``, runs them here).  ``progress(desc, total)``, when given, makes a progress bar
        (``update(n)``, ``close()``) that counts the draws.

        Returns
        -------
        dict
            ``joints`` (S, F, 17, 3) and ``angles`` {name: (S, F)} with noise;
            ``joints_point``, ``angles_point`` without; ``gait_point`` {name: (S,)} from
            the point liftings, ``gait`` from the noisy ones (contacts detected anew);
            ``angle_noise_point`` and ``angle_noise`` {name: (S,)}: the noise (deg) the
            cross-stride angle smoothing estimated in each lifting (angles it smoothed only).
        """
        t0 = time.perf_counter()
        with_noise = self.bootstraps_noise(bootstrap_noise)
        out = self._lift_draws(draws, rng, with_noise, config, workers, progress, draws_per_noise_copy,
                               noise_copies, noise_copy_seeds)
        self.timings["propagation_s"] = time.perf_counter() - t0
        return out

    def band_decomposition(self, draws, prop, rng, n=16, config: LiftConfig = LiftConfig(), workers=None):
        """Where each angle's band comes from: shares of its variance due to the ``lens``
        (``k1``), the ``camera`` (height, i.e. the family member), the ``limbs`` (stature and
        segment proportions) and the ``keypoints`` (2D detector noise).

        Method (documented in ``run.json``): one group at a time varies over ``n`` of the
        posterior draws while the others are held at their posterior medians, and the point
        liftings' variance across those draws (mean over frames) is that group's part (a
        local, first-order variance decomposition; interactions are not attributed); the
        keypoints' part is what the bootstrap adds to the point liftings' variance
        (``prop``: the output of :meth:`propagate`).  The shares are the parts over their sum;
        ``parts_over_total`` compares that sum with the band's full variance (near 1 when the
        groups act independently).  Without an inferred lens its share is 0.

        Returns
        -------
        dict {angle: {"lens", "camera", "limbs", "keypoints", "parts_over_total"}}
        """
        t0 = time.perf_counter()
        draws = np.asarray(draws, float)
        n = min(int(n), len(draws))
        med = np.median(draws, axis=0)
        nseg = draws.shape[1] - 2 - (1 if getattr(self, "lens", None) is not None else 0)
        groups = {"camera": [0], "limbs": list(range(1, 2 + nseg))}
        if getattr(self, "lens", None) is not None:
            groups["lens"] = [draws.shape[1] - 1]
        parts = {k: {} for k in ("lens", "camera", "limbs", "keypoints")}
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN frames of an angle
            # every group's liftings in one call (one set of worker processes for all of them)
            thetas = []
            for cols in groups.values():
                theta = np.tile(med, (n, 1))
                theta[:, cols] = draws[:n, cols]
                thetas.append(theta)
            res = self._lift_draws(np.concatenate(thetas), rng, False, config, workers, None)["angles_point"]
            for i, g in enumerate(groups):
                for a in ANGLE_NAMES:
                    parts[g][a] = float(np.nanmean(np.nanvar(res[a][i * n:(i + 1) * n], axis=0)))
            for a in ANGLE_NAMES:
                parts["keypoints"][a] = float(max(np.nanmean(np.nanvar(prop["angles"][a], axis=0)
                                                             - np.nanvar(prop["angles_point"][a], axis=0)), 0.0))
                if "lens" not in groups:
                    parts["lens"][a] = 0.0
            out = {}
            for a in ANGLE_NAMES:
                v = {g: parts[g][a] for g in parts}
                tot = sum(x for x in v.values() if np.isfinite(x))
                full = float(np.nanmean(np.nanvar(prop["angles"][a], axis=0)))
                if not (tot > 0 and np.isfinite(tot)):
                    out[a] = {g: None for g in parts} | {"parts_over_total": None}
                    continue
                out[a] = {g: (float(x / tot) if np.isfinite(x) else 0.0) for g, x in v.items()}
                out[a]["parts_over_total"] = float(tot / full) if full > 0 else None
        self.timings["decomposition_s"] = time.perf_counter() - t0
        return out

    def bootstraps_noise(self, bootstrap_noise=True):
        """Whether :meth:`propagate` re-simulates detector noise: asked for, and the clip's noise
        level is known (clean keypoints have none to re-simulate)."""
        return bool(bootstrap_noise and np.isfinite(self.noise_sd) and self.noise_sd > 0)

    @staticmethod
    def noise_copy_seeds(rng, n):
        """The seeds of ``n`` noise copies (:meth:`bootstrap_copies`), from ``rng``."""
        return rng.integers(0, 2**63 - 1, size=int(n))

    def bootstrap_copies_ahead(self, rng, n):
        """Start making ``n`` noise copies (seeds from ``rng``) in a forked process, while the
        caller works on (e.g. samples); returns ``finish()``, which stops that process after the
        copy it is making and gives ``(copies, seeds)`` for :meth:`propagate` (copies not made
        are ``None``: the propagation's workers make them from the same seeds).  The time
        ``finish`` waited (for the copy under way) goes to :attr:`timings`."""
        seeds = self.noise_copy_seeds(rng, n)
        stop = stop_flag()
        result = fork_call(lambda: self.bootstrap_copies(seeds, stop=stop.is_set))

        def finish():
            t0 = time.perf_counter()
            stop.set()
            copies = result()
            self.timings["noise_copies_wait_s"] = time.perf_counter() - t0
            return copies, seeds

        return finish

    def stride_frames(self):
        """The clip's stride period (frames) from the whole-body 2-D pattern of the cleaned
        keypoints (:func:`probreg.inference.gait_check.pattern_stride_frames`); NaN without
        repeating strides.  The gait numbers' cross-check (:mod:`probreg.inference.gait_check`)."""
        if getattr(self, "_stride_frames", None) is None:
            from .gait_check import pattern_stride_frames

            self._stride_frames = pattern_stride_frames(self.kp, self.fps, self.pattern_lags())
        return self._stride_frames

    def pattern_lags(self):
        """The per-frame stride lags (frames) of the 2-D pattern (:func:`probreg.filtering.stride_lags`;
        the cross-stride smoothing's when it ran), or None without repeating strides: the stride period's
        and the published cadence's (:func:`probreg.inference.gait_check.pattern_cadence_interval`)."""
        if not hasattr(self, "_pattern_lags"):
            self._pattern_lags = self.stride_lag if self.stride_lag is not None else stride_lags(self.kp, self.fps)
        return self._pattern_lags

    def track_off_heading(self, height_m):
        """The share of the frames with a camera whose ground track (the point lifting's: the
        clip's contacts under the cameras at ``height_m``) heads more than
        :data:`probreg.lifting.trajectory.MAX_HEADING_DEG` from the straight's direction
        (:meth:`probreg.lifting.GroundTrack.off_heading`); NaN without such frames."""
        cams = self.cameras_at(height_m)
        tcfg = camera_track_config(cams, self.kp[:, JOINT_INDEX["pelvis"], :2], self.noise_sd)
        off = fit_ground_track(cams, self.kp, self.fps, contacts=self.contacts, config=tcfg).off_heading()[cams.valid]
        return float(np.mean(off)) if off.size else float("nan")

    def bootstrap_copies(self, seeds, stop=None):
        """Re-noised copies of the cleaned keypoints, each cleaned again as the data were (the
        draw-independent half of the bootstrap), one per seed (:meth:`noise_copy_seeds`), in
        order.  ``stop()``, when given, is asked before each copy: once it is true the rest are
        left ``None`` (:meth:`propagate` makes them from the same seeds, so where a copy was
        made does not change it)."""
        per_joint = self._joint_noise_scale()
        out = [None] * len(seeds)
        for k, sd in enumerate(seeds):
            if stop is not None and stop():
                break
            out[k] = self._noise_copy(np.random.default_rng(int(sd)), per_joint)
        return out

    def _lift_draws(self, draws, rng, with_noise, config, workers, progress, draws_per_noise_copy=1,
                    noise_copies=None, noise_copy_seeds=None):
        S = len(draws)
        if int(draws_per_noise_copy) < 1:
            raise ValueError(f"draws_per_noise_copy must be at least 1, got {draws_per_noise_copy}")
        if noise_copies is not None and len(noise_copies) == 0:
            raise ValueError("noise_copies is empty")
        if noise_copies is not None and any(c is None for c in noise_copies) and (
                noise_copy_seeds is None or len(noise_copy_seeds) != len(noise_copies)):
            raise ValueError("noise_copies has missing entries: noise_copy_seeds (one per copy) must be given")
        cross = config.cross_stride_angles
        cross = self.stride_lag is not None if cross == "auto" else bool(cross)
        cfg = LiftConfig(**{**config.__dict__, "smooth_cutoff_hz": None, "cross_stride_angles": cross})
        L = self.lengths(draws)
        seeds = rng.integers(0, 2**63 - 1, size=S)
        K = -(-S // int(draws_per_noise_copy)) if noise_copies is None else len(noise_copies)
        # noise copies, draw s uses copy s % K: given, or made by the workers from these seeds
        noise_seeds = rng.integers(0, 2**63 - 1, size=K) if with_noise and noise_copies is None else noise_copy_seeds
        job = (draws, L, seeds, K, noise_copies, noise_seeds, cfg, with_noise,
               self._joint_noise_scale() if with_noise else None)
        workers = max(1, min(default_workers() if workers is None else int(workers), S))
        # a few chunks per worker: the progress bar moves, and a slow chunk does not hold the rest;
        # the draws that share a noise copy go in one chunk (the copy is cleaned once)
        n_chunks = min(K, workers * 4) if workers > 1 or progress is not None else 1
        chunks = [[s for s in range(S) if (s % K) % n_chunks == c] for c in range(n_chunks)]
        bar = progress("propagation", S) if progress is not None else None
        try:
            parts = fork_map(lambda idx: self._propagate_draws(idx, *job), chunks, workers,
                              done=None if bar is None else (lambda chunk: bar.update(len(chunk))))
        finally:
            if bar is not None:
                bar.close()
        out = {"joints": np.full((S, self.F, 17, 3), np.nan, np.float32),
               "joints_point": np.full((S, self.F, 17, 3), np.nan, np.float32),
               "angles": {k: np.full((S, self.F), np.nan) for k in ANGLE_NAMES},
               "angles_point": {k: np.full((S, self.F), np.nan) for k in ANGLE_NAMES},
               "gait": {}, "gait_point": {}, "angle_noise": {}, "angle_noise_point": {}}
        for part in parts:
            for s, res in part.items():
                for key in ("joints", "joints_point"):
                    out[key][s] = res[key]
                for key in ("angle_noise", "angle_noise_point"):
                    for k, v in res.get(key, {}).items():
                        out[key].setdefault(k, np.full(S, np.nan))[s] = v
                for key in ("angles", "angles_point"):
                    for k in ANGLE_NAMES:
                        out[key][k][s] = res[key][k]
                for key in ("gait", "gait_point"):
                    for k, v in res[key].items():
                        out[key].setdefault(k, np.full(S, np.nan))[s] = v
        return out

    def _propagate_draws(self, indices, draws, L, seeds, K, noise_copies, noise_seeds, cfg, with_noise, per_joint):
        """The liftings of some draws: {draw index: {joints, joints_point, angles, angles_point, gait}}.

        Every draw's liftings (the point one and, with noise, the bootstrap one) are set up first
        (cameras, limb lengths, ground track) and then cast together (:func:`probreg.lifting.lift_many`)."""
        copies = {}  # noise copy index -> cleaned re-noised keypoints
        out = {}
        # draws in groups whose liftings fill one casting batch (memory as for one batch)
        size = max(1, BATCH_ROWS // (2 * max(self.F, 1)))
        for a in range(0, len(indices), size):
            out.update(self._lift_group(indices[a:a + size], copies, draws, L, seeds, K, noise_copies, noise_seeds,
                                        cfg, with_noise, per_joint))
        return out

    def _lift_group(self, indices, copies, draws, L, seeds, K, noise_copies, noise_seeds, cfg, with_noise, per_joint):
        """:meth:`_propagate_draws` of a group of draws, their liftings cast together; ``copies``
        (noise copy index -> keypoints) is the chunk's, filled here as copies are made."""
        meta = []  # one lifting each: (draw, suffix, cameras, track config, keypoints, segment lengths)
        for s in indices:
            rng = np.random.default_rng(int(seeds[s]))
            h = float(np.exp(draws[s, 0]))
            cams = self._jitter_bridged(self.cameras_at(h), rng)
            if getattr(self, "lens", None) is not None:
                # the draw's own lens: its k1 undistorts the keypoints (the lines' undistortion,
                # and so the family, stays that of the lens model's kappa_star: first order)
                cams = replace(cams, dist=np.array([float(draws[s, -1]), 0.0, 0.0, 0.0, 0.0]))
            seg = {k: float(v[s]) for k, v in L.items()}
            variants = [("_point", self.kp)]
            if with_noise:
                k = s % K
                if k not in copies:
                    given = noise_copies[k] if noise_copies is not None else None
                    copies[k] = (given if given is not None
                                 else self._noise_copy(np.random.default_rng(int(noise_seeds[k])), per_joint))
                variants.append(("", copies[k]))
            # the ground-track filter's contact noise as the likelihood has it for this camera
            # (the keypoint noise cast onto the ground: large across the track in a grazing view)
            tcfg = camera_track_config(cams, self.kp[:, JOINT_INDEX["pelvis"], :2], self.noise_sd)
            meta += [(s, suffix, cams, tcfg, kp, seg) for suffix, kp in variants]
        # the ground tracks of all these liftings in one filter pass, with the same contacts for
        # every draw (detected once on the cleaned keypoints)
        tracks = fit_ground_tracks([m[2] for m in meta], [m[4] for m in meta], self.fps, self.contacts,
                                   [m[3] for m in meta])
        jobs = [(cams, kp, seg, tr) for (_, _, cams, _, kp, seg), tr in zip(meta, tracks)]
        out = {s: {} for s in indices}
        for (s, suffix, cams, tcfg, kp, _), res in zip(meta, lift_many(jobs, self.fps, cfg, self.stride_lag)):
            res_s = out[s]
            a = res.angles_deg()
            res_s["joints" + suffix] = res.joints_track_m.astype(np.float32)
            res_s["angles" + suffix] = a
            # the cross-stride smoother's estimate of each angle's noise (deg): the data's and
            # the bootstrap's are compared by probreg.inference.bands.bootstrap_noise_ratio
            res_s["angle_noise" + suffix] = {k: float(v[0]) for k, v in res.extra.get("angle_noise", {}).items()}
            if suffix == "_point":
                res_s["gait_point"] = dict(gait_summary(res.track, a, self.fps))
            else:
                # the timing of the steps comes from the contacts: in the bootstrap they are
                # detected anew on the re-noised keypoints, so cadence and contact times vary
                res_s["gait"] = dict(gait_summary(fit_ground_track(cams, kp, self.fps, config=tcfg), a, self.fps))
        if not with_noise:
            for res_s in out.values():
                res_s["joints"], res_s["angles"] = res_s["joints_point"], res_s["angles_point"]
                res_s["angle_noise"] = res_s["angle_noise_point"]
                res_s["gait"] = res_s["gait_point"]
        return out

    def _noise_copy(self, rng, per_joint):
        """The cleaned keypoints plus re-simulated detector noise, cleaned again as the data were."""
        noisy = self.kp.copy()
        noisy[..., :2] += (_ar1_noise(rng, self.kp.shape[:2] + (2,), self.noise_sd, self.noise_rho)
                           * per_joint[..., None])
        return clean_keypoints(noisy, self.fps)

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


def _ar1_noise(rng, shape, sd, rho):
    """AR(1) noise along axis 0 with marginal sd ``sd``."""
    e = rng.standard_normal(shape)
    out = np.empty(shape)
    out[0] = e[0]
    c = np.sqrt(1 - rho**2)
    for t in range(1, shape[0]):
        out[t] = rho * out[t - 1] + c * e[t]
    return out * sd
