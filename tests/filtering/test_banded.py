"""The banded series system against the same system written out densely from its definition."""

import numpy as np
import pytest
from scipy import sparse

from probreg.filtering import periodic_smooth_series
from probreg.filtering.banded import SeriesSystem, band_inverse_diagonals, lower_band


def _dense_reference(ok, lag, rho, p2_scale, y0, sn2, cvar):
    """A = Qm + sn2 R' diag(1/cvar) R + p2 D2'D2 as dense matrices; x = A^-1 Qm y0, edf = tr(A^-1 Qm)."""
    F = len(ok)
    Q = np.zeros((F, F))
    for t in range(F):
        Q[t, t] = 1 + rho**2 if 0 < t < F - 1 else 1.0
        if t + 1 < F:
            Q[t, t + 1] = Q[t + 1, t] = -rho
    Q /= 1 - rho**2
    M = np.diag(ok.astype(float))
    Qm = M @ Q @ M
    rows = []
    for t in range(F):
        if np.isfinite(lag[t]) and t + lag[t] + 1 < F:
            k = int(np.floor(t + lag[t]))
            a = t + lag[t] - k
            r = np.zeros(F)
            r[t] += 1
            r[k] -= 1 - a
            r[k + 1] -= a
            rows.append(r)
    R = np.array(rows)
    D2 = np.zeros((F - 2, F))
    for t in range(F - 2):
        D2[t, t:t + 3] = [1, -2, 1]
    A = Qm + sn2 * R.T @ np.diag(1 / cvar) @ R + p2_scale * D2.T @ D2
    return np.linalg.solve(A, Qm @ y0), float(np.trace(np.linalg.solve(A, Qm)))


@pytest.mark.parametrize("rho,missing", [(0.0, 0.0), (0.6, 0.1), (0.9, 0.3)])
def test_series_system_matches_dense_definition(rho, missing):
    rng = np.random.default_rng(int(rho * 10))
    F = 90
    ok = rng.random(F) >= missing
    lag = 17.3 + rng.normal(0, 0.4, F)
    lag[rng.random(F) < 0.05] = np.nan
    y0 = np.where(ok, np.sin(np.arange(F) / 3) + rng.normal(0, 0.2, F), 0.0)
    system = SeriesSystem(ok, lag, rho, p2_scale=0.7)
    cvar = rng.uniform(0.5, 2.0, int(system.has.sum()))
    x, edf = system.solve(y0, 0.3, cvar)
    x_ref, edf_ref = _dense_reference(ok, lag, rho, 0.7, y0, 0.3, cvar)
    assert np.allclose(x, x_ref, atol=1e-9)
    assert edf == pytest.approx(edf_ref, rel=1e-9)
    assert 2 < edf < ok.sum()  # a smoother: fewer degrees of freedom than data, more than a line


def test_lower_band_round_trip():
    rng = np.random.default_rng(1)
    B = rng.normal(size=(30, 30))
    A = B + B.T
    A[np.abs(np.subtract.outer(np.arange(30), np.arange(30))) > 4] = 0
    ab = lower_band(sparse.csr_matrix(A))
    assert ab.shape == (5, 30)
    back = np.zeros_like(A)
    for d in range(5):
        idx = np.arange(30 - d)
        back[idx + d, idx] = back[idx, idx + d] = ab[d, :30 - d]
    assert np.allclose(back, A)


@pytest.mark.parametrize("lags", ["varying", "none", "some missing"])
def test_prior_band_is_the_sparse_prior_to_the_bit(lags):
    """The keypoint smoother's per-joint prior assembled in band storage must be, bit for bit, the
    band of the sparse ``R' diag(1/cvar) R + P2`` it replaced (the cleaning's results depend on it
    to the last bit), for stride lags that vary, that are all missing or partly missing."""
    from probreg.filtering.banded import _band_matrix, _BandTerm, _prior_band, _tie_rows
    from probreg.filtering.periodic import _coupling, _smoothness

    rng = np.random.default_rng(3)
    F = 200
    lag = 20 + 3 * np.sin(np.arange(F) / 15) + rng.normal(0, 0.3, F)
    if lags == "none":
        lag[:] = np.nan
    elif lags == "some missing":
        lag[rng.random(F) < 0.2] = np.nan
    cols, vals, has = _tie_rows(lag)
    R, has_r = _coupling(lag)
    assert np.array_equal(has, has_r) and len(cols) == R.shape[0] == has.sum()
    cvar = rng.uniform(0.1, 3.0, len(cols))
    P2 = _smoothness(F, 50.0, 7.0) * 3.7
    ab = _prior_band(_BandTerm(cols, vals, F), cvar, lower_band(P2))
    assert np.array_equal(ab, lower_band(R.T @ sparse.diags(1.0 / cvar) @ R + P2, min_band=1))
    assert ab.shape[0] - 1 == (2 if lags == "none" else int(np.max(cols[:, 2] - cols[:, 0])))
    # and back to a sparse matrix (the solver's fallback) without loss
    assert abs(_band_matrix(ab) - (R.T @ sparse.diags(1.0 / cvar) @ R + P2)).max() < 1e-12


def test_column_filters_equal_scipys_filters_column_by_column():
    """``hampel_columns`` and ``butterworth_columns`` against SciPy's own 1-D filters applied to each
    column (NaN runs bridged linearly for filtering and restored; too-short columns left alone)."""
    from scipy.ndimage import median_filter
    from scipy.signal import butter, filtfilt

    from probreg.filtering import butterworth_columns, hampel_columns

    rng = np.random.default_rng(4)
    F = 120
    X = np.cumsum(rng.normal(0, 1, (F, 5)), axis=0)
    X[rng.random((F, 5)) < 0.1] = np.nan
    X[::17, 1] += 40.0  # outliers
    X[:, 4] = np.nan
    X[3, 4] = 1.0  # one sample only: too short for either filter
    t = np.arange(F)
    H, B = hampel_columns(X, 4, 3.0, min_scale=1.0), butterworth_columns(X, 50.0, 6.0)
    b, a = butter(2, 6.0 / 25.0)
    for k in range(5):
        ok = np.isfinite(X[:, k])
        if ok.sum() < 12:
            assert np.array_equal(H[:, k], X[:, k], equal_nan=True) and np.array_equal(B[:, k], X[:, k], equal_nan=True)
            continue
        xi = np.interp(t, t[ok], X[ok, k])
        med = median_filter(xi, size=9, mode="nearest")
        mad = 1.4826 * median_filter(np.abs(xi - med), size=9, mode="nearest")
        ref = np.where(np.abs(xi - med) > 3.0 * np.maximum(mad, 1.0), np.nan, X[:, k])
        assert np.array_equal(H[:, k], ref, equal_nan=True)
        assert np.array_equal(B[:, k], np.where(ok, filtfilt(b, a, xi, padlen=9), np.nan), equal_nan=True)
    assert np.isnan(H[:, 1]).sum() >= np.isnan(X[:, 1]).sum() + 3  # the data have outliers, and they are out


def test_series_smoother_reduces_noise_with_gaps():
    rng = np.random.default_rng(5)
    t = np.arange(400)
    truth = 60 + 40 * np.sin(2 * np.pi * t / 31.0)
    y = truth + rng.normal(0, 4, 400)
    y[50:58] = np.nan
    x, info = periodic_smooth_series(y, np.full(400, 31.0), 50.0, rho=0.3)
    assert np.sqrt(np.mean((x - truth) ** 2)) < 0.5 * 4
    assert info["noise_sd"] == pytest.approx(4, rel=0.25)
    assert np.all(np.isfinite(x[50:58]))  # the gap is filled from the neighbouring strides


@pytest.mark.parametrize("n, u, block", [(1, 0, None), (1, 3, None), (2, 2, None), (5, 7, None), (17, 16, None),
                                         (33, 16, None), (200, 40, None), (250, 35, 35), (250, 35, 90)])
def test_band_inverse_diagonals_match_the_dense_inverse(n, u, block):
    """The selected inversion's diagonal and first sub-diagonal equal those of the dense inverse,
    for systems shorter than one block, of exactly a few blocks and of a ragged last block."""
    from scipy.linalg import cholesky_banded

    rng = np.random.default_rng(n + u)
    w = min(u, n - 1)
    B = np.triu(np.tril(rng.normal(size=(n, n)), 0), -w)
    A = B @ B.T + n * np.eye(n)
    ab = np.zeros((u + 1, n))
    for k in range(w + 1):
        ab[k, :n - k] = np.diagonal(A, -k)
    d, s = band_inverse_diagonals(cholesky_banded(ab, lower=True), block=block)
    S = np.linalg.inv(A)
    assert d.shape == (n,) and s.shape == (max(n - 1, 0),)
    np.testing.assert_allclose(d, np.diagonal(S), rtol=1e-10)
    np.testing.assert_allclose(s, np.diagonal(S, -1), rtol=1e-9, atol=1e-14)
