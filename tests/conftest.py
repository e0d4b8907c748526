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
    from probreg.sim import config_from_preset, synthesize, write_clip

    out = tmp_path_factory.mktemp("clips") / "run"
    clip = synthesize(config_from_preset("distorted", 7, n_frames=40), seed=7, preset="distorted")
    write_clip(clip, out, images=True, jobs=1)
    return out


def _distorted_frame_lanes(cam, n_lines=6, n_pts=200):
    """Sub-pixel support points of lane lines 1..n seen through ``cam`` (with its distortion)."""
    from probreg.lanes.types import FrameLanes, LaneLine, _fit_line

    lines = []
    for k in range(1, n_lines + 1):
        x = np.linspace(cam.C[0] - 80, cam.C[0] + 80, 4000)
        P = np.column_stack([x, np.full_like(x, -1.22 * k), np.zeros_like(x)])
        uv, depth = cam.project(P, return_depth=True)
        # (the ideal projection must be in view too: far outside it a distortion polynomial folds back)
        ideal = cam.with_(dist=np.zeros(5)).project(P)
        ok = (depth > 0) & cam.in_image(uv, margin_px=-5) & cam.in_image(ideal, margin_px=-5)
        uv = uv[ok][np.linspace(0, ok.sum() - 1, n_pts).astype(int)]
        lines.append(LaneLine(line=_fit_line(uv), points_px=uv, rms_px=0.0, index=k - 1))
    l0, l1 = lines[0].line, lines[-1].line
    return FrameLanes(status="ok", lines=tuple(lines), vanishing_point=np.cross(l0, l1), image_size=cam.image_size)


@pytest.fixture
def distorted_lanes():
    """Factory: FrameLanes of lane lines 1..n seen through a (distorting) camera."""
    return _distorted_frame_lanes
