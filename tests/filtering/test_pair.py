"""Left/right pair smoothing: the banded pair system against its dense definition, and known
answers for symmetric and asymmetric runners."""

import numpy as np
import pytest

from probreg.filtering import periodic_smooth_pair, periodic_smooth_series
from probreg.filtering.banded import band_inverse_diagonals
from probreg.filtering.pair import PairSystem


def _interp_rows(F, t, pos, col_offset, n):
    """Dense rows e_t - x(pos) of a 2F-vector (own series at ``t``, partner at ``col_offset``)."""
    r = np.zeros(n)
    k = int(np.floor(pos))
    a = pos - k
    r[t] += 1
    r[col_offset + k] -= 1 - a
    r[col_offset + k + 1] -= a
    return r


@pytest.mark.parametrize("rho,missing", [(0.0, 0.0), (0.5, 0.15)])
def test_pair_system_matches_dense_definition(rho, missing):
    rng = np.random.default_rng(11)
    F = 70
    oks = [rng.random(F) >= missing, rng.random(F) >= missing]
    lag = 16.4 + rng.normal(0, 0.3, F)
    y0s = [np.where(ok, np.sin(np.arange(F) / 3 + s) + rng.normal(0, 0.2, F), 0.0) for s, ok in enumerate(oks)]
    ps = PairSystem(oks, lag, rho, p2_scale=0.7)
    sn2s = [0.3, 0.5]
    cvars = [rng.uniform(0.5, 2.0, int(S.has.sum())) for S in ps.series]
    avar = rng.uniform(0.5, 2.0, len(ps.pair_cols))
    z, edf = ps.solve(y0s, sn2s, cvars, avar)
    # dense: each series' own system (divided by its noise variance) plus the half-stride ties,
    # in block order [left; right]
    A = np.zeros((2 * F, 2 * F))
    b = np.zeros(2 * F)
    Qms = []
    for s, S in enumerate(ps.series):
        # the series' own parts written out: AR(1) data precision, second differences, stride ties
        Qm = np.diag(S.qd) + np.diag(S.qo, 1) + np.diag(S.qo, -1)
        Qms.append(Qm)
        D2 = np.zeros((F - 2, F))
        for t in range(F - 2):
            D2[t, t:t + 3] = [1, -2, 1]
        R = np.zeros((int(S.has.sum()), F))
        for i, (cols, vals) in enumerate(zip(S.tie_cols, S.tie_vals)):
            np.add.at(R[i], cols, vals)
        blk = slice(s * F, (s + 1) * F)
        A[blk, blk] += (Qm + 0.7 * D2.T @ D2) / sn2s[s] + R.T @ np.diag(1 / cvars[s]) @ R
        b[blk] = Qm @ y0s[s] / sn2s[s]
    t = np.arange(F)
    rows = []
    for side, other in ((0, 1), (1, 0)):
        for tt in t:
            pos = tt + lag[tt] / 2
            if pos + 1 < F:
                rows.append(_interp_rows(F, side * F + tt, pos, other * F, 2 * F))
    M = np.array(rows)
    A += M.T @ np.diag(1 / avar) @ M
    ref = np.linalg.solve(A, b)
    assert np.allclose(z[0::2], ref[:F], atol=1e-9) and np.allclose(z[1::2], ref[F:], atol=1e-9)
    Ainv = np.linalg.inv(A)
    for s in range(2):
        blk = slice(s * F, (s + 1) * F)
        assert edf[s] == pytest.approx(np.trace(Ainv[blk, blk] @ Qms[s]) / sn2s[s], rel=1e-9)


def test_band_inverse_sub_diagonal_offsets():
    from scipy.linalg import cholesky_banded

    rng = np.random.default_rng(2)
    n, u = 57, 6
    B = np.triu(np.tril(rng.normal(size=(n, n)), 0), -u)
    A = B @ B.T + n * np.eye(n)
    ab = np.array([np.r_[np.diagonal(A, -k), np.zeros(k)] for k in range(2 * u + 1)])
    S = np.linalg.inv(A)
    for offset in (1, 2, 5):
        d, sub = band_inverse_diagonals(cholesky_banded(ab, lower=True), offset=offset)
        assert np.allclose(d, np.diagonal(S)) and np.allclose(sub, np.diagonal(S, -offset))


def _runner(asym_deg, seed, F=240, T=33.0, noise=6.0):
    """Knee-like series of both sides (deg): the right side is the left's pattern half a stride
    later plus an asymmetry of amplitude ``asym_deg``; returns the frames, the symmetric right
    pattern, both truths, both noisy series and the lag."""
    rng = np.random.default_rng(seed)
    t = np.arange(F)
    phase = 2 * np.pi * t / T

    def pattern(p):
        return 55 + 40 * np.sin(p) + 12 * np.sin(2 * p + 0.4)

    left, sym_right = pattern(phase), pattern(phase + np.pi)
    right = sym_right + asym_deg * np.sin(phase + 1.0)
    return t, sym_right, left, right, left + rng.normal(0, noise, F), right + rng.normal(0, noise, F), np.full(F, T)


def test_symmetric_runner_gains_from_the_other_side():
    _, _, left, right, yl, yr, lag = _runner(0.0, 3)
    (xl, xr), info = periodic_smooth_pair(yl, yr, lag, 50.0)
    alone = [periodic_smooth_series(y, lag, 50.0)[0] for y in (yl, yr)]
    for x, a, truth in ((xl, alone[0], left), (xr, alone[1], right)):
        assert np.sqrt(np.mean((x - truth) ** 2)) < 0.85 * np.sqrt(np.mean((a - truth) ** 2))
    assert info["asym_sd"] == pytest.approx(2.0)  # at the floor
    assert info["noise_sd"][0] == pytest.approx(6.0, rel=0.25)


def test_asymmetric_runner_keeps_its_asymmetry():
    # 15 deg of systematic left/right difference: fitted as such, and the fit must not pull
    # each side towards the other
    _, sym_right, _, right, yl, yr, lag = _runner(15.0, 4)
    (_, xr), info = periodic_smooth_pair(yl, yr, lag, 50.0)
    assert info["asym_systematic_sd"] == pytest.approx(15.0 / np.sqrt(2), rel=0.2)
    alone = periodic_smooth_series(yr, lag, 50.0)[0]
    assert np.sqrt(np.mean((xr - right) ** 2)) < 1.1 * np.sqrt(np.mean((alone - right) ** 2))
    # the asymmetry itself survives: its shape is recovered, not averaged away
    assert np.corrcoef(right - sym_right, xr - sym_right)[0, 1] > 0.8


def test_pair_falls_back_to_each_side_alone():
    *_, yl, yr, lag = _runner(0.0, 5, F=120)
    few = yr.copy()
    few[5:] = np.nan  # fewer than 10 frames on the right
    (xl, _), info = periodic_smooth_pair(yl, few, lag, 50.0)
    assert np.isnan(info["asym_sd"])
    assert np.allclose(xl, periodic_smooth_series(yl, lag, 50.0)[0])
    (xl, _), info = periodic_smooth_pair(yl, yr, None, 50.0)  # no strides: nothing to tie
    assert np.isnan(info["asym_sd"]) and np.array_equal(xl, yl)


def test_a_reused_pair_system_gives_the_result_of_a_fresh_one():
    from probreg.filtering import pair

    rng = np.random.default_rng(4)
    F, T = 150, 30.0
    t = np.arange(F)
    lag = np.full(F, T)
    series = []
    for gap in (False, True, False):  # the second pair has missing frames: another system
        yl = 60 + 40 * np.sin(2 * np.pi * t / T) + rng.normal(0, 4, F)
        yr = 60 + 40 * np.sin(2 * np.pi * (t + T / 2) / T) + rng.normal(0, 4, F)
        if gap:
            yl[20:24] = np.nan
        series.append((yl, yr))
    fresh = []
    for yl, yr in series:
        pair._SYSTEMS.clear()
        fresh.append(periodic_smooth_pair(yl, yr, lag, 50.0))
    pair._SYSTEMS.clear()
    for (yl, yr), (want, info) in zip(series + series, fresh + fresh):
        got, got_info = periodic_smooth_pair(yl, yr, lag, 50.0)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        assert got_info == info
    assert len(pair._SYSTEMS) == 2  # one per distinct set of observed frames
