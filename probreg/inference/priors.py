"""Priors of the Bayesian model: camera height, stature, segment proportions.

Each prior is a small object with a vectorised ``logpdf`` and a ``sample``
(one class per distribution); :class:`ModelPriors` bundles the defaults,
every one of which the user can override (command line or ``clip.json``).

Sources
-------
* Camera height of athletics broadcast cameras: no published survey exists;
  the default is weakly informative, log-normal with median 9 m and log-sd 0.8
  (95 % between 1.9 and 43 m, 90 % between 2.4 and 34 m; a 90 % interval of it holds
  88 % of heights spread evenly in log over 2-40 m).  It spans every real
  broadcast position: trackside rail and platform cameras (2-5 m), main-stand
  positions (8-20 m; stands rise about 0.4-0.5 m per row) and the stand roof
  (25-40 m).  Override with the real height when it is known.
* Stature of athletes: normal, mean 1.80 m, sd 0.16 m (95 % between 1.49 and
  2.11 m; its 90 % interval holds 88 % of statures spread evenly over 1.50-2.10 m):
  adult athletes of both sexes from 1.50 to 2.10 m (small sprinters and juniors to
  high jumpers and tall 400 m runners).  A narrower prior (before:
  1.76 +- 0.10 m) let the stature and with it the camera height of tall or short
  athletes be confidently wrong: a clip rarely measures the athlete's scale
  better than this prior (the limb lengths scale with it, and the planted feet
  only weakly), so the prior's width is the interval's width.  Set the athlete's
  measured stature (with a small sd) when known.
* Segment proportions of stature (thigh 0.245, shank 0.246, upper arm
  0.186, forearm 0.146, trunk 0.288, hip-joint separation 0.10, shoulder
  0.207): Drillis & Contini (1966) via Winter (2009), Fig. 4.1; individual
  variation as a normal multiplier with sd 0.04 (segment-to-stature ratios
  vary by a few percent between adults).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Prior", "NormalPrior", "LogNormalPrior", "ModelPriors", "SEGMENT_PROPORTIONS"]


#: Segment length / stature (Drillis & Contini 1966, Winter 2009), keyed like SEGMENT_BONES.
SEGMENT_PROPORTIONS = {
    "thigh": 0.245, "shank": 0.246, "upper_arm": 0.186, "forearm": 0.146,
    "trunk": 0.288, "hip_width": 0.100, "shoulder_width": 0.207,
}

class Prior(ABC):
    """A one-dimensional prior."""

    @abstractmethod
    def logpdf(self, x):
        """Log density, vectorised; ``-inf`` outside the support."""

    @abstractmethod
    def sample(self, rng, size):
        """Draws from the prior."""

    @abstractmethod
    def interval(self, mass=0.9):
        """Central interval holding ``mass``."""

    def centre(self):
        """The prior's median."""
        return float(self.interval(0.0)[0])


@dataclass(frozen=True)
class NormalPrior(Prior):
    """Normal prior.

    >>> p = NormalPrior(1.75, 0.09)
    >>> bool(p.logpdf(1.75) > p.logpdf(1.95))
    True
    """

    mean: float
    sd: float

    def __post_init__(self):
        if not (np.isfinite(self.mean) and self.sd > 0):
            raise ValueError(f"normal prior needs a finite mean and sd > 0, got {self.mean}, {self.sd}")

    def logpdf(self, x):
        x = np.asarray(x, float)
        return -0.5 * ((x - self.mean) / self.sd) ** 2 - np.log(self.sd * np.sqrt(2 * np.pi))

    def sample(self, rng, size):
        return rng.normal(self.mean, self.sd, size)

    def interval(self, mass=0.9):
        from scipy.stats import norm

        z = norm.ppf(0.5 + mass / 2)
        return float(self.mean - z * self.sd), float(self.mean + z * self.sd)


@dataclass(frozen=True)
class LogNormalPrior(Prior):
    """Log-normal prior by its median and log-sd.

    >>> lo, hi = LogNormalPrior(12.0, 0.5).interval(0.9)
    >>> round(lo, 1), round(hi, 1)
    (5.3, 27.3)
    """

    median: float
    log_sd: float

    def __post_init__(self):
        if not (self.median > 0 and self.log_sd > 0):
            raise ValueError(f"log-normal prior needs median > 0 and log-sd > 0, got {self.median}, {self.log_sd}")

    def logpdf(self, x):
        x = np.asarray(x, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            lx = np.log(x)
            out = -0.5 * ((lx - np.log(self.median)) / self.log_sd) ** 2 - lx - np.log(self.log_sd * np.sqrt(2 * np.pi))
        return np.where(x > 0, out, -np.inf)

    def sample(self, rng, size):
        return self.median * np.exp(rng.normal(0, self.log_sd, size))

    def interval(self, mass=0.9):
        from scipy.stats import norm

        z = norm.ppf(0.5 + mass / 2)
        return float(self.median * np.exp(-z * self.log_sd)), float(self.median * np.exp(z * self.log_sd))


@dataclass(frozen=True)
class ModelPriors:
    """Priors of the clip model: camera height, stature, segment-proportion multipliers."""

    camera_height: Prior = field(default_factory=lambda: LogNormalPrior(9.0, 0.8))
    stature: Prior = field(default_factory=lambda: NormalPrior(1.80, 0.16))
    proportion_sd: float = 0.04
    #: the running speed's prior: flat up to ``max_speed_mps``, a half-normal wall beyond
    #: (:meth:`running_speed_logpdf`)
    max_speed_mps: float = 12.5
    speed_wall_sd_mps: float = 0.5

    def running_speed_logpdf(self, speed_mps):
        """Log-density (up to a constant) of the athlete's running speed (m/s): flat up to
        :attr:`max_speed_mps`, 12.5 m/s (the fastest measured sprint speeds are about 12.4 m/s),
        then falling as a half-normal of sd :attr:`speed_wall_sd_mps` (a few per cent of the
        speed: what a clip's ground track measures it to).  A camera height that makes the athlete
        run faster puts them at the wrong scale.  NaN (no track) is not penalised.

        >>> ModelPriors().running_speed_logpdf(np.array([8.0, 13.0, 14.5, np.nan])).tolist()
        [-0.0, -0.5, -8.0, -0.0]
        """
        over = np.maximum(np.nan_to_num(np.asarray(speed_mps, float), nan=0.0) - self.max_speed_mps, 0.0)
        return -0.5 * (over / self.speed_wall_sd_mps) ** 2

    def describe(self):
        """The priors as ``run.json`` records them.

        >>> ModelPriors().describe()["running_speed"]
        'flat up to 12.5 m/s, half-normal of sd 0.5 m/s beyond'
        """
        return {"camera_height": repr(self.camera_height), "stature": repr(self.stature),
                "running_speed": f"flat up to {self.max_speed_mps:g} m/s, half-normal of sd "
                                 f"{self.speed_wall_sd_mps:g} m/s beyond"}

    @classmethod
    def from_options(cls, height=None, height_sd=None, stature=None, stature_sd=None):
        """Defaults with user overrides.

        ``height``/``height_sd``: median and log-sd of the camera height (a known height:
        give a small log-sd such as 0.02); ``stature``/``stature_sd`` in metres.

        Raises
        ------
        ValueError
            For non-positive values, or a stature outside 0.5-3 m (the model has no athlete
            below 0.5 m: a stature of 0, e.g. a missing value, would leave no posterior).

        >>> ModelPriors.from_options(stature=0.0)
        Traceback (most recent call last):
        ...
        ValueError: the athlete's stature must be between 0.5 and 3 m, got 0.0
        """
        if stature is not None and not (np.isfinite(stature) and 0.5 < stature < 3.0):
            raise ValueError(f"the athlete's stature must be between 0.5 and 3 m, got {stature}")
        base = cls()
        ch = base.camera_height
        if height is not None or height_sd is not None:
            ch = LogNormalPrior(height if height is not None else ch.median,
                                height_sd if height_sd is not None else (0.05 if height is not None else ch.log_sd))
        st = base.stature
        if stature is not None or stature_sd is not None:
            st = NormalPrior(stature if stature is not None else st.mean,
                             stature_sd if stature_sd is not None else (0.02 if stature is not None else st.sd))
        return cls(camera_height=ch, stature=st)

    def segment_means(self, stature_m):
        """Prior-mean segment lengths (m) for a stature (array-friendly)."""
        s = np.asarray(stature_m, float)
        return {k: p * s for k, p in SEGMENT_PROPORTIONS.items()}
