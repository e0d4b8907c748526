"""OpenSim files: known coordinates, round trips, and OpenSim's own adapters when installed."""

import numpy as np
import pytest

from probreg.geometry import JOINT_INDEX, JOINT_NAMES
from probreg.io.clip import ClipFormatError
from probreg.io.opensim import (
    TRC_MARKERS,
    markers_from_joints,
    opensim_to_track,
    read_mot,
    read_trc,
    track_to_opensim,
    write_mot,
    write_trc,
)


def _joints(F=5):
    rng = np.random.default_rng(0)
    j = rng.normal(size=(F, 17, 3))
    j[2] = np.nan  # a frame without a pose
    return j


def test_opensim_frame_has_y_up_x_forward_z_right():
    # the runner moves along +x (track), is upright along +z and has the infield (+y) on the left
    assert track_to_opensim([1, 0, 0]).tolist() == [1, 0, 0]      # forward stays X
    assert track_to_opensim([0, 0, 1]).tolist() == [0, 1, 0]      # up becomes Y
    assert track_to_opensim([0, -1, 0]).tolist() == [0, 0, 1]     # the runner's right becomes +Z
    R = track_to_opensim(np.eye(3)).T
    assert np.isclose(np.linalg.det(R), 1.0)  # a rotation, no mirror: left stays left


def test_trc_round_trip_with_missing_frames(tmp_path):
    j = _joints()
    p = write_trc(tmp_path / "markers.trc", j, fps=50.0)
    names, t, m = read_trc(p)
    assert names == list(TRC_MARKERS) and len(names) == 14
    assert np.allclose(t, np.arange(5) / 50.0)
    assert np.all(np.isnan(m[2]))
    back = opensim_to_track(m)
    for k, name in enumerate(names):
        jj = JOINT_INDEX[TRC_MARKERS[name]]
        assert np.allclose(back[[0, 1, 3, 4], k], j[[0, 1, 3, 4], jj], atol=1e-6)
    head = p.read_text().splitlines()
    assert head[0].startswith("PathFileType\t4\t(X/Y/Z)") and head[2].split("\t")[:5] == ["50", "50", "5", "14", "m"]


def test_marker_mapping_uses_the_h36m_names():
    assert set(TRC_MARKERS.values()) <= set(JOINT_NAMES)
    j = np.zeros((1, 17, 3))
    j[0, JOINT_INDEX["r_knee"]] = [1.0, 2.0, 3.0]
    m = markers_from_joints(j)
    assert m[0, list(TRC_MARKERS).index("RKnee")].tolist() == [1.0, 3.0, -2.0]
    with pytest.raises(ValueError, match="17, 3"):
        markers_from_joints(np.zeros((4, 14, 3)))


def test_mot_round_trip_with_bands(tmp_path):
    med = {"knee_l": np.array([10.0, np.nan, 30.0]), "knee_r": np.array([1.0, 2.0, 3.0])}
    lo = {k: v - 5 for k, v in med.items()}
    hi = {k: v + 5 for k, v in med.items()}
    p = write_mot(tmp_path / "angles.mot", 25.0, med, lo, hi)
    cols, t, data = read_mot(p)
    assert cols == ["knee_l", "knee_l_lo", "knee_l_hi", "knee_r", "knee_r_lo", "knee_r_hi"]
    assert np.allclose(t, [0, 0.04, 0.08])
    assert np.allclose(data[:, 0], med["knee_l"], equal_nan=True) and np.allclose(data[:, 5], hi["knee_r"])
    text = p.read_text()
    assert "inDegrees=yes" in text and "nRows=3" in text and "nColumns=7" in text


def test_readers_name_the_file_on_bad_input(tmp_path):
    bad = tmp_path / "x.trc"
    bad.write_text("hello\n")
    with pytest.raises(ClipFormatError, match="x.trc.*not a TRC"):
        read_trc(bad)
    with pytest.raises(ClipFormatError, match="endheader"):
        read_mot(bad)


def test_opensim_reads_both_files(tmp_path):
    osim = pytest.importorskip("opensim")
    j = _joints()
    write_trc(tmp_path / "markers.trc", j, fps=50.0)
    table = osim.TimeSeriesTableVec3(str(tmp_path / "markers.trc"))  # read by TRCFileAdapter
    assert table.getNumRows() == 5 and table.getNumColumns() == 14
    labels = list(table.getColumnLabels())
    assert labels == list(TRC_MARKERS)
    v = table.getDependentColumn("RKnee")[0]
    assert np.allclose([v[0], v[1], v[2]], track_to_opensim(j[0, JOINT_INDEX["r_knee"]]), atol=1e-6)
    assert np.isnan(table.getDependentColumn("RKnee")[2][0])  # the frame without a pose is missing
    med = {"knee_l": np.array([10.0, 20.0, 30.0, 40.0, 50.0])}
    write_mot(tmp_path / "angles.mot", 50.0, med, {"knee_l": med["knee_l"] - 1}, {"knee_l": med["knee_l"] + 1})
    ts = osim.TimeSeriesTable(str(tmp_path / "angles.mot"))
    assert ts.getNumRows() == 5 and list(ts.getColumnLabels()) == ["knee_l", "knee_l_lo", "knee_l_hi"]
    assert np.isclose(ts.getDependentColumn("knee_l")[2], 30.0)
