"""The verdict: which lines are detected, where, how surely, and whether the fit can be trusted."""

import math

import pytest

from vibinverse.verdict import format_probability, format_value, verdict

K = "surfaces.roof.motion."


def summary(**over):
    """A converged MCMC summary of the frame: drive and resonance detected, residuals white."""
    p = lambda median, sd, units, **kw: {
        "median": median,
        "sd": sd,
        "q05": median - 1.645 * sd,
        "q95": median + 1.645 * sd,
        "map": median,
        "units": units,
        "rhat": 1.004,
        "ess_bulk": 900.0,
        "ess_tail": 700.0,
        **kw,
    }
    s = {
        "method": "mcmc",
        "approximation": None,
        "parameters": {
            K + "tilt_frequency": p(3.4661, 0.0041, "Hz", rhat=1.008),
            K + "tilt_damping_ratio": p(0.01, 0.001, "1"),
            K + "drive_frequency": p(10.00002, 0.00011, "Hz"),
            "noise.sigma": p(0.6, 0.01, "DN"),
        },
        "diagnostics": {
            "converged": True,
            "rhat_max": 1.008,
            "ess_min": 700.0,
            "drive_delta_loglike": 900.0,
            "drive_threshold": 18.7,
            "drive_detected": True,
            "drive_false_alarm_probability": 1e-300,
            "resonance_delta_loglike": 240.0,
            "resonance_threshold": 18.7,
            "resonance_detected": True,
            "resonance_false_alarm_probability": 3e-101,
            "residual_checks": {"ljung_box_p": 0.41, "lags": 20, "normality_p": 0.6, "white": True, "normal": True},
        },
    }
    for key, value in over.items():
        section, _, name = key.partition("__")
        if value is None:
            s[section].pop(name, None)
        else:
            s[section][name] = value
    return s


def test_the_headline_of_a_trustworthy_fit():
    v = verdict(summary())
    assert v.trusted is True
    assert v.headline == (
        "drive line detected at 10.00002 +- 0.00011 Hz; tilt resonance detected at 3.466 +- 0.004 Hz; "
        "fit trustworthy (R-hat 1.008, residuals white)"
    )
    drive, resonance = v.lines
    assert (drive.what, drive.parameter, drive.uncertainty_kind) == ("drive", K + "drive_frequency", "sd")
    assert resonance.false_alarm_probability == 3e-101 and resonance.label == "tilt resonance"


def test_a_line_not_detected_gives_its_false_alarm_probability():
    v = verdict(summary(diagnostics__drive_detected=False, diagnostics__drive_false_alarm_probability=0.68))
    assert v.lines[0].text() == "drive line not detected (false-alarm probability 0.68)"
    assert v.headline.startswith("drive line not detected (false-alarm probability 0.68); tilt resonance detected")


def test_not_converged_is_not_trusted():
    v = verdict(summary(diagnostics__converged=False))
    assert v.trusted is False and "has not converged" in v.reasons[0]
    assert v.headline.endswith("fit NOT trustworthy: not converged (R-hat 1.008, ESS 700)")
    s = summary()
    s["parameters"]["noise.sigma"]["rhat"] = 1.05  # one parameter's R-hat is enough
    assert verdict(s).trusted is False


def test_residuals_decide_too():
    v = verdict(summary(diagnostics__residual_checks=None))
    assert v.trusted is None and "residuals not checked" in v.reasons
    assert v.headline.endswith("trust not decided (residuals not checked, R-hat 1.008)")
    bad = {"ljung_box_p": 1e-5, "lags": 20, "normality_p": 0.5, "white": False, "normal": True}
    v = verdict(summary(diagnostics__residual_checks=bad))
    assert v.trusted is False and "not white (Ljung-Box p = 1e-05 over 20 lags)" in v.reasons[0]
    assert v.headline.endswith("fit NOT trustworthy: residuals not white")
    # a long record's Ljung-Box test detects autocorrelations too small to matter: passed, and said so
    small = {**bad, "ljung_box_p": 8e-4, "spectral_departure": 0.064, "white": True, "alpha": 0.01}
    v = verdict(summary(diagnostics__residual_checks=small))
    assert v.trusted is True
    assert "Ljung-Box p = 0.0008 over 20 lags, autocorrelations 0.06 in all: immaterial" in " ".join(v.reasons)


def test_an_approximation_has_no_rhat_and_can_fail_on_its_hessian():
    s = summary(diagnostics__converged=None)
    s["method"], s["approximation"] = "map", "laplace"
    v = verdict(s)
    assert v.trusted is True and v.headline.endswith("fit trustworthy (Laplace approximation, residuals white)")
    s["diagnostics"]["hessian_positive_definite"] = False
    assert verdict(s).trusted is False


def test_without_an_sd_the_uncertainty_is_half_the_90_percent_interval():
    s = summary()
    s["parameters"][K + "tilt_frequency"].update(sd=None, q05=3.40, q95=3.50)
    line = verdict(s).lines[1]
    assert line.uncertainty_kind == "half the 90 % interval" and line.uncertainty == pytest.approx(0.05)
    assert line.where() == "at 3.47 +- 0.05 Hz"


def test_a_detected_frequency_without_uncertainty_leaves_trust_undecided():
    s = summary(diagnostics__converged=None)
    s["method"], s["approximation"] = "spectral", "spectral"
    s["parameters"][K + "drive_frequency"].update(sd=None, q05=None, q95=None)
    v = verdict(s)
    assert v.trusted is None and v.lines[0].where() == "at 10.00002 +- n/a Hz"
    assert v.headline.endswith(
        "trust not decided (no uncertainty for the drive line, spectral approximation, residuals white)"
    )


def test_vibration_lines_map_to_their_frequencies():
    f = lambda v: {"median": v, "sd": 0.01, "units": "Hz"}
    s = {
        "method": "map",
        "parameters": {K + "frequency[0]": f(12.0), K + "frequency[1]": f(31.0), "noise.sigma": f(1.0)},
        "diagnostics": {
            **{f"vibration_{i}_detected": True for i in (0, 1)},
            **{f"vibration_{i}_delta_loglike": 50.0 for i in (0, 1)},
        },
    }
    a, b = verdict(s).lines
    assert (a.label, a.parameter, b.label, b.parameter) == (
        "vibration 0",
        K + "frequency[0]",
        "vibration 1",
        K + "frequency[1]",
    )
    assert verdict(s).headline.startswith("vibration 0 detected at 12.000 +- 0.010 Hz; vibration 1 detected at 31.000")


def test_a_crafted_summary_never_raises():
    s = {
        "method": ["x"],
        "parameters": {"<b>": "not a dict", K + "drive_frequency": {"median": "10", "sd": {}, "units": 3}},
        "diagnostics": {
            "drive_detected": "yes",
            "drive_threshold": "<script>",
            "<x>_detected": True,
            "residual_checks": {"white": "no"},
            "multimodal": "noise",
            "ambiguous": 3,
        },
    }
    v = verdict(s)
    assert [ln.detected for ln in v.lines] == [False, True] and isinstance(v.headline, str)
    assert verdict({}).headline == "no line tested; trust not decided (residuals not checked, Laplace approximation)"


@pytest.mark.parametrize(
    ("value", "sd", "text"),
    [
        (3.4661, 0.0041, "3.466 +- 0.004"),
        (10.00002, 0.0001, "10.00002 +- 0.00010"),
        (1234.5, 56.0, "1234 +- 56"),
        (0.5, math.nan, "0.5 +- n/a"),
        (math.nan, 0.1, "n/a"),
        (2.0e-6, 3.0e-8, "0.00000200 +- 0.00000003"),
    ],
)
def test_format_value(value, sd, text):
    assert format_value(value, sd) == text


def test_format_probability():
    assert [format_probability(p) for p in (0.68, 0.012, 3.1e-7, 0.0, None)] == [
        "0.68",
        "0.012",
        "3.1e-07",
        "< 1e-300",
        "n/a",
    ]


def test_a_line_test_that_names_its_frequency_is_shown_with_that_frequency():
    # the modal model's tests: modes and lines, each naming the parameter that holds its frequency
    f = lambda v: {"median": v, "sd": 0.01, "units": "Hz"}
    s = {
        "method": "map",
        "parameters": {"modes[0].frequency": f(2.3), "lines[0].frequency": f(5.1), "noise.sigma": f(1.0)},
        "diagnostics": {
            "line_0_detected": True,
            "line_0_delta_loglike": 40.0,
            "line_0_frequency_parameter": "lines[0].frequency",
            "mode_0_detected": True,
            "mode_0_delta_loglike": 90.0,
            "mode_0_frequency_parameter": "modes[0].frequency",
        },
    }
    by_what = {line.what: line for line in verdict(s).lines}
    assert by_what["line_0"].parameter == "lines[0].frequency" and by_what["line_0"].value == 5.1
    assert by_what["mode_0"].parameter == "modes[0].frequency" and by_what["mode_0"].value == 2.3


def test_a_slow_sway_in_the_pixels_leaves_trust_undecided_and_gives_detects_reading():
    s = summary(diagnostics__slow_sway=[{"frequency": 2 / 9, "cycles": 2.0, "resolution": 1 / 9}])
    v = verdict(s)
    assert v.trusted is None and "a slow sway: intervals not calibrated" in v.headline
    (reason,) = [r for r in v.reasons if "slow line" in r]
    assert "2 cycles in the record" in reason and "0.2222 +- 0.11 Hz" in reason
    assert verdict(summary(diagnostics__slow_sway=[])).trusted is True  # none: nothing said


def test_a_broad_hump_and_a_product_read_as_such_with_or_without_a_fitted_frequency():
    from vibinverse.verdict import VerdictLine

    line = VerdictLine("mode_2", "mode 2", False, 900.0, 20.0, 1e-9, broad=True)
    assert line.text() == "mode 2: a broad hump, not claimed as a resonance"
    line.parameter, line.value, line.uncertainty = "modes[2].frequency", 4.47, 0.08
    assert line.text() == "mode 2 at 4.47 +- 0.08 Hz: a broad hump, not claimed as a resonance"
    product = VerdictLine("line_3", "line 3", False, 50.0, 20.0, 1e-9, product="120 + 2 x 100 Hz")
    assert product.text() == "line 3: 120 + 2 x 100 Hz, a product of stronger tones, not claimed"
