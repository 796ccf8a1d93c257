"""The deterministic model (plate roof, ground waves): the white-noise likelihood on the reduced
forward model, its default priors, fits with gaps, non-uniform sampling and the hard cases."""

import json

import numpy as np
import pytest

from forward.reduce import compile_scene
from forward.render import pixel_signal
from forward.scene_file import load_scene, scene_from_table
from tests.conftest import LOW_RES, SCENES, G, K, fitted, simulate, z_scores
from vibinverse.design.metrics import evaluate
from vibinverse.errors import VibinverseError
from vibinverse.io.series import validate
from vibinverse.models import build_model
from vibinverse.models.deterministic import DeterministicModel
from vibinverse.pipeline import run
from vibinverse.posterior import Posterior
from vibinverse.priors import Prior
from vibinverse.scene_keys import set_value


def test_mean_equals_the_dense_forward_model_away_from_the_scene_values():
    """The likelihood's mean re-formed for new motion values (frequency, amplitude, phase, gain)
    equals every-subpixel rendering of the scene with those values, to the Taylor bound."""
    table, series = simulate("roof_elastic", LOW_RES)
    like = DeterministicModel(table, series)
    values = {K + "frequency": 41.3, K + "center_deflection": 2e-3, K + "phase": 0.8, "sun.irradiance": 1.7}
    other = json.loads(json.dumps(table))
    for n, v in values.items():
        set_value(other, n, v)
    dense = pixel_signal(scene_from_table(other), series.time)
    mu = like.mean(values)
    bound = like.taylor_error(values)
    assert np.max(np.abs(mu - dense)) <= 1.7 * bound + 1e-12 * np.abs(dense).max()
    assert np.ptp(dense) > 1e3 * bound  # the check is not vacuous


def test_geometry_values_rebuild_the_scene():
    """Sun and view angles and the lobe width are fittable: the mean is the compiled scene there."""
    table, series = simulate("roof_elastic", LOW_RES)
    like = DeterministicModel(table, series)
    values = {"sun.inclination": 1.02, "surfaces.roof.lobe_width": 0.012, K + "center_deflection": 1.5e-3}
    other = json.loads(json.dumps(table))
    for n, v in values.items():
        set_value(other, n, v)
    ref = compile_scene(scene_from_table(other), series.time, force="taylor2").signal()
    np.testing.assert_allclose(like.mean(values), ref, rtol=1e-12)
    assert not np.allclose(like.mean(values), like.mean({}), rtol=1e-3)  # the angles matter


def test_log_likelihood_is_the_gaussian_density_with_shot_noise():
    table, series = simulate("roof_elastic", LOW_RES, "noise.photons_per_unit=1e4")
    like = DeterministicModel(table, series)
    mu = like.mean({})
    var = 0.05**2 + mu / 1e4
    r = series.intensity - mu
    expected = -0.5 * np.sum(r * r / var + np.log(2 * np.pi * var))
    assert like.log_likelihood({}) == pytest.approx(expected, rel=1e-12)


def test_plate_map_recovers_the_truth_and_its_sd_is_the_cramer_rao_bound():
    table, series = simulate("roof_elastic", seed=4)
    _problem, summary = fitted(table, series)
    assert all(abs(z) < 3.0 for z in z_scores(summary).values()), z_scores(summary)
    crb = evaluate(table, [K + "frequency", K + "center_deflection"], {})
    for n in (K + "frequency", K + "center_deflection"):
        # the Laplace sd at the fitted sigma against the bound at the true sigma: sigma's own
        # estimate scatters by 1/sqrt(2N) = 3 %; the nuisances differ (gain and phase vs DC and time)
        assert summary["parameters"][n]["sd"] / crb[f"crlb {n}"] == pytest.approx(1.0, abs=0.12)
    assert summary["diagnostics"]["vibration_detected"]
    assert summary["data"]["model"]["kind"] == "taylor2"


def test_data_in_other_units_are_absorbed_by_the_gain():
    """A sensor in digital numbers: the same series x 1000. The default gain prior follows the
    mean level, sun.irradiance comes out 1000x, and the amplitude is unchanged."""
    table, series = simulate("roof_elastic", LOW_RES, seed=12)
    _, ref = fitted(table, series)
    scaled = validate(series.time, 1000.0 * series.intensity, "dn", series.scene)
    table_dn = json.loads(json.dumps(table))
    table_dn["noise"]["sigma"] = 1000.0 * table["noise"]["sigma"]
    _, dn = fitted(table_dn, scaled)
    assert dn["parameters"]["sun.irradiance"]["median"] == pytest.approx(1000.0, rel=1e-3)
    a, b = (s["parameters"][K + "center_deflection"] for s in (ref, dn))
    assert b["median"] == pytest.approx(a["median"], abs=0.05 * a["sd"]) and b["sd"] == pytest.approx(a["sd"], rel=0.02)


def test_ten_percent_gaps_and_non_uniform_sampling():
    rng = np.random.default_rng(1)
    keep = np.sort(rng.choice(500, size=400, replace=False))  # a fifth of the samples never taken
    table, series = simulate("roof_elastic", seed=6, gaps=0.1, keep=keep)
    assert not series.uniform and series.n_gaps > 20
    _, summary = fitted(table, series)
    assert all(abs(z) < 3.0 for z in z_scores(summary).values()), z_scores(summary)
    assert summary["data"]["n_gaps"] == series.n_gaps


def test_line_near_nyquist_whose_harmonic_aliases():
    """f = 480 Hz at fs = 1 kHz: its 2f term aliases to 40 Hz; the model samples it as the data do."""
    table, series = simulate("roof_elastic", "surfaces.roof.motion.frequency=480", seed=7)
    _, summary = fitted(table, series)
    assert all(abs(z) < 3.0 for z in z_scores(summary).values()), z_scores(summary)


@pytest.mark.parametrize(
    "footprint, amplitude, sigma",
    [
        (
            ("footprint.x=[0.0, 50.0]", "footprint.y=[0.0, 50.0]"),
            1e-9,
            2e-8,
        ),  # quadrant: first order, ~1e-8 of the mean
        (("footprint.x=[-25.0, 25.0]", "footprint.y=[-25.0, 25.0]"), 1e-6, 2e-10),  # centred: first order cancels
    ],
)
def test_tiny_amplitudes_on_quadrant_and_centred_footprints(footprint, amplitude, sigma):
    """A 1e-9 m plate on the quadrant footprint, and a 1e-6 m plate on the centred one, where the
    first order cancels and the whole signal is the 2f term, ~1e-11 of the mean level: the Taylor
    AC keeps its digits and the fit finds the amplitude. (At 1e-9 m the centred signal is 1e-17 of
    the mean, below float64 itself.) On the centred footprint the sign of the amplitude is not
    observable (x ~ a^2), so the phase prior spans pi."""
    overrides = (*footprint, f"noise.sigma={sigma}", f"surfaces.roof.motion.center_deflection={amplitude}", LOW_RES)
    table, series = simulate("roof_elastic", *overrides, seed=8)
    free = {
        K + "frequency": Prior("uniform", (30.0, 50.0)),
        K + "center_deflection": Prior("loguniform", (amplitude / 100, amplitude * 100)),
        K + "phase": Prior("uniform", (-np.pi / 2, np.pi / 2)),
        "noise.sigma": Prior("loguniform", (sigma / 10, sigma * 10)),
    }
    summary = run(Posterior(build_model(table, series), free), "map", progress=False).summary()
    assert np.all(np.isfinite([v["median"] for v in summary["parameters"].values()]))
    assert all(abs(z) < 3.0 for z in z_scores(summary).values()), z_scores(summary)
    assert summary["parameters"][K + "center_deflection"]["sd"] < 0.05 * amplitude


def test_large_amplitude_switches_to_the_compiled_model():
    overrides = (LOW_RES, "noise.sigma=0.005")
    table, series = simulate(
        "roof_elastic", *overrides, truth_overrides=("surfaces.roof.motion.center_deflection=0.02",), seed=9
    )
    problem, summary = fitted(table, series)
    assert summary["data"]["model"]["kind"] == "compiled"
    assert summary["data"]["model"]["error_bound_at_fit"] > 0.1 * 0.005
    assert all(abs(z) < 3.0 for z in z_scores(summary).values()), z_scores(summary)
    # the compiled mean reuses one interpolant per surface over a box of modal coordinates (grown
    # when left): it equals the scene compiled afresh at each value, to the compiler's rtol
    like = problem.model
    for values in (
        {K + "center_deflection": 0.02},
        {K + "center_deflection": 0.035, K + "phase": 0.4, K + "frequency": 41.0},
        {K + "center_deflection": 0.001},
    ):
        level, ac = like.parts(values)
        dc, ref = compile_scene(scene_from_table(like.table_with(values)), series.time).parts()
        assert np.abs((level + ac) - (dc + ref)).max() <= 1e-5 * np.ptp(ref)


def test_zero_noise_that_is_not_free_is_a_clear_error():
    table, series = simulate("roof_elastic", LOW_RES)
    table["noise"]["sigma"] = 0.0
    with pytest.raises(VibinverseError, match=r"noise\.sigma"):
        Posterior(build_model(table, series), {K + "frequency": Prior("uniform", (30.0, 50.0))})


def test_scenes_the_fit_cannot_take_are_clear_errors():
    table, series = simulate(
        "ground_rayleigh",
        LOW_RES,
        "surfaces.ground.motion.frequency=[40.0, 40.0]",
        "surfaces.ground.motion.amplitude=[1e-3, 5e-4]",
    )
    with pytest.raises(VibinverseError, match="share the frequency 40 Hz"):
        build_model(table, series).default_priors()
    _, frame = load_scene(SCENES / "roof_frame.toml", [])
    frame["surfaces"]["wall"] = {
        "x": [30.0, 40.0],
        "y": [30.0, 40.0],
        "material": "ground",
        "motion": {"kind": "plate", "frequency": 40.0, "center_deflection": 1e-3},
    }
    t = np.arange(800) * 0.005
    with pytest.raises(VibinverseError, match=r"surfaces\.wall\.motion"):
        Posterior(build_model(frame, validate(t, np.sin(t), "x")), {"noise.sigma": Prior("loguniform", (0.1, 1))})


@pytest.mark.slow
def test_two_ground_lines_are_both_recovered():
    table, series = simulate(
        "ground_rayleigh",
        LOW_RES,
        "noise.sigma=1e-6",
        "surfaces.ground.motion.frequency=[40.0, 55.0]",
        "surfaces.ground.motion.amplitude=[1e-3, 5e-4]",
        "surfaces.ground.motion.phase=[0.5, 3.0]",
        seed=101,
    )
    _, summary = fitted(table, series, "casadi")  # Rayleigh frequencies move the shapes: the scipy MAP
    assert summary["method"] == "map"
    assert all(abs(z) < 3.0 for z in z_scores(summary).values()), z_scores(summary)
    d = summary["diagnostics"]
    assert d["vibration_0_detected"] and d["vibration_1_detected"]


def test_default_priors_partition_the_band_between_lines_and_centre_the_phase():
    table, series = simulate(
        "ground_rayleigh",
        LOW_RES,
        "noise.sigma=3e-6",
        "surfaces.ground.motion.frequency=[40.0, 55.0]",
        "surfaces.ground.motion.amplitude=[1e-3, 5e-4]",
        "surfaces.ground.motion.phase=[0.0, 3.0]",
    )
    free = build_model(table, series).default_priors()
    f0, f1 = free[G + "frequency[0]"].bounds, free[G + "frequency[1]"].bounds
    assert f0[1] == f1[0] == pytest.approx(47.5) and f1[1] == pytest.approx(500.0)
    assert free[G + "amplitude[1]"].bounds == (0.0, pytest.approx(0.05))
    for i, phase in enumerate((0.0, 3.0)):  # each window is 2 pi wide, centred within 0.5 rad of the true angle
        lo, hi = free[f"{G}phase[{i}]"].bounds
        assert hi - lo == pytest.approx(2 * np.pi) and abs(np.angle(np.exp(1j * (phase - 0.5 * (lo + hi))))) < 0.5


@pytest.mark.slow
def test_a_line_seen_only_at_second_order_gets_a_pi_phase_window_and_is_fitted(tmp_path):
    """Centred footprint: x ~ a^2 cos^2(w t + phase), so phase and phase + pi are one fit. The
    default prior is a pi window; the posterior is then one mode and holds the truth."""
    table, series = simulate(
        "roof_elastic",
        LOW_RES,
        "footprint.x=[-25.0, 25.0]",
        "footprint.y=[-25.0, 25.0]",
        "noise.sigma=2e-4",
        "surfaces.roof.motion.phase=2.0",
        seed=11,
    )
    free = build_model(table, series).default_priors()
    lo, hi = free[K + "phase"].bounds
    assert hi - lo == pytest.approx(np.pi)
    problem = Posterior(build_model(table, series), free)
    summary = run(problem, "mcmc", backend=tmp_path / "c.h5", max_steps=3000, progress=False).summary()
    assert not summary["diagnostics"]["multimodal"]
    assert summary["parameters"][K + "phase"]["truth"] == pytest.approx(lo + (2.0 - lo) % np.pi)  # modulo pi
    for n in (K + "frequency", K + "center_deflection", K + "phase"):
        p = summary["parameters"][n]
        assert p["q05"] <= p["truth"] <= p["q95"], (n, p)


def test_the_detection_null_keeps_the_mean_level_when_the_gain_is_free():
    """At second order the whole line moves the mean level (a^2 cos^2 = a^2 (1 + cos 2wt) / 2); the
    null of the detection test rescales the free gain so that its level is the fit's (a fitted gain
    would absorb it), and leaves a fixed gain alone (then the level is evidence of the line)."""
    table, series = simulate(
        "roof_elastic", LOW_RES, "footprint.x=[-25.0, 25.0]", "footprint.y=[-25.0, 25.0]", "noise.sigma=2e-4"
    )
    like = DeterministicModel(table, series)
    assert like.describe()["second_order"] == [K + "frequency"]
    values = {K + "frequency": 40.0, K + "center_deflection": 2e-3, K + "phase": 0.3, "sun.irradiance": 1.0}
    (test,) = like.line_tests(values, list(values))
    level = np.mean(like.mean(values))
    # the vibration's own level is ~3e-5 of the whole: a relative 1e-12 leaves it 2e-8 of its size
    assert np.mean(like.mean({**values, **test.null})) == pytest.approx(level, rel=1e-12)
    assert np.mean(like.mean({**values, K + "center_deflection": 0.0})) < level * (1 - 1e-6)  # the test is not vacuous
    (fixed,) = like.line_tests(values, [n for n in values if n != "sun.irradiance"])
    assert fixed.null == {K + "center_deflection": 0.0}
