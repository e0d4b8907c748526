"""2D pose of the athlete with ONNX models run by ``onnxruntime`` (YOLO-pose, top-down SimCC or
heatmap heads), and the offline export of a packaged model.  Models come from a path the user
gives or an installed package; nothing is downloaded.
"""

from .models import default_cache_dir, export_yolo
from .pose import (
    Detection,
    PoseModel,
    TopDownPoseModel,
    YoloPoseModel,
    detect_sequence,
    letterbox,
    load_pose_model,
)

__all__ = [
    "Detection", "PoseModel", "YoloPoseModel", "TopDownPoseModel", "load_pose_model", "letterbox",
    "detect_sequence", "export_yolo", "default_cache_dir",
]
