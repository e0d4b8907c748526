"""The sampler mixin on a posterior with a known answer: a strongly correlated Gaussian."""

import numpy as np
import pytest

from probreg.inference import SamplerSettings
from probreg.inference.sampling import EmceeSampling


class _Gaussian(EmceeSampling):
    """A 4-D Gaussian with correlation 0.95 between its first two parameters (as camera
    height and stature are correlated in a clip's posterior)."""

    param_names = ["a", "b", "c", "d"]

    def __init__(self):
        self.cov = np.diag([1.0, 4.0, 0.25, 1.0])
        self.cov[0, 1] = self.cov[1, 0] = 0.95 * 2.0
        self.mean = np.array([1.0, -2.0, 0.5, 3.0])
        self.prec = np.linalg.inv(self.cov)
        self.timings = {}

    def log_prob(self, p):
        d = np.atleast_2d(p) - self.mean
        return -0.5 * np.einsum("ni,ij,nj->n", d, self.prec, d)

    def initial_walkers(self, n, rng):
        return self.mean + rng.normal(0, 0.1, (n, 4))


@pytest.mark.parametrize("moves", ["de", "stretch"])
def test_sampler_recovers_known_gaussian(moves):
    model = _Gaussian()
    sampler, tau = model.sample(SamplerSettings(n_walkers=16, burn_in=300, max_steps=6000, chunk=500, seed=3,
                                                moves=moves))
    flat = sampler.get_chain().reshape(-1, 4)
    assert np.allclose(flat.mean(0), model.mean, atol=0.15)
    assert np.allclose(np.cov(flat.T), model.cov, atol=0.35)
    assert np.all(np.isfinite(tau)) and len(flat) >= 50 * np.max(tau)  # stopped by the 50-tau rule
    assert model.timings["sampling_s"] > 0


def test_de_moves_mix_faster_on_correlated_posterior():
    taus = {}
    for moves in ("de", "stretch"):
        model = _Gaussian()
        sampler, _ = model.sample(SamplerSettings(n_walkers=16, burn_in=300, max_steps=3000, chunk=3000, seed=4,
                                                  moves=moves))
        taus[moves] = float(np.max(sampler.get_autocorr_time(tol=0)))
    assert taus["de"] < 0.7 * taus["stretch"]


def test_unknown_moves_are_a_clear_error():
    with pytest.raises(ValueError, match="moves must be one of"):
        SamplerSettings(moves="gibbs")


def test_a_negative_seed_is_a_clear_error():
    """Not NumPy's 'expected non-negative integer' from deep inside the sampler (the Python API;
    the command line, --config and batch manifests name their flag or column)."""
    with pytest.raises(ValueError, match="seed must be a whole number >= 0, got -1"):
        SamplerSettings(seed=-1)
    assert SamplerSettings(seed=0).seed == 0


@pytest.mark.parametrize("field", ["n_draws", "max_steps", "chunk"])
def test_an_empty_budget_is_a_clear_error(field):
    """``--draws 0`` once ran the whole sampler and then failed with "noise_copies is empty"."""
    with pytest.raises(ValueError, match=f"{field} must be at least 1"):
        SamplerSettings(**{field: 0})


class _StoppedAfter(_Gaussian):
    """The Gaussian, with a Ctrl-C arriving inside the log probability at its ``n``-th call."""

    def __init__(self, n):
        super().__init__()
        self.calls, self.n = 0, n

    def log_prob(self, p):
        self.calls += 1
        if self.calls == self.n:
            raise KeyboardInterrupt
        return super().log_prob(p)


@pytest.mark.parametrize("n", [5, 600])  # in the burn-in, and in a later chunk
def test_a_ctrl_c_inside_the_sampler_stops_it_without_emcees_dump(n, capsys):
    """emcee prints every walker and a traceback for an exception inside the log probability;
    a user who pressed Ctrl-C during `probreg run` saw that screenful (0.2.0.dev39)."""
    model = _StoppedAfter(n)
    with pytest.raises(KeyboardInterrupt):
        model.sample(SamplerSettings(n_walkers=16, burn_in=200, chunk=250, max_steps=2000, seed=0))
    out = capsys.readouterr()
    assert "emcee" not in out.out + out.err and "params" not in out.out + out.err
    # the interrupt ends the sampling within emcee's current call: no step evaluates the model again
    assert model.calls == n


def test_a_ctrl_c_inside_the_branch_evidence_stops_it_without_emcees_dump(capsys):
    from probreg.inference.evidence import laplace_log_evidence

    model = _StoppedAfter(50)
    with pytest.raises(KeyboardInterrupt):
        laplace_log_evidence(model, steps=400)
    out = capsys.readouterr()
    assert "emcee" not in out.out + out.err and model.calls == 50
