"""The periodogram: the FFT on a uniform grid (numbers unchanged), Lomb-Scargle by nifty-ls on
irregular stamps (against scipy's direct sum), the frame model's spectral starts on jittered
stamps with dropped frames, and a logger's anti-alias roll-off (`passband_top`) with the white
floor below it."""

import dataclasses

import numpy as np
import pytest
from scipy import signal

from tests.conftest import SNR10, K, frame_problem
from vibinverse.io.series import Series, validate
from vibinverse.spectrum import highpassed, line_candidates, passband_top, periodogram, white_floor


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


@pytest.mark.parametrize("n", [30_001, 20_000, 999])
def test_sinusoid_amplitudes_on_a_grid_are_the_sinusoids_one_by_one(n):
    """The scan's amplitudes (closed-form normal equations on a long steady record, `sinusoid`
    one by one on a short one) equal `sinusoid`'s at each grid frequency to 1e-9, on stamps that
    do not start at 0, with an offset, a line between grid points and one ill-conditioned frequency
    (under a cycle in the record: to 1e-6); a gap takes the one-by-one path, and the strongest is the first
    maximum."""
    from vibinverse.spectrum import sinusoid, sinusoid_amplitudes, strongest_sinusoid

    rng = np.random.default_rng(n)
    t = 12.345 + np.arange(n) / 200.0
    y = 0.4 * np.cos(2 * np.pi * 7.40312 * t + 0.7) + rng.normal(size=n) + 3.0
    span = t[-1] - t[0]
    grid = np.linspace(7.40312 - 1 / span, 7.40312 + 1 / span, 41)
    # under a cycle the normal equations are ill-conditioned (cond up to ~1e7): rounding grows with it
    for freqs, rtol in ((grid, 1e-9), (np.linspace(0.05 / span, 0.5 / span, 5), 1e-6)):
        one_by_one = np.array([sinusoid(t, y, f)[0] for f in freqs])
        np.testing.assert_allclose(sinusoid_amplitudes(t, y, freqs), one_by_one, rtol=rtol)
    assert strongest_sinusoid(t, y, grid) == grid[int(np.argmax([sinusoid(t, y, f)[0] for f in grid]))]
    gappy = y.copy()
    gappy[n // 3] = np.nan
    np.testing.assert_array_equal(sinusoid_amplitudes(t, gappy, grid[:3]), [sinusoid(t, gappy, f)[0] for f in grid[:3]])


@pytest.mark.parametrize("seed", [1, 3, 4])
def test_line_candidates_find_a_drive_over_coloured_noise_by_its_local_excess(seed):
    """A 10 Hz line (A 0.15) in AR(1) noise (phi 0.9, sd 0.6; scipy.signal.lfilter), 20 s at 200 Hz
    (the robustness bench's ar1 case): the raw periodogram's three largest peaks are the noise's low
    frequencies, the line's power is about 30 times its neighbours'. The candidates (each the
    largest power over the running median) hold 10 Hz, where the scene fit's MAP starts a drive."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    t = np.arange(4000) * 0.005
    phi = 0.9
    noise = lfilter([1.0], [1.0, -phi], rng.normal(0.0, 0.6 * np.sqrt(1 - phi**2), t.size))
    s = validate(t, 0.15 * np.cos(2 * np.pi * 10.0 * t + 0.4) + noise)
    freqs, power = periodogram(s)
    peaks = [i for i in range(1, power.size - 1) if power[i] >= power[i - 1] and power[i] >= power[i + 1]]
    assert all(freqs[i] < 5.0 for i in sorted(peaks, key=lambda i: -power[i])[:3])  # raw power ranks it below
    found = line_candidates(s, (0.0, 100.0))
    assert any(abs(f - 10.0) < 0.01 for f in found), found


def _gain_drift_series(seed):
    """A 10 Hz line (A 0.5) and white noise 0.6 on a level of 537 (the roof scene's), the whole
    times 1 + g, g a 20 % gain drift of 0.5-3 cycles per record (the robustness bench's)."""
    from vibinverse.bench.robustness_cases import gain

    rng = np.random.default_rng(seed)
    t = np.arange(4000) * 0.005
    g = gain(t, 0.2, rng)
    y = (1.0 + g) * (537.0 + 0.5 * np.cos(2 * np.pi * 10.0 * t + 0.4)) + rng.normal(0.0, 0.6, t.size)
    return t, y


@pytest.mark.parametrize("seed", range(4))
def test_line_candidates_see_a_drive_through_a_gain_drift(seed):
    """Untouched, the gain drift's slow power leaks as 1/f^2 over the whole periodogram and stands
    far above the 10 Hz line there; with the slow part regressed out first (`highpassed`, below the
    band's lower edge of 0.2 Hz) the line is a candidate."""
    t, y = _gain_drift_series(seed)
    s = validate(t, y)
    freqs, power = periodogram(s)
    near = np.abs(freqs - 10.0) < 0.5
    assert power[near & (np.abs(freqs - 10.0) > 0.2)].max() > 0.05 * power[near].max()  # leakage around the line
    found = line_candidates(s, (0.2, 100.0))
    assert any(abs(f - 10.0) < 0.01 for f in found), found


def test_highpassed_removes_the_slow_part_and_keeps_the_fast():
    """Of a 20 % gain drift on a level of 537 (tens of units), what is left below 0.2 Hz is under
    0.1 units rms; a 3.46 Hz sinusoid (69 cycles) keeps 99 % of its variance; gaps are kept as
    gaps and do not spoil the fit."""
    from vibinverse.bench.robustness_cases import gain

    t = np.arange(4000) * 0.005
    slow = 537.0 * gain(t, 0.2, np.random.default_rng(0))
    fast = np.sin(2 * np.pi * 3.46 * t + 0.2)
    y = slow + fast
    y[1000:1100] = np.nan
    out = highpassed(t, y, 0.2)
    good = np.isfinite(y)
    assert np.isnan(out[1000:1100]).all() and np.isfinite(out[good]).all()
    assert np.std(out[good] - fast[good]) < 0.1
    assert np.var(highpassed(t, fast, 0.2)) > 0.99 * np.var(fast)


def _uniform(y, fs=10.0):
    return Series(np.arange(y.size) / fs, np.asarray(y, dtype=float), "test")


def _noise(n, seed):
    """White noise beside a weak random walk, at 10 times the rate a record is decimated to."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n) + 0.01 * np.cumsum(rng.standard_normal(n))


@pytest.mark.parametrize("n", [54_000, 6_000])
def test_a_decimated_record_shows_its_anti_alias_roll_off(n):
    """`scipy.signal.decimate`'s Chebyshev filter (0.8 x Nyquist) and a 255-tap FIR at 0.9 x
    Nyquist (a converter's filter) are read within 0.05 x Nyquist below their edges."""
    x = _noise(10 * n, n)
    top = passband_top(_uniform(signal.decimate(x, 10, ftype="iir", zero_phase=True)))
    assert top is not None and 0.75 * 5.0 <= top <= 0.81 * 5.0
    top = passband_top(_uniform(signal.lfilter(signal.firwin(255, 0.9 / 10), 1.0, x)[::10]))
    assert top is not None and 0.8 * 5.0 <= top <= 0.9 * 5.0


@pytest.mark.parametrize("n", [54_000, 6_000])
def test_spectra_that_fall_for_other_reasons_show_no_roll_off(n):
    """White noise, AR(1) (phi 0.9), a random walk, a frame's exposure (a box average), a resonance
    at 0.7 or 0.9 x Nyquist on a flat floor, a resonance's steep tail, and records with gaps or
    irregular stamps: no passband."""
    rng = np.random.default_rng(n)
    e = lambda: rng.standard_normal(n)
    peak = lambda f: signal.lfilter(*signal.iirpeak(f, 30), e()) * 30 + e()
    cases = {
        "white": e(),
        "ar1": signal.lfilter([1.0], [1.0, -0.9], e()),
        "walk": np.cumsum(e()) + 0.1 * e(),
        "box": rng.standard_normal(10 * n).reshape(-1, 10).mean(axis=1),
        "peak 0.7": peak(0.7),
        "peak 0.9": peak(0.9),
        "steep tail": signal.lfilter([1.0], [1.0, -1.8, 0.81], e()) + 1e-4 * e(),
    }
    for name, y in cases.items():
        assert passband_top(_uniform(y)) is None, name
    y = signal.decimate(_noise(10 * n, 1), 10, ftype="iir", zero_phase=True)
    gappy = y.copy()
    gappy[100:110] = np.nan
    assert passband_top(_uniform(gappy)) is None
    t = np.arange(n) / 10.0 + rng.uniform(-0.02, 0.02, n)
    assert passband_top(Series(np.sort(t), y, "irregular")) is None


def test_the_white_floor_bounds_white_noise_from_above():
    """`white_floor` of white noise (sigma 2) within 25 % below its sigma and hardly above it; below
    a passband the bands above its top are left out (a floor there would be the filter's): white
    noise of sigma 2 decimated by 10 is white of 2 / sqrt(10) in its band."""
    rng = np.random.default_rng(4)
    floor = white_floor(_uniform(2.0 * rng.standard_normal(40_000)))
    assert 0.75 * 2.0 <= floor <= 1.03 * 2.0
    y = signal.decimate(2.0 * rng.standard_normal(400_000), 10, ftype="iir", zero_phase=True)
    s = _uniform(y)
    inband = 2.0 / np.sqrt(10.0)
    assert white_floor(s) < 0.1 * inband  # the filter's stop band, read as a floor
    s = dataclasses.replace(s, passband=passband_top(s))
    assert 0.75 * inband <= white_floor(s) <= 1.03 * inband
