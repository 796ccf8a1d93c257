"""The sampler's proposals leave the posterior invariant, even from a poor Laplace approximation,
and the stopping rule is the one promised (R-hat <= 1.01, bulk and tail ESS >= 400)."""

import emcee
import numpy as np
import pytest
from scipy import stats

from vibinverse.estimators.mcmc import ESS_MIN, RHAT_MAX, LaplaceMove, moves, rank_diagnostics


def _sample(log_prob, moves_, ndim, steps, seed):
    rng = np.random.default_rng(seed)
    sampler = emcee.EnsembleSampler(16, ndim, log_prob, moves=moves_)
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(rng.normal(size=(16, ndim)) * 0.1, steps, progress=False)
    return sampler.get_chain(discard=steps // 5, flat=True)


def test_independence_proposals_from_a_wrong_laplace_approximation_sample_the_posterior():
    # a skewed target: x ~ Gamma(3) in log space (z = log x), and y ~ N(0, 1); the proposal is
    # centred off the mode with the wrong scale, so only the MH correction makes it right
    def log_prob(z):  # Gamma(3) density of x = e^z times the Jacobian e^z, and N(0, 1), up to constants
        return 3.0 * z[0] - np.exp(z[0]) - 0.5 * z[1] * z[1]

    move = LaplaceMove(np.array([0.5, 0.3]), np.diag([0.2, 2.0]))
    draws = _sample(log_prob, [(move, 1.0)], 2, 3000, seed=0)
    x = np.exp(draws[:, 0])
    # Gamma(3): mean 3, sd sqrt(3); the flat chain holds ~38 000 draws with tau ~2: sd of the mean < 0.02
    assert x.mean() == pytest.approx(3.0, abs=0.1)
    assert x.std() == pytest.approx(np.sqrt(3.0), rel=0.05)
    assert stats.kstest(draws[::10, 1], "norm").pvalue > 1e-3


def test_the_laplace_move_keeps_a_tiny_variance_beside_a_large_one():
    """Unconstrained sds 1e-7 and 0.3 (a frame's drive frequency and its sensor noise): the
    proposal's sds are SCALE x each, to 1e-9 (a jitter scaled by the trace widened the tiny one
    2-3x, which halved the importance check's effective draws)."""
    move = LaplaceMove(np.zeros(2), np.diag([1e-14, 0.09]))
    sd = np.sqrt(np.diag(move.chol @ move.chol.T))
    assert sd == pytest.approx(LaplaceMove.SCALE * np.array([1e-7, 0.3]), rel=1e-9)


def test_the_laplace_move_joins_the_differential_evolution_moves_only_with_a_covariance():
    assert len(moves()) == 2
    mixed = moves(np.zeros(3), np.eye(3))
    assert len(mixed) == 3 and sum(w for _, w in mixed) == pytest.approx(1.0)
    assert len(moves(np.zeros(3), np.full((3, 3), np.nan))) == 2


def test_rank_diagnostics_flag_chains_that_disagree():
    rng = np.random.default_rng(1)
    good = rng.normal(size=(16, 500, 2))
    rhat, bulk, tail = rank_diagnostics(good)
    assert np.all(rhat <= RHAT_MAX) and np.all(bulk >= ESS_MIN) and np.all(tail >= ESS_MIN)
    bad = good.copy()
    bad[:8, :, 0] += 1.0  # half the walkers one sd away
    assert rank_diagnostics(bad)[0][0] > 1.05
