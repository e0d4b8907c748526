"""The lens from the lane lines: radial distortion inferred by the plumb-line constraint.

Lane lines of the straight are straight on the ground, so a straight line is what a
pinhole camera shows; a zoom lens at its wide end bends them (barrel, ``k1 < 0``, or
pincushion, ``k1 > 0``).  Their curvature, summed over every line of many frames, pins the
radial distortion without knowing anything else about the camera.

Parameterisation
----------------
OpenCV's ``k1`` acts on normalised coordinates ``(x - c) / f``, so how far it moves a pixel
depends on the focal length -- which is what the one-degree-of-freedom family leaves open.
The lines measure the distortion in pixels.  probreg therefore writes it as

    ``kappa = k1 * (r_ref / f)**2``,   ``r_ref`` = half the image diagonal (px),

the *image-space* coefficient (a pixel at the image corner moves by about ``kappa * r_ref``),
which the lines fix whatever the focal length.  The clip's lens is one ``k1`` (the lens
does not change within a clip; frames that zoom see ``kappa_i = k1 (r_ref / f_i)**2``, with
the frames' zoom ratios ``f_i / f_ref`` from the lane families).  ``k1`` is sampled in the
posterior with the camera height: ``f_ref(h)`` comes from the family, so the ``k1`` a
height implies is ``kappa (f_ref(h) / r_ref)**2``; a narrow (telephoto) clip's lines hardly
move for any plausible ``k1``, the evidence is flat and ``k1`` keeps its prior
(:class:`LensPrior`), which then changes nothing in the image either.

Only ``k1`` is inferred; ``k2`` and the tangential terms are taken as zero (a broadcast zoom
lens's distortion over the image is dominated by ``k1``; ``probreg run --dist`` gives all five
when known).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..lanes.types import FrameLanes, _scale_frame
from .zoom import ZOOM_SCAN_MIN_SHIFT_PX, _zoom_by_lines, _zoom_ratios

__all__ = ["LensPrior", "LensEvidence", "LensModel", "plumb_line_evidence", "infer_lens", "undistort_registration",
           "lens_registration", "kappa_grid", "undistort_px", "distort_px",
           "reference_radius"]


@dataclass(frozen=True)
class LensPrior:
    """Weakly informative prior of a broadcast lens's ``k1``: normal, mean ``mean`` (0), sd
    ``sd``, truncated to ``|k1| <= limit``.

    Broadcast zoom lenses at their wide end show ``|k1|`` of about 0.1-0.25 (barrel or
    pincushion), at their long end almost none; sd 0.15 gives those values prior
    density within a factor of 4 of the peak, and the truncation at 0.5 excludes lenses a
    broadcast camera does not carry.

    >>> p = LensPrior()
    >>> bool(p.logpdf(0.0) > p.logpdf(0.25) > p.logpdf(0.45)), bool(np.isinf(p.logpdf(0.6)))
    (True, True)
    """

    sd: float = 0.15
    limit: float = 0.5
    mean: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.sd) and self.sd > 0 and np.isfinite(self.limit) and self.limit > 0):
            raise ValueError(f"the k1 prior needs a positive sd and limit, got sd={self.sd}, limit={self.limit}")
        if not (np.isfinite(self.mean) and abs(self.mean) <= self.limit):
            raise ValueError(f"the k1 prior's mean must be finite and within +-{self.limit}, got {self.mean}")

    @classmethod
    def given(cls, k1, sd=None):
        """The prior of a lens the user gives (``--dist``): sharp at ``k1`` (sd
        :data:`GIVEN_K1_SD`, a lens calibrated on a chart), truncated at ``max(0.5, 2 |k1|)``.

        >>> p = LensPrior.given(-0.2)
        >>> p.interval(0.9)[0] < -0.2 < p.interval(0.9)[1], round(p.interval(0.9)[1] - p.interval(0.9)[0], 4)
        (True, 0.0066)
        """
        k1 = float(k1)
        return cls(sd=GIVEN_K1_SD if sd is None else float(sd), limit=max(0.5, 2.0 * abs(k1)), mean=k1)

    def logpdf(self, k1):
        k1 = np.asarray(k1, float)
        out = -0.5 * ((k1 - self.mean) / self.sd) ** 2 - np.log(self.sd * np.sqrt(2 * np.pi))
        return np.where(np.abs(k1) <= self.limit, out, -np.inf)

    def interval(self, p=0.9):
        from scipy.stats import norm

        z = float(norm.ppf(0.5 + p / 2))
        return max(self.mean - z * self.sd, -self.limit), min(self.mean + z * self.sd, self.limit)


#: sd of the prior of a given ``k1`` (:meth:`LensPrior.given`): a lens calibrated on a chart
#: is known to a few thousandths
GIVEN_K1_SD = 0.002


def reference_radius(image_size):
    """``r_ref``: half the image diagonal in pixels."""
    return float(_scale_frame(image_size)[1])


def distort_px(points_px, centre, q):
    """Radial distortion in pixels: ``x_d = c + (x_u - c) (1 + q |x_u - c|**2)`` (``q = k1 / f**2``).

    ``q`` broadcasts against the points' leading axes (e.g. ``q`` (K, 1) with points (N, 2)
    gives (K, N, 2))."""
    d = np.asarray(points_px, float) - centre
    q = np.asarray(q, float)[..., None]
    return centre + d * (1 + q * np.sum(d * d, -1, keepdims=True))


def undistort_px(points_px, centre, q, iterations=8):
    """Inverse of :func:`distort_px` (Newton on the radius; exact to ~1e-9 px for the
    distortions a lens has); NaN where the distortion is not invertible (beyond the radius
    where a barrel lens's mapping turns back).

    >>> c = np.array([959.5, 539.5])
    >>> p = np.array([[100.0, 50.0], [1800.0, 1000.0]])
    >>> bool(np.allclose(distort_px(undistort_px(p, c, -6e-8), c, -6e-8), p))
    True
    """
    d = np.asarray(points_px, float) - centre
    q = np.asarray(q, float)[..., None]
    rd = np.sqrt(np.sum(d * d, -1, keepdims=True))
    r = rd + 0.0 * q
    for _ in range(iterations):
        g = r + q * r**3 - rd
        dg = 1 + 3 * q * r**2
        r = r - g / np.where(np.abs(dg) > 1e-6, dg, 1e-6)
    scale = np.where(rd > 0, r / np.where(rd > 0, rd, 1.0), 1.0)
    # a strong barrel lens folds the image edge back: no undistorted point maps there (NaN)
    ok = (r >= 0) & (np.abs(r + q * r**3 - rd) <= 1e-6 * np.maximum(rd, 1.0)) & (1 + 3 * q * r**2 > 0)
    return centre + d * np.where(ok, scale, np.nan)


def kappa_grid(limit=0.4, n=81, spread=9.0):
    """Image-space coefficients on which the evidence is evaluated: symmetric, dense near 0
    (``limit sinh(t) / sinh(spread)``, ``t`` uniform: a telephoto clip's plausible ``kappa``
    is ~1e-3, a wide one's ~0.1; with the defaults the step is 2e-5 at 0 and 6e-3 at 0.025)."""
    t = np.linspace(-spread, spread, n)
    return limit * np.sinh(t) / np.sinh(spread)


def _line_rss(points, starts, q):
    """Sum over lines of the squared distances of the points from their total-least-squares
    line, after undistortion with each ``q`` (K,): (K,)."""
    K = len(q)
    out = np.zeros(K)
    for a, b in zip(starts[:-1], starts[1:]):
        p = points[:, a:b]  # (K, n, 2)
        m = p.mean(axis=1, keepdims=True)
        d = p - m
        sxx = np.einsum("kn,kn->k", d[..., 0], d[..., 0])
        syy = np.einsum("kn,kn->k", d[..., 1], d[..., 1])
        sxy = np.einsum("kn,kn->k", d[..., 0], d[..., 1])
        out += 0.5 * (sxx + syy) - np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
    return out


@dataclass(frozen=True)
class LensEvidence:
    """What the lane lines say about the lens.

    Attributes
    ----------
    kappa : ndarray (K,)
        Image-space coefficients of the reference zoom (:func:`kappa_grid`).
    loglik : ndarray (K,)
        Plumb-line log-likelihood of each (0 at the best; tempered, see
        :func:`plumb_line_evidence`); flat when the lines carry no curvature.
    zoom : ndarray (F,)
        Each frame's focal length relative to the clip's reference (median) focal length.
    r_ref : float
    noise_px : float
        Scatter of the support points about straight lines at the best ``kappa`` (px).
    n_frames, n_lines, n_points : int
        What the evidence was summed over.
    weight : float
        Tempering of the summed evidence (effective independent frames per frame, divided
        by ``birge``).
    birge : float
        Excess scatter of the frames' own estimates (Birge ratio, >= 1).
    """

    kappa: np.ndarray
    loglik: np.ndarray
    zoom: np.ndarray
    r_ref: float
    noise_px: float
    n_frames: int
    n_lines: int
    n_points: int
    weight: float
    birge: float = 1.0

    def log_likelihood(self, kappa):
        """Interpolated plumb-line log-likelihood; beyond the grid the edge value minus a
        steep quadratic wall (kappa that large is no broadcast lens)."""
        kappa = np.asarray(kappa, float)
        ll = np.interp(kappa, self.kappa, self.loglik)
        over = np.maximum(np.abs(kappa) - self.kappa[-1], 0.0)
        return ll - 1e4 * over**2

    def k1_of(self, kappa, focal_ref_px):
        """``k1`` (OpenCV, normalised) of an image-space ``kappa`` at the reference focal length."""
        return np.asarray(kappa, float) * (np.asarray(focal_ref_px, float) / self.r_ref) ** 2

    def kappa_of(self, k1, focal_ref_px):
        return np.asarray(k1, float) * (self.r_ref / np.asarray(focal_ref_px, float)) ** 2

    def best_kappa(self, prior: LensPrior | None = None, focal_ref_px=None):
        """Posterior mode of ``kappa`` (with ``prior`` on ``k1`` at ``focal_ref_px``, if given)."""
        lp = self.loglik.copy()
        if prior is not None and focal_ref_px is not None and np.isfinite(focal_ref_px):
            lp = lp + prior.logpdf(self.k1_of(self.kappa, focal_ref_px))
        return float(self.kappa[int(np.nanargmax(np.where(np.isfinite(lp), lp, -np.inf)))])

    def frame_q(self, kappa):
        """Per-frame pixel coefficients ``q_i = kappa / (r_ref zoom_i)**2`` (for :func:`undistort_px`)."""
        return float(kappa) / (self.r_ref * self.zoom) ** 2

    def informative(self, prior: LensPrior, focal_ref_px, min_drop=2.0):
        """Whether the lines tell lenses the prior allows apart: the log-likelihood falls by
        ``min_drop`` or more somewhere within the prior's 90 % interval (else the image
        shows no curvature a plausible lens could make)."""
        lo, hi = prior.interval(0.9)
        ks = self.kappa_of(np.array([lo, hi]), focal_ref_px)
        inside = (self.kappa >= ks.min()) & (self.kappa <= ks.max())
        return bool(inside.any() and np.nanmax(self.loglik[inside]) - np.nanmin(self.loglik[inside]) >= min_drop)

    def to_dict(self):
        return {"noise_px": self.noise_px, "n_frames": self.n_frames, "n_lines": self.n_lines,
                "n_points": self.n_points, "weight": self.weight, "birge": self.birge,
                "r_ref_px": self.r_ref}


def _frame_points(fl: FrameLanes, max_points):
    """A frame's line support points, at most ``max_points`` per line (evenly spaced), with
    each line's share of its full support (``len(kept) / len(all)``)."""
    sets, keep = [], []
    for ln in fl.lines:
        p = np.asarray(ln.points_px, float)
        p = p[np.all(np.isfinite(p), 1)]
        if len(p) < 5:
            continue
        if len(p) > max_points:
            sel = np.linspace(0, len(p) - 1, max_points).round().astype(int)
            keep.append(len(sel) / len(p))
            p = p[sel]
        else:
            keep.append(1.0)
        sets.append(p)
    return sets, np.asarray(keep)


def _evidence_frames(frame_lanes, idx, max_frames, max_points):
    """The frames the evidence is summed over, ``[(index, sets, keep)]``: at most ``max_frames``
    of the frames ``idx`` (evenly spaced), each with its line points (:func:`_frame_points`)."""
    if len(idx) > max_frames:
        idx = [idx[int(j)] for j in np.linspace(0, len(idx) - 1, max_frames).round()]
    frames = []
    for i in idx:
        sets, keep = _frame_points(frame_lanes[i], max_points)
        if sets:
            frames.append((i, sets, keep))
    return frames


def _rss_curve(frames, centre, r_ref, zoom, kappa):
    """RSS of every frame in ``frames`` [(index, sets, keep)] for each ``kappa``: (n_frames, K),
    every line's RSS scaled back to its full support; also the points and lines counted."""
    rss = np.zeros((len(frames), len(kappa)))
    n_pts = n_lines = 0
    for f, (i, sets, keep) in enumerate(frames):
        pts = np.concatenate(sets)
        starts = np.r_[0, np.cumsum([len(p) for p in sets])]
        q = kappa / (r_ref * zoom[i]) ** 2
        und = undistort_px(pts, centre, q[:, None])  # (K, N, 2)
        for k, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
            rss[f] += _line_rss(und, np.array([a, b]), q) / keep[k]
        n_pts += int(round(sum(len(p) / w for p, w in zip(sets, keep))))
        n_lines += len(sets)
    return rss, n_pts, n_lines


def _overdispersion(kappa, rss_frames, s):
    """Birge ratio of the frames' own best ``kappa`` about their weighted mean: (chi2 / dof,
    at least 1).  Each frame's estimate and its variance come from a parabola fitted to its
    RSS curve (``RSS ~ a (kappa - k_i)**2 + c``, variance ``s**2 / a``); frames whose
    estimates scatter more than those variances allow (lines that are not perfectly straight,
    a detector bias that changes with the view) widen the clip's evidence by that ratio."""
    est, var = [], []
    for r in rss_frames:
        if not np.all(np.isfinite(r)):
            continue  # a frame whose points a lens of this grid folds away
        a, b, _ = np.polyfit(kappa, r, 2)
        if a > 0:
            est.append(-b / (2 * a))
            var.append(s**2 / a)
    if len(est) < 3:
        return 1.0
    est, var = np.asarray(est), np.asarray(var)
    w = 1 / var
    mean = np.sum(w * est) / np.sum(w)
    return float(max(1.0, np.sum(w * (est - mean) ** 2) / (len(est) - 1)))


def plumb_line_evidence(frame_lanes, zoom=None, max_frames=40, max_points=40, corr_frames=10.0,
                        floor_px=0.05, n_coarse=81, n_fine=61):
    """Plumb-line evidence for the lens from a clip's lanes.

    Every used frame's line support points are undistorted under each ``kappa`` (the frame's
    own ``q_i = kappa / (r_ref zoom_i)**2``) and each line is fitted by a straight line; the
    residual sum of squares ``RSS(kappa)`` summed over lines and frames is a Gaussian
    log-likelihood ``-(RSS - RSS_min) / (2 s**2)`` with ``s`` the points' scatter at the best
    ``kappa`` (at least ``floor_px``: a line's paint edge is never straighter than that).

    Support points are measured every few pixels along a line, each from its own grey
    profile, so they count as independent; ``max_points`` of them per line are used and the
    line's RSS is scaled back to its full support.  The frames of a clip see the same painted
    lines through nearly the same view, so their errors are not independent: the sum is
    tempered to one frame per ``corr_frames`` frames with lanes (the correlation length used
    for the other per-frame evidence of the clip model).

    The curve is evaluated on a sinh-spaced grid (:func:`kappa_grid`, ``n_coarse`` points:
    telephoto and wide clips alike) and again on ``n_fine`` points around its best value.

    Parameters
    ----------
    frame_lanes : list of FrameLanes
    zoom : ndarray (F,), optional
        Focal length of each frame relative to the reference (1 for all when not given).
    max_frames : int
        Frames used at most (evenly spaced over the frames with lanes).

    Returns
    -------
    LensEvidence or None
        None when no frame has lines with enough support points.
    """
    F = len(frame_lanes)
    zoom = np.ones(F) if zoom is None else np.asarray(zoom, float)
    zoom = np.where(np.isfinite(zoom) & (zoom > 0), zoom, 1.0)
    idx = [i for i, fl in enumerate(frame_lanes) if fl.ok and len(fl.lines)]
    if not idx:
        return None
    centre, r_ref = _scale_frame(frame_lanes[idx[0]].image_size)
    frames = _evidence_frames(frame_lanes, idx, max_frames, max_points)
    if not frames:
        return None
    coarse = kappa_grid(n=n_coarse)
    rss_c, n_pts, n_lines = _rss_curve(frames, centre, r_ref, zoom, coarse)
    if n_pts <= 2 * n_lines:
        return None
    tot = rss_c.sum(0)
    if not np.isfinite(tot).any():
        return None
    j = int(np.nanargmin(tot))
    fine = np.linspace(coarse[max(j - 3, 0)], coarse[min(j + 3, len(coarse) - 1)], n_fine)
    rss_f = _rss_curve(frames, centre, r_ref, zoom, fine)[0]
    kappa = np.concatenate([coarse, fine])
    rss = np.concatenate([rss_c.sum(0), rss_f.sum(0)])
    kappa, first = np.unique(kappa, return_index=True)
    rss = rss[first]
    if not np.isfinite(rss).any():
        return None
    rss = np.where(np.isfinite(rss), rss, np.nanmax(rss) * 10.0)  # lenses that fold the lines' points away
    j = int(np.argmin(rss))
    noise = float(np.sqrt(rss[j] / (n_pts - 2 * n_lines)))
    s = max(noise, floor_px)
    # tempered: one independent frame per corr_frames frames with lanes, and by the frames'
    # excess scatter
    n_clip = sum(fl.ok for fl in frame_lanes)
    birge = _overdispersion(fine, rss_f, s)
    weight = min(1.0, max(n_clip / corr_frames, 1.0) / len(frames)) / birge
    ll = -(rss - rss[j]) / (2 * s**2) * weight
    return LensEvidence(kappa=kappa, loglik=ll, zoom=zoom, r_ref=float(r_ref), noise_px=noise,
                        n_frames=len(frames), n_lines=n_lines, n_points=n_pts, weight=weight, birge=birge)


@dataclass(frozen=True)
class LensModel:
    """The inferred lens a clip model works with: the evidence, the prior, and the
    image-space coefficient ``kappa_star`` (the mode of evidence x prior) with which the
    registration's lines were undistorted (:func:`undistort_registration`)."""

    evidence: LensEvidence
    prior: LensPrior
    kappa_star: float
    focal_ref_px: float  # of the distorted lines' family at the prior's centre height
    # the k1 the user gave (``--dist``; the prior is then :meth:`LensPrior.given`), else None
    given_k1: float | None = None
    # the height the frames' zoom ratios were read at when the lines chose it (:func:`_zoom_by_lines`)
    zoom_height_m: float | None = None

    def camera_k1(self, focal_px):
        """The OpenCV ``k1`` of cameras with these per-frame focal lengths: the given one, or
        that of the lines' undistortion (``kappa_star / zoom_i**2`` per frame; one value per
        clip, the zoom ratios cancel; 0 when no frame has a camera)."""
        if self.given_k1 is not None:
            return float(self.given_k1)
        f = np.asarray(focal_px, float)
        ok = np.isfinite(f)
        if not ok.any():
            return 0.0
        k1 = float(np.median(self.evidence.k1_of(self.kappa_star, f[ok] / self.evidence.zoom[ok])))
        return k1 if np.isfinite(k1) else 0.0

    def to_dict(self):
        return {"kappa_star": self.kappa_star, "corner_shift_px": self.kappa_star * self.evidence.r_ref,
                "given_k1": self.given_k1, "zoom_height_m": self.zoom_height_m,
                "prior_sd": self.prior.sd, "prior_limit": self.prior.limit,
                # whether the lines tell plausible lenses apart (a given lens: those of the default prior)
                "informative": self.evidence.informative(LensPrior() if self.given_k1 is not None else self.prior,
                                                         self.focal_ref_px),
                **self.evidence.to_dict()}


def _frame_curvatures(frame_lanes, kappa_centre, max_frames=40, max_points=40):
    """Each evidence frame's plumb-line RSS as a quadratic in the frame's own image-space
    coefficient ``kappa_i = kappa / zoom_i**2`` (fitted on five values around
    ``kappa_centre``, where the RSS is quadratic to a good approximation: a small lens moves
    the points linearly): ``(frame indices, a, b)`` with ``RSS_i ~ a_i kappa_i**2 + b_i kappa_i
    + c_i``; None without frames whose RSS curves up.  These do not depend on the zoom, so any
    set of zoom ratios can be scored with them (:func:`_zoom_by_lines`)."""
    idx = [i for i, fl in enumerate(frame_lanes) if fl.ok and len(fl.lines)]
    frames = _evidence_frames(frame_lanes, idx, max_frames, max_points)
    if not frames:
        return None
    centre, r_ref = _scale_frame(frame_lanes[idx[0]].image_size)
    grid = kappa_centre + np.linspace(-1.0, 1.0, 5) * (0.4 * abs(kappa_centre) + 0.002)
    rss = _rss_curve(frames, centre, r_ref, np.ones(len(frame_lanes)), grid)[0]
    ok = np.all(np.isfinite(rss), 1)
    if not ok.any():
        return None
    a, b, _ = np.polyfit(grid, rss[ok].T, 2)
    ii = np.array([f[0] for f in frames])[ok]
    up = a > 0
    return (ii[up], a[up], b[up]) if up.any() else None


def infer_lens(reg, prior: LensPrior = LensPrior(), height_m=10.0):
    """The lens of a clip from its lanes: plumb-line evidence (:func:`plumb_line_evidence`,
    frames' zoom ratios from the families at ``height_m``) and its mode under ``prior``.
    None when no frame has lines to measure."""
    zoom, f_ref = _zoom_ratios(reg, height_m)
    ev = plumb_line_evidence(reg.frame_lanes, zoom=zoom)
    if ev is None:
        return None
    return LensModel(evidence=ev, prior=prior, kappa_star=ev.best_kappa(prior, f_ref), focal_ref_px=f_ref)


def undistort_registration(reg, lens: LensModel, min_shift_px=0.02):
    """A copy of ``reg`` whose lines are undistorted with the lens (each frame with its own
    ``q_i``) and whose families are rebuilt from them; ``reg`` itself when the lens moves no
    point by ``min_shift_px`` at the image corner (then the lines are left as they are)."""
    from ..lanes.undistort import undistort_frame_lanes
    from .registration import register_frames

    ev = lens.evidence
    if abs(lens.kappa_star) * ev.r_ref < min_shift_px:
        return reg
    q = ev.frame_q(lens.kappa_star)
    # OpenCV's k1 at focal length r_ref is exactly q * r_ref**2 in pixels
    fls = [undistort_frame_lanes(fl, np.array([q[i] * ev.r_ref**2, 0, 0, 0, 0]), ev.r_ref) if fl.ok else fl
           for i, fl in enumerate(reg.frame_lanes)]
    out = register_frames(fls, reg.image_size, forward_px=reg.forward_px, lane_width_m=reg.lane_width_m)
    for name in ("_oriented", "camera_side"):
        if hasattr(reg, name):
            setattr(out, name, getattr(reg, name))
    return out


def lens_registration(reg, prior: LensPrior = LensPrior(), height_m=10.0, iterations=2, zoom_from_lines=False):
    """The lens of a clip and its registration with undistorted lines: ``(lens, registration)``
    (``(None, reg)`` when no frame has lines to measure).

    The frames' zoom ratios first come from the families of the distorted lines; a wide view's
    bent lines give them errors of several per cent (the straight fit depends on which part
    of each line a frame sees), and the frames' undistortion inherits twice that.  So the
    ratios are read again from the families of the undistorted lines, the evidence and its mode
    recomputed and the lines undistorted anew, ``iterations`` times (on a 35 deg, k1 = -0.17
    view, with the running median of :func:`_zoom_ratios`: zoom-ratio error 5.7 % -> 0.5 %, the
    family's focal length at the true height within 0.3 % on 95 % of the frames instead of 2.5 %).
    With ``zoom_from_lines`` (and a lens that moves the image corner by
    :data:`ZOOM_SCAN_MIN_SHIFT_PX` or more), from the undistorted lines on the height the ratios
    are read at is the one whose ratios let one lens straighten every frame's lines best
    (:func:`_zoom_by_lines`), not the prior's centre: on wide near views of cameras 4-10 m high,
    read at 9 m, the ratios had pan-made errors of up to 20 % and ``kappa`` came out up to 12 %
    off (2 % with the lines' choice).  The pipeline asks for it when the lens is given
    (``probreg run --dist``), where the ratios carry the plumb line's hold on the height; with the
    lens inferred it keeps the prior centre's ratios (docs/method.md, "Zoom ratios chosen by the
    lines")."""
    lens = infer_lens(reg, prior, height_m)
    if lens is None:
        return None, reg
    out = undistort_registration(reg, lens)
    curvatures = None
    for _ in range(int(iterations)):
        if out is reg:
            break  # a lens that moves nothing: the distorted families are the families
        strong = abs(lens.kappa_star) * lens.evidence.r_ref >= ZOOM_SCAN_MIN_SHIFT_PX
        if zoom_from_lines and strong and curvatures is None:
            curvatures = _frame_curvatures(reg.frame_lanes, lens.kappa_star)
        if curvatures is not None:
            # an RSS difference in the evidence's nats (frames tempered; not by the Birge ratio, which
            # the ratios being chosen inflate)
            nats = lens.evidence.weight * lens.evidence.birge / (2.0 * max(lens.evidence.noise_px, 0.05) ** 2)
            zoom, f_ref, zoom_h = _zoom_by_lines(out, curvatures, height_m, nats)
        else:
            zoom, f_ref, zoom_h = (*_zoom_ratios(out, height_m), None)
        if not np.isfinite(f_ref):
            break
        ev = plumb_line_evidence(reg.frame_lanes, zoom=zoom)
        if ev is None:
            break
        lens = LensModel(evidence=ev, prior=prior, kappa_star=ev.best_kappa(prior, f_ref), focal_ref_px=f_ref,
                         zoom_height_m=zoom_h)
        out = undistort_registration(reg, lens)
    return lens, out
