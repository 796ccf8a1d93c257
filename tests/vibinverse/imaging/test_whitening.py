"""The whitened periodogram: the exact tail of the whitened power on white noise, the corrected
false-alarm probability, and the shortcuts of the detection's second pass giving what the whole
computation gives (the DFT at a few bins is the periodogram there, summed over pieces of the
record or not; the kept floor whitens those bins as the whole whitening does)."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vibinverse.imaging.whitening import (
    LOW_BINS,
    corrected,
    dft_basis,
    dft_power,
    dft_sums,
    floor_constant,
    frequency_grid,
    log_tail,
    spectra_rows,
    spectrum_rows,
    white_floor,
    whiten,
    whiten_rows,
)

FS = 100.0  # Hz


# ----------------------------------------------------------------------------------- the statistics
def test_the_tail_of_the_whitened_power_is_exact_for_white_noise():
    """z = P / (median of the 2h+1 powers around it / c): Monte Carlo against log_tail."""
    rng = np.random.default_rng(1)
    h, n = 8, 400_000
    window = rng.exponential(size=(n, 2 * h + 1))
    z = window[:, h] / (np.median(window, axis=1) / floor_constant(h))
    for s in (2.0, 5.0, 9.0):
        p = math.exp(log_tail(s, h))
        sd = math.sqrt(p * (1 - p) / n)
        assert abs(np.mean(z > s) - p) < 4 * sd, s  # binomial error, 4 sigma


@given(st.floats(0, 200), st.floats(0, 200), st.integers(8, 300))
def test_log_tail_is_a_survival_function_near_exp1(z1, z2, h):
    lo, hi = sorted((z1, z2))
    a, b = float(log_tail(lo, h)), float(log_tail(hi, h))
    assert b <= a <= 0.0  # a survival function
    # log1p(x) <= x: never lighter than exp(-r z), r = E[(h+1)-th of 2h Exp(1)] / c = 1 + O(1/h)
    r = float(np.sum(1.0 / (2 * h - np.arange(h + 1)))) / floor_constant(h)
    assert 1.0 < r < 1.0 + 1.0 / h and b >= -r * hi - 1e-9


def test_log_tail_tends_to_exp1_for_wide_windows():
    assert float(log_tail(24.0, 64)) == pytest.approx(-20.52, abs=0.01)  # the docstring's ~30x e^-24 at h = 64
    assert float(log_tail(24.0, 100_000)) == pytest.approx(-24.0, abs=0.01)


@given(st.floats(-700, 0), st.floats(1, 1e9))
def test_corrected_is_the_chance_that_the_largest_of_n_tests_passes(log_p, n):
    p = math.exp(log_p)
    q = float(corrected(log_p, n))
    assert 0.0 <= q <= min(1.0, n * p) * (1 + 1e-9)  # Bonferroni bounds it
    assert q >= p * (1 - 1e-9)  # one test at least
    if n * p < 1e-6:
        assert q == pytest.approx(n * p, rel=1e-5)  # stable where 1 - (1 - p)^n would round to 0


def test_whitening_is_the_same_on_all_bins_or_some():
    rng = np.random.default_rng(10)
    grid = frequency_grid(np.arange(2000) / FS)
    power = rng.exponential(size=(grid.n_freq, 5)) * np.linspace(1, 30, grid.n_freq)[:, None]
    bins = np.array([LOW_BINS, 400, 401, 990])
    assert np.array_equal(whiten(power, grid)[bins], whiten(power, grid, bins))


# ------------------------------------------------------------------ the second pass's shortcuts
def drifting_series(rng, nt, pixels):
    """Large means (100), a slope, white noise and a line: what the DFT's rounding and the removed
    line of `spectrum_rows` must both get right."""
    t = np.arange(nt) / FS
    y = 100.0 + 3.0 * t[:, None] / t[-1] + rng.standard_normal((nt, pixels))
    y[:, : pixels // 2] += 0.5 * np.sin(2 * np.pi * 12.34 * t)[:, None]
    return t, y


@pytest.mark.parametrize("nt", [1000, 1023])
def test_the_dft_at_a_few_bins_is_the_periodogram_there(nt):
    """dft_power from the sums of the whole record, and from the sums of pieces added up, equals
    the rfft periodogram at those bins. Both are the same sum in float64: they differ by rounding,
    ~1e-16 * sqrt(N) * mean / |X| ~ 1e-14 here; a wrong phase, bin or trend is an O(1) change."""
    rng = np.random.default_rng(20)
    t, y = drifting_series(rng, nt, 40)
    grid = frequency_grid(t)
    mean, power = spectrum_rows(y.copy(), grid)
    bins = np.array([0, 1, LOW_BINS, 122, 123, 124, grid.n_freq - 2, grid.n_freq - 1])
    whole = dft_power(dft_sums(y, mean, dft_basis(grid, bins)), grid, bins)
    np.testing.assert_allclose(whole, power[:, bins], rtol=1e-9)
    cuts = [0, 7, 300, 301, nt // 2, nt]
    parts = sum(dft_sums(y[a:b], mean, dft_basis(grid, bins, slice(a, b))) for a, b in itertools.pairwise(cuts))
    np.testing.assert_allclose(dft_power(parts, grid, bins), power[:, bins], rtol=1e-9)


def test_a_missing_sample_counts_as_the_mean_in_the_dft_as_in_the_spectra():
    rng = np.random.default_rng(21)
    t, y = drifting_series(rng, 512, 6)
    grid = frequency_grid(t)
    filled = y.copy()
    y[[3, 200], 2] = np.nan
    filled[[3, 200], 2] = np.nanmean(y[:, 2])  # as the detection fills it before its spectra
    mean, power = spectrum_rows(filled.copy(), grid)
    bins = np.arange(60, 65)
    np.testing.assert_allclose(
        dft_power(dft_sums(y, mean, dft_basis(grid, bins)), grid, bins), power[:, bins], rtol=1e-9
    )


def test_the_kept_floor_whitens_a_few_bins_as_the_whole_whitening():
    """Floor.whiten of the powers at some bins equals whiten_rows at those bins (the same products
    in another order: rounding only), on a coloured spectrum with a pixel of no power."""
    rng = np.random.default_rng(22)
    grid = frequency_grid(np.arange(3000) / FS)
    power = rng.exponential(size=(7, grid.n_freq)) / (1 + np.arange(grid.n_freq) / 50.0)
    power[3] = 0.0
    z, floor = whiten_rows(power, grid)
    bins = np.array([LOW_BINS, 128, 129, 1300, grid.n_freq - 1])
    np.testing.assert_allclose(floor.whiten(power[:, bins], grid, bins), z[:, bins], rtol=1e-12)
    assert np.all(z[3] == 0.0) and np.all(np.isfinite(z))
    np.testing.assert_array_equal(whiten(power.T, grid), z.T)  # the column layout: the same numbers


# ------------------------------------------------------------------------------------ the slow bins
def test_the_slow_coefficients_are_the_dft_of_the_series_less_its_mean_and_line():
    """Uniform stamps: the rfft's at the first LOW_BINS bins, |.|^2 / N the power there; irregular
    stamps: direct sums of the detrended series at those frequencies."""
    rng = np.random.default_rng(21)
    nt = 300
    for t in (np.arange(nt) / FS, np.sort(np.arange(nt) + rng.uniform(-0.3, 0.3, nt)) / FS):
        grid = frequency_grid(t)
        y = rng.standard_normal((nt, 5)) + 3.0 + 0.2 * t[:, None]
        _, power, slow = spectra_rows(y.copy(), grid)
        tc = t - t.mean()
        flat = y - y.mean(axis=0) - np.outer(tc, (tc @ y) / (tc @ tc))
        f = (np.arange(LOW_BINS) + 1) * grid.df
        direct = flat.T @ np.exp(-2j * np.pi * np.outer(t - t[0], f))
        np.testing.assert_allclose(slow, direct, rtol=1e-9, atol=1e-9)
        if grid.uniform:
            np.testing.assert_allclose(np.abs(slow) ** 2 / nt, power[:, :LOW_BINS], rtol=1e-9)


def test_the_white_floors_are_the_first_and_last_windows_medians_and_the_band_limits_the_slow_bins():
    rng = np.random.default_rng(22)
    t = np.arange(1000) / FS
    grid = frequency_grid(t)
    power = rng.exponential(size=(3, grid.n_freq))
    w = 2 * grid.half_width + 1
    floors = white_floor(power, grid)
    c = floor_constant(grid.half_width)
    np.testing.assert_allclose(floors[:, 0], np.median(power[:, :w], axis=1) / c)
    np.testing.assert_allclose(floors[:, 1], np.median(power[:, -w:], axis=1) / c)
    assert grid.slow_bins.tolist() == [0, 1, 2, 3]
    assert frequency_grid(t, (0.25, 10.0)).slow_bins.tolist() == [2, 3]  # 0.3, 0.4 Hz
    assert frequency_grid(t, (1.0, 10.0)).slow_bins.tolist() == []
