"""probreg: 3D running kinematics with honest uncertainty from monocular athletics broadcasts.

Pipeline (one module per stage): frames -> ``lanes`` -> ``calibration`` family ->
``trajectory`` -> ``lifting`` -> ``posterior`` -> kinematics -> ``report``.
The foundation modules are ``camera``, ``track``, ``skeleton``, ``runner``
(gait model), ``render`` and ``synth`` (synthetic broadcast clips).
"""

from .geometry import Camera
from .geometry import ANGLE_NAMES, JOINT_NAMES, joint_angles
from .geometry import STANDARD_TRACK, TrackGeometry

__version__ = "0.2.0.dev29"

__all__ = ["Camera", "TrackGeometry", "STANDARD_TRACK", "JOINT_NAMES", "ANGLE_NAMES",
           "joint_angles", "__version__"]
