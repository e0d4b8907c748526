"""probreg: 3D running kinematics with honest uncertainty from monocular athletics broadcasts.

Pipeline (one module per stage): frames -> ``lanes`` -> ``calibration`` family ->
``trajectory`` -> ``lifting`` -> ``posterior`` -> kinematics -> ``report``.
The foundation modules are ``camera``, ``track``, ``skeleton``, ``runner``
(gait model), ``render`` and ``synth`` (synthetic broadcast clips).
"""

__version__ = "0.2.0.dev42"

__all__ = ["Camera", "TrackGeometry", "STANDARD_TRACK", "JOINT_NAMES", "ANGLE_NAMES",
           "joint_angles", "__version__"]


def __getattr__(name):
    """The package's names from :mod:`probreg.geometry`, imported when first asked for: importing
    ``probreg`` alone loads no NumPy (the ``probreg`` script sets the process's BLAS threads
    before NumPy loads, :func:`probreg.__main__.one_blas_thread`).

    >>> import probreg
    >>> probreg.JOINT_NAMES[0]
    'pelvis'
    """
    if name in __all__ and name != "__version__":
        from . import geometry

        return getattr(geometry, name)
    raise AttributeError(f"module 'probreg' has no attribute {name!r}")


def __dir__():
    """The package's names, the lazily imported ones included (tab completion in a notebook).

    >>> import probreg
    >>> {"Camera", "joint_angles"} <= set(dir(probreg))
    True
    """
    return sorted(set(globals()) | set(__all__))
