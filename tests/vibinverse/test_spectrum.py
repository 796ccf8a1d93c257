"""The periodogram: the FFT on a uniform grid (numbers unchanged), Lomb-Scargle by nifty-ls on
irregular stamps (against scipy's direct sum), and the frame model's spectral starts on jittered
stamps with dropped frames."""

import numpy as np
import pytest

from tests.conftest import SNR10, K, frame_problem
from vibinverse.io.series import validate
from vibinverse.spectrum import line_candidates, periodogram


def _jittered(n=4000, dt=0.005, seed=0):
    """Stamps of n frames at dt, each moved by up to +-20 % of a frame, 10 % of the frames dropped;
    and the kept frames' indices."""
    rng = np.random.default_rng(seed)
    keep = rng.random(n) >= 0.1
    return ((np.arange(n) + rng.uniform(-0.2, 0.2, n)) * dt)[keep], np.flatnonzero(keep)


def test_uniform_stamps_keep_the_zero_padded_fft():
    """On a uniform grid (gaps as NaN) the periodogram is |rfft|^2 / N of the de-meaned series,
    gaps filled with 0, 4-fold zero padding: bit for bit what it was."""
    rng = np.random.default_rng(1)
    t = np.arange(1000) * 0.005
    y = np.sin(2 * np.pi * 10 * t) + rng.normal(0, 1, t.size)
    y[[5, 300, 301]] = np.nan
    s = validate(t, y)
    assert s.uniform
    freqs, power = periodogram(s)
    good = np.isfinite(y)
    filled = np.where(good, y - np.nanmean(y), 0.0)
    np.testing.assert_array_equal(power, (np.abs(np.fft.rfft(filled, 4000)) ** 2 / good.sum())[1:])
    np.testing.assert_array_equal(freqs, np.fft.rfftfreq(4000, s.dt)[1:])


def test_irregular_stamps_take_the_lomb_scargle_periodogram():
    """Jittered stamps with dropped frames: nifty-ls's floating-mean Lomb-Scargle equals scipy's
    direct sum (floating_mean=True) to 1e-6 (nifty-ls's NUFFT tolerance is ~1e-8); its "psd"
    normalization is |sum y e^{-i w t}|^2 / N, as the FFT's."""
    from scipy.signal import lombscargle

    t, _ = _jittered()
    rng = np.random.default_rng(2)
    y = 3.0 + 0.5 * np.cos(2 * np.pi * 10 * t + 0.3) + rng.normal(0, 1, t.size)
    s = validate(t, y)
    assert not s.uniform
    periodogram(s)  # the first call loads the library
    freqs, power = periodogram(s)
    assert freqs[0] == pytest.approx(freqs[1] - freqs[0]) and freqs[-1] <= 0.5 * s.fs
    some = np.arange(0, freqs.size, 97)
    direct = lombscargle(t, y - y.mean(), 2 * np.pi * freqs[some], floating_mean=True)
    np.testing.assert_allclose(power[some], direct, rtol=1e-6)
    peak = int(np.argmax(power))
    assert freqs[peak] == pytest.approx(10.0, abs=freqs[1] - freqs[0])
    dft = np.abs(np.sum((y - y.mean()) * np.exp(-2j * np.pi * freqs[peak] * t))) ** 2 / t.size
    assert power[peak] == pytest.approx(dft, rel=0.02)
    assert line_candidates(s, (0.5, 99.0))[0] == pytest.approx(10.0, abs=0.01)


def test_frame_guesses_on_jittered_stamps_find_the_drive_and_the_resonance():
    """The sec. 4.2 roof at jittered stamps with dropped frames: the spectral start puts the drive
    line at 10 Hz and the tilt resonance near 2 sqrt(3) Hz (the MAP refines them)."""
    prob = frame_problem(SNR10)
    s = prob.series
    t, kept = _jittered(n=s.time.size, dt=s.dt)
    # the 200 Hz series' samples at the kept frames, stamped with the jittered times: the spectral
    # start needs the lines, not an exact process
    model = prob.model.__class__(prob.model.base, validate(t, s.intensity[kept], "jittered", s.scene))
    assert model.per_step
    best = model.guesses({n: p.bounds for n, p in zip(prob.space.names, prob.space.priors)})[0]
    assert best[K + "drive_frequency"] == pytest.approx(10.0, abs=0.01)
    assert best[K + "tilt_frequency"] == pytest.approx(2 * np.sqrt(3), rel=0.1)
