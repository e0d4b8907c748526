"""Sampling the clip posterior with emcee: the budget, the moves and the stopping rule.

The posterior of a clip (camera height, stature, segment multipliers, the lens) is strongly
correlated: a taller camera goes with a taller athlete.  emcee's default stretch move mixes
slowly there (integrated autocorrelation times of about 100 steps on a typical clip); a mixture
of differential-evolution moves (80 % :class:`emcee.moves.DEMove`, 20 %
:class:`emcee.moves.DESnookerMove`) proposes along the ensemble's own differences and mixed about
2.7 times faster per step on the benchmark suite's ``run_a`` (autocorrelation times 33-42
instead of 96-112 steps, 4,200 steps each; the 5-95 % interval of the camera height agreed
within Monte Carlo noise), so the chain reaches its 50 autocorrelation times in fewer steps.
``SamplerSettings(moves="stretch")`` restores the stretch move.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .priors import SEGMENT_PROPORTIONS

__all__ = ["SamplerSettings", "EmceeSampling", "MOVES", "Interruptible"]

#: the move mixtures ``SamplerSettings.moves`` names
MOVES = ("de", "stretch")


class Interruptible:
    """A log probability for emcee that a Ctrl-C leaves quietly.

    emcee wraps the function and, for any exception raised inside it (``KeyboardInterrupt``
    too), prints every walker's parameters and a traceback before passing it on: a user who
    stops a run saw a screenful of numbers.  Here an interrupt inside ``fn`` sets
    :attr:`interrupted` and every call from then on returns ``-inf`` at once (the steps left in
    emcee's current call reject every proposal in microseconds); :meth:`check`, called after each
    ``run_mcmc``, raises the ``KeyboardInterrupt`` outside emcee.

    >>> def lp(theta):
    ...     raise KeyboardInterrupt
    >>> f = Interruptible(lp)
    >>> f(np.zeros((3, 2))).tolist(), f.interrupted
    ([-inf, -inf, -inf], True)
    >>> try:
    ...     f.check()
    ... except KeyboardInterrupt:
    ...     print("raised here, outside emcee")
    raised here, outside emcee
    """

    def __init__(self, fn):
        self.fn = fn
        self.interrupted = False

    def __call__(self, theta):
        if not self.interrupted:
            try:
                return self.fn(theta)
            except KeyboardInterrupt:
                self.interrupted = True
        return np.full(np.atleast_2d(theta).shape[0], -np.inf)

    def check(self):
        if self.interrupted:
            raise KeyboardInterrupt


@dataclass(frozen=True)
class SamplerSettings:
    """Sampling budget and propagation size.

    ``moves``: ``"de"`` (differential evolution, the default) or ``"stretch"`` (emcee's
    default move).  The chain stops when it is ``tau_multiple`` integrated autocorrelation
    times long (checked every ``chunk`` steps) or after ``max_steps``.  ``n_draws`` posterior
    draws are propagated; ``draws_per_noise_copy`` of them share one re-noised copy of the
    keypoints in the bootstrap (:meth:`probreg.inference.ClipModel.propagate`)."""

    n_walkers: int = 24
    tau_multiple: float = 50.0
    max_steps: int = 8000
    chunk: int = 250
    burn_in: int = 200
    n_draws: int = 60
    bootstrap_noise: bool = True
    draws_per_noise_copy: int = 2
    seed: int = 0
    moves: str = "de"

    def __post_init__(self):
        for name in ("n_draws", "max_steps", "chunk"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if int(self.burn_in) < 0:
            raise ValueError(f"burn_in must be at least 0, got {self.burn_in}")
        if int(self.draws_per_noise_copy) < 1:
            raise ValueError(f"draws_per_noise_copy must be at least 1, got {self.draws_per_noise_copy}")
        if int(self.seed) < 0:
            raise ValueError(f"seed must be a whole number >= 0, got {self.seed}")
        if self.moves not in MOVES:
            raise ValueError(f"moves must be one of {', '.join(MOVES)}, got {self.moves!r}")

    def emcee_moves(self):
        """The moves argument of :class:`emcee.EnsembleSampler` (None: its default)."""
        import emcee

        if self.moves == "stretch":
            return None
        return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]


class EmceeSampling:
    """The sampling half of :class:`probreg.inference.ClipModel` (needs ``param_names``,
    ``log_prob`` (vectorised over walkers), ``_grid_log_prob``, ``seg_obs``, ``grid``, ``lens`` and
    ``timings``)."""

    def initial_walkers(self, n, rng):
        """Walkers around the best grid height with lengths at their observed values."""
        theta_grid, lp = self._grid_log_prob()
        g = int(np.nanargmax(np.where(np.isfinite(lp), lp, -np.inf)))
        base = theta_grid[g]
        # stature from the observed thigh + shank at that height, if available
        obs = [self.seg_obs[s][g] / SEGMENT_PROPORTIONS[s] for s in ("thigh", "shank")]
        obs = float(np.mean([v for v in obs if np.isfinite(v)] or [np.nan]))  # neither seen: NaN, no warning
        if np.isfinite(obs):
            base[1] = obs
        step = np.log(self.grid[1] / self.grid[0]) if len(self.grid) > 1 else 0.05
        scale = np.r_[step, 0.02, np.full(len(SEGMENT_PROPORTIONS), 0.02)]
        if self.lens is not None:  # a sharp prior (a given lens): start at its mean
            k_sd = min(self.lens.prior.sd, 0.002 + 0.01 * abs(base[-1]))
            base[-1] = self.lens.prior.mean if k_sd == self.lens.prior.sd else base[-1]
            scale = np.r_[scale, k_sd]
        p0 = base + rng.normal(0, 1, (n, len(base))) * scale
        # every walker must start where the posterior is positive
        for _ in range(50):
            bad = ~np.isfinite(self.log_prob(p0))
            if not bad.any():
                break
            p0[bad] = base + rng.normal(0, 1, (bad.sum(), len(base))) * scale * 0.5
        return p0

    def sample(self, settings: SamplerSettings = SamplerSettings(), progress=None):
        """Run emcee; returns ``(sampler, tau)``.

        ``progress(desc, total)``, when given, makes a progress bar (``update(n)``, ``close()``)
        that counts the steps (burn-in and the budget; it jumps to the end on convergence)."""
        import emcee

        rng = np.random.default_rng(settings.seed)
        D = len(self.param_names)
        if settings.n_walkers < 2 * D:
            raise ValueError(f"the sampler needs at least {2 * D} walkers for {D} parameters, "
                             f"got {settings.n_walkers}")
        p0 = self.initial_walkers(settings.n_walkers, rng)
        log_prob = Interruptible(self.log_prob)
        sampler = emcee.EnsembleSampler(settings.n_walkers, D, log_prob, vectorize=True,
                                        moves=settings.emcee_moves())
        sampler.random_state = np.random.RandomState(settings.seed).get_state()  # reproducible moves
        t0 = time.perf_counter()
        total = settings.burn_in + settings.max_steps
        bar = progress("sampling", total) if progress is not None else None
        state = sampler.run_mcmc(p0, settings.burn_in, progress=False, skip_initial_state_check=True)
        log_prob.check()
        if bar is not None:
            bar.update(settings.burn_in)
        sampler.reset()
        tau = np.full(D, np.inf)
        steps = 0
        while steps < settings.max_steps:
            state = sampler.run_mcmc(state, settings.chunk, progress=False, skip_initial_state_check=True)
            log_prob.check()
            steps += settings.chunk
            if bar is not None:
                bar.update(settings.chunk)
            tau = sampler.get_autocorr_time(tol=0)
            if np.all(np.isfinite(tau)) and steps >= settings.tau_multiple * np.max(tau):
                break
        if bar is not None:
            bar.update(max(0, total - settings.burn_in - steps))  # converged: the rest of the budget is not needed
            bar.close()
        self.timings["sampling_s"] = time.perf_counter() - t0
        self.sampler = sampler
        return sampler, tau
