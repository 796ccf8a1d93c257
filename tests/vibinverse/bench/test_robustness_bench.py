"""The robustness bench: its simulator keeps the statistics each case promises, its metrics count
what they say, its peers recover a clean resonance, and a reduced run goes end to end."""

import importlib.util
import json
import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import welch

from vibinverse.bench import robustness_bench as rb

CLEAN = rb.CASES["clean"]


# ------------------------------------------------------------------ the simulator


@pytest.mark.parametrize("dt", [0.005, 0.00025, 0.0035, 0.05])
def test_oscillator_discretization_is_exact(dt):
    """Van Loan's Phi is exp(A dt) and its Q the closed form P - Phi P Phi^T of a stationary process."""
    mode = rb.RESONANCE
    w, z = 2 * np.pi * mode.frequency, mode.damping_ratio
    phi, q = rb.oscillator_matrices(mode, dt)
    np.testing.assert_allclose(phi, expm(np.array([[0, 1], [-(w**2), -2 * z * w]]) * dt), rtol=1e-10, atol=1e-13)
    p = rb.stationary_covariance(mode)
    np.testing.assert_allclose(q, p - phi @ p @ phi.T, rtol=1e-7, atol=1e-12 * p.max())


@pytest.mark.parametrize("irregular", [False, True])
def test_oscillator_keeps_its_stationary_variance(irregular):
    """20 000 replicas started stationary: var q = rms^2 at every stamp, on uniform and on the
    irregular case's stamps (sampling sd of the variance sqrt(2 / 20000) = 1 %)."""
    rng = np.random.default_rng(1)
    t = rb.stamps(rb.CASES["irregular"], rng)[:150] if irregular else np.arange(150) / 200.0
    q = rb.oscillator(t, rb.RESONANCE, rng, replicas=20000)
    var = q.var(axis=0)
    assert np.all(np.abs(var / rb.RESONANCE.rms**2 - 1) < 0.05)
    assert abs(var.mean() / rb.RESONANCE.rms**2 - 1) < 0.03


def test_oscillator_spectrum_peaks_at_the_resonance():
    """The averaged periodogram (Hann window) of 40 series of 82 s peaks at f sqrt(1 - 2 zeta^2)
    = 3.4634 Hz within one bin (0.0122 Hz); its half-power width is 2 zeta f (0.097 Hz) within 25 %."""
    mode = rb.RESONANCE
    q = rb.oscillator(np.arange(16384) / 200.0, mode, np.random.default_rng(2), replicas=40)
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
    e = rb.ar1(100_000, 0.9, 0.6, np.random.default_rng(3))
    assert abs(np.corrcoef(e[:-1], e[1:])[0, 1] - 0.9) < 0.006
    assert abs(e.var() / 0.36 - 1) < 0.06
    noise = rb.simulate_parts("ar1", 0)[1]["noise"]
    assert noise.size == 4000
    assert abs(np.corrcoef(noise[:-1], noise[1:])[0, 1] - 0.9) < 0.03


def test_one_over_f_noise_is_a_sum_of_ou_processes_with_a_one_over_f_spectrum():
    """Each Ornstein-Uhlenbeck part has correlation exp(-dt / tau) and its sd; the sum of the
    case's four (0.01-10 s) has a spectrum ~ 1/f between 0.05 and 5 Hz (slope -1 +- 0.15)."""
    rng = np.random.default_rng(4)
    t = np.arange(100_000) / 200.0
    for tau in (0.01, 0.1):
        e = rb.ou(t, tau, 0.3, rng)
        assert abs(np.corrcoef(e[:-1], e[1:])[0, 1] - math.exp(-0.005 / tau)) < 0.01
        assert abs(e.std() / 0.3 - 1) < 0.05
    case = rb.CASES["one_over_f"]
    sd = case.sigma / math.sqrt(len(case.flicker_times))
    t = np.arange(80_000) / 200.0
    ps = []
    for seed in range(4):
        r = np.random.default_rng(seed)
        f, p = welch(sum(rb.ou(t, tau, sd, r) for tau in case.flicker_times), fs=200.0, nperseg=2**14)
        ps.append(p)
    band = (f >= 0.05) & (f <= 5.0)
    slope = np.polyfit(np.log(f[band]), np.log(np.mean(ps, axis=0)[band]), 1)[0]
    assert abs(slope + 1) < 0.15


def test_irregular_stamps_are_jittered_on_the_fine_grid_with_frames_dropped():
    """Strictly increasing, on the 20x finer grid, each within 20 % of an interval of its nominal
    stamp (and the jitter reaches it), exactly 10 % of the frames dropped."""
    case = rb.CASES["irregular"]
    t = rb.stamps(case, np.random.default_rng(5))
    n = round(case.duration * case.fs)
    assert t.size == n - round(0.1 * n)
    assert np.all(np.diff(t) > 0)
    fine = t * case.fs * rb.FINE
    np.testing.assert_allclose(fine, np.round(fine), atol=1e-6)
    shift = t * case.fs - 0.2  # the stamps are offset by the largest jitter so that none is negative
    offset = shift - np.round(shift)
    assert np.abs(offset).max() <= 0.2 + 1e-9 and np.abs(offset).max() >= 0.2 - 1e-9
    assert 0.05 < np.mean(np.abs(offset)) < 0.15  # uniform over 9 fine steps: mean |offset| 0.11
    data = rb.simulate("irregular", 5)
    assert data.time.size == t.size and np.all(np.isfinite(data.intensity))


def test_gaps_are_ten_percent_of_the_samples_in_runs():
    data = rb.simulate("gaps", 6)
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
    _, parts, _ = rb.simulate_parts("drift", 7)
    d = parts["drift"]
    assert np.ptp(d) == pytest.approx(3 * rb.REFERENCE_SD, rel=1e-12)
    assert math.isclose(rb.REFERENCE_SD, math.sqrt(0.3**2 + 0.15**2 / 2))
    spec = np.abs(np.fft.rfft(d - d.mean())) ** 2
    noise = np.abs(np.fft.rfft(parts["noise"])) ** 2
    f = np.fft.rfftfreq(d.size, 1 / 200.0)
    assert spec[f > 1.0].sum() < 1e-2 * spec.sum()
    assert spec[f > 1.0].sum() < 1e-3 * noise[f > 1.0].sum()
    _, parts, _ = rb.simulate_parts("gain_drift", 7)
    g = parts["gain"]
    assert np.abs(g).max() == pytest.approx(0.2)
    spec = np.abs(np.fft.rfft(g * np.hanning(g.size))) ** 2  # Hann: no leakage from the record's ends
    assert spec[np.fft.rfftfreq(g.size, 1 / 200.0) > 0.2].sum() < 1e-3 * spec.sum()
    data = rb.simulate("gain_drift", 7)
    expected = (1 + g) * (rb.LEVEL + parts["modes"] + parts["lines"]) + parts["noise"]
    np.testing.assert_allclose(data.intensity, expected)
    assert np.all(parts["drift"] == 0)


def test_clean_case_has_the_demo_snr_and_the_truth():
    """Signal sd sqrt(0.3^2 + 0.15^2/2), a 10 Hz line of amplitude 0.15 (least squares within its
    sd ~0.02), white noise 0.6; the truth names what the fits are scored against."""
    t, parts, truth = rb.simulate_parts("clean", 8)
    assert t.size == 4000 and t[1] == pytest.approx(0.005)
    x = np.column_stack([np.cos(2 * np.pi * 10 * t), np.sin(2 * np.pi * 10 * t)])
    y = rb.simulate("clean", 8).intensity - rb.LEVEL
    amp = np.hypot(*np.linalg.lstsq(x, y, rcond=None)[0])
    assert abs(amp - 0.15) < 0.06
    assert abs(parts["noise"].std() - 0.6) < 0.03
    assert truth["modes"] == [{"frequency": pytest.approx(3.4641016), "damping_ratio": 0.014, "rms": 0.3}]
    assert truth["lines"][0]["frequency"] == 10.0 and truth["lines"][0]["amplitude"] == 0.15
    json.dumps(truth)
    # seeded: the same series twice, another seed another series
    np.testing.assert_array_equal(rb.simulate("clean", 8).intensity, rb.simulate("clean", 8).intensity)
    assert not np.allclose(rb.simulate("clean", 9).intensity, rb.simulate("clean", 8).intensity)


def test_every_case_simulates_with_its_order_and_quick_halves_the_records():
    for name, case in rb.CASES.items():
        data = rb.simulate(name, 0, quick=True)
        nominal = round(case.duration * case.fs / 2)
        assert data.time.size == nominal - round(case.drop * nominal)
        assert data.truth["order"] == list(case.analyst_order())
        assert np.isfinite(data.intensity).mean() == pytest.approx(1 - case.gaps, abs=1e-3)
    assert rb.CASES["noise_only"].analyst_order() == (1, 1)
    assert rb.CASES["three_modes"].analyst_order() == (3, 0)
    assert rb.simulate("three_modes", 0).time.size == 4000


# ------------------------------------------------------------------ the metrics


def test_match_is_a_hungarian_assignment_within_the_tolerance():
    assert rb.match([1.6, 2.1, 2.7], [2.72, 1.59, 5.0, 2.12]) == [1, 3, 0]
    assert rb.match([2.1, 2.2], [2.15]) == [None, 0]  # 2.15 is nearer 2.2 (relative)
    assert rb.match([2.0], [2.3]) == [None]  # 15 % away: missed
    assert rb.match([3.46], []) == [None]
    assert rb.match([], [1.0]) == []


def _truth(modes=((3.46, 0.014),), lines=((10.0, 0.15),)):
    return {
        "modes": [{"frequency": f, "damping_ratio": z, "rms": 0.3} for f, z in modes],
        "lines": [{"frequency": f, "amplitude": a, "phase": 0.0} for f, a in lines],
    }


def test_score_counts_coverage_misses_detections_and_failures():
    good = rb.FitOutcome(
        frequencies=[3.5],
        damping_ratios=[0.02],
        line_frequencies=[10.001],
        line_amplitudes=[0.12],
        intervals={"modes[0].frequency": (3.4, 3.6), "modes[0].damping_ratio": (0.012, 0.03)},
        lines_detected=[True],
        modes_detected=[True],
        seconds=1.0,
    )
    # the line fitted but not detected; the mode's interval misses; a spurious detected mode
    weak = rb.FitOutcome(
        frequencies=[3.45, 7.0],
        damping_ratios=[0.014, 0.1],
        line_frequencies=[10.0],
        line_amplitudes=[0.15],
        intervals={"modes[0].frequency": (3.30, 3.40)},
        lines_detected=[False],
        modes_detected=[True, True],
        seconds=3.0,
    )
    # the mode missed (fitted 20 % away), the line found
    miss = rb.FitOutcome(
        frequencies=[4.2], damping_ratios=[0.01], line_frequencies=[10.0], line_amplitudes=[0.15], seconds=2.0
    )
    failed = rb.FitOutcome(seconds=4.0, failed=True, note="boom")
    rows = rb.score("clean", "m", [_truth()] * 4, [good, weak, miss, failed])
    by = {r["param"]: r for r in rows}
    assert set(by) == {"mode frequency", "mode damping", "line frequency", "line amplitude"}
    f = by["mode frequency"]
    assert f["n"] == 4 and f["n_failed"] == 1 and f["n_missed"] == 1
    assert f["coverage90"] == 0.5 and f["n_intervals"] == 2
    assert f["coverage_se"] == pytest.approx(math.sqrt(0.25 / 2))
    assert f["median_rel_error"] == pytest.approx(np.median([0.04 / 3.46, 0.01 / 3.46]))
    assert by["mode damping"]["coverage90"] == 1.0 and by["mode damping"]["n_intervals"] == 1
    assert by["mode damping"]["median_rel_error"] == pytest.approx(np.median([0.006 / 0.014, 0.0]))
    assert by["line amplitude"]["median_rel_error"] == pytest.approx(np.median([0.2, 0.0, 0.0]))
    assert by["line frequency"]["coverage90"] is None
    assert f["line_detection"] == pytest.approx(2 / 3)  # detected, not detected, detected
    # the spurious detected 7 Hz mode; a mode missed at 4.2 Hz is itself spurious (nothing there)
    assert f["false_detection"] == pytest.approx(2 / 3)
    assert f["seconds"] == pytest.approx(2.5)
    json.dumps(rows)


def test_score_noise_only_counts_any_detection_as_false():
    quiet = rb.FitOutcome(frequencies=[5.0], damping_ratios=[0.1], modes_detected=[False], seconds=1)
    loud = rb.FitOutcome(line_frequencies=[3.0], line_amplitudes=[0.1], lines_detected=[True], seconds=1)
    claims = rb.FitOutcome(frequencies=[5.0], damping_ratios=[0.1], seconds=1)  # no test: a claim
    rows = rb.score("noise_only", "m", [_truth((), ())] * 3, [quiet, loud, claims])
    assert len(rows) == 1 and rows[0]["param"] == "-"
    assert rows[0]["false_detection"] == pytest.approx(2 / 3)
    assert rows[0]["line_detection"] is None and rows[0]["median_rel_error"] is None


def test_outcome_from_a_modal_summary():
    p = lambda m, lo=None, hi=None: {"median": m, "q05": lo, "q95": hi}
    summary = {
        "parameters": {
            "modes[0].frequency": p(3.4, 3.3, 3.5),
            "modes[0].damping_ratio": p(0.01, 0.005, 0.02),
            "modes[1].frequency": p(5.0),
            "modes[1].damping_ratio": p(0.1),
            "lines[0].frequency": p(10.0, 9.99, 10.01),
            "lines[0].amplitude": p(0.15, 0.1, 0.2),
            "noise.sigma": p(0.6, 0.5, 0.7),
        },
        "diagnostics": {"mode_0_detected": True, "mode_1_detected": False, "line_0_detected": True},
    }
    o = rb.outcome_from_summary(summary)
    assert o.frequencies == [3.4, 5.0] and o.damping_ratios == [0.01, 0.1]
    assert o.modes_detected == [True, False] and o.lines_detected == [True]
    assert o.line_frequencies == [10.0] and o.line_amplitudes == [0.15]
    assert o.intervals["modes[0].frequency"] == (3.3, 3.5) and "modes[1].frequency" not in o.intervals
    assert "noise.sigma" not in o.intervals


def test_stable_clusters_of_a_stabilization_diagram():
    """Poles stable at one frequency over most orders form a mode; a scatter of noise poles does not."""
    orders = 20
    fn = np.full((10, orders), np.nan)
    xi = np.full((10, orders), np.nan)
    rng = np.random.default_rng(0)
    fn[0, 2:] = 3.46 * (1 + 1e-3 * rng.standard_normal(orders - 2))
    xi[0, 2:] = 0.014 * (1 + 0.01 * rng.standard_normal(orders - 2))
    fn[1, 4:] = 10.0
    xi[1, 4:] = 1e-4 * rng.random(orders - 4)  # a line: damping ~0, stable only thanks to the floor
    fn[2, :] = rng.uniform(1, 20, orders)  # noise poles
    xi[2, :] = rng.uniform(0.01, 0.1, orders)
    lab = rb.stability_labels(fn, xi, 0.05, 0.1, 0.002)
    clusters = rb.stable_clusters(fn, xi, lab, 0.4, lo=0.5, hi=25.0)
    assert [round(f, 2) for f, _ in clusters] == [3.46, 10.0]
    assert clusters[1][1] < rb.LINE_DAMPING < clusters[0][1]
    assert rb.stability_labels(fn, xi, 0.05, 0.1, 0.0)[1].sum() <= 2  # without the floor the line is lost


# ------------------------------------------------------------------ the peers and the run


@pytest.mark.skipif(importlib.util.find_spec("celerite2") is None, reason="celerite2 is not installed")
def test_celerite2_peer_recovers_the_clean_resonance():
    data = rb.simulate("clean", 1)
    out = rb.Celerite2Fitter().fit(data.time, data.intensity, (1, 1))
    assert not out.failed, out.note
    assert abs(out.frequencies[0] / rb.RESONANCE.frequency - 1) < 0.02
    assert abs(out.line_frequencies[0] - 10.0) < 0.01 and abs(out.line_amplitudes[0] - 0.15) < 0.05
    assert out.modes_detected == [True] and out.lines_detected == [True]
    lo, hi = out.intervals["modes[0].frequency"]
    assert lo < out.frequencies[0] < hi and hi - lo < 0.2
    assert "lines[0].amplitude" in out.intervals and "modes[0].damping_ratio" in out.intervals


@pytest.mark.skipif(importlib.util.find_spec("pyoma2") is None, reason="pyOMA2 is not installed")
def test_ssi_peer_finds_the_three_ambient_modes():
    data = rb.simulate("three_modes", 0)
    out = rb.SSIFitter().fit(data.time, data.intensity)
    assert not out.failed, out.note
    found = rb.match([1.6, 2.1, 2.7], out.frequencies, tol=0.02)
    assert None not in found and out.intervals == {}


class _Fake:
    """A fitter that reports the truth of the clean case (with a 1 % error), for the harness."""

    name = "fake"

    def fit(self, t, y, order=None):
        k, m = order
        return rb.FitOutcome(
            frequencies=[3.5] * k,
            damping_ratios=[0.014] * k,
            line_frequencies=[10.0] * m,
            line_amplitudes=[0.15] * m,
            intervals={"modes[0].frequency": (3.4, 3.6)} if k else {},
            lines_detected=[True] * m,
            modes_detected=[True] * k,
            seconds=0.01,
        )


def test_run_table_and_plot_with_a_hand_made_fitter(tmp_path):
    res = rb.run(quick=True, n=2, cases=["clean", "noise_only"], fitters=[_Fake()], workers=1, log=lambda *a: None)
    json.dumps(res)
    rows = {(r["case"], r["param"]): r for r in res["rows"]}
    assert rows["clean", "mode frequency"]["coverage90"] == 1.0
    assert rows["clean", "mode frequency"]["median_rel_error"] == pytest.approx(0.0359 / 3.4641, rel=0.02)
    assert rows["clean", "line amplitude"]["line_detection"] == 1.0
    assert rows["noise_only", "-"]["false_detection"] == 1.0  # it claims the clean case's components
    # the oracle: the clean 10 s resonance gains ~200 in log-likelihood at the truth, 10x its threshold
    assert rows["clean", "mode damping"]["oracle_detection"] == 1.0 and rows["clean", "mode frequency"]["found"] == 1.0
    assert rows["clean", "line frequency"]["oracle_known_frequency"] is not None
    assert rows["clean", "line frequency"]["oracle_refit_detection"] is not None
    assert rows["noise_only", "-"]["oracle_detection"] is None and res["settings"]["oracle"] is True
    assert res["settings"]["durations_s"] == {"clean": 10.0, "noise_only": 10.0}
    text = rb.table(res)
    assert text.splitlines()[0].split()[:3] == ["case", "method", "parameter"]
    assert {"found", "oracle", "or_kf", "or_rf"} <= set(text.splitlines()[0].split())
    assert len(text.splitlines()) == 1 + len(res["rows"])
    rb.plot(res["rows"], tmp_path / "robustness.png")
    assert (tmp_path / "robustness.png").read_bytes()[:4] == b"\x89PNG"


def test_run_without_the_oracle_leaves_its_columns_empty():
    res = rb.run(
        quick=True, n=1, cases=["weak_drive"], fitters=[_Fake()], workers=1, log=lambda *a: None, with_oracle=False
    )
    assert all(r["oracle_detection"] is None and r["oracle_refit_detection"] is None for r in res["rows"])


def test_unknown_names_are_refused():
    with pytest.raises(ValueError, match="case"):
        rb.run(cases=["nope"], fitters=[_Fake()], log=lambda *a: None)
    with pytest.raises(ValueError, match="fitter"):
        rb.available_fitters(["nope"])


@pytest.mark.slow
def test_quick_run_end_to_end_with_the_available_fitters(tmp_path):
    """`run(quick=True, cases=["clean"], n=2)` with every fitter that can run here (ours once the
    modal model is there, celerite2, SSI-cov); the others are listed as skipped."""
    res = rb.run(quick=True, n=2, cases=["clean"], workers=1, log=lambda *a: None)
    methods = {r["method"] for r in res["rows"]}
    assert methods | set(res["skipped"]) == set(rb.QUICK_FITTERS)
    for r in res["rows"]:
        assert r["n"] == 2 and r["seconds"] > 0
    freq = {r["method"]: r for r in res["rows"] if r["param"] == "mode frequency"}
    for m in methods & {"ours", "celerite2"}:
        assert freq[m]["n_failed"] == 0 and freq[m]["median_rel_error"] < 0.05
    json.dumps(res)
    rb.plot(res["rows"], tmp_path / "r.png")


# ------------------------------------------------------------------ the oracle


def _autocovariance(mode, unit, kmax):
    """q's autocovariance at lags 0, unit, .., kmax unit: [Phi^k P]_00, Phi = expm(A unit)."""
    w, z = 2 * np.pi * mode["frequency"], mode["damping_ratio"]
    phi = expm(np.array([[0.0, 1.0], [-(w**2), -2 * z * w]]) * unit)
    x = np.diag([mode["rms"] ** 2, (w * mode["rms"]) ** 2])
    out = np.empty(kmax + 1)
    for k in range(kmax + 1):
        out[k] = x[0, 0]
        x = phi @ x
    return out


def _brute_force_log_likelihood(case, t, parts, y, truth, drop=None):
    """ln N(y; mean, C) of the observed samples from scratch: the oscillator's autocovariance by
    powers of the matrix exponential (`_autocovariance`), the noise's from its definition, the gain and the
    drift as the data set's own; `drop` ("modes"/"lines", i) leaves that component out."""
    from scipy.stats import multivariate_normal

    good = np.isfinite(y)
    tt, idx = t[good], np.flatnonzero(good)
    s = 1.0 + parts["gain"][good]
    lag = np.abs(tt[:, None] - tt[None, :])
    cov = {
        "white": lambda: case.sigma**2 * np.eye(tt.size),
        "ar1": lambda: case.sigma**2 * case.ar_phi ** np.abs(idx[:, None] - idx[None, :]),
        "1/f": lambda: sum(case.sigma**2 / 4 * np.exp(-lag / tau) for tau in case.flicker_times),
    }[case.noise]()
    unit = 1.0 / (case.fs * rb.FINE)  # every case's stamps lie on the fine grid
    steps = np.round(lag / unit).astype(int)
    for i, m in enumerate(truth["modes"]):
        if drop != ("modes", i):
            cov = cov + np.outer(s, s) * _autocovariance(m, unit, int(steps.max()))[steps]
    mean = np.full(tt.size, case.level)
    for j, ln in enumerate(truth["lines"]):
        if drop != ("lines", j):
            mean = mean + ln["amplitude"] * np.cos(2 * np.pi * ln["frequency"] * tt + ln["phase"])
    mean = s * mean + parts["drift"][good]
    return multivariate_normal.logpdf(y[good], mean, cov)


@pytest.mark.parametrize("name", ["ar1", "gaps", "irregular", "drift", "one_over_f", "gain_drift", "three_modes"])
def test_oracle_gain_is_the_dense_gaussian_log_likelihood_ratio(name):
    """On a 1.5 s record (300 samples; three_modes 20 s at 20 Hz, 400), each component's oracle gain, by
    the Kalman filter or the module's dense Gaussian, is ln L with it minus ln L without it from a
    brute-force dense Gaussian (autocovariances by powers of the matrix exponential): 1e-8 relative, the
    rounding of two log-likelihoods of ~-500 (each to ~1e-13 relative) over a gain of >= 0.1."""
    from dataclasses import replace

    case = replace(rb.CASES[name], duration=20.0 if name == "three_modes" else 1.5)
    out = rb.oracle(case, 3)
    t, parts, truth = rb.simulate_parts(case, 3)
    y = rb.simulate(case, 3).intensity
    assert [o["likelihood"] for o in out] == ["dense" if name in ("one_over_f", "gain_drift") else "kalman"] * len(out)
    full = _brute_force_log_likelihood(case, t, parts, y, truth)
    kinds = [(k, i) for k in ("modes", "lines") for i in range(len(truth[k]))]
    assert [o["kind"] for o in out] == [k for k, _ in kinds]
    for o, (kind, i) in zip(out, kinds):
        expected = full - _brute_force_log_likelihood(case, t, parts, y, truth, drop=(kind, i))
        assert abs(expected) > 0.1
        assert o["gain"] == pytest.approx(expected, rel=1e-8)
        assert o["detected"] == (o["gain"] > o["threshold"]) and o["threshold"] > o["threshold_known"]
    if out[0]["likelihood"] == "kalman":  # the dense path agrees on the cases the filter is exact for
        dense = rb.oracle(case, 3, likelihood="dense")
        np.testing.assert_allclose([o["gain"] for o in dense], [o["gain"] for o in out], rtol=1e-8)


def test_oracle_thresholds_are_the_order_search_and_detection_ones():
    """n = 4000 at 200 Hz over 20 s: a mode needs 1.5 ln n + ln M (M = (100 - 1/19.995) x 19.995,
    the order search's), a line the larger of that and 12.5 + ln N (N = prior width x (span + dt),
    the detection test's); at a known frequency 1.5 ln n, and max(1.5 ln n, 12.5) for a line."""
    out = {o["kind"]: o for o in rb.oracle("clean", 0)}
    span = 3999 / 200.0
    m = (100.0 - 1.0 / span) * span
    assert out["modes"]["threshold"] == pytest.approx(1.5 * math.log(4000) + math.log(m), rel=1e-12)
    assert out["modes"]["threshold_known"] == pytest.approx(1.5 * math.log(4000), rel=1e-12)
    n_line = (100.0 - 1.0 / span * (1 + 1e-9)) * 20.0
    assert out["lines"]["threshold"] == pytest.approx(12.5 + math.log(n_line), rel=1e-12)
    assert out["lines"]["threshold_known"] == 12.5
    with pytest.raises(ValueError, match="likelihood"):
        rb.oracle("one_over_f", 0, likelihood="kalman")  # four OU processes: not the filter's model
    with pytest.raises(ValueError, match="likelihood"):
        rb.oracle("clean", 0, likelihood="nope")
    assert rb.oracle("noise_only", 0) == []


def _line_information(case, seeds):
    """lambda = s' C^-1 s of each data set's line s (C: the resonance plus white noise, Toeplitz on
    the uniform 20 s record, its first column by powers of the matrix exponential)."""
    from scipy.linalg import solve_toeplitz

    t = rb.simulate_parts(case, seeds[0])[0]
    m = case.modes[0]
    col = _autocovariance({"frequency": m.frequency, "damping_ratio": m.damping_ratio, "rms": m.rms}, t[1], t.size - 1)
    col[0] += case.sigma**2
    ln = case.lines[0]
    x = np.column_stack([np.cos(2 * np.pi * ln.frequency * t), -np.sin(2 * np.pi * ln.frequency * t)])
    gram = x.T @ solve_toeplitz(col, x)  # s = A (cos phase, sin phase) . x: lambda a quadratic form
    lam = []
    for seed in seeds:
        phase = rb.simulate_parts(case, seed)[2]["lines"][0]["phase"]
        u = ln.amplitude * np.array([math.cos(phase), math.sin(phase)])
        lam.append(float(u @ gram @ u))
    return np.array(lam)


@pytest.mark.parametrize("name", ["weak_drive", "near_drive"])
def test_oracle_line_detection_rate_is_the_gaussian_prediction(name):
    """At the truth a line's gain is s' C^-1 (y - mean without it) - s' C^-1 s / 2 = lambda / 2 +
    s' C^-1 e: Gaussian, mean lambda / 2, variance lambda, exactly. Over seeds 0-49 the standardized
    gains are N(0, 1) (mean within 3 / sqrt 50, variance within 3 sqrt(2 / 49)), and the number of
    data sets passing each threshold is a sum of independent Bernoulli(p_s), p_s = P(N(lambda/2,
    lambda) > threshold): within 3 sd sqrt(sum p (1 - p)) of sum p, plus 1 for the discreteness.
    near_drive's amplitude is chosen so that the mean p_s (the expected oracle rate) is >= 0.97."""
    from scipy.stats import norm

    case = rb.CASES[name]
    seeds = list(range(50))
    lam = _line_information(case, seeds)
    tests = [next(o for o in rb.oracle(case, s) if o["kind"] == "lines") for s in seeds]
    gain = np.array([o["gain"] for o in tests])
    zs = (gain - lam / 2) / np.sqrt(lam)
    assert abs(zs.mean()) < 3 / math.sqrt(50) and abs(zs.var(ddof=1) - 1) < 3 * math.sqrt(2 / 49)
    for key, limit in (("detected", "threshold"), ("detected_known", "threshold_known")):
        p = norm.sf((tests[0][limit] - lam / 2) / np.sqrt(lam))
        hits = sum(o[key] for o in tests)
        assert abs(hits - p.sum()) <= 3 * math.sqrt(np.sum(p * (1 - p))) + 1, (key, hits, p.sum())
    p = norm.sf((tests[0]["threshold"] - lam / 2) / np.sqrt(lam))
    if name == "near_drive":
        assert p.mean() >= 0.97
    else:  # the weak drive is at the information limit: about half of the records decide it
        assert 0.2 < p.mean() < 0.7


def test_near_drive_simulates_the_weak_drive_with_the_stated_amplitude():
    """The 4 Hz line at A = 0.2 next to the resonance, in the clean case's noise; the line part is
    exactly A cos(2 pi 4 t + phase), and least squares on 10 records finds A within 0.02 (the mean of
    10 estimates of sd ~0.02 each: the noise density at 4 Hz is ~2.2 x the white 0.6^2 / 200)."""
    case = rb.CASES["near_drive"]
    assert case.lines == (rb.Line(4.0, 0.2),) and case.modes == rb.CASES["weak_drive"].modes
    assert rb.CASES["weak_drive"].lines == (rb.Line(4.0, 0.12),)
    est = []
    for seed in range(10):
        t, parts, truth = rb.simulate_parts("near_drive", seed)
        ln = truth["lines"][0]
        assert (ln["frequency"], ln["amplitude"]) == (4.0, 0.2)
        np.testing.assert_allclose(parts["lines"], 0.2 * np.cos(2 * np.pi * 4.0 * t + ln["phase"]), rtol=1e-12)
        x = np.column_stack([np.ones_like(t), np.cos(2 * np.pi * 4 * t), np.sin(2 * np.pi * 4 * t)])
        est.append(np.hypot(*np.linalg.lstsq(x, rb.simulate("near_drive", seed).intensity, rcond=None)[0][1:]))
    assert abs(np.mean(est) - 0.2) < 0.02


def test_score_reports_the_oracle_rates_of_each_kind():
    """oracle_detection counts every data set's components of the row's kind, failed fits included."""
    o = lambda kind, d, k: {"kind": kind, "detected": d, "detected_known": k}
    truths = [
        {**_truth(), "oracle": [o("modes", True, True), o("lines", False, True)]},
        {**_truth(), "oracle": [o("modes", False, True), o("lines", False, False)]},
    ]
    fits = [rb.FitOutcome(frequencies=[3.46], damping_ratios=[0.014], seconds=1), rb.FitOutcome(failed=True)]
    by = {r["param"]: r for r in rb.score("clean", "m", truths, fits)}
    assert by["mode damping"]["oracle_detection"] == 0.5 and by["mode damping"]["oracle_known_frequency"] == 1.0
    assert by["line amplitude"]["oracle_detection"] == 0.0 and by["line amplitude"]["oracle_known_frequency"] == 0.5
    assert by["mode frequency"]["found"] == 1.0 and by["line frequency"]["found"] == 0.0
    assert by["mode frequency"]["oracle_refit_detection"] is None  # no refitted gains
    truths[0]["oracle"][0]["detected_refit"] = True  # one refitted: the rate over that one
    assert rb.score("clean", "m", truths, fits)[0]["oracle_refit_detection"] == 1.0
    assert rb.score("clean", "m", [_truth()], fits[:1])[0]["oracle_detection"] is None  # no oracle: None


def test_oracle_refit_gain_of_a_lone_line_exceeds_the_truth_by_wilks():
    """The 10 Hz line, far from the resonance: refitting both orders (the full one from the truth,
    the one without the line likewise) raises its gain by the noise the line's three free parameters
    fit, chi2(3) / 2 asymptotically: mean 1.5, sd 1.22, so the mean over 8 quick records is 1.5
    within 3 x 1.22 / sqrt 8 = 1.3. A mode's refitted gain is far lower (the white noise, refitted
    without it, takes its variance); the dense cases have none."""
    out = [rb.oracle("clean", seed, quick=True, refit=True) for seed in range(8)]
    lines = [next(o for o in x if o["kind"] == "lines") for x in out]
    diff = np.array([o["gain_refit"] - o["gain"] for o in lines])
    assert abs(diff.mean() - 1.5) < 1.3
    assert all(o["detected_refit"] == (o["gain_refit"] > o["threshold"]) for o in lines)
    modes = [next(o for o in x if o["kind"] == "modes") for x in out]
    assert np.median([o["gain_refit"] - o["gain"] for o in modes]) < -5
    assert rb.oracle("one_over_f", 0, quick=True, refit=True)[0]["gain_refit"] is None
