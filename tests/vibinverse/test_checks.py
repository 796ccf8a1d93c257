"""Residual checks: white Gaussian residuals pass at the promised rate; coloured or heavy-tailed ones
fail; below a logger's anti-alias roll-off they are checked in the band below it."""

import math

import numpy as np
import pytest
from scipy import stats

from vibinverse.checks import ALPHA, WHITE_MATERIAL, autocorrelation, describes_data, ljung_box, residual_checks


def _binomial_upper(n: int, p: float) -> float:
    """The fraction of n trials at rate p that is exceeded with probability 1e-3."""
    return stats.binom.ppf(1 - 1e-3, n, p) / n


def test_white_gaussian_residuals_pass_at_the_promised_rate():
    rng = np.random.default_rng(0)
    n_sets = 300
    failed_white = failed_normal = 0
    for _ in range(n_sets):
        c = residual_checks(rng.standard_normal(2000))
        failed_white += not c["white"]
        failed_normal += not c["normal"]
    # each check fails with probability ALPHA on a model that describes the data
    assert failed_white / n_sets <= _binomial_upper(n_sets, ALPHA)
    assert failed_normal / n_sets <= _binomial_upper(n_sets, ALPHA)


def test_ljung_box_q_is_chi_squared_under_the_null():
    rng = np.random.default_rng(1)
    qs = np.array([ljung_box(rng.standard_normal(1000), lags=10)[0] for _ in range(400)])
    # chi2(10): mean 10, sd sqrt(20); the mean of 400 draws has sd 0.22
    assert abs(qs.mean() - 10.0) < 4 * np.sqrt(20 / 400)


def test_coloured_and_heavy_tailed_residuals_fail():
    rng = np.random.default_rng(2)
    e = rng.standard_normal(3000)
    ar = np.empty_like(e)
    ar[0] = e[0]
    for k in range(1, e.size):  # AR(1), phi = 0.3: a model that missed coloured noise
        ar[k] = 0.3 * ar[k - 1] + e[k]
    c = residual_checks(ar / ar.std())
    assert not c["white"] and c["ljung_box_p"] < 1e-10
    assert "not white" in describes_data(c)
    t = rng.standard_t(3, size=3000)  # heavy tails: outliers
    c = residual_checks(t / t.std())
    assert c["white"] and not c["normal"]
    assert "not Gaussian" in describes_data(c)


def test_gaps_are_skipped_not_filled():
    rng = np.random.default_rng(3)
    e = rng.standard_normal(4000)
    ar = e.copy()
    ar[1:] += 0.5 * e[:-1]  # MA(1): rho_1 = 0.4, rho_2 = 0
    holed = ar.copy()
    holed[rng.random(ar.size) < 0.2] = np.nan
    rho = autocorrelation(holed, 2)
    # 0.4 at lag 1 and 0 at lag 2, each to ~3 sd of a 3000-sample estimate (sd ~0.02)
    assert abs(rho[0] - 0.4) < 0.06 and abs(rho[1]) < 0.06
    assert residual_checks(np.where(np.isnan(holed), np.nan, e))["white"]


def test_too_few_residuals_give_no_verdict():
    assert residual_checks(np.ones(10)) == {}
    assert describes_data({}) is None


def test_a_long_record_s_immaterial_departure_from_normality_passes():
    """720 000 residuals with excess kurtosis ~0.06 (a t distribution with 100 degrees of freedom):
    the test detects it (p < 1e-6), yet it widens no interval by more than ~2 %, so the check
    passes and records the effect sizes; the same p with kurtosis ~1 (t with 10) fails."""
    rng = np.random.default_rng(5)
    e = rng.standard_t(100, size=720_000)
    c = residual_checks(e / e.std())
    assert c["normality_p"] < 1e-6 and abs(c["excess_kurtosis"] - 0.0625) < 0.02 and c["normal"]
    e = rng.standard_t(10, size=720_000)
    c = residual_checks(e / e.std())
    assert not c["normal"] and c["excess_kurtosis"] > 0.5


def test_a_long_record_s_immaterial_autocorrelation_passes():
    """720 000 residuals of an MA(1) with rho_1 = 0.01: Ljung-Box detects it (Q ~ n rho^2 = 72 over
    20 lags, p < 1e-4), yet the residual spectrum is within 2 % of flat (2 sum |rho_k| ~ 0.02 plus
    the sampling noise of 20 lags, ~0.03), so the check passes and records it; rho_1 = 0.1 fails."""
    rng = np.random.default_rng(6)
    e = rng.standard_normal(720_001)
    for theta, white in ((0.01, True), (0.1, False)):
        ma = (e[1:] + theta * e[:-1]) / np.sqrt(1 + theta**2)
        c = residual_checks(ma)
        assert c["ljung_box_p"] < 1e-4 and c["white"] is white
        assert (c["spectral_departure"] <= WHITE_MATERIAL) is white
        if white:
            assert c["spectral_departure"] == pytest.approx(0.02 + 0.03, abs=0.03)


def test_below_ten_thousand_samples_a_rejection_is_always_material():
    """The smallest departure 2 sum |rho_k| Ljung-Box rejects at ALPHA over 20 lags is one lag's,
    2 sqrt(chi2_{0.99}(20) / n), above WHITE_MATERIAL for n < ~9600: on 5000 residuals with weak
    MA(1) or MA(7) correlation, every rejection fails the check (none is waved through)."""
    rng = np.random.default_rng(7)
    rejected = 0
    for theta in np.linspace(0.02, 0.08, 40):
        e = rng.standard_normal(5007)
        for lag in (1, 7):
            c = residual_checks((e[lag:] + theta * e[:-lag])[:5000])
            rejected += c["ljung_box_p"] < ALPHA
            assert c["white"] is bool(c["ljung_box_p"] >= ALPHA)
    assert rejected >= 10  # the loop did test rejections


def test_residuals_below_a_passband_are_checked_in_that_band():
    """White residuals low-passed by a logger's anti-alias filter (`scipy.signal.decimate`'s
    Chebyshev, 0.8 x Nyquist, forwards and back) fail the whole-band check; checked in the band
    below 0.4 cycles per sample (`in_band`) they pass at the promised rate over 300 sets; a
    resonance's misfit inside the band still fails there."""
    from scipy import signal

    from vibinverse.checks import in_band

    rng = np.random.default_rng(3)
    b, a = signal.cheby1(8, 0.05, 0.8)
    n_sets, failed = 300, 0
    for _ in range(n_sets):
        e = signal.filtfilt(b, a, rng.standard_normal(3000))
        e /= e.std()
        failed += not residual_checks(e, 0.4)["white"]
    assert failed / n_sets <= _binomial_upper(n_sets, ALPHA)
    assert not residual_checks(e)["white"]
    assert in_band(e, 0.4).size == 2 * math.floor(0.4 * e.size)
    bump = signal.lfilter(*signal.iirpeak(0.3, 10), rng.standard_normal(3000))
    assert not residual_checks(signal.filtfilt(b, a, rng.standard_normal(3000) + 2.0 * bump), 0.4)["white"]
