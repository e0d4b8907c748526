"""``probreg bench race``: a generated clip's race version is the same clip with other runners."""

import json

import numpy as np
import pytest

from probreg.bench.race import race_clip
from probreg.io import load_clip
from probreg.sim.heldout import write_heldout


def test_the_race_version_keeps_the_athlete_keypoints_and_cameras_and_adds_the_field(tmp_path):
    (alone,) = write_heldout(tmp_path / "tuning", n_frames=4, seeds=[8103], label="tuning", jobs=1)
    race = race_clip(alone, tmp_path / "race", rivals=2, jobs=1)
    a, r = load_clip(alone), load_clip(race)
    assert np.array_equal(a.keypoints_px, r.keypoints_px, equal_nan=True) and a.image_size == r.image_size
    assert (json.loads((alone / "groundtruth" / "cameras.json").read_text())
            == json.loads((race / "groundtruth" / "cameras.json").read_text()))
    meta = json.loads((race / "clip.json").read_text())["generator"]
    assert meta["rivals"] == 2 and meta["seed"] == 8103 and meta["preset"].startswith("tuning:")
    assert len(json.loads((race / "groundtruth" / "rivals.json").read_text())["rivals"]) == 2
    stamp = (race / "clip.json").stat().st_mtime_ns
    assert race_clip(alone, tmp_path / "race", rivals=2) == race and (race / "clip.json").stat().st_mtime_ns == stamp


def test_a_clip_of_another_generator_preset_is_refused(tmp_path):
    """Only the held-out generator's clips can be rebuilt from their seed; another preset's would
    come back as a different clip."""
    from probreg.sim import config_from_preset, synthesize, write_clip

    other = write_clip(synthesize(config_from_preset("run", 8103, n_frames=4), seed=8103, preset="run"),
                       tmp_path / "run", images=False)
    with pytest.raises(ValueError, match="not a clip of probreg.sim.heldout"):
        race_clip(other, tmp_path / "race")
