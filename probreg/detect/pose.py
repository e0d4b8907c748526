"""2D human pose from frames with onnxruntime: YOLO-pose and top-down (SimCC / heatmap) heads.

Models are never downloaded: pass a path to an ``.onnx`` file (``probreg
models export-yolo`` writes one from the optional ``yolo`` extra).  Each head is
one small class behind :class:`PoseModel`; :func:`load_pose_model` picks the
class from the model's outputs:

* YOLO-pose: one output ``(1, 56, N)`` (or ``(1, N, 56)``): box ``cx, cy, w,
  h``, person score, 17 COCO keypoints ``(x, y, score)``, in the letterboxed
  input; decoded with non-maximum suppression and mapped back to the frame.
* SimCC (RTMPose): outputs ``(1, 17, Wx)`` and ``(1, 17, Hy)``, split ratio
  ``Wx / input width``; the crop is an affine warp of a box enlarged by 25 %.
* heatmap: one output ``(1, 17, h, w)``; arg-max with a quarter-pixel refinement.

Broadcast athletes are small: the athlete found in the full frame is run
again on an enlarged crop around them, and is followed from frame to frame
(box overlap) rather than re-chosen in every frame.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

__all__ = ["Detection", "PoseModel", "YoloPoseModel", "TopDownPoseModel", "load_pose_model", "letterbox", "detect_sequence"]


_MEAN = np.array([123.675, 116.28, 103.53], np.float32)  # ImageNet RGB mean/std (RTMPose/MMPose)

_STD = np.array([58.395, 57.12, 57.375], np.float32)

@dataclass(frozen=True)
class Detection:
    """One person: ``box`` ``(x0, y0, x1, y1)`` px, ``score``, ``keypoints`` (17, 3) COCO order px."""

    box: np.ndarray
    score: float
    keypoints: np.ndarray


def letterbox(image_bgr, size):
    """Resize keeping the aspect ratio into ``size`` = (w, h), pad with grey (114).

    Returns
    -------
    padded : ndarray (h, w, 3)
    scale : float
    pad : (float, float)
        ``x_model = x_image * scale + pad``.

    >>> img = np.zeros((720, 1280, 3), np.uint8)
    >>> out, s, pad = letterbox(img, (640, 640))
    >>> out.shape, s, pad
    ((640, 640, 3), 0.5, (0.0, 140.0))
    """
    h, w = image_bgr.shape[:2]
    tw, th = size
    s = min(tw / w, th / h)
    nw, nh = int(round(w * s)), int(round(h * s))
    resized = cv2.resize(image_bgr, (nw, nh), interpolation=cv2.INTER_LINEAR)
    px, py = (tw - nw) / 2, (th - nh) / 2
    out = np.full((th, tw, 3), 114, np.uint8)
    x0, y0 = int(np.floor(px)), int(np.floor(py))
    out[y0:y0 + nh, x0:x0 + nw] = resized
    return out, s, (float(x0), float(y0))


class PoseModel(ABC):
    """A 2D pose model: ``__call__(image, box=None) -> list of Detection`` (frame pixels)."""

    needs_box = False

    @abstractmethod
    def __call__(self, image_bgr, box=None):
        """Detections in the frame's pixel coordinates."""


def _session(path):
    import onnxruntime as ort

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: ONNX model not found")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 2
    try:
        return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own exception types
        raise ValueError(f"{path}: not a loadable ONNX model ({exc})") from None


def _input_hw(sess, default=(640, 640)):
    shape = sess.get_inputs()[0].shape
    try:
        return int(shape[2]), int(shape[3])
    except (TypeError, ValueError, IndexError):
        return default


class YoloPoseModel(PoseModel):
    """YOLO-pose ONNX (e.g. exported ``yolo11n-pose``)."""

    def __init__(self, path_or_session, conf=0.25, iou=0.5):
        self.sess = _session(path_or_session) if isinstance(path_or_session, (str, Path)) else path_or_session
        self.h, self.w = _input_hw(self.sess)
        self.conf, self.iou = conf, iou

    def _run(self, image_bgr):
        padded, s, (px, py) = letterbox(image_bgr, (self.w, self.h))
        blob = cv2.cvtColor(padded, cv2.COLOR_BGR2RGB).astype(np.float32).transpose(2, 0, 1)[None] / 255.0
        out = self.sess.run(None, {self.sess.get_inputs()[0].name: blob})[0]
        return self.decode(out, s, (px, py))

    def decode(self, raw, scale, pad):
        """Raw output (1, 56, N) or (1, N, 56) -> detections in frame pixels (after NMS)."""
        a = np.asarray(raw, np.float32)[0]
        if a.shape[0] != 56 and a.shape[-1] == 56:
            a = a.T
        if a.shape[0] != 56:
            raise ValueError(f"YOLO-pose output must have 56 channels, got shape {np.shape(raw)}")
        score = a[4]
        keep = score >= self.conf
        a, score = a[:, keep], score[keep]
        if a.shape[1] == 0:
            return []
        cx, cy, bw, bh = a[:4]
        boxes = np.stack([cx - bw / 2, cy - bh / 2, bw, bh], -1)
        idx = cv2.dnn.NMSBoxes(boxes.tolist(), score.tolist(), self.conf, self.iou)
        idx = np.array(idx).reshape(-1)
        dets = []
        px, py = pad
        for i in idx:
            kp = a[5:, i].reshape(17, 3).copy()
            kp[:, 0] = (kp[:, 0] - px) / scale
            kp[:, 1] = (kp[:, 1] - py) / scale
            x0, y0, w_, h_ = boxes[i]
            box = np.array([(x0 - px) / scale, (y0 - py) / scale, (x0 + w_ - px) / scale, (y0 + h_ - py) / scale])
            dets.append(Detection(box=box, score=float(score[i]), keypoints=kp))
        return sorted(dets, key=lambda d: -d.score)

    def __call__(self, image_bgr, box=None):
        if box is None:
            return self._run(image_bgr)
        # run again on an enlarged crop around the athlete (small people in broadcast frames)
        x0, y0, x1, y1 = _enlarge(box, 2.0, image_bgr.shape)
        crop = image_bgr[y0:y1, x0:x1]
        if crop.size == 0:
            return []
        dets = self._run(crop)
        return [Detection(box=d.box + [x0, y0, x0, y0], score=d.score,
                          keypoints=d.keypoints + [x0, y0, 0]) for d in dets]


def _enlarge(box, factor, shape):
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    half = max(box[2] - box[0], box[3] - box[1]) * factor / 2
    h, w = shape[:2]
    return (int(max(0, cx - half)), int(max(0, cy - half)), int(min(w, cx + half)), int(min(h, cy + half)))


class TopDownPoseModel(PoseModel):
    """Top-down model (RTMPose-style SimCC, or heatmap) on a person box."""

    needs_box = True

    def __init__(self, path_or_session, padding=1.25):
        self.sess = _session(path_or_session) if isinstance(path_or_session, (str, Path)) else path_or_session
        self.h, self.w = _input_hw(self.sess, default=(256, 192))
        self.padding = padding

    def crop_transform(self, box):
        """2x3 affine from frame pixels to the model input for a box (aspect kept, padded)."""
        cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
        bw, bh = (box[2] - box[0]) * self.padding, (box[3] - box[1]) * self.padding
        aspect = self.w / self.h
        if bw / max(bh, 1e-6) > aspect:
            bh = bw / aspect
        else:
            bw = bh * aspect
        s = self.w / bw
        return np.array([[s, 0, self.w / 2 - s * cx], [0, s, self.h / 2 - s * cy]], np.float64)

    def decode(self, outputs, M):
        """Model outputs -> (17, 3) keypoints in frame pixels (``M`` the crop transform)."""
        if len(outputs) == 2:  # SimCC
            sx, sy = (np.asarray(o, np.float32)[0] for o in outputs)
            ratio_x, ratio_y = sx.shape[-1] / self.w, sy.shape[-1] / self.h
            ix, iy = sx.argmax(-1), sy.argmax(-1)
            x = ix / ratio_x
            y = iy / ratio_y
            score = np.minimum(sx.max(-1), sy.max(-1))
        else:  # heatmap (1, 17, h, w)
            hm = np.asarray(outputs[0], np.float32)[0]
            k, hh, ww = hm.shape
            flat = hm.reshape(k, -1)
            idx = flat.argmax(-1)
            y, x = np.divmod(idx, ww)
            x, y = x.astype(float), y.astype(float)
            for j in range(k):  # quarter-pixel shift towards the larger neighbour
                xi, yi = int(x[j]), int(y[j])
                if 0 < xi < ww - 1:
                    x[j] += 0.25 * np.sign(hm[j, yi, xi + 1] - hm[j, yi, xi - 1])
                if 0 < yi < hh - 1:
                    y[j] += 0.25 * np.sign(hm[j, yi + 1, xi] - hm[j, yi - 1, xi])
            score = flat.max(-1)
            x = (x + 0.5) * self.w / ww - 0.5
            y = (y + 0.5) * self.h / hh - 0.5
        Minv = cv2.invertAffineTransform(M)
        pts = np.stack([x, y, np.ones_like(x)], -1) @ Minv.T
        return np.column_stack([pts, score])

    def __call__(self, image_bgr, box=None):
        if box is None:
            raise ValueError("a top-down pose model needs a person box (give --box or a detector model)")
        M = self.crop_transform(np.asarray(box, float))
        crop = cv2.warpAffine(image_bgr, M, (self.w, self.h), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
        rgb = cv2.cvtColor(crop, cv2.COLOR_BGR2RGB).astype(np.float32)
        blob = ((rgb - _MEAN) / _STD).transpose(2, 0, 1)[None]
        outs = self.sess.run(None, {self.sess.get_inputs()[0].name: blob})
        kp = self.decode(outs, M)
        return [Detection(box=np.asarray(box, float), score=float(np.mean(kp[:, 2])), keypoints=kp)]


def load_pose_model(path):
    """Open an ONNX pose model and pick its head from the outputs.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the outputs match no supported head.
    """
    sess = _session(path)
    outs = sess.get_outputs()
    shapes = [o.shape for o in outs]
    if len(outs) == 1 and len(shapes[0]) == 3 and 56 in (shapes[0][1], shapes[0][2]):
        return YoloPoseModel(sess)
    if len(outs) == 2 and all(len(s) == 3 for s in shapes):
        return TopDownPoseModel(sess)
    if len(outs) == 1 and len(shapes[0]) == 4:
        return TopDownPoseModel(sess)
    raise ValueError(f"{path}: unsupported pose-model outputs {shapes} "
                     f"(YOLO-pose (1, 56, N), SimCC (1, 17, W) + (1, 17, H), heatmap (1, 17, h, w))")


def _iou(a, b):
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[2], b[2]), min(a[3], b[3])
    inter = max(0.0, x1 - x0) * max(0.0, y1 - y0)
    area = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / area if area > 0 else 0.0


def _choose(dets, prev_box, image_shape, point=None):
    if not dets:
        return None
    if prev_box is not None:
        return max(dets, key=lambda d: _iou(d.box, prev_box) - 1e-4 * np.linalg.norm(
            (d.box[:2] + d.box[2:]) / 2 - (prev_box[:2] + prev_box[2:]) / 2))
    if point is not None:
        inside = [d for d in dets if d.box[0] <= point[0] <= d.box[2] and d.box[1] <= point[1] <= d.box[3]]
        if inside:
            return max(inside, key=lambda d: d.score)
    h, w = image_shape[:2]
    centre = np.array([w / 2, h / 2])
    # default athlete: large and central
    return max(dets, key=lambda d: (d.box[2] - d.box[0]) * (d.box[3] - d.box[1]) /
               (1 + np.linalg.norm((d.box[:2] + d.box[2:]) / 2 - centre) / max(w, h)))


def detect_sequence(frames, model: PoseModel, detector: PoseModel | None = None, box=None, point=None,
                    min_score=0.3):
    """COCO-17 keypoints (F, 17, 3) of the followed athlete over frames ``(index, image)``.

    With a YOLO model the athlete is detected on the full frame, then refined on an
    enlarged crop; with a top-down model the box comes from ``detector``, from
    ``box`` (first frame), or from the previous frame's keypoints.
    """
    out = []
    prev_box = None if box is None else np.asarray(box, float)
    for _, img in frames:
        kp = np.full((17, 3), np.nan)
        if img is not None:
            if model.needs_box:
                b = prev_box
                if detector is not None:
                    d = _choose(detector(img), prev_box, img.shape, point)
                    b = d.box if d is not None else prev_box
                dets = model(img, b) if b is not None else []
            else:
                full = model(img)
                d = _choose(full, prev_box, img.shape, point)
                dets = model(img, d.box) if d is not None else []
                dets = [_choose(dets, d.box, img.shape)] if dets else ([d] if d is not None else [])
            if dets and dets[0] is not None:
                kp = dets[0].keypoints.copy()
                ok = np.isfinite(kp[:, 0]) & (kp[:, 2] >= min_score)
                if ok.sum() >= 4:
                    lo, hi = kp[ok, :2].min(0), kp[ok, :2].max(0)
                    pad = 0.1 * (hi - lo)
                    prev_box = np.r_[lo - pad, hi + pad]
                kp[kp[:, 2] < min_score] = np.nan
        out.append(kp)
    return np.stack(out) if out else np.zeros((0, 17, 3))
