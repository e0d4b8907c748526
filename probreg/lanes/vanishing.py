"""The vanishing point of the lanes and the ordered pencil of lines through it.

Least-squares refinement of the vanishing point in homogeneous coordinates (a vanishing point
at infinity, a camera square onto the straight, is an ordinary case), lines re-fitted through
it, ordered across the track and given integer indices from their projective spacing, and a
Kalman/RTS smoother of the vanishing point over a clip with an outlier gate.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np

from ..geometry import cross3
from .types import _from_unit, _scale_frame, _to_unit

__all__ = ["lines_through_point", "assign_line_indices", "smooth_vanishing_points"]


def _scatter_matrices(point_sets, image_size):
    """Per line, the 3x3 scatter ``sum q q^T`` of its points in the scaled frame (``q = ((p - c)/s, 1)``)."""
    c, s = _scale_frame(image_size)
    sizes = [len(p) for p in point_sets]
    pts = np.concatenate(point_sets)
    q = np.column_stack([(pts - c) / s, np.ones(len(pts))])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    outer = (q[:, :, None] * q[:, None, :]).reshape(len(q), 9)
    return np.add.reduceat(outer, starts, axis=0).reshape(len(sizes), 3, 3)


def _pencil_fit(scatter, vp_unit):
    """Geometrically best lines through a point, from the lines' scatter matrices.

    For each line, minimises the sum of squared point-to-line distances over
    the lines through ``vp_unit`` (a generalised 2x2 eigenproblem in the
    pencil's basis; closed form, also for a vanishing point at infinity).
    ``vp_unit`` may also be a stack (K, 3) of points, fitted in one pass.

    Returns
    -------
    lines : ndarray (n, 3), or (K, n, 3)
        Lines in the scaled frame, normalised so that ``hypot(l0, l1) = 1``.
    sq : ndarray (n,), or (K, n)
        Sum of squared distances of each line's points (scaled-frame units).
    """
    V = np.asarray(vp_unit, float)
    single = V.ndim == 1
    V = np.atleast_2d(V)
    V = V / np.sqrt(np.sum(V * V, -1, keepdims=True))
    v0, v1, v2 = V[:, 0], V[:, 1], V[:, 2]
    # orthonormal basis (e1, e2) of the lines through v: e1 = v x axis, e2 = v x e1
    zero = np.zeros_like(v0)
    e1 = np.where((np.abs(v0) < 0.9)[:, None], np.stack([zero, v2, -v1], -1), np.stack([-v2, zero, v0], -1))
    e1 /= np.sqrt(np.sum(e1 * e1, -1, keepdims=True))
    e2 = cross3(V, e1)
    # quadratic forms of the scatter in the basis: a = e1' S e1, b = e2' S e1, cc = e2' S e2
    Se1 = np.einsum("nij,kj->kni", scatter, e1)  # (K, n, 3)
    a = np.einsum("kni,ki->kn", Se1, e1)
    b = np.einsum("kni,ki->kn", Se1, e2)
    cc = np.einsum("ki,nij,kj->kn", e2, scatter, e2)
    # metric of hypot(l0, l1)^2 in the basis
    p = (e1[:, 0] ** 2 + e1[:, 1] ** 2)[:, None]
    q = (e1[:, 0] * e2[:, 0] + e1[:, 1] * e2[:, 1])[:, None]
    r = (e2[:, 0] ** 2 + e2[:, 1] ** 2)[:, None]
    qa = p * r - q * q
    qb = a * r + cc * p - 2 * b * q
    qc = a * cc - b * b
    disc = np.sqrt(np.maximum(qb * qb - 4 * qa * qc, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = np.where(qb + disc > 0, 2 * qc / (qb + disc), 0.0)  # the smaller root
    lam = np.maximum(lam, 0.0)
    x1 = np.stack([-(b - lam * q), a - lam * p], -1)
    x2 = np.stack([cc - lam * r, -(b - lam * q)], -1)
    x = np.where((np.sum(x1**2, -1) >= np.sum(x2**2, -1))[..., None], x1, x2)  # (K, n, 2)
    lines = x[..., 0:1] * e1[:, None, :] + x[..., 1:2] * e2[:, None, :]
    nrm = np.hypot(lines[..., 0], lines[..., 1])
    lines = lines / np.maximum(nrm, 1e-300)[..., None]
    return (lines[0], lam[0]) if single else (lines, lam)


def lines_through_point(point_sets, vp_unit, image_size):
    """Best lines through a common (homogeneous) point, each fitted to its support points.

    Each line minimises the squared perpendicular distances (px) of its
    points among all lines through the point.

    Parameters
    ----------
    point_sets : list of ndarray (N_i, 2)
        Support points (px) of each line.
    vp_unit : ndarray, shape (3,)
        The common point as a unit vector in the scaled frame (see ``FrameLanes``).
    image_size : tuple

    Returns
    -------
    lines : ndarray, shape (n, 3)
        Unit-normal homogeneous lines in pixel coordinates.
    residuals : list of ndarray
        Signed distances (px) of every support point from its line.
    """
    ls, _ = _pencil_fit(_scatter_matrices(point_sets, image_size), vp_unit)
    lines = _lines_from_scaled(ls, image_size)
    return lines, _line_residuals(point_sets, lines)


def _lines_from_scaled(ls, image_size):
    """Lines (n, 3) of the scaled frame in pixel coordinates (the normal keeps its length)."""
    c, s = _scale_frame(image_size)
    return np.stack([ls[:, 0], ls[:, 1], ls[:, 2] * s - ls[:, 0] * c[0] - ls[:, 1] * c[1]], -1)


def _line_residuals(point_sets, lines):
    """Signed distances (px) of each set's points from its unit-normal line: list of arrays."""
    sizes = [len(p) for p in point_sets]
    seg = np.repeat(np.arange(len(sizes)), sizes)
    pts = np.concatenate(point_sets)
    r = np.einsum("ij,ij->i", pts, lines[seg, :2]) + lines[seg, 2]
    return np.split(r, np.cumsum(sizes)[:-1])


def _refine_vp(point_sets, vp_unit0, image_size, iterations=20):
    """Least-squares vanishing point (2 DOF on the sphere) with covariance of the unit vector.

    Minimises the sum of squared point-to-line distances (px) over the
    vanishing point, each line being re-fitted through it (:func:`_pencil_fit`
    on precomputed scatter matrices, so one evaluation costs O(lines)).
    Newton's method on the tangent plane with a central-difference Hessian,
    until the next Newton step's predicted decrease is negligible.  (Nearly
    parallel lines make the cost very flat along the pencil, and not quadratic
    there: a few steps are needed, and a stopping rule that judged the step
    just taken stopped up to one standard deviation short of the minimum.)
    """
    _, s = _scale_frame(image_size)
    S = _scatter_matrices(point_sets, image_size)
    v0 = vp_unit0 / np.linalg.norm(vp_unit0)
    t1 = cross3(v0, [1.0, 0, 0] if abs(v0[0]) < 0.9 else [0, 1.0, 0])
    t1 = t1 / np.linalg.norm(t1)
    t2 = cross3(v0, t1)
    T = np.stack([t1, t2], 1)

    def unit(x):
        u = v0 + T @ x
        return u / np.linalg.norm(u)

    def costs(X):  # (K, 2) tangent-plane offsets -> (K,) costs, in one batched fit
        U = v0 + X @ T.T
        return s * s * np.sum(_pencil_fit(S, U / np.linalg.norm(U, axis=1, keepdims=True))[1], -1)

    def cost(x):
        return float(costs(x[None])[0])

    # central differences: +h e1, +h e2, -h e1, -h e2, the four diagonal points, and
    # the point itself (all evaluated in one batched fit)
    stencil = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0],
                        [1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0], [0.0, 0.0]])

    def grad_hess(x, h, f0=None):
        f = costs(x + h * stencil[:8 if f0 is not None else 9])
        f0 = f[8] if f0 is None else f0
        fp, fm = f[0:2], f[2:4]
        g = (fp - fm) / (2 * h)
        H = np.diag((fp - 2 * f0 + fm) / h**2)
        H[0, 1] = H[1, 0] = (f[4] - f[5] - f[6] + f[7]) / (4 * h * h)
        return f0, g, H

    x = np.zeros(2)
    # the step of the differences: the cost is a difference of nearly equal scatter terms,
    # good to ~1e-8 of itself; with 1e-6 that noise reached the Hessian's flat direction
    # (nearly parallel lines: 44 % off on a frame of a low view), while steps from 1e-5 to
    # 1e-3 agree to 0.1 % there (the cost is quadratic over them)
    h = 1e-4
    f0, g, H = grad_hess(x, h)
    for _ in range(iterations):
        try:
            step = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(step)):
            break
        if -0.5 * (g @ step) < 1e-10 * max(f0, 1e-12):
            break  # converged: the Newton step's predicted decrease is negligible
        # backtracking: never accept a step that increases the cost
        lam = 1.0
        f_new = cost(x + step)
        while lam > 1e-4 and f_new > f0:
            lam *= 0.5
            f_new = cost(x + lam * step)
        if lam <= 1e-4:
            break
        x = x + lam * step
        f0, g, H = grad_hess(x, h, f_new)
        if np.linalg.norm(lam * step) < 1e-10:
            break
    v = unit(x)
    n_pts = sum(len(p) for p in point_sets)
    dof = max(n_pts - 2 - len(point_sets), 1)
    sigma2 = f0 / dof
    try:
        cov_x = 2.0 * sigma2 * np.linalg.inv(H)  # Hessian of the SSR ~ 2 J^T J
    except np.linalg.LinAlgError:
        cov_x = np.full((2, 2), np.nan)
    cov_u = T @ cov_x @ T.T
    return v, cov_u, np.sqrt(sigma2)


def _pencil_basis(vp_unit):
    v = vp_unit / np.linalg.norm(vp_unit)
    e1 = cross3(v, [0.0, 0.0, 1.0]) if abs(v[2]) < 0.99 else cross3(v, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, cross3(v, e1)


def _line_to_scaled(l_px, image_size):
    c, s = _scale_frame(image_size)
    return np.array([l_px[0] * s, l_px[1] * s, l_px[2] + l_px[0] * c[0] + l_px[1] * c[1]])


def _pencil_coordinate(lines_px, vp_unit, image_size):
    """Angle (rad) of each line within the pencil through the vanishing point.

    Lines through ``v`` form a projective line; the angle of a line in the
    basis ``(e1, e2)`` of the plane orthogonal to ``v`` is a coordinate on it.
    The circle of angles is cut at its largest empty gap so that the lines
    seen in the image have increasing, continuous coordinates.
    """
    e1, e2 = _pencil_basis(vp_unit)
    ls = np.array([_line_to_scaled(l, image_size) for l in lines_px])
    ang = np.mod(np.arctan2(ls @ e2, ls @ e1), np.pi)
    sa = np.sort(ang)
    gaps = np.diff(np.concatenate([sa, [sa[0] + np.pi]]))
    cut = sa[(np.argmax(gaps) + 1) % len(sa)]
    return np.where(ang < cut, ang + np.pi, ang)


def assign_line_indices(pencil_coord, max_missing=2):
    """Integer lane-line indices (0 = first in order) for lines sorted by pencil coordinate.

    With three lines the lines are taken as consecutive.  With four or more,
    gap patterns (a missing line in between) are scored by the misfit of a
    1-D projective map from index to pencil coordinate, the image of equally
    spaced lines; a gap must improve the fit clearly to be accepted.

    Returns
    -------
    indices : ndarray of int
    residual : float
        RMS misfit of the chosen fit in pencil-coordinate units (NaN for three lines).
    """
    t = np.asarray(pencil_coord, float)
    n = len(t)
    base = np.arange(n)
    if n < 4 or not np.all(np.isfinite(t)):  # (degenerate pencils give no coordinates: consecutive)
        return base, float("nan")

    def fit(k):
        A = np.column_stack([k, np.ones(n), -t * k, -t])
        try:
            _, _, vt = np.linalg.svd(A)
        except np.linalg.LinAlgError:
            return float("inf")
        a, b, c, d = vt[-1]
        pred = (a * k + b) / (c * k + d)
        return float(np.sqrt(np.mean((pred - t) ** 2)))

    best_k, best_r = base, fit(base.astype(float))
    for extra in range(1, max_missing + 1):
        for gaps in itertools.combinations_with_replacement(range(n - 1), extra):
            inc = np.ones(n - 1)
            for g in gaps:
                inc[g] += 1
            k = np.concatenate([[0], np.cumsum(inc)])
            if k[-1] > 8:
                continue
            r = fit(k)
            if r < 0.3 * best_r:
                best_k, best_r = k.astype(int), r
    return np.asarray(best_k, int), best_r


def smooth_vanishing_points(frames, process_std=5e-4, min_var=1e-8, gate_chi2=25.0, max_gated_run=5,
                            gate_process_std=5e-5):
    """RTS-smooth the vanishing points of a clip (the broadcast camera moves smoothly).

    The unit vector of each vanishing point (scaled homogeneous frame) is
    smoothed with a constant-velocity Kalman filter and RTS smoother
    (``filterpy``); frames without lanes are bridged.  Each frame's lines are
    then re-fitted through its smoothed vanishing point.

    Parameters
    ----------
    frames : list of FrameLanes
    process_std : float
        Acceleration noise of the unit vector per frame.  A camera that follows
        the runner pans with the stride (the pelvis slows and speeds up within
        each step); a smoother much stiffer than the default (5e-5) lags that
        motion, and the lag turns into a gait-synchronous pan error that makes
        planted feet seem to slide (the posterior's stillness term: its error at
        the true camera height, rms over the suite, was 0.10 of the running speed
        with 5e-5 against 0.06 unsmoothed).  With 5e-4 the vanishing-point error on the
        benchmark suite is 0.16 % (0.23 % unsmoothed, 0.17 % with 5e-5).
    gate_chi2 : float or None
        Innovation gate (squared Mahalanobis distance): a frame whose
        vanishing point is this far from the prediction is treated as an
        outlier and bridged (``extra["vp_gated"]`` is True).  None disables it.
    gate_process_std : float
        Acceleration noise of the stiffer filter pass that decides the gate: a
        filter as loose as ``process_std`` would follow a single wrong frame.
    max_gated_run : int
        After this many consecutive gated frames the next measurement is
        accepted, so a real sudden camera move cannot lock the filter out.

    Returns
    -------
    list of FrameLanes
        Same statuses; ``ok`` frames carry the smoothed vanishing point
        (``extra["vp_raw"]`` keeps the per-frame estimate).
    """
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    ok = [i for i, f in enumerate(frames) if f.ok]
    if len(ok) < 3:
        return list(frames)
    size = frames[ok[0]].image_size
    zs = []
    ref = None
    for f in frames:
        if not f.ok:
            zs.append(None)
            continue
        u = f.extra.get("vp_unit", _to_unit(f.vanishing_point, size))
        if ref is not None and u @ ref < 0:
            u = -u
        ref = u
        zs.append(u)
    def run_filter(q_std, gate, skip=()):
        kf = KalmanFilter(dim_x=6, dim_z=3)
        kf.F = np.kron(np.eye(3), np.array([[1.0, 1.0], [0.0, 1.0]]))
        kf.H = np.kron(np.eye(3), np.array([[1.0, 0.0]]))
        kf.Q = np.kron(np.eye(3), Q_discrete_white_noise(2, dt=1.0, var=q_std**2))
        kf.x = np.zeros(6)
        kf.x[0::2] = zs[ok[0]]
        kf.P = np.eye(6) * 1e-2
        means, covs, gated = [], [], []
        n_updates = run_gated = 0
        for i, (f, z) in enumerate(zip(frames, zs)):
            kf.predict()
            if z is not None and i not in skip:
                R = f.vp_cov + np.eye(3) * min_var if f.vp_cov is not None and np.all(np.isfinite(f.vp_cov)) \
                    else np.eye(3) * 1e-6
                if n_updates >= 3 and gate is not None and run_gated < max_gated_run:
                    y = z - kf.H @ kf.x
                    S = kf.H @ kf.P @ kf.H.T + R
                    d2 = float(y @ np.linalg.lstsq(S, y, rcond=None)[0])
                    if not np.isfinite(d2) or d2 > gate:
                        gated.append(i)
                        run_gated += 1
                        z = None
                if z is not None:
                    kf.update(z, R=R)
                    n_updates += 1
                    run_gated = 0
            means.append(kf.x.copy())
            covs.append(kf.P.copy())
        return kf, means, covs, gated

    # outliers judged against a stiff motion model, the rest smoothed with the looser one
    gated_set = set(run_filter(gate_process_std, gate_chi2)[3]) if gate_chi2 is not None else set()
    kf, means, covs, _ = run_filter(process_std, None, gated_set)
    xs, Ps, _, _ = kf.rts_smoother(np.array(means), np.array(covs))
    out = []
    for i, (f, x, P) in enumerate(zip(frames, xs, Ps)):
        if not f.ok:
            out.append(f)
            continue
        u = x[0::2] / np.linalg.norm(x[0::2])
        lines_px, res = lines_through_point([ln.points_px for ln in f.lines], u, size)
        lanes = tuple(replace(ln, line=l, rms_px=float(np.sqrt(np.mean(r ** 2))))
                      for ln, l, r in zip(f.lines, lines_px, res))
        cov = P[0::2, 0::2]
        out.append(replace(f, lines=lanes, vanishing_point=_from_unit(u, size), vp_cov=cov,
                           extra={**f.extra, "vp_unit": u, "vp_raw": f.vanishing_point,
                                  "vp_gated": i in gated_set}))
    return out

def _spacing_residual_px(lanes, coord, idx, vp_unit, image_size):
    """RMS distance (px) of each line's support points from the line that the best
    equally spaced pencil (a 1-D projective map of the indices) predicts."""
    k = np.asarray(idx, float)
    t = np.asarray(coord, float)
    if not np.all(np.isfinite(t)):
        return float("nan")
    A = np.column_stack([k, np.ones(len(k)), -t * k, -t])
    try:
        _, _, vt = np.linalg.svd(A)
    except np.linalg.LinAlgError:  # non-finite coordinates: no spacing fit
        return float("nan")
    a, b, c, d = vt[-1]
    pred = (a * k + b) / (c * k + d)
    e1, e2 = _pencil_basis(vp_unit)
    ls = np.cos(pred)[:, None] * e1 + np.sin(pred)[:, None] * e2  # predicted lines, scaled frame
    lp = _lines_from_scaled(ls, image_size)
    lp /= np.hypot(lp[:, 0], lp[:, 1])[:, None]
    res = _line_residuals([ln.points_px for ln in lanes], lp)
    return float(np.sqrt(np.mean([np.mean(r**2) for r in res])))
