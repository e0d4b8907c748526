"""Partial sports field registration: the one-DOF family of cameras that explain the lane lines.

Geometry (closed form, no lookup grid).  For a hypothesised focal length
``f`` (principal point at the image centre, square pixels):

1. the lane direction in camera coordinates is ``r1 ~ K^-1 v`` (``v`` the
   vanishing point, homogeneous, so ``v`` at infinity is ordinary);
2. each image line ``l_i`` and the camera centre span an interpretation plane
   with normal ``K^T l_i``; all contain ``r1``.  In the cross-section
   orthogonal to ``r1`` each plane is a ray at angle ``theta_i``;
3. the ground is a line in that cross-section, at distance ``h`` (the camera
   height) with unit normal ``u`` (the track's up axis) at angle ``phi``.  The
   rays meet it at lateral offsets ``h * tan(theta_i - phi)``; equal lane
   spacing means these are affine in the line indices ``k_i``.  For any
   triple of lines that condition is *linear* in ``(cos phi, sin phi)``, so
   ``phi`` is the null vector of a small matrix (exact for three lines, least
   squares for more), and ``h = 1.22 / slope``.

So every ``f`` gives one camera (rotation, height, lateral position; the
position along the track is unobservable), and the family is the curve
``f -> camera``.  It is parameterised by one scalar: camera height (default),
horizontal field of view, or azimuth; other parameterisations are one small
class each (:class:`FamilyParameter`).

Sign conventions: the track ``x`` axis is the running direction, which lane
lines alone cannot tell; ``forward_px`` gives the image direction of running
(default: to the right).  ``z`` is up; ``y = z cross x`` points to the infield,
so the innermost observed line (largest ``y``) gets index 0.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from ..geometry import Camera, cross3, focal_from_fov, fov_from_focal
from ..lanes import FrameLanes

__all__ = ["FamilyMember", "CalibrationFamily", "members_on_grid", "prime_focal_ranges", "FamilyParameter", "HeightParameter", "FovParameter", "AzimuthParameter", "PARAMETERS", "SequenceCalibration", "CalibrationError"]


LANE_WIDTH_M = 1.22

class CalibrationError(ValueError):
    """The requested family member does not exist (degenerate geometry, out-of-range value)."""


@dataclass(frozen=True)
class FamilyMember:
    """One camera of the family (``x`` of the centre set to 0: unobservable).

    Attributes
    ----------
    focal_px : float
    R : ndarray (3, 3)
        Track -> camera rotation.
    height_m : float
    y_m : float
        Lateral camera position, for line index offset 0 (innermost observed line at ``y = 0``).
    residual : float
        Algebraic misfit of the equal-spacing condition (0 for three exact lines).
    valid : bool
        All lane rays hit the ground in front of the camera with a positive height.
    """

    focal_px: float
    R: np.ndarray
    height_m: float
    y_m: float
    residual: float
    valid: bool
    index_flipped: bool = False

    def camera(self, image_size, principal_point=None, line_offset=0, x_m=0.0, dist=None,
               lane_width_m=LANE_WIDTH_M):
        """The :class:`~probreg.geometry.camera.Camera` of this member.

        ``line_offset`` is the absolute index of the innermost observed line
        (``y = -lane_width * offset``); ``x_m`` the unobservable position along the track.
        """
        w, h = image_size
        c = principal_point if principal_point is not None else ((w - 1) / 2, (h - 1) / 2)
        K = np.array([[self.focal_px, 0, c[0]], [0, self.focal_px, c[1]], [0, 0, 1.0]])
        C = np.array([x_m, self.y_m - lane_width_m * line_offset, self.height_m])
        return Camera(K=K, R=self.R, C=C, dist=np.zeros(5) if dist is None else dist, image_size=(w, h))


def _null_vector_2(M):
    """Least-squares null vectors of stacked (F, m, 2) matrices, in closed form.

    The eigenvector of the smallest eigenvalue of the 2 x 2 normal matrix (a batched
    SVD costs a LAPACK call per matrix).  Returns the unit vectors (F, 2) (sign
    arbitrary) and the ratio of the smallest to the largest singular value, the
    smallest taken as ``|M v|`` (accurate even where it is tiny).

    >>> v, r = _null_vector_2(np.array([[[1.0, 2.0], [2.0, 4.0]]]))
    >>> np.round(np.abs(v[0]) * np.sqrt(5), 12).tolist(), float(np.round(r[0], 12))
    ([2.0, 1.0], 0.0)
    """
    a = np.einsum("fm,fm->f", M[..., 0], M[..., 0])
    b = np.einsum("fm,fm->f", M[..., 0], M[..., 1])
    c = np.einsum("fm,fm->f", M[..., 1], M[..., 1])
    half_gap = np.hypot(0.5 * (a - c), b)
    lam_max = 0.5 * (a + c) + half_gap
    lam_min = 0.5 * (a + c) - half_gap
    # two expressions for the same eigenvector; take the one with the larger norm
    v1 = np.stack([b, lam_min - a], -1)
    v2 = np.stack([lam_min - c, b], -1)
    n1, n2 = np.linalg.norm(v1, axis=-1), np.linalg.norm(v2, axis=-1)
    v = np.where((n1 >= n2)[:, None], v1, v2)
    n = np.maximum(n1, n2)
    # an isotropic (or zero) normal matrix: every direction is as good
    v = np.where((n > 0)[:, None], v / np.where(n > 0, n, 1.0)[:, None], [[1.0, 0.0]])
    smallest = np.linalg.norm(np.einsum("fmk,fk->fm", M, v), axis=-1)
    return v, smallest / np.maximum(np.sqrt(np.maximum(lam_max, 0.0)), 1e-300)


def _members_batch(fams, focal_px):
    """:meth:`CalibrationFamily.members` of several families with the same number of lines
    at once: ``focal_px`` (B, m), one row per family; arrays with leading shape (B, m).

    The closed form, batched: for each focal length the lane direction ``r1`` follows from
    the vanishing point; each line's interpretation plane gives a ray in the cross-section
    perpendicular to ``r1``; the equal spacing of the lines fixes the ground normal in that
    cross-section (a 2 x 2 null vector), and the spacing's scale the height."""
    f = np.asarray(focal_px, float)
    nb, nm = f.shape
    pp = np.stack([fam.principal_point for fam in fams])
    cx, cy = pp[:, 0:1], pp[:, 1:2]  # (B, 1)
    v = np.stack([fam.vp for fam in fams])
    # lane direction r1 in camera coordinates (per f)
    r1 = np.stack([(v[:, 0:1] - cx * v[:, 2:3]) / f, (v[:, 1:2] - cy * v[:, 2:3]) / f,
                   np.broadcast_to(v[:, 2:3], f.shape)], -1)
    r1 = r1 / np.linalg.norm(r1, axis=-1, keepdims=True)
    # orient r1 along the running direction: image motion of +x at a sample point
    S = np.stack([fam.samples for fam in fams])  # (B, n, 2)
    s0 = S.mean(1)
    xn = np.stack([(s0[:, 0:1] - cx) / f, (s0[:, 1:2] - cy) / f], -1)
    img_dir = r1[..., :2] - xn * r1[..., 2:3]
    fwd = np.stack([fam.forward_px for fam in fams])
    sign = np.sign(img_dir[..., 0] * fwd[:, 0:1] + img_dir[..., 1] * fwd[:, 1:2])
    sign[sign == 0] = 1.0
    r1 = r1 * sign[..., None]
    # interpretation-plane normals K^T l (per f), and rays w_i = r1 x n_i in the cross-section
    L = np.stack([fam.lines for fam in fams])  # (B, n, 3)
    nl = L.shape[1]
    c3 = L[..., 0] * cx + L[..., 1] * cy + L[..., 2]
    n = np.stack([f[:, :, None] * L[:, None, :, 0], f[:, :, None] * L[:, None, :, 1],
                  np.broadcast_to(c3[:, None, :], (nb, nm, nl))], -1)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    wv = cross3(r1[:, :, None, :], n)
    wv /= np.linalg.norm(wv, axis=-1, keepdims=True)
    d = np.stack([(S[:, None, :, 0] - cx[:, :, None]) / f[:, :, None],
                  (S[:, None, :, 1] - cy[:, :, None]) / f[:, :, None], np.ones((nb, nm, nl))], -1)
    wv *= np.sign(np.sum(wv * d, -1, keepdims=True))
    # cross-section basis (a, b) with a x b = r1
    helper = np.where(np.abs(r1[..., 1:2]) < 0.9, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    a = cross3(helper, r1)
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b = cross3(r1, a)
    th = np.arctan2(np.sum(wv * b[:, :, None], -1), np.sum(wv * a[:, :, None], -1))  # (B, m, n)
    # equal-spacing condition for triples (0, j, j+1): rows linear in (cos phi, sin phi)
    k = np.stack([fam.indices for fam in fams])  # (B, n)
    rows = []
    for j in range(1, nl - 1):
        m = j + 1
        s_j0 = np.sin(th[..., j] - th[..., 0])
        s_m0 = np.sin(th[..., m] - th[..., 0])
        dk_m, dk_j = (k[:, m] - k[:, 0])[:, None], (k[:, j] - k[:, 0])[:, None]
        rows.append(np.stack([s_j0 * dk_m * np.cos(th[..., m]) - s_m0 * dk_j * np.cos(th[..., j]),
                              s_j0 * dk_m * np.sin(th[..., m]) - s_m0 * dk_j * np.sin(th[..., j])], -1))
    M = np.stack(rows, 2)  # (B, m, n-2, 2)
    cs, resid = _null_vector_2(M.reshape(nb * nm, nl - 2, 2))  # null vector = (cos phi, sin phi) up to sign
    cs, resid = cs.reshape(nb, nm, 2), resid.reshape(nb, nm)
    u = cs[..., 0:1] * a + cs[..., 1:2] * b
    cosd = np.sum(wv * u[:, :, None], -1)  # w_i . u: rays must point down
    flip = np.sum(cosd, -1) > 0
    u[flip] *= -1
    cosd[flip] *= -1
    ey = cross3(u, r1)
    g = -np.sum(wv * ey[:, :, None], -1) / cosd  # lateral offsets / h
    # affine fit g = A + B k  ->  h = -lane_width / B
    kc = k - k.mean(-1, keepdims=True)
    B = np.einsum("bmn,bn->bm", g - g.mean(-1, keepdims=True), kc) / np.sum(kc * kc, -1)[:, None]
    A = g.mean(-1) - B * k.mean(-1)[:, None]
    # index orientation: line 0 must be the innermost (largest y).  With B > 0 the
    # image order of the pencil runs outward-in: count the indices from the other end.
    flipped = B > 0
    A = np.where(flipped, A + B * k.max(-1)[:, None], A)
    B = np.where(flipped, -B, B)
    h = -np.array([fam.lane_width_m for fam in fams])[:, None] / B
    y_cam = -h * A  # line 0 at y = 0: 0 = y_cam + h * (A + B * 0)
    valid = np.all(cosd < 0, -1) & (h > 0) & np.isfinite(h)
    R = np.stack([r1, ey, u], -1)  # columns: track axes in camera coordinates
    return {"R": R, "height_m": h, "y_m": y_cam, "residual": resid, "valid": valid,
            "index_flipped": flipped}


#: families per batch of :func:`members_on_grid` (250 frames x 500 focal lengths: 0.42 s one at a time,
#: 0.31 s in batches of 16, 0.44 s all at once: larger batches trade call overhead for cache misses)
MEMBERS_BATCH = 16


def members_on_grid(families, focal_px):
    """:meth:`CalibrationFamily.members` of many families: {key: members} for ``families``
    {key: family} at the focal lengths ``focal_px`` (an array for all, or {key: array}, all of one
    length), solved in batches of families with the same number of lines (the same arithmetic
    element by element: bit for bit what ``members`` gives each).

    >>> fam = CalibrationFamily.from_camera(Camera.look_at([30.0, -60.0, 12.0], [30.0, -4.0, 1.0], fov_deg=10.0),
    ...                                     line_indices=range(4))
    >>> f = np.array([800.0, 2000.0, 6000.0])
    >>> m = members_on_grid({"a": fam, "b": fam}, {"a": f / 2, "b": f})
    >>> all(np.array_equal(m["b"][k], fam.members(f)[k], equal_nan=True) for k in m["b"])
    True
    """
    grid = (lambda key: focal_px[key]) if isinstance(focal_px, dict) else (lambda key: focal_px)
    groups, out = {}, {}
    for key, fam in families.items():
        groups.setdefault(len(fam.lines), []).append(key)
    for keys in groups.values():
        for a in range(0, len(keys), MEMBERS_BATCH):
            part = keys[a:a + MEMBERS_BATCH]
            mm = _members_batch([families[k] for k in part],
                                np.stack([np.atleast_1d(np.asarray(grid(k), float)) for k in part]))
            for r, k in enumerate(part):
                out[k] = {name: v[r] for name, v in mm.items()}
    return out


def prime_focal_ranges(families, fov_range_deg=(0.3, 150.0), n=120):
    """Fill the cache of :meth:`CalibrationFamily.focal_range` of every family (None skipped) that
    lacks it, in batches (:func:`members_on_grid`): a clip's frames then bracket their members
    without a members call each."""
    key = (tuple(fov_range_deg), n)
    todo = {i: f for i, f in enumerate(families) if f is not None and key not in f._focal_range_cache}
    grids = {i: np.geomspace(focal_from_fov(fov_range_deg[1], f.image_size[0]),
                             focal_from_fov(fov_range_deg[0], f.image_size[0]), n) for i, f in todo.items()}
    for i, m in members_on_grid(todo, grids).items():
        todo[i]._focal_range_cache[key] = (grids[i], m)


class CalibrationFamily:
    """The one-DOF family of cameras consistent with one frame's lane lines.

    Parameters
    ----------
    vanishing_point : array_like, shape (3,)
        Homogeneous pixel coordinates (``w = 0`` at infinity).
    lines : array_like, shape (n, 3)
        Homogeneous image lines (pixel coordinates), ``n >= 3``.
    indices : array_like of int, shape (n,)
        Lane-line indices across the track (consecutive unless a line is missing).
    image_size : tuple
    sample_points_px : array_like, shape (n, 2), optional
        A point on each line inside the image (fixes which side of the camera the line is).
        Default: the point of each line closest to the image centre.
    forward_px : array_like, shape (2,)
        Image direction in which the athlete runs (track ``+x``); default ``(1, 0)``.
    lane_width_m : float

    Raises
    ------
    CalibrationError
        For fewer than three lines or repeated indices.

    Examples
    --------
    >>> cam = Camera.look_at([30, -60, 15], [30, -4, 0], fov_deg=12.0)
    >>> fam = CalibrationFamily.from_camera(cam, line_indices=range(1, 6))
    >>> member = fam.member(height_m=15.0)
    >>> round(member.focal_px / cam.focal_px, 9)
    1.0
    """

    def __init__(self, vanishing_point, lines, indices, image_size, sample_points_px=None,
                 forward_px=(1.0, 0.0), lane_width_m=LANE_WIDTH_M, principal_point=None):
        lines = np.asarray(lines, float)
        idx = np.asarray(indices, float)
        if lines.ndim != 2 or lines.shape[1] != 3 or len(lines) < 3:
            raise CalibrationError("a calibration family needs at least three lane lines")
        if len(idx) != len(lines) or len(np.unique(idx)) != len(idx):
            raise CalibrationError("every line needs its own lane-line index")
        v = np.asarray(vanishing_point, float)
        if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
            raise CalibrationError("vanishing point must be a finite homogeneous 3-vector")
        self.image_size = tuple(int(s) for s in image_size)
        w, h = self.image_size
        self.principal_point = np.asarray(principal_point if principal_point is not None
                                          else ((w - 1) / 2, (h - 1) / 2), float)
        self.lines = lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)
        self.indices = idx - idx.min()
        self.vp = v
        self.lane_width_m = float(lane_width_m)
        if sample_points_px is None:
            c = self.principal_point
            d = self.lines @ np.array([c[0], c[1], 1.0])
            sample_points_px = c - d[:, None] * self.lines[:, :2]
        self.samples = np.asarray(sample_points_px, float)
        self.forward_px = np.asarray(forward_px, float)
        self._focal_range_cache = {}

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_frame_lanes(cls, fl: FrameLanes, forward_px=(1.0, 0.0), lane_width_m=LANE_WIDTH_M):
        """Family of a frame with ``status == "ok"``."""
        if not fl.ok:
            raise CalibrationError(f"frame has no usable lanes (status {fl.status!r})")
        return cls(fl.vanishing_point, [ln.line for ln in fl.lines], [ln.index for ln in fl.lines],
                   fl.image_size, sample_points_px=[ln.points_px.mean(0) for ln in fl.lines],
                   forward_px=forward_px, lane_width_m=lane_width_m)

    @classmethod
    def from_camera(cls, camera: Camera, line_indices=range(0, 9), x_range_m=(-50, 150),
                    lane_width_m=LANE_WIDTH_M):
        """Family from the exact (undistorted) projection of lane lines by a known camera.

        Used for known-answer tests and benchmarks; lines behind the camera are skipped.
        """
        P = camera.projection_matrix
        lines, idx, samples = [], [], []
        fwd = None
        for i in line_indices:
            y = -lane_width_m * i
            xs = np.linspace(*x_range_m, 2001)
            pts = np.column_stack([xs, np.full_like(xs, y), np.zeros_like(xs), np.ones_like(xs)])
            hp = pts @ P.T
            front = hp[:, 2] > 1e-6
            if front.sum() < 2:
                continue
            px = hp[front, :2] / hp[front, 2:]
            inside = camera.in_image(px)
            sel = np.flatnonzero(inside) if inside.any() else np.flatnonzero(front)[:2]
            a, b = pts[front][sel[0]], pts[front][sel[-1]]
            pa, pb = P @ a, P @ b
            lines.append(cross3(pa, pb))  # the image line through two projected points
            idx.append(i)
            samples.append(px[sel[len(sel) // 2]] if inside.any() else px[0])
            if fwd is None:
                fwd = (P @ (a + [1.0, 0, 0, 0]))
                fwd = fwd[:2] / fwd[2] - pa[:2] / pa[2]
        v = camera.K @ camera.R @ np.array([1.0, 0.0, 0.0])
        return cls(v, lines, idx, camera.image_size, sample_points_px=samples, forward_px=fwd,
                   lane_width_m=lane_width_m, principal_point=camera.K[:2, 2])

    # ------------------------------------------------------------------ the closed form
    def members(self, focal_px):
        """Family members for an array of focal lengths (vectorised).

        Returns
        -------
        dict of arrays with leading shape ``focal_px.shape``: ``R`` (..., 3, 3),
        ``height_m``, ``y_m``, ``residual``, ``valid``, ``index_flipped`` (the lines'
        indices count from the other end of the pencil: absolute index = max - index).
        """
        f = np.atleast_1d(np.asarray(focal_px, float))
        return {k: v[0] for k, v in _members_batch([self], f[None]).items()}

    def member_at_focal(self, focal_px):
        return _member_at(self.members(np.array([float(focal_px)])), float(focal_px), 0)

    def oriented_indices(self, member: "FamilyMember"):
        """Indices counted from the innermost observed line (0) outwards, for a member."""
        k = self.indices.astype(int)
        return k.max() - k if member.index_flipped else k

    def focal_range(self, fov_range_deg=(0.3, 150.0), n=120):
        """Focal lengths (log grid) over which the family exists, with their heights."""
        key = (tuple(fov_range_deg), n)
        if key not in self._focal_range_cache:  # the family is fixed once built: solves share the grid
            w = self.image_size[0]
            f = np.geomspace(focal_from_fov(fov_range_deg[1], w), focal_from_fov(fov_range_deg[0], w), n)
            self._focal_range_cache[key] = (f, self.members(f))
        return self._focal_range_cache[key]

    def focal_for(self, parameter: "FamilyParameter", value):
        """Solve the focal length at which ``parameter`` takes ``value`` (1-D root finding)."""
        return parameter.focal_for(self, value)

    def member(self, height_m=None, fov_deg=None, azimuth_deg=None):
        """The member with the given height (default parameter), FOV or azimuth.

        Raises
        ------
        CalibrationError
            If no member has that value, or not exactly one value is given.
        """
        given = [(p, v) for p, v in ((HeightParameter(), height_m), (FovParameter(), fov_deg),
                                     (AzimuthParameter(), azimuth_deg)) if v is not None]
        if len(given) != 1:
            raise CalibrationError("give exactly one of height_m, fov_deg, azimuth_deg")
        p, v = given[0]
        return self.member_at_focal(p.focal_for(self, v))

    def camera(self, height_m=None, fov_deg=None, azimuth_deg=None, line_offset=0, x_m=0.0, dist=None):
        """Camera of a family member; see :meth:`member` and :meth:`FamilyMember.camera`."""
        m = self.member(height_m=height_m, fov_deg=fov_deg, azimuth_deg=azimuth_deg)
        return m.camera(self.image_size, self.principal_point, line_offset=line_offset, x_m=x_m,
                        dist=dist, lane_width_m=self.lane_width_m)


class FamilyParameter(ABC):
    """A scalar that selects one member of a calibration family (one small class per choice)."""

    name = "parameter"
    unit = ""

    @abstractmethod
    def values(self, family: CalibrationFamily, focal_px, members):
        """The parameter's value for each focal length (array) given the vectorised members."""

    def focal_for(self, family: CalibrationFamily, value, branch="narrow"):
        """Focal length with ``values == value``: bracket on a log grid, then Brent's method.

        The family is a curve; a parameter such as the height can take the same
        value twice along it (camera height peaks where the camera looks about
        45 deg down: below that height there is a zoomed-in member looking
        across the track and a wide-angle member looking steeply down).
        ``branch="narrow"`` (default, the broadcast case) takes the solution
        with the longest focal length, ``"wide"`` the shortest.
        """
        lo, hi = self._bracket(family, value, branch)
        grid = _fine_grid(lo, hi)
        fx = np.exp(grid)
        mm = family.members(fx)
        root = _root_on_grid(grid, np.where(mm["valid"], self.values(family, fx, mm), np.nan) - value, branch)
        return root if root is not None else self._root_by_brent(family, value, lo, hi)

    def _bracket(self, family, value, branch):
        """``(log f, log f)`` of the grid step of :meth:`CalibrationFamily.focal_range` where the
        parameter crosses ``value`` on ``branch`` (raises :class:`CalibrationError`)."""
        if not np.isfinite(value):
            raise CalibrationError(f"{self.name} must be finite")
        f, m = family.focal_range()
        vals = np.where(m["valid"], self.values(family, f, m), np.nan)
        diff = vals - value
        ok = np.isfinite(diff)
        cross = np.flatnonzero(ok[:-1] & ok[1:] & (np.sign(diff[:-1]) != np.sign(diff[1:])))
        if len(cross) == 0:
            lo, hi = np.nanmin(vals) if ok.any() else np.nan, np.nanmax(vals) if ok.any() else np.nan
            raise CalibrationError(f"no family member with {self.name} = {value:g} {self.unit} "
                                   f"(family spans {lo:.3g}..{hi:.3g} {self.unit})")
        if branch not in ("narrow", "wide"):
            raise CalibrationError(f"branch must be 'narrow' or 'wide', got {branch!r}")
        i = cross[-1] if branch == "narrow" else cross[0]
        return np.log(f[i]), np.log(f[i + 1])

    def _root_by_brent(self, family, value, lo, hi):
        """Brent's method inside the bracket, where the refinement of :func:`_root_on_grid` lost
        the crossing (raises :class:`CalibrationError` when the bracket does not hold)."""

        def fn(logf):
            fx = np.exp(logf)
            mm = family.members(np.array([fx]))
            return float(self.values(family, np.array([fx]), mm)[0] - value)

        # the coarse crossing did not survive the refinement (a member turned invalid inside the
        # bracket, or the values there are not finite): a bracket that does not hold is no member
        # here, not a root-finder error
        f_lo, f_hi = fn(lo), fn(hi)
        if not (np.isfinite(f_lo) and np.isfinite(f_hi)) or np.sign(f_lo) == np.sign(f_hi):
            raise CalibrationError(f"no family member with {self.name} = {value:g} {self.unit} "
                                   f"(the crossing near f = {np.exp(lo):.4g} px does not hold)")
        return float(np.exp(brentq(fn, lo, hi, xtol=1e-13, rtol=1e-13)))


def _member_at(members, focal_px, j):
    """The :class:`FamilyMember` at position ``j`` of vectorised ``members``."""
    return FamilyMember(focal_px=focal_px, R=members["R"][j], height_m=float(members["height_m"][j]),
                        y_m=float(members["y_m"][j]), residual=float(members["residual"][j]),
                        valid=bool(members["valid"][j]), index_flipped=bool(members["index_flipped"][j]))


def _fine_grid(lo, hi):
    """One refinement of a bracket ``(lo, hi)`` of log focal lengths, on a finer log grid (a
    single vectorised evaluation: a call costs far more than its points).  It brackets the
    root to ~4e-3 in log f; inverse cubic interpolation through the four grid points around
    it is then exact to ~1e-10.  The grid reaches one step beyond the bracket on each side,
    so that the interpolation has its four points wherever the root lies."""
    return lo + (hi - lo) / 16 * np.arange(-1, 18)


def _root_on_grid(grid, d, branch):
    """Focal length where ``d`` (the parameter minus its value on :func:`_fine_grid`) crosses
    zero inside the bracket, or ``None`` when the crossing did not survive the refinement."""
    ok = np.isfinite(d)
    c = np.flatnonzero(ok[:-1] & ok[1:] & (np.sign(d[:-1]) != np.sign(d[1:])))
    c = c[(c >= 1) & (c <= 16)]  # crossings inside the bracket only
    if not len(c):
        return None
    j = c[-1] if branch == "narrow" else c[0]
    return float(np.exp(_inverse_interpolate(grid, d, j)))


def _inverse_interpolate(x, y, j):
    """Root of ``y(x)`` bracketed by samples ``j`` and ``j + 1``: inverse cubic
    interpolation through the samples ``j - 1 .. j + 2`` where they exist and are
    monotone, else linear.

    >>> x = np.linspace(0.0, 1.0, 17)  # root of exp(x) - 2 at log(2) = 0.693...
    >>> bool(abs(_inverse_interpolate(x, np.exp(x) - 2.0, 11) - np.log(2.0)) < 1e-6)
    True
    """
    if y[j] == 0.0:
        return float(x[j])
    linear = x[j] + (x[j + 1] - x[j]) * y[j] / (y[j] - y[j + 1])
    if j < 1 or j + 2 >= len(x):
        return float(linear)
    xs, ys = x[j - 1:j + 3], y[j - 1:j + 3]
    dy = np.diff(ys)
    if not (np.all(np.isfinite(ys)) and (np.all(dy > 0) or np.all(dy < 0))):
        return float(linear)
    root = 0.0
    for i in range(4):
        others = np.delete(ys, i)
        root += xs[i] * np.prod(-others / (ys[i] - others))
    return float(root) if x[j] <= root <= x[j + 1] else float(linear)


class HeightParameter(FamilyParameter):
    """Camera height above the track (m): the default parameter (static over a clip)."""

    name, unit = "height", "m"

    def values(self, family, focal_px, members):
        return members["height_m"]


class FovParameter(FamilyParameter):
    """Horizontal field of view (deg)."""

    name, unit = "fov", "deg"

    def values(self, family, focal_px, members):
        return fov_from_focal(focal_px, family.image_size[0])

    def focal_for(self, family, value, branch="narrow"):
        if not 0 < value < 180:
            raise CalibrationError(f"field of view must lie in (0, 180) degrees, got {value}")
        return float(focal_from_fov(value, family.image_size[0]))


class AzimuthParameter(FamilyParameter):
    """Azimuth (deg) of the optical axis from the track's ``+x`` axis, in the ground plane
    (90 = looking square onto the straight towards the infield)."""

    name, unit = "azimuth", "deg"

    def values(self, family, focal_px, members):
        R = members["R"]
        axis = R[..., 2, :]  # optical axis in track coordinates (third row of R)
        return np.degrees(np.arctan2(axis[..., 1], axis[..., 0]))


PARAMETERS = {"height": HeightParameter(), "fov": FovParameter(), "azimuth": AzimuthParameter()}

@dataclass
class SequenceCalibration:
    """Per-frame families of a clip from one static camera.

    One height selects a member in every frame; ``line_offsets`` holds the absolute
    lane-line index of each frame's innermost observed line (set by
    :meth:`probreg.calibration.registration.ClipRegistration.track_offsets` and
    :func:`probreg.calibration.registration.lane_anchor_shift`).
    """

    families: list  # CalibrationFamily or None per frame
    image_size: tuple
    lane_width_m: float = LANE_WIDTH_M
    line_offsets: np.ndarray = field(default=None)
    branch: str = "narrow"
    #: members per (height, branch, families) -> (families, members): see :meth:`members_at_height`
    _members_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.line_offsets is None:
            self.line_offsets = np.zeros(len(self.families), int)

    @property
    def n_frames(self):
        return len(self.families)

    def members_at_height(self, height_m):
        """FamilyMember (or None where a frame has no family or no such member) per frame.

        Remembered per height, branch and families (several steps of a registration ask for
        the same height; the members are immutable)."""
        key = (float(height_m), self.branch, tuple(map(id, self.families)))
        cache = self._members_cache
        if key not in cache:
            if len(cache) >= 16:
                cache.clear()
            # the entry holds the families themselves, so their ids cannot be reused meanwhile
            cache[key] = (tuple(self.families), self._solve_members(height_m))
        return list(cache[key][1])

    def focal_at_height(self, height_m):
        """(F,) focal length (px) of every frame's member at ``height_m`` (NaN without one)."""
        return np.array([np.nan if m is None else m.focal_px for m in self.members_at_height(float(height_m))])

    def _solve_members(self, height_m):
        """Every frame's member at ``height_m``: :meth:`HeightParameter.focal_for` per frame, with
        the refinement and the members at the roots evaluated for all frames at once (families
        with the same number of lines in one batch)."""
        param = HeightParameter()
        out = [None] * len(self.families)
        prime_focal_ranges(self.families)  # every frame's bracket below
        groups = {}
        for i, fam in enumerate(self.families):
            if fam is None:
                continue
            try:
                lo, hi = param._bracket(fam, height_m, self.branch)
            except CalibrationError:
                continue
            groups.setdefault(len(fam.lines), []).append((i, fam, lo, hi))
        roots = {}
        for group in groups.values():
            grids = np.stack([_fine_grid(lo, hi) for _, _, lo, hi in group])
            mm = _members_batch([g[1] for g in group], np.exp(grids))
            d = np.where(mm["valid"], mm["height_m"], np.nan) - height_m
            for r, (i, fam, lo, hi) in enumerate(group):
                root = _root_on_grid(grids[r], d[r], self.branch)
                try:
                    roots[i] = root if root is not None else param._root_by_brent(fam, height_m, lo, hi)
                except CalibrationError:
                    continue
        for group in groups.values():
            found = [(i, fam) for i, fam, _, _ in group if i in roots]
            if not found:
                continue
            f = np.array([[roots[i]] for i, _ in found])
            mm = _members_batch([fam for _, fam in found], f)
            for r, (i, _) in enumerate(found):
                out[i] = _member_at({k: v[r] for k, v in mm.items()}, float(f[r, 0]), 0)
        return out

    def cameras_at_height(self, height_m, extra_offset=0, x_m=0.0, dist=None):
        """Per-frame cameras (None where unavailable) of the member at ``height_m``."""
        out = []
        for fam, m, off in zip(self.families, self.members_at_height(height_m), self.line_offsets):
            if m is None:
                out.append(None)
                continue
            out.append(m.camera(self.image_size, fam.principal_point, line_offset=off + extra_offset,
                                x_m=x_m, dist=dist, lane_width_m=self.lane_width_m))
        return out
