"""Known answers for the check that the camera height's terms tell one story
(:func:`probreg.inference.heights.term_conflict`) and its tempering in the clip model."""

import numpy as np
import pytest

from probreg.inference import ClipModel, ModelPriors
from probreg.inference.heights import CONFLICT_P, height_terms_note, term_conflict

GRID = np.geomspace(2.0, 40.0, 4001)


def _quad(h0, s):
    """A locally quadratic log-likelihood of log height: peak at ``h0``, sd ``s`` (log)."""
    return -0.5 * (np.log(GRID / h0) / s) ** 2


def test_two_contradicting_terms_give_the_analytic_conflict_and_birge_temper():
    # equal widths: the sum peaks at the geometric mean, each term log(10/6)/2 = 0.2554 from
    # it, 0.5 (0.2554 / 0.03)**2 = 36.2 nats each
    c = term_conflict(GRID, {"a": _quad(6.0, 0.03), "b": _quad(10.0, 0.03)})
    assert c["height_m"] == pytest.approx(np.sqrt(60.0), rel=1e-3)
    assert c["deficits_nats"]["a"] == pytest.approx(36.2, abs=0.1)
    assert c["conflict_nats"] == pytest.approx(72.5, abs=0.2)
    assert c["threshold_nats"] == pytest.approx(0.5 * 10.828, abs=1e-3)  # chi2(1) at 0.999
    assert c["temper"] == pytest.approx(0.5 / c["conflict_nats"])
    assert c["peaks_m"] == pytest.approx({"a": 6.0, "b": 10.0}, rel=1e-3)
    # tempered, twice the conflict is chi-square's mean for one degree of freedom
    t = term_conflict(GRID, {"a": c["temper"] * _quad(6.0, 0.03), "b": c["temper"] * _quad(10.0, 0.03)})
    assert 2 * t["conflict_nats"] == pytest.approx(1.0, rel=1e-3) and t["temper"] == 1.0


def test_terms_that_agree_within_their_widths_are_left_alone():
    c = term_conflict(GRID, {"a": _quad(8.0, 0.05), "b": _quad(8.4, 0.05), "c": _quad(7.7, 0.1)})
    assert c["temper"] == 1.0 and 0 < c["conflict_nats"] < c["threshold_nats"]
    assert c["threshold_nats"] == pytest.approx(0.5 * 13.816, abs=1e-3)  # chi2(2) at 0.999


def test_flat_and_partly_undefined_terms():
    flat = np.zeros(len(GRID))
    half = np.where(GRID < 20.0, _quad(12.0, 0.02), -np.inf)  # no value above 20 m
    c = term_conflict(GRID, {"flat": flat, "a": _quad(6.0, 0.02), "b": half})
    assert set(c["peaks_m"]) == {"a", "b"}  # a flat term measures nothing
    assert c["height_m"] < 20.0 and c["temper"] < 1.0
    # one informative term: nothing to compare
    one = term_conflict(GRID, {"flat": flat, "a": _quad(6.0, 0.02)})
    assert one["temper"] == 1.0 and one["conflict_nats"] == 0.0 and one["peaks_m"] == {}
    assert term_conflict(GRID, {})["temper"] == 1.0


def test_consistent_noisy_terms_are_flagged_at_the_stated_rate():
    """Four terms measuring one height, each with its own sd and its peak scattered by that sd:
    the check fires on about CONFLICT_P of such clips (and never tempers many)."""
    rng = np.random.default_rng(5)
    sds = np.array([0.02, 0.05, 0.08, 0.03])
    fired = 0
    n = 1500
    for _ in range(n):
        peaks = 10.0 * np.exp(rng.normal(0, sds))
        c = term_conflict(GRID, {str(k): _quad(p, s) for k, (p, s) in enumerate(zip(peaks, sds))})
        fired += c["temper"] < 1.0
    # binomial: expect 1.5 of 1500; 8 or more has probability < 1e-4
    assert fired < 8
    # and a real contradiction among the same four is found every time
    c = term_conflict(GRID, {str(k): _quad(p, s) for k, (p, s) in enumerate(zip([6.0, 10, 10, 10], sds))})
    assert c["temper"] < 0.1 and c["peaks_m"]["0"] == pytest.approx(6.0, rel=1e-3)
    assert CONFLICT_P == 1e-3


def _toy_model(static_peak, limbs_peak, sd=0.02):
    """A clip model reduced to its height-only terms on a grid (no limb lengths observed)."""
    from probreg.inference.model import OBSERVED_SEGMENTS

    m = object.__new__(ClipModel)
    m.grid = GRID
    G = len(GRID)
    m.ll_track, m.ll_still = np.zeros(G), np.zeros(G)
    m.ll_static, m.ll_limbs = _quad(static_peak, sd), _quad(limbs_peak, sd)
    m.track_weight, m.lens, m._precompute_id = 0.2, None, 1
    m.priors, m.speed_grid = ModelPriors(), np.full(G, np.nan)
    m.seg_obs = {s: np.full(G, np.nan) for s in OBSERVED_SEGMENTS}
    m.seg_se = dict(m.seg_obs)
    m.height_systematic_sd = 0.0
    m.height_conflict, m.height_temper = term_conflict(GRID, m._height_term_curves()), 1.0
    return m


def _theta(h):
    return np.array([np.r_[np.log(x), 1.8, np.ones(7)] for x in np.atleast_1d(h)])


def test_the_model_tempers_contradicting_terms_once_asked():
    m = _toy_model(6.0, 10.0)
    both = np.sqrt(60.0)
    ll = m.log_likelihood(_theta([both, 10.0]))
    exact = [-0.5 * (np.log(h / 6.0) / 0.02) ** 2 - 0.5 * (np.log(h / 10.0) / 0.02) ** 2 for h in (both, 10.0)]
    assert ll[1] - ll[0] == pytest.approx(exact[1] - exact[0], abs=0.5)  # -326 + 163 nats
    assert m.height_temper == 1.0  # not before the branch is chosen
    w = m.temper_height_terms()
    assert w == pytest.approx(m.height_conflict["temper"]) and w < 0.01
    ll_t = m.log_likelihood(_theta([both, 10.0]))
    assert ll_t[1] - ll_t[0] == pytest.approx(w * (ll[1] - ll[0]), rel=1e-6)
    # terms that agree: nothing changes
    ok = _toy_model(8.0, 8.1)
    before = ok.log_likelihood(_theta([7.0, 8.0, 9.0]))
    assert ok.temper_height_terms() == 1.0
    assert np.array_equal(ok.log_likelihood(_theta([7.0, 8.0, 9.0])), before)


def test_the_note_says_where_each_term_puts_the_camera():
    agree = _toy_model(8.0, 8.1).height_conflict
    split = _toy_model(6.0, 10.0).height_conflict
    assert height_terms_note(split).startswith("camera height terms disagree (static camera 6.00 m, "
                                               "limb consistency 10.00 m; 163.")
    assert agree["temper"] == 1.0 and split["temper"] < 0.01


def test_the_limbs_term_holds_at_most_a_hundred_frames_of_evidence():
    """A clip four times as long measures the same spreads: past
    :data:`probreg.inference.heights.LIMB_EVIDENCE_FRAMES` frames the term is that of a clip of
    that length (its keypoints' bias does not average out); shorter clips are untouched."""
    from probreg.inference.heights import LIMB_EVIDENCE_FRAMES, limb_consistency

    assert LIMB_EVIDENCE_FRAMES == 100
    spread = {"thigh": np.array([0.08, 0.04, 0.05]), "shank": np.array([0.06, 0.05, 0.09])}
    short = limb_consistency(spread, {"thigh": 200, "shank": 200}, frames=100)
    long = limb_consistency(spread, {"thigh": 800, "shank": 800}, frames=400)
    np.testing.assert_allclose(long, short, rtol=1e-12)
    # at or under the cap nothing changes: the held-out and validation clips (40-100 frames)
    np.testing.assert_array_equal(limb_consistency(spread, {"thigh": 140, "shank": 140}, frames=70),
                                  limb_consistency(spread, {"thigh": 140, "shank": 140}))
    # uncapped, the long clip's term is four times as sharp
    sharp = limb_consistency(spread, {"thigh": 800, "shank": 800})
    np.testing.assert_allclose(sharp - sharp[1], 4 * (short - short[1]), rtol=1e-9)
