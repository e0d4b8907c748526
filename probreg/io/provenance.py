"""The software a result was made with, written beside it (``run.json``'s ``"software"``).

A result's numbers depend on more than probreg's own version: OpenCV's image operations feed the
lane lines (0.2.0.dev38: OpenCV 5's phase correlation stopped windowing its inputs in place, and
until the lane tracking windowed them itself, validation clip v08_tele's camera height moved from
4.70 % to 6.18 % off, its knee error from 2.37° to 2.35°), and numpy, SciPy and emcee the sampler.  Every result therefore names
the versions that made it, read from the installed distributions' metadata (no module is
imported for it: ``importlib.metadata`` reads the installed files).
"""

from __future__ import annotations

import platform
from importlib import metadata

__all__ = ["SOFTWARE_DISTRIBUTIONS", "software_versions"]

#: the distributions whose behaviour reaches a result's numbers, as ``run.json`` names them
SOFTWARE_DISTRIBUTIONS = {"numpy": ("numpy",), "scipy": ("scipy",),
                          "opencv": ("opencv-python-headless", "opencv-python", "opencv-contrib-python",
                                     "opencv-contrib-python-headless"),
                          "emcee": ("emcee",), "filterpy": ("filterpy",), "arviz": ("arviz",),
                          "onnxruntime": ("onnxruntime", "onnxruntime-gpu")}


def software_versions():
    """``{"probreg": ..., "python": ..., "numpy": ..., "scipy": ..., "opencv": ..., ...}``: the
    installed versions (None for a distribution that is not installed; for OpenCV the first of its
    wheels that is).

    >>> v = software_versions()
    >>> import numpy; v["numpy"] == numpy.__version__ and v["python"] == platform.python_version()
    True
    """
    from .. import __version__

    out = {"probreg": __version__, "python": platform.python_version()}
    for name, dists in SOFTWARE_DISTRIBUTIONS.items():
        out[name] = None
        for d in dists:
            try:
                out[name] = metadata.version(d)
                break
            except metadata.PackageNotFoundError:
                continue
    return out
