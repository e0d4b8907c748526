"""Drawing a frame's lanes and vanishing point (report thumbnails, registration overlays)."""

from __future__ import annotations

import cv2
import numpy as np

from .types import FrameLanes

__all__ = ["draw_lanes"]


def draw_lanes(image_bgr, fl: FrameLanes, color=(255, 0, 255)):
    """Overlay of the detected lines (with their indices) and the vanishing point (if in view)."""
    img = image_bgr.copy()
    h, w = img.shape[:2]
    for ln in fl.lines:
        a, b, c = ln.line
        if abs(b) > abs(a):
            p0 = (0, -c / b)
            p1 = (w - 1, -(c + a * (w - 1)) / b)
        else:
            p0 = (-c / a, 0)
            p1 = (-(c + b * (h - 1)) / a, h - 1)
        if all(np.isfinite(p0 + p1)) and max(map(abs, p0 + p1)) < 1e6:
            cv2.line(img, tuple(int(round(v)) for v in p0), tuple(int(round(v)) for v in p1), color, 2, cv2.LINE_AA)
        e = ln.endpoints_px
        if np.all(np.isfinite(e[1])) and np.max(np.abs(e[1])) < 1e6:
            cv2.putText(img, str(ln.index), tuple(int(v) for v in e[1]), cv2.FONT_HERSHEY_SIMPLEX, 1.0, color, 2)
    vp = fl.vp_px()
    if np.all(np.isfinite(vp)) and -w < vp[0] < 2 * w and -h < vp[1] < 2 * h:
        cv2.circle(img, (int(vp[0]), int(vp[1])), 12, (0, 255, 255), 3)
    label = f"{fl.status}  lines={len(fl.lines)}"
    cv2.putText(img, label, (20, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.2, (0, 255, 255), 2)
    return img
