"""Banded building blocks of the cross-stride smoothers: the normal equations of one series
assembled directly in LAPACK's lower band storage (no sparse matrices), their banded Cholesky
factor, and the effective degrees of freedom of the fit from that factor (by a selected
inversion: only the band of the inverse that the trace needs).

A series smoother's system ``(Qm + sn2 R' W R + P2) x = Qm y`` couples each frame to its
neighbours (AR(1) noise, second differences) and to the frame one stride later (``R``), so it is
banded with about one stride's width; built and solved in band storage it costs ``n u^2``
instead of the sparse machinery's per-call overhead, which dominated a clip's angle smoothing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SeriesSystem", "band_inverse_diagonals", "lower_band"]


def _band_add(ab, cols, vals, w):
    """``ab += sum_rows w_r v_r v_r'`` (each row ``v_r`` given by its columns ``cols[r]`` and
    values ``vals[r]``) in lower band storage ``ab[i - j, j] = A[i, j]``."""
    _BandTerm(cols, vals, ab.shape[1]).add(ab, w)


class _BandTerm:
    """Fixed rows ``v_r`` (columns ``cols``, values ``vals``, (m, p) each) of a sum
    ``sum_r w_r v_r v_r'`` into lower band storage of ``n`` columns: the index arithmetic done once,
    :meth:`add` for each weight vector (a system solved again and again with new variances keeps
    its rows).  Every product ``v_ra v_rb`` of a row goes into one sum over the flat band index
    (one ``bincount`` instead of ``p^2`` scattered adds).

    >>> ab = np.zeros((2, 3)); _BandTerm(np.array([[0, 1]]), np.array([[1.0, -1.0]]), 3).add(ab, 2.0)
    >>> ab.tolist()   # 2 (x0 - x1)^2: diagonal 2, 2, 0; first sub-diagonal -2
    [[2.0, 2.0, 0.0], [-2.0, 0.0, 0.0]]
    """

    def __init__(self, cols, vals, n):
        cols, vals = np.asarray(cols), np.asarray(vals, float)
        r, c = cols[:, :, None], cols[:, None, :]
        shape = (len(cols),) + (cols.shape[1],) * 2
        keep = np.broadcast_to(r >= c, shape)
        self.n, self.m = int(n), len(cols)
        self.flat = ((r - c) * self.n + c)[keep]
        self.row = np.broadcast_to(np.arange(len(cols))[:, None, None], shape)[keep]
        self.va = np.broadcast_to(vals[:, :, None], shape)[keep]
        self.vb = np.broadcast_to(vals[:, None, :], shape)[keep]
        #: the farthest sub-diagonal a row reaches
        self.reach = int(np.max(cols.max(1) - cols.min(1))) if len(cols) else 0

    def add(self, ab, w):
        """``ab += sum_r w_r v_r v_r'`` (``w`` one weight per row, or one for all)."""
        w = np.broadcast_to(np.asarray(w, float), (self.m,))
        ab += np.bincount(self.flat, (w[self.row] * self.va) * self.vb, minlength=ab.size).reshape(ab.shape)


class SeriesSystem:
    """The fixed parts of :func:`probreg.filtering.periodic_smooth_series` for one series.

    ``ok`` (F,) marks observed frames, ``lag`` (F,) the stride lag (NaN: none), ``rho`` the
    noise's lag-1 correlation and ``p2_scale`` the smoothness weight
    (``1 / (2 - 2 cos wc)^2``).  :meth:`solve` returns the fit and the effective degrees of
    freedom for given noise and stride-tie variances.

    >>> F = 60; ok = np.ones(F, bool); lag = np.full(F, 12.0)
    >>> y = np.sin(np.arange(F) * 2 * np.pi / 12)
    >>> free = SeriesSystem(ok, lag, rho=0.0, p2_scale=0.0)   # no smoothness, hardly any noise
    >>> x, edf = free.solve(y, sn2=1e-9, cvar=np.ones(int(free.has.sum())))
    >>> bool(np.allclose(x, y, atol=1e-6)), bool(abs(edf - F) < 1e-3)   # the data, F degrees
    (True, True)
    >>> stiff = SeriesSystem(ok, lag, rho=0.0, p2_scale=1e6)   # and no stride tie (cvar huge)
    >>> x, edf = stiff.solve(y, 1.0, np.full(int(free.has.sum()), 1e12))
    >>> bool(abs(edf - 2) < 0.05)   # stiff: a straight line, two degrees of freedom
    True
    """

    def __init__(self, ok, lag, rho, p2_scale):
        ok = np.asarray(ok, bool)
        F = len(ok)
        self.F = F
        lag = np.asarray(lag, float)
        # stride tie rows: x_t - (1 - a) x_k - a x_{k+1}
        self.tie_cols, self.tie_vals, self.has = _tie_rows(lag)
        self._ties = _BandTerm(self.tie_cols, self.tie_vals, F)
        self.u = max(self._ties.reach, 2)
        # AR(1) precision Q = B' B (B lower bidiagonal: the innovations), masked to the observed
        # frames: Qm, tridiagonal
        rho = float(np.clip(rho, 0.0, 0.9))
        s = np.sqrt(1 - rho**2)
        m = ok.astype(float)
        qd = np.full(F, (1 + rho**2) / s**2)
        qd[[0, -1]] = 1.0 / s**2
        self.qd = m * qd
        self.qo = m[:-1] * m[1:] * (-rho / s**2)  # Qm[i, i + 1]
        base = np.zeros((self.u + 1, F))
        base[0] += self.qd
        base[1, :-1] += self.qo
        # second differences: rows [1, -2, 1]
        r = np.arange(F - 2)
        _band_add(base, np.column_stack([r, r + 1, r + 2]),
                  np.tile([1.0, -2.0, 1.0], (F - 2, 1)), np.full(F - 2, float(p2_scale)))
        self.base = base

    def qm(self, v):
        """``Qm @ v``."""
        out = self.qd * v
        out[:-1] += self.qo * v[1:]
        out[1:] += self.qo * v[:-1]
        return out

    def tie(self, v):
        """``R @ v`` (the repeat differences, one per frame with a partner)."""
        return np.sum(self.tie_vals * v[self.tie_cols], axis=1)

    def stride_tie_variance(self, rep, sel, x, sn2, sv2, min_sv, lag_sd_frames):
        """The stride variability and the stride ties' variances at the fit ``x``:
        ``(sv2, cvar)``.  ``rep`` are the data's repeat differences (:meth:`tie`), ``sel`` which
        of them are observed; ``sv2`` (kept when none is) is their variance beyond twice the
        noise ``sn2`` and the timing term, floored at ``min_sv**2``; each tie's variance is
        ``2 sv2`` plus its timing uncertainty (the fit's speed times ``lag_sd_frames``)."""
        timing = (np.abs(np.gradient(x))[self.has] * lag_sd_frames) ** 2
        if sel.any():
            sv2 = max((float(np.mean(rep[sel] ** 2 - timing[sel])) - 2 * sn2) / 2, min_sv**2)
        return sv2, 2 * sv2 + timing

    def noise_variance(self, y, x, ok, edf):
        """The noise variance of the residuals of fit ``x`` to the observed ``y`` (mask ``ok``):
        their AR(1) quadratic form over the degrees of freedom left (``edf`` the fit's)."""
        r = np.where(ok, y - x, 0.0)
        return max(float(r @ self.qm(r)) / max(int(ok.sum()) - edf, 1.0), 1e-6)

    def solve(self, y0, sn2, cvar):
        """Fit and effective degrees of freedom ``tr((Qm + sn2 R' diag(1/cvar) R + P2)^-1 Qm)``
        (``y0``: the data with missing frames at 0).  Raises ``numpy.linalg.LinAlgError`` when
        the system is not positive definite."""
        from scipy.linalg import cho_solve_banded, cholesky_banded

        ab = self.base.copy()
        self._ties.add(ab, sn2 / np.asarray(cvar, float))
        L = cholesky_banded(ab, lower=True, check_finite=False)
        x = cho_solve_banded((L, True), self.qm(y0), check_finite=False)
        # tr(A^-1 Qm) needs only the diagonal and first sub-diagonal of A^-1 (Qm is tridiagonal)
        d, o = band_inverse_diagonals(L)
        return x, float(self.qd @ d + 2.0 * (self.qo @ o))


def band_inverse_diagonals(L, block=None, offset=1):
    """Diagonal and one sub-diagonal (the first, or ``offset``-th) of ``A^-1`` from the banded
    Cholesky factor ``L`` of ``A``
    (lower band storage ``L[i - j, j]``, as :func:`scipy.linalg.cholesky_banded` gives it).

    Selected inversion by blocks (Takahashi's recursion): a factor of bandwidth ``u`` is block
    lower bidiagonal in blocks of ``b >= u`` frames, and with ``X_i = L_{i+1,i} L_ii^-1`` the
    blocks of ``S = A^-1`` follow from the last one up,
    ``S_{i+1,i} = -S_{i+1,i+1} X_i``, ``S_ii = L_ii^-T L_ii^-1 + X_i' S_{i+1,i+1} X_i``,
    at ``O(n b^2)`` instead of the ``O(n^2 u)`` of solving for all of ``L^-1``.

    Returns ``(diag, sub)``: ``diag[i] = S[i, i]`` (n,), ``sub[i] = S[i + offset, i]``
    (n - offset,).
    Raises ``numpy.linalg.LinAlgError`` for a singular factor.

    >>> from scipy.linalg import cholesky_banded
    >>> rng = np.random.default_rng(0); n = 40
    >>> B = np.triu(np.tril(rng.normal(size=(n, n)), 0), -5)   # bandwidth 5
    >>> A = B @ B.T + n * np.eye(n)
    >>> ab = np.array([np.r_[np.diagonal(A, -k), np.zeros(k)] for k in range(11)])
    >>> d, s = band_inverse_diagonals(cholesky_banded(ab, lower=True), block=7)
    >>> S = np.linalg.inv(A)
    >>> bool(np.allclose(d, np.diagonal(S)) and np.allclose(s, np.diagonal(S, -1)))
    True
    >>> d, s2 = band_inverse_diagonals(cholesky_banded(ab, lower=True), block=7, offset=2)
    >>> bool(np.allclose(s2, np.diagonal(S, -2)))
    True
    """
    from scipy.linalg.lapack import dtrtri

    L = np.asarray(L, float)
    u1, n = L.shape
    o = int(offset)
    b = max(u1 - 1, 16, o) if block is None else max(int(block), u1 - 1, 1, o)
    # dense blocks straight from the band storage (memory n b, not n^2): entry (s + r, s + c) of
    # the factor is L[r - c, s + c] (+ b rows for the block below the diagonal one)
    off = np.arange(2 * b)[:, None] - np.arange(b)[None, :]
    inside = (off >= 0) & (off < u1)
    off = np.where(inside, off, 0)
    col = np.broadcast_to(np.arange(b), off.shape)

    def block_at(s, e):  # rows s .. min(s + 2b, n), columns s .. e of the factor
        rows, w = min(2 * b, n - s), e - s
        return L[off[:rows, :w], s + col[:rows, :w]] * inside[:rows, :w]

    diag, sub = np.empty(n), np.zeros(max(n - o, 0))
    S_next = None
    for s in range(((n - 1) // b) * b, -1, -b):
        e = min(s + b, n)
        D = block_at(s, e)
        Linv, info = dtrtri(D[:e - s], lower=1)
        if info != 0:
            raise np.linalg.LinAlgError("singular band factor")
        S = Linv.T @ Linv
        if S_next is not None:
            X = D[e - s:] @ Linv
            SX = S_next @ X
            S += X.T @ SX
            for i in range(min(o, n - e)):  # S[e + i, e - o + i], across the block boundary
                if e - o + i >= s:
                    sub[e - o + i] = -SX[i, e - o + i - s]
        diag[s:e] = np.diagonal(S)
        sub[s:max(e - o, s)] = np.diagonal(S, -o)
        S_next = S
    return diag, sub


def lower_band(S, min_band=0):
    """A symmetric sparse matrix in lower band storage ``ab[i - j, j] = S[i, j]`` with at least
    ``min_band`` sub-diagonals.

    >>> from scipy import sparse
    >>> S = sparse.diags([[2.0, 2.0, 2.0], [-1.0, -1.0], [-1.0, -1.0]], [0, 1, -1])
    >>> lower_band(S).tolist()
    [[2.0, 2.0, 2.0], [-1.0, -1.0, 0.0]]
    """
    coo = S.tocoo()
    keep = coo.row >= coo.col
    r, c, v = coo.row[keep], coo.col[keep], coo.data[keep]
    u = max(int(np.max(r - c)) if len(r) else 0, int(min_band))
    ab = np.zeros((u + 1, S.shape[0]))
    np.add.at(ab, (r - c, c), v)
    return ab


def _tie_rows(lag):
    """The stride ties ``x_t - x(t + lag_t)`` (linear interpolation) of the frames with a partner
    one stride later, as rows of an operator ``R``: their columns ``(t, k, k + 1)`` and values
    ``(1, -(1 - a), -a)`` (``t + lag_t = k + a``), (m, 3) each, and ``has`` (F,) marking the frames."""
    F = len(lag)
    t = np.arange(F)
    has = np.isfinite(lag) & (t + np.nan_to_num(lag) + 1 < F)
    pos = t[has] + lag[has]
    k = np.floor(pos).astype(int)
    a = pos - k
    return np.column_stack([t[has], k, k + 1]), np.column_stack([np.ones(len(k)), -(1 - a), -a]), has


def _prior_band(ties, cvar, p2_band, min_band=1):
    """The prior precision ``R' diag(1 / cvar) R + P2`` of one joint in lower band storage,
    assembled directly (``ties``: the rows of ``R`` as a :class:`_BandTerm`, from :func:`_tie_rows`;
    ``p2_band``: the smoothness term's band), with as many sub-diagonals as its non-zero entries
    reach (at least ``min_band``).  The same numbers, summed in the same order, as the sparse
    products (:func:`probreg.filtering.banded.lower_band` of them) that it replaces: 17 joints a
    clip and a bootstrap copy's cleaning each, ~0.1 ms instead of ~0.5 ms a joint.

    >>> from scipy import sparse
    >>> from probreg.filtering.periodic import _coupling, _smoothness
    >>> lag = np.full(30, 7.4); cols, vals, _ = _tie_rows(lag); R = _coupling(lag)[0]
    >>> P2 = _smoothness(30, 50.0, 7.0); cvar = np.linspace(0.5, 2.0, len(cols))
    >>> ab = _prior_band(_BandTerm(cols, vals, 30), cvar, lower_band(P2))
    >>> np.array_equal(ab, lower_band(R.T @ sparse.diags(1.0 / cvar) @ R + P2, min_band=1))
    True
    """
    F = p2_band.shape[1]
    ab = np.zeros((max(ties.reach, p2_band.shape[0] - 1) + 1, F))
    if ties.m:
        ties.add(ab, 1.0 / np.asarray(cvar, float))
    ab[:p2_band.shape[0]] += p2_band
    nonzero = np.flatnonzero(np.any(ab != 0, axis=1))
    return ab[:max(int(nonzero[-1]) if len(nonzero) else 0, min_band) + 1]


def _band_matrix(ab):
    """The symmetric sparse matrix of a lower band ``ab`` (the inverse of ``lower_band``)."""
    from scipy import sparse

    F = ab.shape[1]
    lower = [ab[k, :F - k] for k in range(1, len(ab))]
    return sparse.diags([ab[0]] + lower + lower, [0] + [-k for k in range(1, len(ab))] + list(range(1, len(ab))),
                        format="csr")
