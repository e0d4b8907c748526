"""`probreg bench distortion`: the wrong-lens runs and their table (no clip is run here)."""

from probreg.bench.common import BenchReport
from probreg.bench.distortion import _mode_args, _wrong_lens


def test_half_lens_mode_halves_k1_only():
    assert _mode_args("given", [-0.2, 0.01, 0.0, 0.0, 0.0]) == ["--dist=-0.2,0.01,0.0,0.0,0.0"]
    assert _mode_args("given_half", [-0.2, 0.01, 0.0, 0.0, 0.0]) == ["--dist=-0.1,0.01,0.0,0.0,0.0"]


def test_wrong_lens_table_counts_the_verdict_reason():
    hit = {"verdict_reasons": ["given lens contradicts the clip (camera height 7.15 m by it, 5.62 m by the rest; "
                               "32.1 nats)"]}
    res = {("a", "given"): {"verdict_reasons": []}, ("a", "given_half"): hit,
           ("b", "given"): {"verdict_reasons": ["oblique view (40 deg from the side)"]},
           ("b", "given_half"): {"verdict_reasons": []},
           ("c", "given"): {"rc": 1}, ("c", "given_half"): hit,  # a failed run is not counted
           ("d", "inferred"): {"verdict_reasons": []}}  # no half-lens run: not a wide clip
    rep, numbers = BenchReport("distortion", "t"), {}
    _wrong_lens(rep, res, numbers)
    assert numbers["wrong_lens"] == {"true_flagged": [0, 2], "half_flagged": [2, 3]}
    text = rep.to_markdown("cmd")
    assert "| true k1 | 0 of 2 |" in text and "| half the true k1 | 2 of 3 |" in text
    empty = {}
    _wrong_lens(BenchReport("distortion", "t"), {("a", "given"): {}}, empty)
    assert empty == {}
