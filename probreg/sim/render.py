"""OpenCV rendering of a broadcast frame: stadium ground, lane lines and a shaded runner.

Ground polygons are clipped in camera coordinates against the near plane and
a widened viewing frustum, then projected (with lens distortion, edges are
subdivided so that straight lines bend as the lens bends them) and filled with
sub-pixel precision (``cv2.fillPoly`` with fractional bits), so that a rendered
line centre lies where :meth:`probreg.geometry.camera.Camera.project` puts it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import ndtr

from ..geometry import (
    JOINT_INDEX,
    STANDARD_TRACK,
    Camera,
    TrackGeometry,
    distort_normalized,
)

__all__ = ["RenderStyle", "render_background", "render_runner", "render_frame", "finish_image", "lane_line_polygons"]


_SHIFT = 4  # fractional bits for sub-pixel polygon filling

_SCALE = float(1 << _SHIFT)

@dataclass(frozen=True)
class RenderStyle:
    """Colours (BGR) and image degradations."""

    track_bgr: tuple = (62, 72, 182)
    line_bgr: tuple = (238, 238, 238)
    infield_bgr: tuple = (40, 105, 30)
    surround_bgr: tuple = (120, 120, 118)
    stands_bgr: tuple = (88, 84, 92)
    skin_bgr: tuple = (120, 150, 200)
    shirt_bgr: tuple = (200, 200, 210)
    shorts_bgr: tuple = (60, 40, 30)
    blur_sigma_px: float = 0.6
    #: optical blur (px) the lane lines get *before* sampling, on top of the pixel's area.
    #: A lens blurs the scene before the sensor samples it, so a thin line's sampled profile
    #: is smooth and its discrete centroid does not lock to the pixel grid; ``blur_sigma_px``
    #: is applied after sampling and keeps the area-sampling aliasing (~0.05 px on lines
    #: ~1 px wide).  0 (the default) renders the benchmark suite as its reports were
    #: measured; 0.4 with ``blur_sigma_px = 0.45`` gives lines of the same overall width.
    line_psf_sigma_px: float = 0.0
    noise_sigma: float = 3.0
    jpeg_quality: int = 90
    supersample: int = 4


def _clip_polygon(pts_cam, halfspaces):
    """Sutherland-Hodgman clipping of a polygon (N, 3) against half-spaces ``n . p >= c``."""
    poly = pts_cam
    for n, c in halfspaces:
        if len(poly) == 0:
            break
        d = poly @ n - c
        nxt = np.roll(poly, -1, axis=0)
        dn = np.roll(d, -1)
        out = []
        for p, q, dp, dq in zip(poly, nxt, d, dn):
            if dp >= 0:
                out.append(p)
            if (dp >= 0) != (dq >= 0):
                out.append(p + (q - p) * (dp / (dp - dq)))
        poly = np.array(out) if out else np.zeros((0, 3))
    return poly


def _view_halfspaces(camera: Camera, margin=0.25, near_m=0.5):
    """Near plane and a frustum widened by ``margin`` (camera coordinates)."""
    w, h = camera.image_size
    tx = (w / 2) * (1 + margin) / camera.focal_px
    ty = (h / 2) * (1 + margin) / camera.focal_px
    return [(np.array([0.0, 0.0, 1.0]), near_m),
            (np.array([-1.0, 0.0, tx]), 0.0), (np.array([1.0, 0.0, tx]), 0.0),
            (np.array([0.0, -1.0, ty]), 0.0), (np.array([0.0, 1.0, ty]), 0.0)]


def _project_polygon(camera: Camera, poly_track):
    """Clip a ground polygon to the view and project it; (M, 2) pixels, or None if unseen."""
    clipped = _clip_polygon(camera.track_to_camera(poly_track), _view_halfspaces(camera))
    if len(clipped) < 3:
        return None
    if camera.has_distortion:
        # subdivide edges so that the polygon bends as the lens bends straight lines
        nxt = np.roll(clipped, -1, axis=0)
        seg_px = np.linalg.norm(nxt[:, :2] / nxt[:, 2:] - clipped[:, :2] / clipped[:, 2:],
                                axis=1) * camera.focal_px
        pieces = np.clip(np.ceil(seg_px / 6.0), 1, 400).astype(int)
        clipped = np.concatenate([p + (q - p) * (np.arange(n) / n)[:, None]
                                  for p, q, n in zip(clipped, nxt, pieces)])
    xy = clipped[:, :2] / clipped[:, 2:]
    if camera.has_distortion:
        xy = distort_normalized(xy, camera.dist)
    return xy * camera.focal_px + camera.K[:2, 2]


def _fill(img, pts_px, color, supersample=1):
    """Fill a polygon given in output-pixel coordinates.

    With ``supersample = s`` the canvas is ``s`` times larger and is later
    area-averaged down: pixel centres map as ``p_hi = (p + 0.5) s - 0.5``, and
    the area average gives exact coverage anti-aliasing (OpenCV's own polygon
    anti-aliasing shifts thin lines by up to a quarter pixel).
    """
    if pts_px is None or len(pts_px) < 3:
        return
    if supersample > 1:
        pts_px = (pts_px + 0.5) * supersample - 0.5
    pts = np.round(pts_px * _SCALE).astype(np.int64)
    lim = 2**28
    pts = np.clip(pts, -lim, lim).astype(np.int32)
    aa = cv2.LINE_AA if supersample == 1 else cv2.LINE_8
    cv2.fillPoly(img, [pts.reshape(-1, 1, 2)], color, lineType=aa, shift=_SHIFT)


def _strip(points, width_m):
    """Polygon (2N, 3) of a ground strip of ``width_m`` around a polyline (N, 3)."""
    d = np.gradient(points[:, :2], axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    nrm = np.stack([-d[:, 1], d[:, 0]], -1) * width_m / 2
    left = points.copy()
    right = points.copy()
    left[:, :2] += nrm
    right[:, :2] -= nrm
    return np.concatenate([left, right[::-1]])


def lane_line_polygons(track: TrackGeometry = STANDARD_TRACK, bends=True, straights=None):
    """Ground polygons of the lane lines: straight quads (all, or the indices in
    ``straights``), then bend strips."""
    x0, x1 = track.straight_x_range()
    polys = []
    hw = track.line_width_m / 2
    for i in range(track.n_lines) if straights is None else straights:
        y = float(track.line_y(i))
        polys.append(np.array([[x0, y - hw, 0], [x1, y - hw, 0], [x1, y + hw, 0], [x0, y + hw, 0]]))
    if bends:
        for i in range(track.n_lines):
            for curve in track.bend_line_points(i):
                polys.append(_strip(curve, track.line_width_m))
    return polys


def _oriented(line, inside_px):
    """Unit-normal homogeneous line, signed so that ``inside_px`` is on its positive side."""
    line = line / np.hypot(line[0], line[1])
    return line if line @ [inside_px[0], inside_px[1], 1.0] > 0 else -line


def _edge_response(d, sigma):
    """Coverage of a pixel at signed distance ``d`` (px) inside a straight edge, seen through
    a Gaussian blur of ``sigma`` (px) and integrated over the pixel's width along the
    edge normal: the box-filtered ramp ``clip(d + 1/2, 0, 1)`` when ``sigma = 0``.

    >>> [round(float(v), 3) for v in _edge_response(np.array([-2.0, 0.0, 2.0]), 0.45)]
    [0.0, 0.5, 1.0]
    """
    if sigma <= 0:
        return np.clip(d + 0.5, 0.0, 1.0)

    def integral(u):  # antiderivative of the Gaussian CDF Phi(u / sigma)
        z = u / sigma
        return u * ndtr(z) + sigma * np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi)

    return integral(d + 0.5) - integral(d - 0.5)


def _straight_lines_alpha(camera: Camera, track: TrackGeometry, alpha, max_band_px=80, psf_sigma_px=0.0):
    """Exact coverage of the straight lane lines (undistorted camera only).

    Each line is the band between the images of its two edges, cut by the
    images of its end caps and by the horizon; a pixel's coverage is the
    overlap of those half-planes, each blurred by a Gaussian of
    ``psf_sigma_px`` and box-filtered over the pixel along its normal
    (exact for thin lines and axis-aligned edges, symmetric otherwise, so
    centres are unbiased).  Returns the indices of lines too wide for a band
    (drawn as polygons instead).
    """
    P = camera.projection_matrix
    w, h = camera.image_size
    up = camera.R @ [0.0, 0.0, 1.0]
    horizon = np.linalg.inv(camera.K).T @ up  # image of the ground's line at infinity
    x0, x1 = track.straight_x_range()
    hw = track.line_width_m / 2
    too_wide = []

    def img_line(p, q):
        return np.cross(P @ np.append(p, 1.0), P @ np.append(q, 1.0))

    for i in range(track.n_lines):
        y = float(track.line_y(i))
        # a visible point of the line's centre, to orient the half-planes
        xs = np.linspace(x0, x1, 400)
        cen = camera.project(np.column_stack([xs, np.full_like(xs, y), np.zeros_like(xs)]))
        vis = np.all(np.isfinite(cen), 1) & camera.in_image(cen, margin_px=50)
        if not vis.any():
            continue
        inside = cen[np.flatnonzero(vis)[vis.sum() // 2]]
        edges = [_oriented(img_line([0, y - hw, 0], [1, y - hw, 0]), inside),
                 _oriented(img_line([0, y + hw, 0], [1, y + hw, 0]), inside)]
        caps = [_oriented(img_line([xc, y - hw, 0], [xc, y + hw, 0]), inside) for xc in (x0, x1)
                if np.all(np.isfinite(camera.project([xc, y, 0.0])))]
        caps.append(_oriented(horizon, inside))
        horizontal = abs(edges[0][1]) >= abs(edges[0][0])  # normal mostly vertical
        n_long = w if horizontal else h
        t = np.arange(n_long, dtype=float)
        # positions across the band where each edge crosses every column (row)
        a_i, b_i = (1, 0) if horizontal else (0, 1)
        cross = [-(e[b_i] * t + e[2]) / e[a_i] for e in edges]
        reach = 1 + int(np.ceil(4 * psf_sigma_px))
        lo = np.floor(np.minimum(*cross)) - reach
        hi = np.ceil(np.maximum(*cross)) + reach
        band = int(np.nanmax(hi - lo)) + 1 if np.any(np.isfinite(hi - lo)) else 0
        if band > max_band_px:
            too_wide.append(i)
            continue
        if band <= 0:
            continue
        n_across = h if horizontal else w
        start = np.clip(lo, -band, n_across)
        across = start[:, None] + np.arange(band)[None, :]
        along = np.broadcast_to(t[:, None], across.shape)
        X, Y = (along, across) if horizontal else (across, along)
        ok = (across >= 0) & (across < n_across)
        cov = np.clip(_edge_response(edges[0][0] * X + edges[0][1] * Y + edges[0][2], psf_sigma_px)
                      + _edge_response(edges[1][0] * X + edges[1][1] * Y + edges[1][2], psf_sigma_px)
                      - 1.0, 0, 1)
        for cap in caps:
            cov *= _edge_response(cap[0] * X + cap[1] * Y + cap[2], psf_sigma_px)
        keep = ok & (cov > 0)
        xi, yi = X[keep].astype(int), Y[keep].astype(int)
        alpha[yi, xi] = np.maximum(alpha[yi, xi], cov[keep].astype(np.float32))
    return too_wide


def render_background(camera: Camera, track: TrackGeometry = STANDARD_TRACK,
                      style: RenderStyle = RenderStyle(), supersample=None):
    """Stands, surround, track surface, infield and lane lines (uint8 BGR, H x W x 3).

    The large surfaces are filled with OpenCV's anti-aliasing.  Lane lines,
    whose centres the benchmarks measure, get exact coverage: analytically for
    the straight lines of an undistorted camera, otherwise on a
    ``supersample`` times larger coverage mask that is area-averaged down
    (OpenCV's own polygon anti-aliasing shifts thin lines by up to a quarter
    pixel, which would bias every calibration benchmark).
    """
    s = int(style.supersample if supersample is None else supersample)
    w, h = camera.image_size
    img = np.empty((h, w, 3), np.uint8)
    img[:] = style.stands_bgr
    ground = np.array([[-150, -150, 0], [250, -150, 0], [250, 150, 0], [-150, 150, 0]], float)
    _fill(img, _project_polygon(camera, ground), style.surround_bgr)
    _fill(img, _project_polygon(camera, track.outer_outline(margin_m=1.5)), style.track_bgr)
    _fill(img, _project_polygon(camera, track.straight_surface(margin_m=1.5)), style.track_bgr)
    _fill(img, _project_polygon(camera, track.infield_outline()), style.infield_bgr)
    alpha = np.zeros((h, w), np.float32)
    if camera.has_distortion:
        polys = lane_line_polygons(track)
    else:
        wide = _straight_lines_alpha(camera, track, alpha, psf_sigma_px=style.line_psf_sigma_px)
        polys = lane_line_polygons(track, straights=wide)
    projected = [p for p in (_project_polygon(camera, q) for q in polys) if p is not None]
    if projected and s > 1:
        allp = np.concatenate(projected)
        pad = 2 + int(np.ceil(4 * style.line_psf_sigma_px))
        x0, y0 = np.clip(np.floor(allp.min(0)).astype(int) - pad, 0, [w, h])
        x1, y1 = np.clip(np.ceil(allp.max(0)).astype(int) + pad + 1, 0, [w, h])
        if x1 > x0 and y1 > y0:
            cover = np.zeros(((y1 - y0) * s, (x1 - x0) * s), np.uint8)
            for p in projected:
                _fill(cover, p - [x0, y0], 255, s)
            if style.line_psf_sigma_px > 0:  # the lens blurs before the sensor samples
                cover = cv2.GaussianBlur(cover.astype(np.float32), (0, 0), style.line_psf_sigma_px * s)
            sub = cv2.resize(cover, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
            alpha[y0:y1, x0:x1] = np.maximum(alpha[y0:y1, x0:x1], sub.astype(np.float32) / 255.0)
    elif projected:
        for p in projected:
            _fill(img, p, style.line_bgr)
    ys, xs = np.nonzero(alpha)
    if len(ys):
        y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
        a = alpha[y0:y1, x0:x1, None]
        roi = img[y0:y1, x0:x1].astype(np.float32)
        roi += a * (np.array(style.line_bgr, np.float32) - roi)
        img[y0:y1, x0:x1] = np.round(roi).astype(np.uint8)
    return img


# body radii as fractions of stature (rough cylinder model for drawing only)
_LIMB_RADII = {
    ("r_hip", "r_knee"): 0.040, ("r_knee", "r_ankle"): 0.030,
    ("l_hip", "l_knee"): 0.040, ("l_knee", "l_ankle"): 0.030,
    ("r_shoulder", "r_elbow"): 0.024, ("r_elbow", "r_wrist"): 0.020,
    ("l_shoulder", "l_elbow"): 0.024, ("l_elbow", "l_wrist"): 0.020,
    ("thorax", "neck"): 0.030,
}

def render_runner(img, camera: Camera, joints_track_m, stature_m, style: RenderStyle = RenderStyle()):
    """Draw a shaded runner (capsule limbs, torso, head) over ``img`` in place.

    Parts are drawn far-to-near so the near side occludes the far side, and
    the body occludes the lines behind it.
    """
    J = JOINT_INDEX
    px, depth = camera.project(joints_track_m, return_depth=True)
    if np.any(~np.isfinite(px)) or np.any(depth <= 0):
        return img
    f = camera.focal_px
    parts = []
    for (a, b), r in _LIMB_RADII.items():
        ia, ib = J[a], J[b]
        z = 0.5 * (depth[ia] + depth[ib])
        col = style.skin_bgr if not a.endswith("hip") else style.shorts_bgr
        if a.startswith("l_") != _left_is_near(camera, joints_track_m):
            col = tuple(int(c * 0.75) for c in col)
        parts.append((z, "line", (px[ia], px[ib]), max(1.0, 2 * r * stature_m * f / z), col))
    # torso as a quadrilateral hips-shoulders
    torso = px[[J["r_hip"], J["l_hip"], J["l_shoulder"], J["r_shoulder"]]]
    zt = float(np.mean(depth[[J["pelvis"], J["thorax"]]]))
    parts.append((zt, "poly", torso, None, style.shirt_bgr))
    pelvis_w = 2 * 0.045 * stature_m * f / zt
    parts.append((zt, "line", (px[J["pelvis"]], px[J["spine"]]), max(1.0, pelvis_w * 1.6),
                  style.shorts_bgr))
    parts.append((zt - 1e-3, "line", (px[J["spine"]], px[J["thorax"]]), max(1.0, pelvis_w * 1.8),
                  style.shirt_bgr))
    zh = depth[J["head"]]
    parts.append((zh, "circle", px[J["head"]], max(1.0, 0.06 * stature_m * f / zh), style.skin_bgr))
    for z, kind, geom, size, col in sorted(parts, key=lambda p: -p[0]):
        if kind == "line":
            p0 = tuple(np.round(geom[0] * _SCALE).astype(int))
            p1 = tuple(np.round(geom[1] * _SCALE).astype(int))
            cv2.line(img, p0, p1, col, int(round(size)), cv2.LINE_AA, _SHIFT)
        elif kind == "poly":
            _fill(img, geom, col)
        else:
            c = tuple(np.round(geom * _SCALE).astype(int))
            cv2.circle(img, c, int(round(size * _SCALE)), col, -1, cv2.LINE_AA, _SHIFT)
    return img


def _left_is_near(camera, joints_track_m):
    J = JOINT_INDEX
    dl = np.linalg.norm(joints_track_m[J["l_hip"]] - camera.C)
    dr = np.linalg.norm(joints_track_m[J["r_hip"]] - camera.C)
    return dl < dr


def finish_image(img, rng, style: RenderStyle = RenderStyle()):
    """Optical blur and sensor noise (in place where possible); returns the image."""
    if style.blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), style.blur_sigma_px)
    if style.noise_sigma > 0:
        noise = np.empty(img.shape, np.int16)
        cv2.setRNGSeed(int(rng.integers(0, 2**31 - 1)))
        cv2.randn(noise, 0, style.noise_sigma)
        img = cv2.add(img.astype(np.int16), noise, dtype=cv2.CV_16S)
        img = np.clip(img, 0, 255).astype(np.uint8)
    return img


def render_frame(camera: Camera, joints_track_m=None, stature_m=1.8, rng=None,
                 track: TrackGeometry = STANDARD_TRACK, style: RenderStyle = RenderStyle()):
    """Full frame: background, runner, blur and noise (noise only when ``rng`` is given)."""
    img = render_background(camera, track, style)
    if joints_track_m is not None:
        render_runner(img, camera, np.asarray(joints_track_m, float), stature_m, style)
    if rng is not None:
        img = finish_image(img, rng, style)
    return img
