"""The robustness bench's simulator keeps the statistics each case promises."""

import json
import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import welch

from vibinverse.bench import robustness_cases as rc

CLEAN = rc.CASES["clean"]


# ------------------------------------------------------------------ the simulator


@pytest.mark.parametrize("dt", [0.005, 0.00025, 0.0035, 0.05])
def test_oscillator_discretization_is_exact(dt):
    """Van Loan's Phi is exp(A dt) and its Q the closed form P - Phi P Phi^T of a stationary process."""
    mode = rc.RESONANCE
    w, z = 2 * np.pi * mode.frequency, mode.damping_ratio
    phi, q = rc.oscillator_matrices(mode, dt)
    np.testing.assert_allclose(phi, expm(np.array([[0, 1], [-(w**2), -2 * z * w]]) * dt), rtol=1e-10, atol=1e-13)
    p = rc.stationary_covariance(mode)
    np.testing.assert_allclose(q, p - phi @ p @ phi.T, rtol=1e-7, atol=1e-12 * p.max())


@pytest.mark.parametrize("irregular", [False, True])
def test_oscillator_keeps_its_stationary_variance(irregular):
    """20 000 replicas started stationary: var q = rms^2 at every stamp, on uniform and on the
    irregular case's stamps (sampling sd of the variance sqrt(2 / 20000) = 1 %)."""
    rng = np.random.default_rng(1)
    t = rc.stamps(rc.CASES["irregular"], rng)[:150] if irregular else np.arange(150) / 200.0
    q = rc.oscillator(t, rc.RESONANCE, rng, replicas=20000)
    var = q.var(axis=0)
    assert np.all(np.abs(var / rc.RESONANCE.rms**2 - 1) < 0.05)
    assert abs(var.mean() / rc.RESONANCE.rms**2 - 1) < 0.03


def test_oscillator_spectrum_peaks_at_the_resonance():
    """The averaged periodogram (Hann window) of 40 series of 82 s peaks at f sqrt(1 - 2 zeta^2)
    = 3.4634 Hz within one bin (0.0122 Hz); its half-power width is 2 zeta f (0.097 Hz) within 25 %."""
    mode = rc.RESONANCE
    q = rc.oscillator(np.arange(16384) / 200.0, mode, np.random.default_rng(2), replicas=40)
    f, p = welch(q, fs=200.0, nperseg=16384, axis=-1)
    p = p.mean(axis=0)
    peak = f[np.argmax(p)]
    assert abs(peak - mode.frequency * math.sqrt(1 - 2 * mode.damping_ratio**2)) < 1.01 * (f[1] - f[0])
    above = f[p > 0.5 * p.max()]
    width = above.max() - above.min() + (f[1] - f[0])
    assert abs(width / (2 * mode.damping_ratio * mode.frequency) - 1) < 0.25


def test_ar1_noise_has_its_correlation_and_variance():
    """phi = 0.9 at lag 1 (sd sqrt((1 - phi^2) / n) = 0.0014) and sd 0.6 (sd of the variance ~1.4 %),
    directly and in the ar1 case (n = 4000: lag-1 sd 0.007)."""
    e = rc.ar1(100_000, 0.9, 0.6, np.random.default_rng(3))
    assert abs(np.corrcoef(e[:-1], e[1:])[0, 1] - 0.9) < 0.006
    assert abs(e.var() / 0.36 - 1) < 0.06
    noise = rc.simulate_parts("ar1", 0)[1]["noise"]
    assert noise.size == 4000
    assert abs(np.corrcoef(noise[:-1], noise[1:])[0, 1] - 0.9) < 0.03


def test_one_over_f_noise_is_a_sum_of_ou_processes_with_a_one_over_f_spectrum():
    """Each Ornstein-Uhlenbeck part has correlation exp(-dt / tau) and its sd; the sum of the
    case's four (0.01-10 s) has a spectrum ~ 1/f between 0.05 and 5 Hz (slope -1 +- 0.15)."""
    rng = np.random.default_rng(4)
    t = np.arange(100_000) / 200.0
    for tau in (0.01, 0.1):
        e = rc.ou(t, tau, 0.3, rng)
        assert abs(np.corrcoef(e[:-1], e[1:])[0, 1] - math.exp(-0.005 / tau)) < 0.01
        assert abs(e.std() / 0.3 - 1) < 0.05
    case = rc.CASES["one_over_f"]
    sd = case.sigma / math.sqrt(len(case.flicker_times))
    t = np.arange(80_000) / 200.0
    ps = []
    for seed in range(4):
        r = np.random.default_rng(seed)
        f, p = welch(sum(rc.ou(t, tau, sd, r) for tau in case.flicker_times), fs=200.0, nperseg=2**14)
        ps.append(p)
    band = (f >= 0.05) & (f <= 5.0)
    slope = np.polyfit(np.log(f[band]), np.log(np.mean(ps, axis=0)[band]), 1)[0]
    assert abs(slope + 1) < 0.15


def test_irregular_stamps_are_jittered_on_the_fine_grid_with_frames_dropped():
    """Strictly increasing, on the 20x finer grid, each within 20 % of an interval of its nominal
    stamp (and the jitter reaches it), exactly 10 % of the frames dropped."""
    case = rc.CASES["irregular"]
    t = rc.stamps(case, np.random.default_rng(5))
    n = round(case.duration * case.fs)
    assert t.size == n - round(0.1 * n)
    assert np.all(np.diff(t) > 0)
    fine = t * case.fs * rc.FINE
    np.testing.assert_allclose(fine, np.round(fine), atol=1e-6)
    shift = t * case.fs - 0.2  # the stamps are offset by the largest jitter so that none is negative
    offset = shift - np.round(shift)
    assert np.abs(offset).max() <= 0.2 + 1e-9 and np.abs(offset).max() >= 0.2 - 1e-9
    assert 0.05 < np.mean(np.abs(offset)) < 0.15  # uniform over 9 fine steps: mean |offset| 0.11
    data = rc.simulate("irregular", 5)
    assert data.time.size == t.size and np.all(np.isfinite(data.intensity))


def test_gaps_are_ten_percent_of_the_samples_in_runs():
    data = rc.simulate("gaps", 6)
    gap = np.isnan(data.intensity)
    assert gap.sum() == round(0.1 * gap.size)
    assert not gap[0] and not gap[-1]
    starts = np.flatnonzero(np.diff(gap.astype(int)) == 1)
    assert gap.sum() / starts.size >= 5  # runs, not scattered samples
    assert np.all(np.diff(data.time) > 0)


def test_drift_and_gain_are_slow_and_of_the_promised_size():
    """drift: 3x the clean signal's sd peak to peak, nearly all its power below 1 Hz (above 1 Hz
    less than 1 % of its total and 1e-3 of the white noise's there); gain: max |g| = 0.2, slow,
    multiplying the vibration: y = (1 + g)(level + modes + lines) + noise."""
    _, parts, _ = rc.simulate_parts("drift", 7)
    d = parts["drift"]
    assert np.ptp(d) == pytest.approx(3 * rc.REFERENCE_SD, rel=1e-12)
    assert math.isclose(rc.REFERENCE_SD, math.sqrt(0.3**2 + 0.15**2 / 2))
    spec = np.abs(np.fft.rfft(d - d.mean())) ** 2
    noise = np.abs(np.fft.rfft(parts["noise"])) ** 2
    f = np.fft.rfftfreq(d.size, 1 / 200.0)
    assert spec[f > 1.0].sum() < 1e-2 * spec.sum()
    assert spec[f > 1.0].sum() < 1e-3 * noise[f > 1.0].sum()
    _, parts, _ = rc.simulate_parts("gain_drift", 7)
    g = parts["gain"]
    assert np.abs(g).max() == pytest.approx(0.2)
    spec = np.abs(np.fft.rfft(g * np.hanning(g.size))) ** 2  # Hann: no leakage from the record's ends
    assert spec[np.fft.rfftfreq(g.size, 1 / 200.0) > 0.2].sum() < 1e-3 * spec.sum()
    data = rc.simulate("gain_drift", 7)
    expected = (1 + g) * (rc.LEVEL + parts["modes"] + parts["lines"]) + parts["noise"]
    np.testing.assert_allclose(data.intensity, expected)
    assert np.all(parts["drift"] == 0)


def test_clean_case_has_the_demo_snr_and_the_truth():
    """Signal sd sqrt(0.3^2 + 0.15^2/2), a 10 Hz line of amplitude 0.15 (least squares within its
    sd ~0.02), white noise 0.6; the truth names what the fits are scored against."""
    t, parts, truth = rc.simulate_parts("clean", 8)
    assert t.size == 4000 and t[1] == pytest.approx(0.005)
    x = np.column_stack([np.cos(2 * np.pi * 10 * t), np.sin(2 * np.pi * 10 * t)])
    y = rc.simulate("clean", 8).intensity - rc.LEVEL
    amp = np.hypot(*np.linalg.lstsq(x, y, rcond=None)[0])
    assert abs(amp - 0.15) < 0.06
    assert abs(parts["noise"].std() - 0.6) < 0.03
    assert truth["modes"] == [{"frequency": pytest.approx(3.4641016), "damping_ratio": 0.014, "rms": 0.3}]
    assert truth["lines"][0]["frequency"] == 10.0 and truth["lines"][0]["amplitude"] == 0.15
    json.dumps(truth)
    # seeded: the same series twice, another seed another series
    np.testing.assert_array_equal(rc.simulate("clean", 8).intensity, rc.simulate("clean", 8).intensity)
    assert not np.allclose(rc.simulate("clean", 9).intensity, rc.simulate("clean", 8).intensity)


def test_every_case_simulates_with_its_order_and_quick_halves_the_records():
    for name, case in rc.CASES.items():
        data = rc.simulate(name, 0, quick=True)
        nominal = round(case.duration * case.fs / 2)
        assert data.time.size == nominal - round(case.drop * nominal)
        assert data.truth["order"] == list(case.analyst_order())
        assert np.isfinite(data.intensity).mean() == pytest.approx(1 - case.gaps, abs=1e-3)
    assert rc.CASES["noise_only"].analyst_order() == (1, 1)
    assert rc.CASES["three_modes"].analyst_order() == (3, 0)
    assert rc.simulate("three_modes", 0).time.size == 4000


def test_near_drive_simulates_the_weak_drive_with_the_stated_amplitude():
    """The 4 Hz line at A = 0.2 next to the resonance, in the clean case's noise; the line part is
    exactly A cos(2 pi 4 t + phase), and least squares on 10 records finds A within 0.02 (the mean of
    10 estimates of sd ~0.02 each: the noise density at 4 Hz is ~2.2 x the white 0.6^2 / 200)."""
    case = rc.CASES["near_drive"]
    assert case.lines == (rc.Line(4.0, 0.2),) and case.modes == rc.CASES["weak_drive"].modes
    assert rc.CASES["weak_drive"].lines == (rc.Line(4.0, 0.12),)
    est = []
    for seed in range(10):
        t, parts, truth = rc.simulate_parts("near_drive", seed)
        ln = truth["lines"][0]
        assert (ln["frequency"], ln["amplitude"]) == (4.0, 0.2)
        np.testing.assert_allclose(parts["lines"], 0.2 * np.cos(2 * np.pi * 4.0 * t + ln["phase"]), rtol=1e-12)
        x = np.column_stack([np.ones_like(t), np.cos(2 * np.pi * 4 * t), np.sin(2 * np.pi * 4 * t)])
        est.append(np.hypot(*np.linalg.lstsq(x, rc.simulate("near_drive", seed).intensity, rcond=None)[0][1:]))
    assert abs(np.mean(est) - 0.2) < 0.02
