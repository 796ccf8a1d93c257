"""The robustness bench's scene column: its simulator keeps what each case promises, and a data set
goes through the fitters to the scored rows."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import periodogram

from vibinverse.bench import robustness_scene as rs


@pytest.fixture(scope="module")
def clean_parts():
    return rs.simulate_parts("clean", 4)


def test_truth_is_the_papers_roof():
    """Sec. 4.2: tilt 2 sqrt 3 Hz, damping ratio 0.01378, drive 10 Hz of 1 mm; the analyst says sigma 0.6."""
    truth = rs.scene_truth()
    assert truth["tilt_frequency"] == pytest.approx(2 * math.sqrt(3), rel=1e-12)
    assert truth["tilt_damping_ratio"] == pytest.approx(0.0137832223855448, rel=1e-9)
    assert truth["drive_frequency"] == 10.0 and truth["drive_amplitude"] == 1e-3
    assert rs.analyst_scene()["noise"]["sigma"] == 0.6


@pytest.mark.parametrize("case", ["clean", "irregular", "gain_drift"])
def test_data_sets_are_reproducible_per_case_and_seed(case):
    a, b, c = rs.simulate(case, 3, duration=5.0), rs.simulate(case, 3, duration=5.0), rs.simulate(case, 4, duration=5.0)
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert not np.array_equal(a.intensity, c.intensity)
    assert a.truth == b.truth


def test_cases_differ_for_one_seed():
    """The seed is drawn per (case, seed): gaps' data are not clean's with holes."""
    a, b = rs.simulate_parts("clean", 0, duration=5.0), rs.simulate_parts("gaps", 0, duration=5.0)
    assert not np.allclose(a[1]["signal"], b[1]["signal"])


def test_clean_is_the_forward_signal_plus_white_noise_of_sd_0_6(clean_parts):
    """The sensor noise is the case's alone (forward's is off): sd 0.6 (sampling sd ~1 % at n = 4000)."""
    t, parts, truth = clean_parts
    assert t.size == 4000 and truth["n"] == 4000
    np.testing.assert_allclose(np.diff(t), 0.005, rtol=1e-9)
    assert abs(parts["noise"].std() / 0.6 - 1) < 0.05
    assert abs(np.mean(parts["noise"])) < 4 * 0.6 / math.sqrt(4000)
    assert not parts["gaps"].any() and not parts["drift"].any() and not parts["gain"].any()
    _, clean = rs.forward_signal(0, duration=20.0)
    assert np.std(np.diff(clean)) < 0.2  # the forward signal itself carries no white noise (sd 0.6 would give 0.85)


def test_ar1_noise_has_its_variance_and_lag1_correlation():
    """phi 0.9 (lag-1 sd sqrt((1 - phi^2) / n) = 0.007 at n = 4000) and sd 0.6 (variance sd ~5 % with
    the correlation); no white noise on top: the noise part is the whole residual."""
    for seed in (0, 1):
        _, parts, truth = rs.simulate_parts("ar1", seed)
        e = parts["noise"]
        assert truth["noise"] == "ar1"
        assert abs(np.corrcoef(e[:-1], e[1:])[0, 1] - 0.9) < 0.03
        assert abs(e.std() / 0.6 - 1) < 0.15
        y = rs.simulate("ar1", seed).intensity
        np.testing.assert_allclose(y - parts["signal"], e, atol=1e-9)


def test_one_over_f_noise_has_total_sd_0_6():
    """4 OU processes of equal variance: the slowest (10 s) makes one record's sd wander, so the
    variance is checked over 6 records (each within a factor 2)."""
    var = [rs.simulate_parts("one_over_f", s, duration=20.0)[1]["noise"].var() for s in range(6)]
    assert min(var) > 0.25 * 0.36 and max(var) < 4 * 0.36
    assert abs(np.mean(var) / 0.36 - 1) < 0.35


def test_drift_is_three_signal_sd_peak_to_peak():
    _, parts, truth = rs.simulate_parts("drift", 2)
    assert np.ptp(parts["drift"]) == pytest.approx(3.0 * np.std(parts["signal"]), rel=1e-9)
    assert truth["signal_sd"] == pytest.approx(np.std(parts["signal"]))


def test_gain_multiplies_the_whole_intensity_within_bounds():
    _, parts, _ = rs.simulate_parts("gain_drift", 1)
    assert np.abs(parts["gain"]).max() == pytest.approx(0.2, rel=1e-12)
    y = rs.simulate("gain_drift", 1).intensity
    np.testing.assert_allclose(y, (1 + parts["gain"]) * parts["signal"] + parts["noise"], rtol=1e-12)
    # the level moves by the gain: the record's mean intensity times g dominates
    assert np.ptp(y) > 0.2 * np.mean(parts["signal"])


def test_gaps_are_ten_percent_nan_in_runs():
    d = rs.simulate("gaps", 5)
    mask = np.isnan(d.intensity)
    assert mask.mean() == pytest.approx(0.10, abs=1 / 4000)
    assert not mask[0] and not mask[-1]
    starts = np.flatnonzero(np.diff(mask.astype(int)) == 1)
    assert 4000 * 0.10 / 40 <= starts.size <= 4000 * 0.10 / 5


def test_irregular_stamps_are_jittered_and_dropped():
    """Stamps on the 1/20 grid, each within 20 % of an interval of its nominal place, 10 % dropped;
    the signal at each stamp is the fine simulation's there."""
    t, _, _ = rs.simulate_parts("irregular", 1, duration=5.0)
    assert t.size == round(0.9 * 1000)
    fine = np.rint(t * 200.0 * rs.FINE)
    np.testing.assert_allclose(t * 200.0 * rs.FINE, fine, atol=1e-6)
    nominal = np.rint(t * 200.0 - 0.2)  # stamps lie in [k - 0.2, k + 0.2] intervals after a 0.2 offset
    assert np.all(np.abs(t * 200.0 - 0.2 - nominal) <= 0.2 + 1e-9)
    assert np.all(np.diff(t) > 0)
    tf, _ = rs.forward_signal(0, rs.FINE, duration=5.0)  # seed 0 is not this data set's: only the grid
    assert tf.size == 20 * 1000 and fine.max() < tf.size


def test_boxcar_samples_are_block_means_of_the_fine_signal():
    """Each sample is the mean of the FINE fine-grid samples of its frame, stamped at their centre."""
    seed = int(rs._rng("boxcar", 2).integers(2**32))  # the forward seed simulate_parts draws first
    tf, yf = rs.forward_signal(seed, rs.FINE, duration=5.0)
    t, parts, _ = rs.simulate_parts("boxcar", 2, duration=5.0)
    assert t.size == 1000
    np.testing.assert_allclose(parts["signal"], yf.reshape(1000, rs.FINE).mean(axis=1), rtol=1e-13)
    np.testing.assert_allclose(t, tf.reshape(1000, rs.FINE).mean(axis=1), rtol=1e-13)
    np.testing.assert_allclose(np.diff(t), 0.005, rtol=1e-9)
    assert parts["signal"].std() < yf.std()  # averaging removes some variance, never adds


def _resonance_power(t: np.ndarray, y: np.ndarray) -> float:
    """The periodogram's power over 3.2-3.75 Hz: the tilt resonance (zeta f = 0.048 Hz wide)."""
    f, p = periodogram(y - y.mean(), fs=1.0 / (t[1] - t[0]))
    band = (f > 3.2) & (f < 3.75)
    return float(p[band].sum() * (f[1] - f[0]))


def test_fine_grid_keeps_the_resonance_amplitude():
    """The forward model holds its white base motion over each of its samples, so a grid 20x finer
    has 20x less low-frequency base noise unless noise_rms is scaled by sqrt(20). With the scaling
    the tilt resonance's power (fine signal read every 20th sample) matches the nominal simulation's:
    over 3 records of 200 s (a 20 s tilt correlation time: ~10 % sd each, ~8 % on the ratio of
    means) within 30 %; without it, it would be 1/20."""
    nominal = [_resonance_power(*rs.forward_signal(s, 1, duration=200.0)) for s in range(3)]
    fine = []
    for s in range(3):
        t, y = rs.forward_signal(10 + s, rs.FINE, duration=200.0)
        fine.append(_resonance_power(t[:: rs.FINE], y[:: rs.FINE]))
    ratio = np.mean(fine) / np.mean(nominal)
    assert 0.7 < ratio < 1.3


def test_nonlinear_case_uses_the_nonlinear_frame_and_stays_close():
    """The nonlinear model is weak at 1 mm: with the same forward seed its signal differs from the
    linear one's by a start transient that decays at the tilt's zeta omega (0.3 / s), then by far
    less than the sensor noise, but it differs."""
    case = rs.SCENE_CASES["nonlinear"]
    assert rs.scene_table(case.overrides)["surfaces"]["roof"]["motion"]["model"] == "nonlinear"
    _, lin = rs.forward_signal(7, duration=10.0)
    _, non = rs.forward_signal(7, overrides=case.overrides, duration=10.0)
    diff = non - lin
    first, last = np.std(diff[:400]), np.std(diff[-400:])
    assert 0 < last < 0.05 * rs.SIGMA and last < 0.3 * first


# ------------------------------------------------------------------ outcomes and scores


def _summary(terms=None, q=(0.9, 1.1)):
    entry = lambda v: {"median": v, "q05": v * q[0], "q95": v * q[1]}
    p = {f"surfaces.roof.motion.{k}": entry(v) for k, v in rs.scene_truth().items()}
    model = {"terms": terms} if terms else None
    return {
        "parameters": p,
        "approximation": None,
        "diagnostics": {"n_steps": 10, "converged": True},
        "data": {"model": model},
    }


def test_scene_outcome_reads_the_summary():
    o = rs.scene_outcome(_summary("AR(1) noise"))
    assert o.terms == "AR(1) noise" and o.posterior == "emcee" and o.converged is True
    assert set(o.values) == set(rs.PARAMS.values())
    assert rs.scene_outcome(_summary()).terms == "white noise"


def test_score_counts_errors_coverage_and_terms():
    truth = {**rs.scene_truth(), "case": "x", "seed": 0}
    good = rs.scene_outcome(_summary("AR(1) noise"))
    off = rs.scene_outcome(_summary("gain drift", q=(1.2, 1.3)))  # the interval misses every truth
    failed = rs.SceneOutcome(failed=True, note="boom")
    rows = rs.score("x", "ours-scene", [truth] * 3, [good, off, failed])
    assert [r["param"] for r in rows] == list(rs.PARAMS)
    r = rows[0]
    assert r["n"] == 3 and r["n_failed"] == 1 and r["n_intervals"] == 2
    assert r["coverage90"] == 0.5 and r["coverage_se"] == pytest.approx(0.5 / math.sqrt(2))
    assert r["median_rel_error"] == 0.0
    assert r["terms"] == {"AR(1) noise": 1, "gain drift": 1}
    json.dumps(rows)


def test_modal_outcome_takes_the_nearest_mode_and_line(monkeypatch):
    from vibinverse.bench import robustness_bench as rb
    from vibinverse.bench.robustness_fit import FitOutcome

    fake = FitOutcome(
        frequencies=[2.0, 3.5, 6.9],
        damping_ratios=[0.1, 0.02, 0.03],
        line_frequencies=[4.0, 10.01],
        line_amplitudes=[0.1, 0.2],
        intervals={"modes[1].frequency": (3.4, 3.6), "lines[1].frequency": (10.0, 10.02)},
        posterior="importance",
    )
    monkeypatch.setattr(rb.ModalFitter, "fit", lambda self, t, y, order=None: fake)
    o = rs.ModalSceneFitter().fit(np.zeros(3), np.zeros(3))
    assert o.values == {"tilt_frequency": 3.5, "tilt_damping_ratio": 0.02, "drive_frequency": 10.01}
    assert o.intervals == {"tilt_frequency": (3.4, 3.6), "drive_frequency": (10.0, 10.02)}


def test_a_failed_fit_is_recorded_but_an_interrupt_stops_the_bench(monkeypatch):
    import vibinverse as vi
    from vibinverse.bench import robustness_bench as rb
    from vibinverse.bench.robustness_fit import FitOutcome
    from vibinverse.errors import Interrupted

    def boom(*a, **k):
        raise ValueError("no optimum\nsecond line")

    monkeypatch.setattr(vi, "fit", boom)
    t, y = np.arange(100) / 200.0, np.random.default_rng(0).normal(size=100)
    o = rs.SceneFitter().fit(t, y)
    assert o.failed and o.note == "ValueError: no optimum" and not o.values
    monkeypatch.setattr(vi, "fit", lambda *a, **k: (_ for _ in ()).throw(Interrupted("stopped", 15)))
    with pytest.raises(Interrupted):
        rs.SceneFitter(white=True).fit(t, y)
    stopped = FitOutcome(failed=True, note="Interrupted: stopped")
    monkeypatch.setattr(rb.ModalFitter, "fit", lambda self, t, y, order=None: stopped)
    with pytest.raises(Interrupted):
        rs.ModalSceneFitter().fit(t, y)


@pytest.mark.slow
def test_one_data_set_of_a_case_through_the_scorer(tmp_path):
    """clean, seed 0, every fitter: rows for each, the modal fit without drive amplitude, the records
    file scores to the same rows, the table names the chosen terms (the frame likelihood with gaps:
    `tests/vibinverse/models/test_frame.py`)."""
    records = tmp_path / "fits.jsonl"
    res = rs.run(n=1, cases=["clean"], records=records)
    rows = res["rows"]
    assert {(r["case"], r["method"]) for r in rows} == {("clean", m) for m in rs.FITTERS}
    assert all(r["n_failed"] == 0 for r in rows), res["notes"]
    tilt = [r for r in rows if r["param"] == "tilt frequency"]
    assert all(r["median_rel_error"] < 0.05 for r in tilt)
    assert not any(r["param"] == "drive amplitude" for r in rows if r["method"] == "ours")
    assert rs.rows_from_fits(rs.read_records(records), ["clean"], list(rs.FITTERS)) == json.loads(json.dumps(rows))
    text = rs.table(res)
    assert "terms chosen by ours-scene on clean" in text
    json.dumps(res)


def test_bench_robustness_scene_merges_into_robustness_json(tmp_path, capsys, monkeypatch):
    """--robustness --scene keeps an earlier run's modal columns and puts its own under "scene"
    (the run itself stands in: it takes minutes), --fitters chooses the fitters; --scene alone,
    unknown cases or fitters and --workers or --fitters without --scene are refused."""
    from tests.conftest import run_cli
    from vibinverse.cli import main

    seen = {}

    def fake_run(**kw):
        seen.update(kw)
        Path(kw["records"]).write_text("[]\n")
        return {"rows": [], "fits": [], "notes": [], "settings": {"n": 1}, "seconds": 0.1}

    monkeypatch.setattr(rs, "run", fake_run)
    (tmp_path / "robustness.json").write_text(json.dumps({"rows": [{"case": "clean"}], "settings": {}}))
    code = main(["bench", "--robustness", "--scene", "--cases", "ar1,drift", "--workers", "1", "-o", str(tmp_path)])
    assert code in (0, None), capsys.readouterr().err
    doc = json.loads((tmp_path / "robustness.json").read_text())
    assert doc["rows"] == [{"case": "clean"}] and doc["scene"]["settings"] == {"n": 1}
    assert seen["cases"] == ["ar1", "drift"] and seen["workers"] == 1 and seen["quick"] is False
    assert seen["fitters"] is None  # all three
    args = ["bench", "--robustness", "--scene", "--cases", "ar1", "--fitters", "ours-scene", "-o", str(tmp_path)]
    assert main(args) in (0, None), capsys.readouterr().err
    assert seen["fitters"] == ["ours-scene"] and seen["cases"] == ["ar1"]
    assert (tmp_path / "robustness_scene.txt").read_text().startswith("case")
    for args, message in (
        (["--scene"], "--scene: the scene column"),
        (["--robustness", "--scene", "--cases", "nope"], "--cases: 'nope'"),
        (["--robustness", "--workers", "1"], "--workers: only with --robustness --scene"),
        (["--robustness", "--scene", "--fitters", "ours,celerite2"], "--fitters: 'celerite2'; allowed: ours-scene"),
        (["--robustness", "--scene", "--fitters", ","], "--fitters: none given"),
        (["--realdata", "--fitters", "ours"], "--fitters: only with --robustness --scene"),
    ):
        r = run_cli("bench", *args, "-o", str(tmp_path / "x"))
        assert r.returncode == 2 and message in r.stderr, r.stderr
    assert not (tmp_path / "x").exists()
