"""The ground track's Kalman filter and RTS smoother, written for its model: two independent
constant-velocity axes (along and across the track).

:func:`gated_forward_pass` and :func:`rts_backward` run ``filterpy``'s formulas in scalars (the
filter runs for every camera hypothesis and every posterior draw); :func:`forward_pass_batch` and
:func:`rts_backward_batch` run the same formulas for many hypotheses at once, one array element per
hypothesis, and give each hypothesis exactly (to the bit) what the scalar functions give it: the
operations are the same IEEE ones in the same order, and the two that Python and NumPy compute
differently (a float's ``** 2``, which Python hands to the C library's ``pow``, and the logarithm)
are taken from Python's own ``**`` and :func:`math.log` at the few measured frames.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["gated_forward_pass", "forward_pass_batch", "rts_backward", "rts_backward_batch"]


def gated_forward_pass(kf, meas, n, first=None, max_rejected_run=2, gate=16.0):
    """The forward pass of the ground-track filter: ``(xs (n, 4), Ps (n, 4, 4), log_likelihood)``.

    ``kf`` is a ``filterpy`` ``KalmanFilter`` of two independent constant-velocity axes (state
    ``[x, vx, y, vy]``, ``H`` picking ``x`` and ``y``; ``F``, ``Q``, ``R`` and the start ``P``
    without cross-axis terms, as :func:`_track_from_contacts` builds it); ``meas`` maps a frame
    index to its 2-D measurement.  Each step is ``kf.predict()`` then, for a measured frame,
    ``kf.update(z)`` -- the same formulas (Joseph-form update) written per axis in scalars, which
    the block structure keeps exact (other models are refused) and which takes a seventh of the
    time of filterpy's calls (the filter runs for every posterior draw).  An innovation whose
    squared Mahalanobis length exceeds
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
    return np.array(states, float).reshape(n, 4), _covariance_blocks(np.array(covs, float).reshape(n, 6)), loglik


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
    a, K, B = _rts_gains(x, P, F, Q)
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


def _rts_gains(x, P, F, Q):
    """The parts of the backward pass that depend on the filtered states ``x`` (n, d) and
    covariances ``P`` (n, d, d) alone, for all steps at once: ``(a, K, B)`` with the smoother
    gains ``K`` (n - 1, d, d), ``a = x[k] - K F x[k]`` and ``B = P[k] - K Pp K'``, so that
    ``x_s[k] = a[k] + K[k] x_s[k + 1]`` and ``P_s[k] = B[k] + K[k] P_s[k + 1] K[k]'``.

    With a leading axis of hypotheses (``x`` (H, n, d), ``P`` (H, n, d, d)) the same for each,
    computed together (each hypothesis's matrices are the same products, so the same numbers)."""
    Pf = P[..., :-1, :, :]
    Pp = F @ Pf @ F.T + Q  # predicted covariance of step k + 1 from step k
    K = Pf @ F.T @ np.linalg.inv(Pp)
    xf = x[..., :-1, :]  # x[k] + K (x_s[k + 1] - F x[k]):
    a = xf - np.einsum("kij,kj->ki" if x.ndim == 2 else "hkij,hkj->hki", K, xf @ F.T)
    B = Pf - K @ Pp @ np.swapaxes(K, -2, -1)  # P[k] + K (P_s[k + 1] - Pp) K'
    return a, K, B


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


def _covariance_blocks(c):
    """``(..., 4, 4)`` covariances from the per-axis triples ``c`` (..., 6): ``(a, b, c)`` of x,
    then of y."""
    Ps = np.zeros(c.shape[:-1] + (4, 4))
    for o, j in ((0, 0), (2, 3)):
        Ps[..., o, o], Ps[..., o, o + 1], Ps[..., o + 1, o + 1] = c[..., j], c[..., j + 1], c[..., j + 2]
        Ps[..., o + 1, o] = c[..., j + 1]
    return Ps


def _py_square(v):
    """``v ** 2`` element by element as Python computes it for a float (the C library's ``pow``,
    which differs from ``v * v`` in the last bit now and then)."""
    return np.array([e ** 2 for e in v.tolist()])


def forward_pass_batch(x0, p0, r, dt, q, z, measured, first, max_rejected_run=2, gate=16.0):
    """:func:`gated_forward_pass` of ``H`` hypotheses at once, each exactly as that function gives it.

    Parameters
    ----------
    x0 : ndarray (H, 4)
        Start states ``[x, vx, y, vy]``.
    p0 : ndarray (H, 6)
        Start covariances per axis, ``(P_xx, P_xvx, P_vxvx, P_yy, P_yvy, P_vyvy)``.
    r : ndarray (H, 2)
        Measurement variances along and across.
    dt : float
    q : ((float, float, float), (float, float, float))
        Process noise per axis, ``(Q_00, Q_01, Q_11)`` of x, then of y (shared).
    z : ndarray (H, n, 2)
        Measurements (any value where not ``measured``).
    measured : ndarray of bool (H, n)
    first : ndarray of int (H,)
        The frame whose measurement is never gated out (each hypothesis's first).

    Returns
    -------
    xs : ndarray (H, n, 4)
    Ps : ndarray (H, n, 4, 4)
    loglik : ndarray (H,)

    >>> from filterpy.common import Q_discrete_white_noise
    >>> from filterpy.kalman import KalmanFilter
    >>> dt, rng, H, n = 0.02, np.random.default_rng(3), 5, 60
    >>> Q = np.zeros((4, 4)); Q[:2, :2] = Q_discrete_white_noise(2, dt=dt, var=2.0)
    >>> Q[2:, 2:] = Q_discrete_white_noise(2, dt=dt, var=0.4)
    >>> def kf_of(x, p, r):
    ...     kf = KalmanFilter(dim_x=4, dim_z=2); kf.F = np.kron(np.eye(2), np.array([[1.0, dt], [0.0, 1.0]]))
    ...     kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]]); kf.Q = Q
    ...     kf.R = np.diag(r); kf.x = x; kf.P = np.diag(p[[0, 2, 3, 5]]); return kf
    >>> x0 = np.column_stack([rng.normal(0, 1, H), rng.normal(8, 1, H), rng.normal(0, 0.3, H), np.zeros(H)])
    >>> p0 = np.tile([4.0, 0.0, 4.0, 0.09, 0.0, 0.01], (H, 1)); r = np.tile([0.01, 0.002], (H, 1))
    >>> measured = rng.random((H, n)) < 0.15; measured[:, 0] = True  # noisy: gated out, restarted
    >>> z = np.stack([0.16 * np.arange(n) + rng.normal(0, 0.3, (H, n)), rng.normal(0, 0.1, (H, n))], -1)
    >>> q = ((Q[0, 0], Q[0, 1], Q[1, 1]), (Q[2, 2], Q[2, 3], Q[3, 3]))
    >>> xs, Ps, ll = forward_pass_batch(x0, p0, r, dt, q, z, measured, np.zeros(H, int))
    >>> one = [gated_forward_pass(kf_of(x0[h], p0[h], r[h]), {i: z[h, i] for i in np.flatnonzero(measured[h])}, n,
    ...                           first=0) for h in range(H)]
    >>> all(np.array_equal(xs[h], o[0]) and np.array_equal(Ps[h], o[1]) and ll[h] == o[2] for h, o in enumerate(one))
    True
    """
    x0, p0, r = (np.asarray(v, float) for v in (x0, p0, r))
    z, measured, first = np.asarray(z, float), np.asarray(measured, bool), np.asarray(first)
    H, n = measured.shape
    dt = float(dt)
    px, vx, py, vy = (x0[:, k].copy() for k in range(4))
    ax, bx, cx, ay, by, cy = (p0[:, k].copy() for k in range(6))
    (qx1, qx2, qx3), (qy1, qy2, qy3) = ((float(v) for v in t) for t in q)
    rx, ry = r[:, 0], r[:, 1]
    log_2pi_sq = 2.0 * math.log(2.0 * math.pi)
    states, covs = np.empty((n, 4, H)), np.empty((n, 6, H))
    loglik, run_rejected = np.zeros(H), np.zeros(H, int)
    for i in range(n):
        if i > 0:  # predict, every hypothesis
            px, py = px + dt * vx, py + dt * vy
            ax, bx, cx = ax + dt * (2.0 * bx + dt * cx) + qx1, bx + dt * cx + qx2, cx + qx3
            ay, by, cy = ay + dt * (2.0 * by + dt * cy) + qy1, by + dt * cy + qy2, cy + qy3
        m = np.flatnonzero(measured[:, i])
        if len(m):  # update, the hypotheses measured at this frame
            zx, zy = z[m, i, 0], z[m, i, 1]
            sx, sy = ax[m] + rx[m], ay[m] + ry[m]
            ex, ey = zx - px[m], zy - py[m]
            nis = ex * ex / sx + ey * ey / sy
            rejected = (nis > gate) & (first[m] != i)
            log_det = np.array([math.log(v) for v in (sx * sy).tolist()])
            loglik[m] += -0.5 * np.where(rejected, gate, nis) - 0.5 * (log_2pi_sq + log_det)
            restart = rejected & (run_rejected[m] >= max_rejected_run)
            run_rejected[m[rejected & ~restart]] += 1
            take = ~rejected | restart
            t = m[take]
            run_rejected[t] = 0
            a1, b1, c1, a2, b2, c2 = (np.where(restart[take], p0[t, k], v[t])
                                      for k, v in enumerate((ax, bx, cx, ay, by, cy)))
            ex, ey, rxt, ryt = ex[take], ey[take], rx[t], ry[t]
            sx, sy = a1 + rxt, a2 + ryt
            k0, k1 = a1 / sx, b1 / sx
            px[t], vx[t] = px[t] + k0 * ex, vx[t] + k1 * ex
            ax[t], bx[t], cx[t] = (_py_square(1 - k0) * a1 + k0 * k0 * rxt, (1 - k0) * (b1 - k1 * a1) + k0 * k1 * rxt,
                                   c1 - 2.0 * k1 * b1 + k1 * k1 * (a1 + rxt))
            k0, k1 = a2 / sy, b2 / sy
            py[t], vy[t] = py[t] + k0 * ey, vy[t] + k1 * ey
            ay[t], by[t], cy[t] = (_py_square(1 - k0) * a2 + k0 * k0 * ryt, (1 - k0) * (b2 - k1 * a2) + k0 * k1 * ryt,
                                   c2 - 2.0 * k1 * b2 + k1 * k1 * (a2 + ryt))
        states[i] = px, vx, py, vy
        covs[i] = ax, bx, cx, ay, by, cy
    return np.ascontiguousarray(states.transpose(2, 0, 1)), _covariance_blocks(covs.transpose(2, 0, 1)), loglik


def rts_backward_batch(xs, Ps, F, Q):
    """:func:`rts_backward` of ``H`` hypotheses at once (``xs`` (H, n, d), ``Ps`` (H, n, d, d)), each
    exactly as that function gives it: the gains per hypothesis as there, the two recursions of
    every decoupled pair for all hypotheses together.

    >>> rng = np.random.default_rng(1); F = np.kron(np.eye(2), [[1.0, 0.02], [0.0, 1.0]])
    >>> Q = np.kron(np.eye(2), [[1e-4, 1e-3], [1e-3, 0.1]])
    >>> xs = rng.normal(size=(3, 30, 4)); A = rng.normal(size=(3, 30, 2, 2))
    >>> blk = A @ np.swapaxes(A, -1, -2) + np.eye(2); Ps = np.zeros((3, 30, 4, 4))
    >>> Ps[..., :2, :2], Ps[..., 2:, 2:] = blk, 2 * blk
    >>> x, P = rts_backward_batch(xs, Ps, F, Q)
    >>> one = [rts_backward(xs[h], Ps[h], F, Q) for h in range(3)]
    >>> all(np.array_equal(x[h], o[0]) and np.array_equal(P[h], o[1]) for h, o in enumerate(one))
    True
    """
    x, P = np.array(xs, float), np.array(Ps, float)
    H, n, d = x.shape
    if n < 2 or not all(_pairs_decoupled(F, Q, P[h]) for h in range(H)):
        for h in range(H):
            x[h], P[h] = rts_backward(x[h], P[h], F, Q)
        return x, P
    a, K, B = _rts_gains(x, P, F, Q)
    # every pair (i, i + 1) of every hypothesis is one row of the recursions
    pairs = [(i, i + 1) for i in range(0, d, 2)]
    rows = lambda arr, u, v: np.concatenate([arr[:, :, i + u, i + v] for i, _ in pairs])  # noqa: E731
    a0 = np.concatenate([a[:, :, i] for i, _ in pairs])
    a1 = np.concatenate([a[:, :, j] for _, j in pairs])
    k00, k01, k10, k11 = (rows(K, u, v) for u, v in ((0, 0), (0, 1), (1, 0), (1, 1)))
    b00, b01, b11 = (rows(B, u, v) for u, v in ((0, 0), (0, 1), (1, 1)))
    x0 = np.concatenate([x[:, -1, i] for i, _ in pairs])
    x1 = np.concatenate([x[:, -1, j] for _, j in pairs])
    p = np.concatenate([P[:, -1, i, i] for i, _ in pairs])
    q = np.concatenate([P[:, -1, i, j] for i, j in pairs])
    r = np.concatenate([P[:, -1, j, j] for _, j in pairs])
    out = np.empty((5, len(x0), n))
    out[:, :, -1] = x0, x1, p, q, r
    for k in range(n - 2, -1, -1):
        c00, c01, c10, c11 = k00[:, k], k01[:, k], k10[:, k], k11[:, k]
        x0, x1 = a0[:, k] + c00 * x0 + c01 * x1, a1[:, k] + c10 * x0 + c11 * x1
        m00, m01 = c00 * p + c01 * q, c00 * q + c01 * r  # K P
        m10, m11 = c10 * p + c11 * q, c10 * q + c11 * r
        p, q, r = (b00[:, k] + m00 * c00 + m01 * c01, b01[:, k] + m00 * c10 + m01 * c11,
                   b11[:, k] + m10 * c10 + m11 * c11)
        out[:, :, k] = x0, x1, p, q, r
    for s, (i, j) in enumerate(pairs):
        blk = out[:, s * H:(s + 1) * H]
        x[:, :, i], x[:, :, j] = blk[0], blk[1]
        P[:, :, i, i], P[:, :, i, j], P[:, :, j, i], P[:, :, j, j] = blk[2], blk[3], blk[3], blk[4]
    return x, P
