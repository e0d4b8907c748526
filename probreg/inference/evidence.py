"""Which branch of the calibration family: decided by the evidence of each.

The one-DOF family of a frame (every camera consistent with its lane lines) is a curve on which
the camera height first rises and then falls with the focal length: below its highest point the
*wide* branch (short focal lengths: a camera close by, looking down steeply), above it the
*narrow* branch (long lenses: the usual broadcast camera far away).  Every height below the peak
is reached twice, once on each branch, with different distances, focal lengths and tilts; the lane
lines alone cannot tell the two apart.  The athlete can: on the wrong branch the ground track,
the planted feet and the limb lengths do not fit one camera (a steep camera near the track read
on the narrow branch made a 1.99 m athlete 0.98 m tall and run 33 m/s).

So the branch is a discrete hypothesis like the camera side: the clip model is built for each
branch, the log marginal likelihood of each is estimated, and the larger wins; ``run.json``
reports both and the verdict flags a ratio below 20.  The estimate is a Laplace approximation
around a short emcee run of each branch's posterior::

    log Z ~ max log p(theta, data) + D/2 log(2 pi) + 1/2 log det Cov(theta)

(D parameters, the covariance of the draws): the posterior is close to Gaussian in the model's
parameters (log height, stature, multipliers, k1), and the branches differ by tens to thousands
of nats where they differ at all, far beyond the approximation's error.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

__all__ = ["BranchChoice", "laplace_log_evidence", "BRANCHES"]

#: the branches of the family, in the order they are tried
BRANCHES = ("narrow", "wide")


@dataclass(frozen=True)
class BranchChoice:
    """The family branch of a clip: ``chosen``, ``source`` (``"evidence"``, ``"given"`` or
    ``"only"`` when just one branch has a camera), each branch's ``log_evidence`` (None where it
    could not be built, with the reason in ``errors``)."""

    chosen: str
    source: str
    log_evidence: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)

    @property
    def log_ratio(self):
        """log evidence of the chosen branch over the best other one (inf when no other)."""
        other = [v for k, v in self.log_evidence.items() if k != self.chosen and v is not None]
        mine = self.log_evidence.get(self.chosen)
        if mine is None or not other:
            return float("inf")
        return float(mine - max(other))

    def to_json(self):
        return {"chosen": self.chosen, "source": self.source,
                "log_evidence": {k: (None if v is None else float(v)) for k, v in self.log_evidence.items()},
                "log_ratio": None if not np.isfinite(self.log_ratio) else self.log_ratio,
                "errors": dict(self.errors),
                "method": "Laplace approximation around a short emcee run of each branch's posterior "
                          "(probreg.inference.evidence)"}


def laplace_log_evidence(model, seed=0, n_walkers=24, burn_in=200, steps=400):
    """Laplace estimate of the log marginal likelihood of a clip model (see the module docstring).

    ``model`` needs ``param_names``, ``log_prob`` (vectorised) and ``initial_walkers``; the run
    uses emcee's differential-evolution moves with a fixed seed.  Returns ``(log_z, draws)``,
    the draws (n, D) for inspection.

    >>> class Gauss:  # unnormalised N(0, diag(0.1, 2)^2) times 3: log Z = log(2 pi 0.2) + log 3
    ...     param_names = ["a", "b"]
    ...     def log_prob(self, p):
    ...         p = np.atleast_2d(p)
    ...         return np.log(3.0) - 0.5 * ((p[:, 0] / 0.1) ** 2 + (p[:, 1] / 2.0) ** 2)
    ...     def initial_walkers(self, n, rng):
    ...         return rng.normal(0, 0.05, (n, 2))
    >>> log_z, _ = laplace_log_evidence(Gauss(), steps=2000)
    >>> bool(abs(log_z - (np.log(2 * np.pi * 0.2) + np.log(3.0))) < 0.2)
    True
    """
    import emcee

    from .sampling import Interruptible, SamplerSettings

    D = len(model.param_names)
    rng = np.random.default_rng(seed)
    n_walkers = max(int(n_walkers), 2 * D)
    p0 = model.initial_walkers(n_walkers, rng)
    log_prob = Interruptible(model.log_prob)  # a Ctrl-C without emcee's screenful of walkers
    sampler = emcee.EnsembleSampler(n_walkers, D, log_prob, vectorize=True,
                                    moves=SamplerSettings(moves="de").emcee_moves())
    sampler.random_state = np.random.RandomState(seed).get_state()
    with warnings.catch_warnings():
        # a branch whose cameras cannot explain the clip may leave walkers at -inf: emcee's
        # acceptance test then subtracts infinities (the walker stays; its draws are dropped below)
        warnings.simplefilter("ignore", RuntimeWarning)
        state = sampler.run_mcmc(p0, burn_in, progress=False, skip_initial_state_check=True)
        log_prob.check()
        sampler.reset()
        sampler.run_mcmc(state, steps, progress=False, skip_initial_state_check=True)
        log_prob.check()
    draws = sampler.get_chain().reshape(-1, D)
    lp = sampler.get_log_prob().ravel()
    ok = np.isfinite(lp)
    if ok.sum() < 2 * D:
        return float("-inf"), draws
    cov = np.atleast_2d(np.cov(draws[ok].T))
    sign, logdet = np.linalg.slogdet(cov)
    if sign <= 0:
        logdet = float(np.sum(np.log(np.maximum(np.diag(cov), 1e-300))))
    return float(np.max(lp[ok]) + 0.5 * D * np.log(2 * np.pi) + 0.5 * logdet), draws
