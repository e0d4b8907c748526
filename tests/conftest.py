import os
from pathlib import Path

import numpy as np
import pytest

SHARED = Path(os.environ.get("PROBREG_SHARED_DATA", Path(__file__).resolve().parents[1] / "../shared/data")).resolve()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def shared_data():
    if not SHARED.is_dir():
        pytest.skip("../shared/data not available")
    return SHARED


@pytest.fixture(scope="session")
def small_clip(tmp_path_factory):
    """A 40-frame synthetic clip with images, written once per session."""
    from probreg.synth import config_from_preset, synthesize, write_clip

    out = tmp_path_factory.mktemp("clips") / "run"
    clip = synthesize(config_from_preset("distorted", 7, n_frames=40), seed=7, preset="distorted")
    write_clip(clip, out, images=True, jobs=1)
    return out
