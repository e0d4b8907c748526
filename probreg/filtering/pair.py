"""Left and right limbs smoothed together: a runner's legs (and arms) repeat each other's
pattern half a stride apart.

:func:`periodic_smooth_series` ties every frame of a joint angle to the same phase one stride
later.  Running is also nearly symmetric: the left knee at ``t`` bends as the right knee does
half a stride later, up to the athlete's left/right asymmetry.  Smoothing the two sides of a
joint as one system with that second tie doubles the repetitions the noise is averaged over.
The tie is to the athlete's own systematic left/right difference (harmonics of the stride
phase fitted to the clip, shrunk towards zero), so a real asymmetry is kept; what varies beyond
it enters the tie's variance, estimated from the clip (the half-stride differences of the data
minus the noise's share) and floored at ``min_asym`` because a short noisy clip underestimates it.  The floor comes from
real running: in the CMU motion capture of ``shared/data/mocap`` (7 runs, 4 subjects) the
left/right half-stride knee differences have an rms of 3.0-7.8 deg (timing jitter included),
an asymmetry sd of ``rms / sqrt(2)`` = 2.1-5.5 deg; 2 deg is the most symmetric runner's.

The system is assembled with both series interleaved (frame ``t`` of side ``s`` at row
``2 t + s``), which keeps it banded: about one stride wide in each series, half a stride
between them.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

from .banded import SeriesSystem, _BandTerm, _tie_rows, band_inverse_diagonals

__all__ = ["PairSystem", "pair_system", "periodic_smooth_pair"]


#: harmonics of the stride phase in the systematic asymmetry (a knee's left/right difference
#: changes smoothly over the stride: more flexion at the swing peak, a later touchdown)
ASYM_HARMONICS = 2


class PairSystem:
    """The fixed parts of :func:`periodic_smooth_pair`: two :class:`SeriesSystem` and the
    half-stride ties between them, in interleaved band storage.

    ``oks`` two (F,) masks of observed frames, ``lag`` (F,) the stride lag (NaN: none).

    >>> F = 80; ok = np.ones(F, bool); lag = np.full(F, 20.0)
    >>> ps = PairSystem([ok, ok], lag, rho=0.0, p2_scale=0.0)
    >>> t = np.arange(F); yl = np.sin(2 * np.pi * t / 20); yr = np.sin(2 * np.pi * (t + 10) / 20)
    >>> bool(np.allclose(ps.pair_tie(np.ravel(np.column_stack([yl, yr]))), 0, atol=1e-9))  # symmetric
    True
    """

    def __init__(self, oks, lag, rho, p2_scale):
        self.series = [SeriesSystem(ok, lag, rho, p2_scale) for ok in oks]
        F = self.F = self.series[0].F
        t = np.arange(F)
        cols, vals, has = _tie_rows(np.asarray(lag, float) / 2)  # ties half a stride on
        # rows l(t) - r(t + h) and r(t) - l(t + h), interleaved indices 2 t + side
        self.pair_cols = np.concatenate([2 * cols + [0, 1, 1], 2 * cols + [1, 0, 0]])
        self.pair_vals = np.tile(vals, (2, 1))
        # stride phase (radians) of every frame, for the systematic asymmetry's harmonics:
        # rows r(t) - l(t + h) read the asymmetry a(phase_t), rows l(t) - r(t + h) read
        # -a(phase_t + pi)
        lag_f = np.asarray(lag, float)
        fin = np.isfinite(lag_f) & (lag_f > 0)
        step = 2 * np.pi / np.interp(t, t[fin], lag_f[fin]) if fin.any() else np.zeros(F)
        phase = np.concatenate([[0.0], np.cumsum(step)[:-1]])
        self.pair_phase = np.concatenate([phase[t[has]] + np.pi, phase[t[has]]])
        self.pair_sign = np.repeat([-1.0, 1.0], len(cols))
        width = [2 * S.u + 1 for S in self.series]
        if len(cols):
            width.append(int(np.max(self.pair_cols[:, 2] - self.pair_cols[:, 0])))
        self.u = max(width)
        # the stride ties of both series and the half-stride ties, as fixed rows of the interleaved band
        self._ties = [_BandTerm(2 * S.tie_cols + s, S.tie_vals, 2 * F) for s, S in enumerate(self.series)]
        self._pair_ties = _BandTerm(self.pair_cols, self.pair_vals, 2 * F)
        # each series' fixed band (noise precision and smoothness) in interleaved storage: series
        # band d -> interleaved band 2 d, at the series' own columns (the two never share an entry)
        self._base_il = []
        for s, S in enumerate(self.series):
            b = np.zeros((self.u + 1, 2 * F))
            for d in range(min(S.base.shape[0], self.u // 2 + 1)):
                b[2 * d, s:2 * (F - d):2] = S.base[d, :F - d]
            self._base_il.append(b)
        self._design = {}

    def asymmetry_design(self, harmonics=ASYM_HARMONICS):
        """Regressors (rows, 2 * harmonics + 1) of the systematic asymmetry at the pair rows (the
        same array on every call: do not modify it)."""
        if harmonics not in self._design:
            cols = [np.ones(len(self.pair_phase))]
            for m in range(1, harmonics + 1):
                cols += [np.cos(m * self.pair_phase), np.sin(m * self.pair_phase)]
            self._design[harmonics] = self.pair_sign[:, None] * np.column_stack(cols)
        return self._design[harmonics]

    def pair_tie(self, z):
        """The half-stride differences of interleaved series ``z`` (2F,)."""
        return np.sum(self.pair_vals * z[self.pair_cols], axis=1)

    def solve(self, y0s, sn2s, cvars, avar, offset=None, with_edf=True):
        """Fit of both series (interleaved, 2F) and each series' effective degrees of freedom
        (None without ``with_edf``: the selected inversion costs several times the solve).

        ``y0s`` the two data series (missing at 0), ``sn2s`` their noise variances, ``cvars``
        their stride-tie variances (one per tie row), ``avar`` the half-stride ties' (one per
        pair row) and ``offset`` what each half-stride difference should be (the systematic
        asymmetry; default 0).  Raises ``numpy.linalg.LinAlgError`` when the system is not
        positive definite."""
        from scipy.linalg import cho_solve_banded, cholesky_banded

        F = self.F
        ab = self._base_il[0] / sn2s[0] + self._base_il[1] / sn2s[1]
        rhs = np.zeros(2 * F)
        for s, S in enumerate(self.series):
            self._ties[s].add(ab, 1.0 / np.asarray(cvars[s], float))
            rhs[s::2] = S.qm(y0s[s]) / sn2s[s]
        if len(self.pair_cols):
            w = 1.0 / np.asarray(avar, float)
            self._pair_ties.add(ab, w)
            if offset is not None:
                np.add.at(rhs, self.pair_cols, self.pair_vals * (w * offset)[:, None])
        L = cholesky_banded(ab, lower=True, check_finite=False)
        z = cho_solve_banded((L, True), rhs, check_finite=False)
        if not with_edf:
            return z, None
        # tr(A^-1 Qm_s / sn2_s): Qm_s is tridiagonal in its series, i.e. offsets 0 and 2 here
        diag, sub2 = band_inverse_diagonals(L, offset=2)
        edf = [float((S.qd @ diag[s::2] + 2.0 * (S.qo @ sub2[s::2][:F - 1])) / sn2s[s])
               for s, S in enumerate(self.series)]
        return z, edf


#: the pair systems built last (a clip's liftings smooth the same stride lags and, nearly always,
#: the same observed frames draw after draw)
_SYSTEMS: OrderedDict = OrderedDict()
_SYSTEMS_MAX = 8
_SYSTEMS_LOCK = threading.Lock()


def pair_system(oks, lag, rho, p2_scale):
    """A :class:`PairSystem` for these inputs, reused when the same ones come again (its arrays
    are only read by :meth:`PairSystem.solve`).

    >>> ok = np.ones(40, bool); lag = np.full(40, 10.0)
    >>> pair_system([ok, ok], lag, 0.0, 1.0) is pair_system([ok.copy(), ok], lag.copy(), 0.0, 1.0)
    True
    >>> pair_system([ok, ok], lag, 0.0, 1.0) is pair_system([ok, ok], lag + 1, 0.0, 1.0)
    False
    """
    oks = [np.asarray(o, bool) for o in oks]
    lag = np.asarray(lag, float)
    key = (oks[0].tobytes(), oks[1].tobytes(), lag.tobytes(), float(rho), float(p2_scale))
    with _SYSTEMS_LOCK:  # liftings may run in threads (e.g. a Dask worker with several)
        system = _SYSTEMS.get(key)
        if system is not None:
            _SYSTEMS.move_to_end(key)
            return system
    system = PairSystem(oks, lag, rho, p2_scale)
    with _SYSTEMS_LOCK:
        _SYSTEMS[key] = system
        while len(_SYSTEMS) > _SYSTEMS_MAX:
            _SYSTEMS.popitem(last=False)
    return system


def _shrunk_harmonics(X, d):
    """Coefficients of the systematic asymmetry: least squares shrunk towards 0 (empirical Bayes,
    normal prior of common variance ``tau^2`` on the coefficients, ``tau^2`` by the method of
    moments), so that the differences' noise is not read as asymmetry while a real one of
    several degrees is kept almost whole.

    >>> rng = np.random.default_rng(0); ph = np.linspace(0, 20, 300)
    >>> X = np.column_stack([np.ones(300), np.cos(ph), np.sin(ph)])
    >>> np.abs(_shrunk_harmonics(X, rng.normal(0, 8, 300))).max() < 0.5   # noise: close to 0
    np.True_
    >>> np.round(_shrunk_harmonics(X, 10 * np.sin(ph) + rng.normal(0, 8, 300))).tolist()   # kept
    [-0.0, -1.0, 10.0]
    """
    XtX = X.T @ X
    ols = np.linalg.lstsq(X, d, rcond=None)[0]
    n, p = X.shape
    s2 = float(np.sum((d - X @ ols) ** 2)) / max(n - p, 1)
    cov = s2 * np.linalg.pinv(XtX)
    tau2 = max((float(ols @ ols) - float(np.trace(cov))) / p, 0.0)
    if tau2 == 0.0:
        return np.zeros(p)
    return np.linalg.solve(XtX / s2 + np.eye(p) / tau2, X.T @ d / s2)


def periodic_smooth_pair(y_l, y_r, lag, fps, rho=0.0, smooth_cutoff_hz=14.0, lag_sd_frames=0.35, min_sv=0.5,
                         min_asym=2.0, iters=2):
    """Cross-stride smoothing of a left/right pair of series, tied half a stride apart.

    The model of :func:`probreg.filtering.periodic_smooth_series` for each side (noise sd
    ``s_n``, stride-to-stride variability ``s_v``, smoothness with its half-power point at
    ``smooth_cutoff_hz``), plus ties ``x_l(t) - x_r(t + lag_t / 2)`` and
    ``x_r(t) - x_l(t + lag_t / 2)`` to the systematic asymmetry (harmonics of the stride phase,
    fitted to the data's half-stride differences, so a runner's own left/right difference is
    kept) with variance ``2 s_a^2 + (v_t lag_sd)^2``: ``s_a`` the asymmetry beyond it,
    estimated alternately with the other variances and floored at ``min_asym`` (module
    docstring).

    ``iters`` rounds of that alternation: the fit of the last round uses the variances of the
    one before.  The alternation converges slowly on some series (after 4 rounds some frames are
    still 3 deg from its limit) but the error does not follow it: on the 30 tuning clips with
    their true cameras the knee error was 3.31/3.30/3.30/3.31/3.32/3.33 deg after 1/2/3/4/8/30
    rounds.  With 2 rounds, no selected inversion in the last one and the band assembled by one
    ``bincount`` per term, a call costs about 0.4 of what it did with the 4 rounds used until
    0.2.0.dev2.  The system's fixed parts are built once per set of observed
    frames and stride lags (:func:`pair_system`): a clip's liftings share them draw after draw
    (0.2.0.dev10: 7.3 -> 4.5 ms a call on 250 frames, results bit-identical).

    Parameters
    ----------
    y_l, y_r : ndarray (F,)
        The two sides' series (e.g. left and right knee flexion, degrees); NaN = missing.
    lag : ndarray (F,) or None
        Stride lag per frame (:func:`probreg.filtering.stride_lags`).
    fps : float

    Returns
    -------
    (x_l, x_r) : tuple of ndarray (F,)
    info : dict
        ``noise_sd`` and ``stride_sd`` (pairs, left then right), ``asym_sd`` (the asymmetry
        beyond the systematic one) and ``asym_systematic_sd`` (sd of the fitted systematic
        left/right difference), in the series' unit.  Without enough data for the pair (fewer than 10 observed frames a
        side, no lag, no half-stride partner) each side is smoothed alone and ``asym_sd`` is
        NaN.

    >>> rng = np.random.default_rng(5)
    >>> t = np.arange(200); T = 34.0
    >>> truth_l = 60 + 45 * np.sin(2 * np.pi * t / T); truth_r = 60 + 45 * np.sin(2 * np.pi * (t + T / 2) / T)
    >>> yl, yr = truth_l + rng.normal(0, 5, 200), truth_r + rng.normal(0, 5, 200)
    >>> (xl, xr), info = periodic_smooth_pair(yl, yr, np.full(200, T), 50.0)
    >>> from probreg.filtering import periodic_smooth_series
    >>> alone = periodic_smooth_series(yl, np.full(200, T), 50.0)[0]
    >>> bool(np.mean(np.abs(xl - truth_l)) < np.mean(np.abs(alone - truth_l)))  # the other side helps
    True
    >>> bool(abs(info["noise_sd"][0] - 5) < 1), info["asym_sd"] == 2.0   # symmetric: at the floor
    (True, True)
    """
    from .periodic import periodic_smooth_series

    ys = [np.asarray(y_l, float), np.asarray(y_r, float)]
    oks = [np.isfinite(y) for y in ys]
    F = len(ys[0])

    def alone():
        fits = [periodic_smooth_series(y, lag, fps, rho=rho, smooth_cutoff_hz=smooth_cutoff_hz,
                                       lag_sd_frames=lag_sd_frames, min_sv=min_sv) for y in ys]
        return ((fits[0][0], fits[1][0]),
                {"noise_sd": tuple(f[1]["noise_sd"] for f in fits),
                 "stride_sd": tuple(f[1]["stride_sd"] for f in fits), "asym_sd": float("nan"),
                 "asym_systematic_sd": float("nan")})

    if lag is None or len(ys[1]) != F or min(int(o.sum()) for o in oks) < 10:
        return alone()
    wc = 2 * np.pi * smooth_cutoff_hz / fps
    system = pair_system(oks, lag, rho, p2_scale=1.0 / (2 - 2 * np.cos(min(wc, np.pi))) ** 2)
    if not len(system.pair_cols):
        return alone()
    t = np.arange(F)
    yi = [np.interp(t, t[o], y[o]) for y, o in zip(ys, oks)]
    y0 = [np.where(o, y, 0.0) for y, o in zip(ys, oks)]
    rep = [S.tie(v) for S, v in zip(system.series, yi)]
    sel = [o[S.has] for o, S in zip(oks, system.series)]
    z_data = np.ravel(np.column_stack(yi))
    prep = system.pair_tie(z_data)
    ok_int = np.ravel(np.column_stack(oks))
    # a half-stride difference counts when its frame and both partner frames were observed
    psel = ok_int[system.pair_cols].all(axis=1)
    # the systematic asymmetry: harmonics of the stride phase fitted to the data's half-stride
    # differences (a runner's own left/right difference is kept, not averaged away; only what
    # varies beyond it is tied)
    X = system.asymmetry_design()
    if psel.sum() < 3 * X.shape[1]:
        return alone()
    offset = X @ _shrunk_harmonics(X[psel], prep[psel])
    prep = prep - offset
    # start: all repeat differences read as noise, the sides as symmetric as the floor allows
    sn2 = [max(float(np.mean(r[s] ** 2)) / 2, 1e-6) if s.any() else float(np.var(v))
           for r, s, v in zip(rep, sel, yi)]
    sv2 = [min_sv**2, min_sv**2]
    sa2 = min_asym**2
    x = yi
    rounds = max(int(iters), 1)
    for it in range(rounds):
        cvars = []
        for s, S in enumerate(system.series):
            sv2[s], cvar = S.stride_tie_variance(rep[s], sel[s], x[s], sn2[s], sv2[s], min_sv, lag_sd_frames)
            cvars.append(cvar)
        vel = np.ravel(np.column_stack([np.abs(np.gradient(v)) for v in x]))
        ptiming = (vel[system.pair_cols[:, 0]] * lag_sd_frames) ** 2
        if psel.any():
            sa2 = max((float(np.mean(prep[psel] ** 2 - ptiming[psel])) - sn2[0] - sn2[1]) / 2, min_asym**2)
        last = it == rounds - 1
        try:
            z, edf = system.solve(y0, sn2, cvars, 2 * sa2 + ptiming, offset, with_edf=not last)
        except np.linalg.LinAlgError:  # singular: each side on its own
            return alone()
        x = [z[0::2], z[1::2]]
        if last:  # the noise variances the fit used are the ones reported
            break
        sn2 = [S.noise_variance(y, v, o, e) for S, y, v, o, e in zip(system.series, ys, x, oks, edf)]
    return (x[0], x[1]), {"noise_sd": tuple(float(np.sqrt(v)) for v in sn2),
                          "stride_sd": tuple(float(np.sqrt(v)) for v in sv2), "asym_sd": float(np.sqrt(sa2)),
                          "asym_systematic_sd": float(np.std(offset[psel]))}
