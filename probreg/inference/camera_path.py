"""The camera's path through a clip, smoothed as far as its noise asks: a broadcast camera pans,
tilts and zooms smoothly.

Every frame's camera is the member of that frame's own family at the clip's camera height, so
it carries the noise of that frame's lane lines.  Where the lines are far apart in the image
(a stand or long-lens view) that noise is small (focal length ~0.5 % per frame).  Where they
crowd together -- a low camera grazing the track, whose far lines are 8-10 px apart -- one
frame's family is barely pinned: on the grazing tuning clips (``probreg.sim.heldout`` seeds
8414, 8951, 8958; never the held-out seeds) the members at the true height scattered by
7-13 % in focal length and 0.5-1.7 deg in pan from frame to frame, while the true camera moved
by 0.014 deg.  Cast onto the ground through those cameras a planted foot seemed to move at
running speed, so 80-90 % of the foot-frames were taken for ground contacts (26 % are); the
swinging feet then put the athlete's track 6-8 % too far, the limbs measured 8 % too long at
the true height and the height came out 9-15 % low (knee 5.6-6.5 deg where the true cameras
give 2.5-3.4 deg).

:class:`CameraPath` smooths each of the path's series -- log focal length, the rotation (as a
rotation vector relative to the clip's middle frame) and the lateral position -- with a
second-difference penalty (Whittaker smoother: the MAP path of a camera whose acceleration is
white noise), weighted by the measurement noise of that series, which it estimates from the
clip (robust scatter of the second differences): ``lambda = noise variance / process
variance``.  The process sd is the vanishing-point smoother's
(:func:`probreg.lanes.smooth_vanishing_points`, 5e-4 per frame^2, which follows a camera that
pans with the runner's stride), for the lateral position of the static camera 1 mm, so a
noisier path is smoothed more strongly.  A path whose noise is below :data:`PATH_NOISE_GATE`
(all stand, long-lens, steep and wide views of the tuning clips but one) is not smoothed at all:
there each frame keeps its own member, as before.  The noise is measured once per clip model,
on the cameras at the height where the lines' identities are settled, and the same smoothing
then applies to the cameras at every height (the ground track, contacts, limb lengths and
planted feet of every height hypothesis, and the lifting of every posterior draw).  The
camera's height is the clip's one parameter and is not touched; the static-camera term of the
likelihood keeps scoring each frame's own member (:mod:`probreg.inference.static`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["PATH_NOISE_GATE", "PATH_PROCESS_SD", "CameraPath", "along_path", "path_noise_var", "whittaker_system"]

#: process sd per frame^2 of the path's series: rotation (rad) and log focal length as the
#: vanishing-point smoother's, lateral position (m) of the static camera
PATH_PROCESS_SD = {"rotation": 5e-4, "log_focal": 5e-4, "lateral": 1e-3}

#: the path is smoothed only when its measured noise per frame exceeds one of these: rotation
#: (deg, the largest of the three components) or log focal length.  On the tuning clips the
#: chosen branch's path noise was at most 0.16 deg and 0.67 % on the 55 stand, long-lens, steep
#: and wide views (all but one, wide view 8857 at 0.158 deg, below the gates) and 0.45-2.7 deg
#: and 1.9-16 % on the 8 grazing ones that calibrate.  Below them smoothing has little to gain,
#: and it is not neutral: it
#: loosens the coupling of each frame's focal length, rotation and position, which only that
#: frame's lines hold together, and on stand and long-lens views at heights away from the truth
#: that moved the contacts the planted-feet term is measured on (camera height on four such
#: tuning clips 3.0/7.0/8.2/10.6 % -> 11.9/12.4/8.7/17.2 % with every path smoothed).
PATH_NOISE_GATE = {"rotation_deg": 0.15, "log_focal": 0.015}


def path_noise_var(z, measured):
    """Measurement-noise variance of a series from the robust scatter of its second differences
    over runs of measured frames (``var = 6 s^2`` for white noise); NaN with fewer than 5.

    >>> rng = np.random.default_rng(0); t = np.arange(400.0)
    >>> v = path_noise_var(0.001 * t**2 + rng.normal(0, 0.5, 400), np.ones(400, bool))
    >>> bool(abs(np.sqrt(v) - 0.5) < 0.05)
    True
    """
    z = np.asarray(z, float)
    m = np.asarray(measured, bool) & np.isfinite(z)
    d2 = z[2:] - 2 * z[1:-1] + z[:-2]
    d2 = d2[m[2:] & m[1:-1] & m[:-2]]
    if len(d2) < 5:
        return float("nan")
    return float((1.4826 * np.median(np.abs(d2 - np.median(d2)))) ** 2 / 6.0)


def whittaker_system(weights, lam):
    """Cholesky factor (``scipy.linalg.cholesky_banded``, upper form) of
    ``diag(weights) + lam D'D`` with ``D`` the second-difference operator.

    >>> from scipy.linalg import cho_solve_banded
    >>> t = np.arange(20.0); w = np.ones(20); w[5] = 0.0
    >>> bool(np.allclose(cho_solve_banded((whittaker_system(w, 50.0), False), w * (3 - 0.5 * t)), 3 - 0.5 * t))
    True
    >>> D = np.diff(np.eye(20), 2, axis=0); z = np.sin(t)    # the dense system gives the same fit
    >>> dense = np.linalg.solve(np.diag(w) + 50.0 * D.T @ D, w * z)
    >>> bool(np.allclose(cho_solve_banded((whittaker_system(w, 50.0), False), w * z), dense))
    True
    """
    from scipy.linalg import cholesky_banded

    w = np.asarray(weights, float)
    F = len(w)
    # D'D in upper band storage: ab[2] the diagonal, ab[1] the first, ab[0] the second superdiagonal
    # (each row of D is (1, -2, 1) at t, t + 1, t + 2)
    ab = np.zeros((3, F))
    for k, c in enumerate((1.0, -2.0, 1.0)):
        ab[2, k:F - 2 + k] += c * c
    ab[1, 1:F - 1] -= 2.0
    ab[1, 2:F] -= 2.0
    ab[0, 2:] = 1.0
    ab = lam * ab
    ab[2] += w
    return cholesky_banded(ab, lower=False, check_finite=False)


@dataclass(frozen=True)
class CameraPath:
    """A clip's camera-path smoother: one penalised fit per series, with the noise of each
    series measured once (:meth:`from_cameras`), applied to the cameras at any height."""

    measured: np.ndarray
    factors: dict
    lam: dict
    R0: np.ndarray

    @classmethod
    def from_cameras(cls, cams, measured=None, gate=PATH_NOISE_GATE):
        """The smoother for the path of ``cams`` (:class:`~probreg.geometry.CameraArrays`, one
        frame's member each); ``measured`` (F,) the frames whose camera comes from their own
        lanes (default: every frame with a camera; the others are left out of the fits and take
        the fitted path).  None without 5 measured frames, or when the path's noise is below
        ``gate`` (:data:`PATH_NOISE_GATE`; ``{"rotation_deg": 0, "log_focal": 0}`` smooths every
        path).

        >>> from probreg.geometry import CameraArrays
        >>> F = 60; rng = np.random.default_rng(0); t = np.arange(F)
        >>> R = _exp_rotation(np.column_stack([np.zeros(F), np.radians(0.2 * t), np.zeros(F)]))
        >>> f = 3000 * np.exp(0.002 * t); noisy = f * np.exp(rng.normal(0, 0.05, F))
        >>> cams = CameraArrays(np.ones(F, bool), np.zeros((F, 3)), R, noisy, np.zeros((F, 2)), np.zeros(5))
        >>> out = CameraPath.from_cameras(cams)(cams)
        >>> bool(np.std(np.log(out.focal_px / f)) < 0.3 * np.std(np.log(noisy / f)) and np.allclose(out.R, R))
        True
        """
        valid = np.asarray(cams.valid, bool)
        meas = valid if measured is None else valid & np.asarray(measured, bool)
        if meas.sum() < 5:
            return None
        R0 = cams.R[np.flatnonzero(meas)[meas.sum() // 2]]
        series = cls._series(cams, R0)
        noise = {key: path_noise_var(z, meas) for key, z in series.items()}
        rot_sd = np.degrees(np.sqrt(np.nanmax([noise[k] for k in ("rot_x", "rot_y", "rot_z")] + [0.0])))
        focal_sd = np.sqrt(noise["log_focal"]) if np.isfinite(noise["log_focal"]) else 0.0
        if not (rot_sd > gate["rotation_deg"] or focal_sd > gate["log_focal"]):
            return None  # a clean path: each frame's own member
        w = meas.astype(float)
        lam, factors = {}, {}
        for key, var in noise.items():
            q = PATH_PROCESS_SD[key if key in PATH_PROCESS_SD else "rotation"] ** 2
            ratio = var / q if np.isfinite(var) else 0.0
            lam[key] = float(ratio) if ratio > 1e-6 else 0.0  # below: a kernel far under one frame
            factors[key] = _factor(w, lam[key])
        return cls(measured=meas, factors=factors, lam=lam, R0=R0)

    @staticmethod
    def _series(cams, R0):
        valid = np.asarray(cams.valid, bool)
        rel = np.full((len(valid), 3), np.nan)
        v = np.flatnonzero(valid)
        rel[v] = _log_rotation(cams.R[v] @ R0.T)
        return {"log_focal": np.where(valid, np.log(cams.focal_px), np.nan), "lateral": cams.C[:, 1].copy(),
                "rot_x": rel[:, 0], "rot_y": rel[:, 1], "rot_z": rel[:, 2]}

    def __call__(self, cams):
        """``cams`` with their path smoothed (frames without a camera stay without one; frames
        measured at the reference height that have no camera here are left out of the fits)."""
        from scipy.linalg import cho_solve_banded

        valid = np.asarray(cams.valid, bool)
        if len(valid) != len(self.measured):
            return cams
        series = self._series(cams, self.R0)
        use = self.measured & valid & np.all(np.isfinite(np.column_stack(list(series.values()))), -1)
        if use.sum() < 5:
            return cams
        same = np.array_equal(use, self.measured)
        out = {}
        for key, z in series.items():
            factor = self.factors[key] if same else _factor(use.astype(float), self.lam[key])
            out[key] = z if factor is None else cho_solve_banded((factor, False), np.where(use, z, 0.0),
                                                                 check_finite=False)
        rot = np.column_stack([out["rot_x"], out["rot_y"], out["rot_z"]])
        R, f, C = cams.R.copy(), cams.focal_px.copy(), cams.C.copy()
        R[valid] = _exp_rotation(rot[valid]) @ self.R0
        f[valid] = np.exp(out["log_focal"][valid])
        C[valid, 1] = out["lateral"][valid]
        return replace(cams, R=R, focal_px=f, C=C)


def along_path(path, cams):
    """``cams`` smoothed by ``path`` (a :class:`CameraPath`), or as they are when ``path`` is None
    (a clean path, or too few frames to measure it)."""
    return cams if path is None else path(cams)


def _factor(weights, lam):
    """:func:`whittaker_system`, or None (no smoothing) for ``lam`` 0 or a singular system."""
    if not lam > 0:
        return None
    try:
        return whittaker_system(weights, lam)
    except np.linalg.LinAlgError:
        return None


def _log_rotation(R):
    """Rotation vectors of rotation matrices (..., 3, 3) (angles below pi)."""
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.where(th > 1e-9, th / (2.0 * np.sin(np.maximum(th, 1e-9))), 0.5)
    return v * s[..., None]


def _exp_rotation(w):
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3) (Rodrigues).

    >>> w = np.array([[0.1, -0.2, 0.3]]); bool(np.allclose(_log_rotation(_exp_rotation(w)), w))
    True
    """
    th = np.linalg.norm(w, axis=-1)
    k = w / np.maximum(th, 1e-12)[..., None]
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    return np.eye(3) + np.sin(th)[..., None, None] * K + (1.0 - np.cos(th))[..., None, None] * (K @ K)
