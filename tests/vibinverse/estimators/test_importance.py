"""The importance-sampled Laplace approximation (the long-record sampler): exact where the Laplace
approximation is, corrected where one parameter's posterior is skewed, refused where it misses a
mode."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from vibinverse.errors import Unsupported
from vibinverse.estimators.base import base_result
from vibinverse.estimators.importance import KHAT_MAX, LaplaceImportance, systematic_resample
from vibinverse.estimators.mcmc import ESS_MIN, LaplaceMove, split_scales
from vibinverse.inference_data import psislw
from vibinverse.priors import parse_prior


class Target:
    """A posterior over z = (a, b) with a given log density, the identity map to values."""

    def __init__(self, log_density):
        self.log_density = log_density
        self.space = SimpleNamespace(names=["a", "b"], priors=[parse_prior("uniform(-100, 100)", n) for n in "ab"])
        self.series = None
        self.model = SimpleNamespace(releases_gil=True)

    def log_posterior(self, z):
        return float(self.log_density(np.asarray(z)))

    def values(self, z):
        return dict(zip(self.space.names, np.asarray(z, dtype=float).tolist()))


def importance(target, z_map, cov, seed=0):
    start = base_result(target, "map", target.values(z_map), z=np.asarray(z_map, float), cov_z=np.asarray(cov, float))
    start.log_post = target.log_posterior(z_map)
    return LaplaceImportance().estimate(target, start, seed=seed, workers=2)


def test_a_gaussian_posterior_is_its_laplace_approximation():
    """Laplace exact: k well below KHAT_MAX, nearly every draw effective, and the resampled draws'
    5 and 95 % quantiles at mean -+ 1.645 sd to 0.2 sd (their standard error at ~1500 effective
    draws is ~0.06 sd)."""
    cov = np.array([[1.0, 0.6], [0.6, 2.0]])
    target = Target(lambda z: multivariate_normal.logpdf(z, [1.0, -2.0], cov))
    r = importance(target, [1.0, -2.0], cov)
    d = r.diagnostics
    assert d["psis_khat"] < 0.5 and d["importance_ess"] > 1000
    for j, (m, s) in enumerate([(1.0, 1.0), (-2.0, np.sqrt(2.0))]):
        q05, q95 = np.percentile(r.approximate_draws[:, j], [5, 95])
        assert abs(q05 - (m - 1.645 * s)) < 0.2 * s and abs(q95 - (m + 1.645 * s)) < 0.2 * s


def test_a_skewed_parameter_is_corrected():
    """b = log of an exponential variable (density e^(b - e^b)): mode 0 and curvature 1, so the
    Laplace interval is -+1.645, while the truth is [log(-log 0.95), log(-log 0.05)] = [-2.97, 1.10];
    the weighted draws find it (to 0.25)."""
    target = Target(lambda z: -0.5 * z[0] ** 2 + z[1] - np.exp(z[1]))
    r = importance(target, [0.0, 0.0], np.eye(2))
    assert r.diagnostics["psis_khat"] < KHAT_MAX and r.diagnostics["importance_ess"] >= ESS_MIN
    q05, q95 = np.percentile(r.approximate_draws[:, 1], [5, 95])
    assert q05 == pytest.approx(np.log(-np.log(0.95)), abs=0.25)
    assert q95 == pytest.approx(np.log(-np.log(0.05)), abs=0.25)


def cut_log_density(z, kappa=25.0):
    """a ~ N(0, 1); b with density e^(b - e^(kappa b) / kappa): mode 0, Laplace sd 1 / sqrt(kappa),
    a cliff above the mode and an exponential tail below it, as the unconstrained coordinate of a
    log-uniform parameter whose posterior the prior's lower bound cuts (the sensor noise of a record
    without any). e^(kappa b) / kappa is then Gamma(1 / kappa, 1)-distributed."""
    return -0.5 * z[0] ** 2 + z[1] - np.exp(kappa * z[1]) / kappa


def test_a_posterior_cut_by_its_prior_passes_with_the_split_t():
    """The tail below reaches ~15 Laplace sds (b's 5 % quantile is -0.76 at Laplace sd 0.2): the
    symmetric t's weights fail the check (k > KHAT_MAX), the split t's pass with most draws
    effective, and the resampled quantiles of b are the exact ones from the Gamma distribution to
    0.05 (their standard error at ~1000 effective draws is ~0.02)."""
    from scipy.stats import gamma

    kappa = 25.0
    symmetric = LaplaceMove(np.zeros(2), np.diag([1.0, 1.0 / kappa]))
    zs = symmetric.draw(2000, np.random.default_rng(0))
    lw = np.array([cut_log_density(z) for z in zs]) - symmetric.log_density(zs)
    assert psislw(lw - lw.max())[1] > KHAT_MAX
    r = importance(Target(cut_log_density), [0.0, 0.0], np.diag([1.0, 1.0 / kappa]))
    assert r.diagnostics["psis_khat"] < 0.5 and r.diagnostics["importance_ess"] > 800
    exact = np.log(kappa * gamma(1.0 / kappa).ppf([0.05, 0.5, 0.95])) / kappa
    assert np.percentile(r.approximate_draws[:, 1], [5, 50, 95]) == pytest.approx(exact, abs=0.05)


def test_split_scales_are_one_for_a_gaussian_and_each_sides_own_for_a_split_normal():
    """A Gaussian posterior that its Laplace approximation describes: every scale 1 (to rounding).
    A split normal with sds 0.5 above and 3 below the mode along b: those sds, in units of the
    Laplace sd (here 1). A side flat out to the last probe gets 2 x 16."""
    cov = np.array([[2.0, 0.5], [0.5, 1.0]])
    chol = np.linalg.cholesky(cov)
    gauss = lambda zs: multivariate_normal.logpdf(zs, [1.0, 2.0], cov)
    assert split_scales(gauss, np.array([1.0, 2.0]), chol) == pytest.approx(np.ones((2, 2)), abs=1e-9)

    def split(zs):
        b = zs[:, 1]
        return -0.5 * zs[:, 0] ** 2 - 0.5 * np.where(b > 0, b / 0.5, b / 3.0) ** 2

    assert split_scales(split, np.zeros(2), np.eye(2)) == pytest.approx(np.array([[1.0, 1.0], [0.5, 3.0]]), rel=1e-9)
    flat = lambda zs: -0.5 * zs[:, 0] ** 2 - 0.5 * np.maximum(zs[:, 1], 0.0) ** 2
    assert split_scales(flat, np.zeros(2), np.eye(2))[1] == pytest.approx([1.0, 32.0])


def test_the_split_t_density_is_normalized_and_its_draws_follow_it():
    """The split t's density, normalized by the constant of the symmetric t (2 pi |chol| for d = 2
    and 5 degrees of freedom: each side keeps half the mass whatever its scale), integrated over a
    box on a fine grid, is the fraction of its draws in the box (to 3 binomial sds)."""
    cov = np.array([[1.0, 0.3], [0.3, 0.5]])
    h = 0.005
    x, y = np.meshgrid(np.arange(0.5, 2.0, h) + h / 2, np.arange(-1.0, 80.0, h) + h / 2, indexing="ij")
    cells = np.column_stack([x.ravel(), y.ravel()])
    for scales in (np.ones((2, 2)), np.array([[0.5, 2.0], [3.0, 0.7]])):
        move = LaplaceMove(np.array([0.2, -0.1]), cov, scales)
        p = np.exp(move.log_density(cells)).sum() * h * h / (2 * np.pi * np.prod(np.diag(move.chol)))
        draws = move.draw(20000, np.random.default_rng(3))
        frac = np.mean((draws[:, 0] > 0.5) & (draws[:, 0] < 2.0) & (draws[:, 1] > -1.0))
        assert frac == pytest.approx(p, abs=3 * np.sqrt(p * (1 - p) / 20000))


def two_modes(width):
    """Two modes of equal mass 8 sd apart along a, the second `width` sd wide."""
    return Target(
        lambda z: -0.5 * z[1] ** 2 + np.logaddexp(-0.5 * z[0] ** 2, -0.5 * ((z[0] - 8.0) / width) ** 2 - np.log(width))
    )


def test_a_missed_mode_is_refused():
    """Two modes 8 sd apart, the second 0.3 sd wide, the Laplace approximation at the first: the
    split-t reaches the second only in its tail, 2000 draws give ~135 effective (under 10 %: too
    few to top up), and the check refuses (the pipeline then runs emcee)."""
    for seed in range(3):
        with pytest.raises(Unsupported, match=r"fails its importance check \(Pareto k"):
            importance(two_modes(0.3), [0.0, 0.0], np.eye(2), seed=seed)


def test_weights_hopeless_on_the_first_draws_are_refused_without_weighing_the_rest():
    """The Laplace approximation 3 sd off a narrow posterior (sd 0.2 of the approximation's): of
    the first FIRST_DRAWS (500) a handful are effective, far under a quarter of the 10 % that could
    pass (ESS_MIN of the 4000 draws allowed), so the other 1500 are not weighed and the check
    refuses at once."""
    from vibinverse.estimators.importance import FIRST_DRAWS

    calls = []
    target = Target(lambda z: -0.5 * np.sum(((z - 3.0) / 0.2) ** 2))
    weigh = target.log_posterior
    target.log_posterior = lambda z: calls.append(1) or weigh(z)
    with pytest.raises(Unsupported, match=rf"effective draws \d+ of the first {FIRST_DRAWS}"):
        importance(target, [0.0, 0.0], np.eye(2))
    assert FIRST_DRAWS < len(calls) < FIRST_DRAWS + 200  # the split-t's scales cost a few dozen more


def test_a_second_mode_the_split_t_reaches_gets_its_share():
    """Two equal modes 8 sd apart, the Laplace approximation at one: the split-t's scale on the far
    side (`split_scales`) reaches the other, 2000 draws give ~310 effective, ~1000 more reach
    ESS_MIN, and the draws hold each mode's half: 0.5 within 3 standard errors (0.07 at ~480
    effective draws)."""
    r = importance(two_modes(1.0), [0.0, 0.0], np.eye(2))
    assert r.diagnostics["importance_draws"] > 2000 and r.diagnostics["importance_ess"] >= ESS_MIN
    assert np.mean(r.approximate_draws[:, 0] > 4.0) == pytest.approx(0.5, abs=0.07)


def test_systematic_resampling_keeps_each_draw_its_share():
    """Draw i is kept floor(n w_i) or ceil(n w_i) times."""
    rng = np.random.default_rng(1)
    w = rng.random(500) ** 3
    w /= w.sum()
    counts = np.bincount(systematic_resample(w, rng), minlength=w.size)
    assert counts.sum() == w.size
    assert np.all(counts >= np.floor(w * w.size)) and np.all(counts <= np.ceil(w * w.size))


def test_trustworthy_weights_too_few_to_count_are_topped_up_with_more_draws():
    """Draw 25 of examples/modal_calibration.py (one resonance, 5.60 Hz, zeta 0.029, 20 s at 200 Hz
    in white noise, its priors): 2000 draws of the split-t proposal pass the Pareto check (k 0.48)
    with 313 effective draws, short of ESS_MIN; the effective fraction is the proposal's, so ~1.3 x
    as many more reach it, where before the fit went to emcee (8 of the first 60 calibration draws
    did, all with k < 0.7). The intervals are emcee's to 0.12 of their width (the quantiles' Monte
    Carlo error is ~0.02 of the width at 400-1000 effective draws: 0.12 is ~4 standard errors of
    the difference)."""
    import math

    import vibinverse as vi
    from vibinverse.bench.robustness_cases import Mode, oscillator

    rng = np.random.default_rng([25, 777])
    f = rng.uniform(2.0, 6.0)
    zeta = math.exp(rng.uniform(math.log(0.005), math.log(0.05)))
    rms = math.exp(rng.uniform(math.log(0.15), math.log(0.6)))
    t = np.arange(4000) / 200.0
    y = 2.0 + oscillator(t, Mode(f, zeta, rms), rng) + 0.6 * rng.standard_normal(t.size)
    priors = {
        "modes[0].frequency": "uniform(2, 6)",
        "modes[0].damping_ratio": "loguniform(0.005, 0.05)",
        "modes[0].rms": "loguniform(0.15, 0.6)",
        "level": "uniform(-5, 9)",
        "noise.sigma": "loguniform(0.06, 6)",
    }
    order = {"modal": {"modes": 1, "lines": 0, "drift": False, "noise": "white", "gain": False}}
    s = vi.series(t, y)
    fast = vi.fit(s, order, free=priors, method="importance").summary()
    d = fast["diagnostics"]
    assert fast["approximation"] == "importance" and "mcmc_s" not in fast["timing"]
    assert d["importance_draws"] > 2000 and d["importance_ess"] >= ESS_MIN and d["psis_khat"] < KHAT_MAX
    sampled = vi.fit(s, order, free=priors, method="mcmc").summary()
    for name, p in sampled["parameters"].items():
        width = p["q95"] - p["q05"]
        for q in ("q05", "median", "q95"):
            assert abs(fast["parameters"][name][q] - p[q]) <= 0.12 * width, (name, q)
