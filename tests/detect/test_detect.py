"""Pose-model heads on tiny ONNX graphs with known outputs: decoding, letterbox, back-mapping, tracking."""

import json

import cv2
import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from probreg.cli import main  # noqa
from probreg.detect import (
    TopDownPoseModel,
    YoloPoseModel,
    detect_sequence,
    letterbox,
    load_pose_model,
)


def _constant_model(path, input_shape, outputs):
    """An ONNX graph with one image input whose outputs are fixed tensors."""
    inp = helper.make_tensor_value_info("images", TensorProto.FLOAT, list(input_shape))
    nodes, outs = [], []
    for name, arr in outputs.items():
        arr = np.asarray(arr, np.float32)
        nodes.append(helper.make_node("Constant", [], [name], value=numpy_helper.from_array(arr, name + "_v")))
        outs.append(helper.make_tensor_value_info(name, TensorProto.FLOAT, list(arr.shape)))
    graph = helper.make_graph(nodes, "g", [inp], outs)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


def _yolo_output(people):
    """(1, 56, N) tensor from [(cx, cy, w, h, score, kp (17, 3))] in model pixels."""
    out = np.zeros((1, 56, len(people)), np.float32)
    for i, (cx, cy, w, h, s, kp) in enumerate(people):
        out[0, :5, i] = [cx, cy, w, h, s]
        out[0, 5:, i] = np.asarray(kp, np.float32).ravel()
    return out


def test_letterbox_geometry():
    img = np.zeros((720, 1280, 3), np.uint8)
    out, s, pad = letterbox(img, (640, 640))
    assert out.shape == (640, 640, 3) and s == 0.5 and pad == (0.0, 140.0)
    assert out[0, 0, 0] == 114 and out[320, 320, 0] == 0


def test_yolo_decoding_and_back_mapping(tmp_path):
    kp = np.column_stack([np.linspace(300, 340, 17), np.linspace(200, 400, 17), np.full(17, 0.9)])
    people = [(320, 300, 60, 220, 0.9, kp), (322, 301, 58, 218, 0.5, kp + 1),  # duplicate -> NMS
              (100, 300, 40, 100, 0.1, kp)]  # below the threshold
    path = _constant_model(tmp_path / "yolo.onnx", (1, 3, 640, 640), {"output0": _yolo_output(people)})
    model = load_pose_model(path)
    assert isinstance(model, YoloPoseModel)
    dets = model(np.zeros((720, 1280, 3), np.uint8))
    assert len(dets) == 1
    d = dets[0]
    # frame = (model - pad) / scale with scale 0.5, pad (0, 140)
    assert np.allclose(d.keypoints[:, 0], kp[:, 0] / 0.5)
    assert np.allclose(d.keypoints[:, 1], (kp[:, 1] - 140) / 0.5)
    assert np.allclose(d.box, [(320 - 30) / 0.5, (300 - 110 - 140) / 0.5, (320 + 30) / 0.5, (300 + 110 - 140) / 0.5])


def test_yolo_transposed_output_layout(tmp_path):
    kp = np.column_stack([np.full(17, 320.0), np.full(17, 320.0), np.full(17, 0.8)])
    out = _yolo_output([(320, 320, 50, 100, 0.9, kp)]).transpose(0, 2, 1)  # (1, N, 56)
    path = _constant_model(tmp_path / "yolo_t.onnx", (1, 3, 640, 640), {"output0": out})
    d = load_pose_model(path)(np.zeros((640, 640, 3), np.uint8))[0]
    assert np.allclose(d.keypoints[:, :2], 320.0)


def test_simcc_decoding_and_crop_back_mapping(tmp_path):
    # peaks at model-input pixel (96, 128) for every joint, split ratio 2
    sx = np.zeros((1, 17, 384), np.float32)
    sy = np.zeros((1, 17, 512), np.float32)
    sx[0, :, 192] = 1.0
    sy[0, :, 256] = 1.0
    path = _constant_model(tmp_path / "rtm.onnx", (1, 3, 256, 192), {"simcc_x": sx, "simcc_y": sy})
    model = load_pose_model(path)
    assert isinstance(model, TopDownPoseModel) and model.needs_box
    box = np.array([500.0, 300.0, 600.0, 500.0])
    kp = model(np.zeros((720, 1280, 3), np.uint8), box)[0].keypoints
    # the crop centre maps back to the box centre
    assert np.allclose(kp[:, :2], [550.0, 400.0], atol=1e-6)
    assert np.allclose(kp[:, 2], 1.0)
    with pytest.raises(ValueError, match="box"):
        model(np.zeros((10, 10, 3), np.uint8))


def test_heatmap_decoding(tmp_path):
    hm = np.zeros((1, 17, 64, 48), np.float32)
    hm[0, :, 32, 24] = 1.0
    path = _constant_model(tmp_path / "hm.onnx", (1, 3, 256, 192), {"heatmaps": hm})
    model = load_pose_model(path)
    M = model.crop_transform(np.array([0.0, 0.0, 192 / 1.25, 256 / 1.25]))
    kp = model.decode([hm], M)
    # heatmap cell (24, 32) -> input pixel ((24 + 0.5) * 4 - 0.5, (32 + 0.5) * 4 - 0.5)
    x_in, y_in = 24.5 * 4 - 0.5, 32.5 * 4 - 0.5
    back = cv2.invertAffineTransform(M) @ np.array([x_in, y_in, 1.0])
    assert np.allclose(kp[0, :2], back)


def test_unsupported_and_missing_models(tmp_path):
    path = _constant_model(tmp_path / "bad.onnx", (1, 3, 64, 64), {"out": np.zeros((1, 10), np.float32)})
    with pytest.raises(ValueError, match="unsupported"):
        load_pose_model(path)
    with pytest.raises(FileNotFoundError):
        load_pose_model(tmp_path / "none.onnx")


def test_detect_sequence_follows_the_athlete(tmp_path):
    kp_a = np.column_stack([np.full(17, 200.0), np.linspace(250, 350, 17), np.full(17, 0.9)])
    kp_b = np.column_stack([np.full(17, 450.0), np.linspace(250, 350, 17), np.full(17, 0.9)])
    people = [(200, 300, 40, 120, 0.8, kp_a), (450, 300, 80, 200, 0.95, kp_b)]
    path = _constant_model(tmp_path / "y.onnx", (1, 3, 640, 640), {"output0": _yolo_output(people)})
    model = load_pose_model(path)
    frames = [(i, np.zeros((640, 640, 3), np.uint8)) for i in range(3)]
    # a point on the smaller, left athlete picks them, and they are followed
    kp = detect_sequence(frames, model, point=(200, 300))
    assert kp.shape == (3, 17, 3) and np.all(np.isfinite(kp[:, :, 0]))


def test_detect_command_writes_keypoints(tmp_path, small_clip):
    import shutil

    from probreg.io import load_clip

    clip = tmp_path / "clip"
    shutil.copytree(small_clip, clip)
    kp = np.column_stack([np.full(17, 320.0), np.linspace(200, 400, 17), np.full(17, 0.9)])
    path = _constant_model(tmp_path / "y.onnx", (1, 3, 640, 640),
                           {"output0": _yolo_output([(320, 300, 60, 220, 0.9, kp)])})
    out = tmp_path / "kp.json"
    assert main(["detect", str(clip), "--model", str(path), "--out", str(out)]) == 0
    shutil.copyfile(out, clip / "keypoints2d.json")
    got = load_clip(clip).keypoints_px
    assert got.shape == (40, 17, 3) and np.isfinite(got[:, 0, 0]).all()
    sx = np.zeros((1, 17, 384), np.float32)
    sy = np.zeros((1, 17, 512), np.float32)
    rtm = _constant_model(tmp_path / "r.onnx", (1, 3, 256, 192), {"simcc_x": sx, "simcc_y": sy})
    assert main(["detect", str(clip), "--model", str(rtm), "--out", str(tmp_path / "r.json")]) == 2  # needs a box


def test_detect_never_overwrites_keypoints_it_did_not_write(tmp_path, small_clip, capsys):
    """The default output is the clip's own keypoints2d.json: one from another detector (or labelled
    by hand) is refused before the model runs, moved aside with --overwrite, never lost; a file of
    probreg detect's own is replaced."""
    import shutil

    clip = tmp_path / "clip"
    shutil.copytree(small_clip, clip)
    theirs = (clip / "keypoints2d.json").read_bytes()
    kp = np.column_stack([np.full(17, 320.0), np.linspace(200, 400, 17), np.full(17, 0.9)])
    path = _constant_model(tmp_path / "y.onnx", (1, 3, 640, 640),
                           {"output0": _yolo_output([(320, 300, 60, 220, 0.9, kp)])})
    assert main(["detect", str(clip), "--model", str(path)]) == 2
    err = capsys.readouterr().err
    assert "keypoints2d.json: exists and was not written by probreg detect" in err and "Traceback" not in err
    assert (clip / "keypoints2d.json").read_bytes() == theirs
    assert main(["detect", str(clip), "--model", str(path), "--overwrite"]) == 0
    aside = sorted(clip.glob("keypoints2d.json.previous-*"))
    assert len(aside) == 1 and aside[0].read_bytes() == theirs
    ours = json.loads((clip / "keypoints2d.json").read_text())
    assert ours["written_by"] == "probreg detect" and len(ours["frames"]) == 40
    assert main(["detect", str(clip), "--model", str(path)]) == 0  # its own file: replaced
    assert len(list(clip.glob("keypoints2d.json.previous-*"))) == 1
    assert not list(clip.glob(".keypoints2d.json.tmp-*"))


def test_real_model_finds_the_runner_in_paper_frames(shared_data):
    """Optional: the exported yolo11n-pose (``probreg models export-yolo``) finds a runner."""
    from probreg.detect import default_cache_dir

    path = default_cache_dir() / "yolo11n-pose.onnx"
    if not path.exists():
        pytest.skip("no exported YOLO model (optional 'yolo' extra)")
    model = load_pose_model(path)
    found = 0
    frames = sorted((shared_data / "paper_frames").glob("*.jpeg"))
    for p in frames:
        kp = detect_sequence([(0, cv2.imread(str(p)))], model)[0]
        found += int(np.isfinite(kp[:, 0]).sum() >= 10)
    assert found >= len(frames) - 2


def test_export_yolo_refuses_a_file_it_did_not_write(tmp_path, capsys):
    """Checked before anything else (the optional extra need not be installed): a model file of the
    user's at --out is never replaced."""
    mine = tmp_path / "my_model.onnx"
    mine.write_bytes(b"the user's own model")
    assert main(["models", "export-yolo", "--out", str(mine)]) == 2
    err = capsys.readouterr().err
    assert "exists; probreg does not replace a file it did not write" in err and "Traceback" not in err
    assert mine.read_bytes() == b"the user's own model"
