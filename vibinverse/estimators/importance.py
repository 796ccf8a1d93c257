"""The Laplace approximation checked, and corrected, by Pareto-smoothed importance sampling (PSIS;
Vehtari et al. 2024, `arviz.psislw`): the sampler's stage for long records.

Draws of the MAP stage's Laplace approximation, heavier-tailed (the multivariate t of the sampler's
independence move, `mcmc.LaplaceMove`) and split (Geweke 1989: each axis of the Laplace covariance
gets its own scale on either side of the MAP, measured on the posterior by `split_scales`), are
weighted by posterior / proposal. The split matters where a prior cuts the posterior: the sensor
noise of a record without any has a posterior flat in log sigma down to its prior's lower bound,
in the unconstrained coordinate a cliff above the MAP and an exponential tail below it that
reaches 5-10 Laplace sds (a 5-minute frame record: Pareto k 0.79 and 128 effective draws of 2000
with the symmetric t, 0.21 and 636 split; a one-hour one: k 11.7 and 15 before). The Pareto shape
k of the largest weights says whether the weights can be trusted (k < KHAT_MAX; Vehtari et al.:
above 0.7 the error of an importance estimate falls too slowly to rely on), and their effective
number (1 / sum w^2, Kish) must reach the sampler's ESS_MIN. Where k passes and the effective
number falls short, the effective fraction is the proposal's, so more draws of it reach ESS_MIN:
up to MAX_DRAWS_FACTOR times those asked for, i.e. where the first ones are at least ~10 %
effective (below that the proposal misses the posterior's shape: a second mode it reaches only in
its tail). The first FIRST_DRAWS (500) are weighed first: where under a quarter of that 10 % are
effective, the rest are not weighed and the check fails at once (the LIGO strain's 32 s: 33
effective of 2000, ~10 s of likelihoods spent to learn it). Of 160 draws of
examples/modal_calibration.py 18 had gone to emcee (the 8 among the first 60 each with k < 0.7
and 313-399 effective draws of 2000); topped up, 159 pass, with the same coverage. Then the
draws resampled by their smoothed weights are the posterior draws: each
call is independent, so N draws cost N likelihood calls (2000 on a one-hour record at 200 Hz:
~20-40 s), where emcee's walkers need thousands of dependent steps (on that record without
sensor noise, sigma's skewed posterior held emcee's acceptance at 14 % and its autocorrelation
time at ~40 steps: over 30 minutes). When the check fails, Unsupported says why, and the pipeline
samples with emcee.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from vibinverse.errors import Unsupported
from vibinverse.estimators.base import Estimator, base_result, register_estimator
from vibinverse.estimators.mcmc import ESS_MIN, split_laplace
from vibinverse.inference_data import psislw
from vibinverse.parallel import thread_map
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

IMPORTANCE_DRAWS = 2000
KHAT_MAX = 0.7
#: at most this many times the draws asked for, drawn when the weights pass the Pareto check but
#: their effective number falls short of ESS_MIN
MAX_DRAWS_FACTOR = 2
#: the draws weighed first (`LaplaceImportance`): when their effective fraction is below HOPELESS of
#: the fraction that could pass (ESS_MIN of the cap), the rest are not weighed
FIRST_DRAWS = 500
HOPELESS = 0.25


def psis_weights(log_w: np.ndarray) -> tuple[float, np.ndarray, float]:
    """(Pareto k, normalized smoothed weights, their effective number 1 / sum w^2) of log weights
    (non-finite ones count as 0); k is inf when no weight is finite."""
    if not np.any(np.isfinite(log_w)):
        raise Unsupported("no draw of the Laplace approximation has a finite posterior")
    log_w = np.where(np.isfinite(log_w), log_w, -np.inf)
    smoothed, khat = psislw(log_w - np.max(log_w))
    weights = np.exp(smoothed - np.max(smoothed))
    weights /= weights.sum()
    return float(khat), weights, float(1.0 / np.sum(weights**2))


def log_posteriors(posterior: Posterior, zs: np.ndarray, workers: int = 1) -> np.ndarray:
    """The log posterior at each row of zs; `workers` threads where the model releases the GIL."""
    threads = workers if posterior.model.releases_gil else 1
    return np.array(thread_map(posterior.log_posterior, zs, threads, "vibinverse-importance"))


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices of len(weights) draws resampled by their normalized weights (systematic resampling:
    each draw kept floor(n w) or ceil(n w) times)."""
    n = weights.size
    positions = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(weights), positions), n - 1)


@register_estimator
class LaplaceImportance(Estimator):
    """PSIS-weighted draws of the MAP's Laplace approximation, resampled (see the module)."""

    name = "importance"
    approximation = "importance"

    def estimate(
        self,
        posterior: Posterior,
        start: FitResult | None,
        *,
        seed: int = 0,
        workers: int = 1,
        draws: int = IMPORTANCE_DRAWS,
        **options: Any,
    ) -> FitResult:
        if start is None or start.z is None or start.cov_z is None or not np.all(np.isfinite(start.cov_z)):
            raise Unsupported("importance sampling needs a MAP with its Laplace covariance")
        try:
            proposal = split_laplace(lambda zs: log_posteriors(posterior, zs, workers), start.z, start.cov_z)
        except np.linalg.LinAlgError as exc:
            raise Unsupported("the Laplace covariance is not positive definite") from exc
        scales = proposal.scales
        logger.debug("importance sampling: split-t scales %s", np.round(scales, 2).tolist())
        rng = np.random.default_rng(seed)
        zs = proposal.draw(draws, rng)
        cap = MAX_DRAWS_FACTOR * draws
        first = min(FIRST_DRAWS, draws)
        log_w = log_posteriors(posterior, zs[:first], workers) - proposal.log_density(zs[:first])
        if first < draws:  # the first draws say whether the rest can help (the same draws either way)
            khat, _, ess = psis_weights(log_w)
            logger.debug("importance sampling: Pareto k %.2f, %.0f effective of the first %d draws", khat, ess, first)
            if ess / first < HOPELESS * ESS_MIN / cap:
                raise Unsupported(
                    f"the Laplace approximation fails its importance check (effective draws {ess:.0f} of the "
                    f"first {first}: the {cap} draws allowed would hold ~{ess / first * cap:.0f}, "
                    f"needs >= {ESS_MIN:.0f})"
                )
            rest = zs[first:]
            log_w = np.concatenate([log_w, log_posteriors(posterior, rest, workers) - proposal.log_density(rest)])
        khat, weights, ess = psis_weights(log_w)
        if khat < KHAT_MAX and ess < ESS_MIN and ess > 0 and ESS_MIN / ess * zs.shape[0] <= cap:
            # trustworthy weights, too few of them: the effective fraction ess / n is the proposal's,
            # so more draws of it reach ESS_MIN (with a margin for the fraction's own noise)
            more = min(cap, math.ceil(1.2 * ESS_MIN / ess * zs.shape[0])) - zs.shape[0]
            extra = proposal.draw(more, rng)
            zs = np.concatenate([zs, extra])
            log_w = np.concatenate([log_w, log_posteriors(posterior, extra, workers) - proposal.log_density(extra)])
            logger.info("importance sampling: %.0f effective draws of %d, %d more drawn", ess, draws, more)
            khat, weights, ess = psis_weights(log_w)
        if not khat < KHAT_MAX or not ess >= ESS_MIN:
            raise Unsupported(
                f"the Laplace approximation fails its importance check (Pareto k {khat:.2f}, needs < {KHAT_MAX}; "
                f"effective draws {ess:.0f} of {zs.shape[0]}, needs >= {ESS_MIN:.0f})"
            )
        keep = systematic_resample(weights, rng)
        values = np.array([list(posterior.values(z).values()) for z in zs[keep]])
        logger.info("importance sampling: Pareto k %.2f, %.0f effective draws of %d", khat, ess, zs.shape[0])
        sd = values.std(axis=0, ddof=1)
        return base_result(
            posterior,
            self.name,
            start.point,
            sd=dict(zip(posterior.space.names, sd.tolist())),
            z=start.z,
            cov_z=start.cov_z,
            log_post=start.log_post,
            approximate_draws=values,
            diagnostics={
                "converged": True,
                "log_posterior": start.log_post,
                "psis_khat": khat,
                "importance_ess": ess,
                "importance_draws": int(zs.shape[0]),
                "split_scales": scales.tolist(),  # (positive, negative side) per Cholesky axis
            },
        )
