"""Detection, not invention: a weak or absent line is not reported as detected."""

from tests.conftest import SNR10, fitted, frame_problem, simulate
from vibinverse.pipeline import run


def test_weak_line_is_not_reported_as_a_detection():
    prob = frame_problem(
        SNR10, "surfaces.roof.motion.drive_frequency=[95.0]", "surfaces.roof.motion.drive_amplitude=[0.01]"
    )  # line SNR ~1
    summary = run(prob, "map").summary()
    assert not summary["diagnostics"]["drive_detected"]


def test_noise_only_series_reports_no_detection():
    prob = frame_problem(
        "surfaces.roof.motion.drive_amplitude=[0.0]", "surfaces.roof.motion.noise_rms=0", "noise.sigma=0.05"
    )
    summary = run(prob, "map").summary()
    assert not summary["diagnostics"]["drive_detected"]
    assert not summary["diagnostics"]["resonance_detected"]


def test_a_vibration_absent_from_the_data_is_not_detected():
    table, series = simulate("roof_elastic", truth_overrides=("surfaces.roof.motion.center_deflection=0",), seed=5)
    _, summary = fitted(table, series)
    d = summary["diagnostics"]
    assert not d["vibration_detected"] and d["vibration_delta_loglike"] < d["vibration_threshold"]
