"""The frame model (sec. 4.2): its likelihood against the forward model's linear frame, its
drive-mean kernel, fittable geometry, and fits of simulated sec. 4.2 data."""

import numpy as np
import pytest

from forward.scene_file import load_scene
from tests.conftest import SCENES, SNR10, K, frame_problem
from vibinverse.fisher import crlb_sd
from vibinverse.io.series import validate
from vibinverse.models import build_model
from vibinverse.pipeline import run
from vibinverse.posterior import Posterior


def within(summary, truth, names, n_sd):
    for n in names:
        p = summary["parameters"][n]
        assert abs(p["map"] - truth[n]) <= n_sd * p["sd"], (n, p, truth[n])


def test_map_recovers_the_frame_and_its_sd_matches_the_cramer_rao_bound():
    prob = frame_problem(SNR10)
    summary = run(prob, "map").summary()
    truth = prob.truth()
    within(
        summary,
        truth,
        [K + n for n in ("tilt_frequency", "tilt_damping_ratio", "drive_frequency", "drive_amplitude")],
        3,
    )
    crlb = crlb_sd(prob.model, truth, [K + "drive_frequency", K + "drive_amplitude", K + "drive_phase"])
    assert summary["parameters"][K + "drive_frequency"]["sd"] / crlb[K + "drive_frequency"] == pytest.approx(
        1.0, abs=0.5
    )
    assert summary["diagnostics"]["drive_detected"] and summary["diagnostics"]["resonance_detected"]


def test_ten_percent_gaps():
    prob = frame_problem(SNR10, gaps=0.1)
    assert 0.08 < prob.series.n_gaps / prob.series.time.size < 0.12
    summary = run(prob, "map").summary()
    within(summary, prob.truth(), [K + "tilt_frequency", K + "drive_frequency", K + "drive_amplitude"], 3)


def test_drive_line_near_nyquist():
    # far above the 3.46 Hz resonance the tilt response falls as (3.46/95)^2: a 4 cm drive and low
    # sensor noise keep the line detectable (a weak one is reported as not detected, tested below)
    prob = frame_problem(
        "noise.sigma=0.05", "surfaces.roof.motion.drive_frequency=[95.0]", "surfaces.roof.motion.drive_amplitude=[0.04]"
    )
    summary = run(prob, "map").summary()
    assert summary["diagnostics"]["drive_detected"]
    p = summary["parameters"][K + "drive_frequency"]
    assert abs(p["map"] - 95.0) <= 3 * p["sd"]


def test_fast_likelihood_components_equal_the_forward_models_linear_frame():
    """The likelihood scales a unit frame's tilt rows and writes the ZOH in closed form; the
    forward model's `linearize`, `steady_state` and matrix-exponential ZOH are the oracle."""
    from scipy.linalg import expm

    from forward.motion.frame import Drive, FrameParameters, linearize, steady_state

    prob = frame_problem(SNR10)
    like = prob.model
    values = {**prob.truth(), K + "tilt_frequency": 3.1, K + "tilt_damping_ratio": 0.05, K + "drive_phase": 0.4}
    c = like.components(values)
    m = like.base["surfaces"][like.roof]["motion"]
    params = FrameParameters.from_modal(like.lx, like.ly, like.mass, tilt=(3.1, 0.05), lateral=(4.0, 0.004))
    lin = linearize(params)
    plane = np.array(m["drive_plane"], dtype=float)
    drive = Drive(
        np.array([values[K + "drive_frequency"]]),
        np.array([values[K + "drive_amplitude"]]),
        int(m.get("drive_corner", 0)),
        plane[0],
        plane[1],
        np.array([0.4]),
    )
    q, _ = steady_state(lin, drive, like.t, coords=slice(3, 5))
    gx, gy = -q[:, 1], q[:, 0]
    hs = like.hess
    mean = (
        like.x0
        + like.jac[0] * gx
        + like.jac[1] * gy
        + 0.5 * (hs[0, 0] * gx**2 + 2 * hs[0, 1] * gx * gy + hs[1, 1] * gy**2)
    )
    assert np.abs(c.mean - mean).max() <= 1e-12 * np.ptp(mean)
    aug = np.zeros((3, 3))
    i = 4 if abs(like.jac[0]) > 0 else 3
    aug[0, 1] = like.dt
    aug[1, 0], aug[1, 1], aug[1, 2] = (
        -lin.stiffness[i] / lin.mass[i] * like.dt,
        -lin.damping[i] / lin.mass[i] * like.dt,
        like.dt / lin.mass[i],
    )
    assert np.abs(c.phi[:2, :2] - expm(aug)[:2, :2]).max() < 1e-12


def test_frame_geometry_is_fittable_through_the_observation():
    """A geometry value re-forms the observation: the likelihood equals one built from a scene with
    that value, and a MAP with the view angle free recovers it (the casadi MAP, which holds the
    observation fixed, hands over to the scipy MAP)."""
    import copy

    from vibinverse.models.frame import FrameModel
    from vibinverse.priors import Prior
    from vibinverse.scene_keys import set_value

    problem = frame_problem(SNR10, "footprint.resolution=32")
    table = problem.model.base
    view = float(load_scene(SCENES / "roof_frame.toml", [])[0].sensor.inclination)
    other = copy.deepcopy(table)
    set_value(other, "sensor.inclination", view + 0.004)
    ref = FrameModel(other, problem.series).log_likelihood({})
    assert problem.model.log_likelihood({"sensor.inclination": view + 0.004}) == pytest.approx(ref, rel=1e-12)
    assert problem.model.log_likelihood({}) != pytest.approx(ref, rel=1e-6)
    free = {
        K + "drive_amplitude": Prior("uniform", (0.0, 0.05)),
        "sensor.inclination": Prior("normal", (view, 0.01)),
        "noise.sigma": Prior("loguniform", (0.01, 10.0)),
    }
    summary = run(Posterior(build_model(table, problem.series), free), "casadi", progress=False).summary()
    p = summary["parameters"]["sensor.inclination"]
    assert summary["method"] == "map" and abs(p["median"] - view) < 3 * p["sd"]


def test_compiled_drive_mean_equals_the_complex_exponential_on_a_long_series():
    """The drive mean's kernel (per-sample rotations re-anchored every 64 samples) against
    exp(i w t) in numpy: three lines up to 0.98 Nyquist over 200 000 samples."""
    from vibinverse.models.frame import FrameModel

    problem = frame_problem(SNR10, "footprint.resolution=32")
    t = np.arange(200_000) * 0.005 + 3.0
    like = FrameModel(problem.model.base, validate(t, np.sin(t), "grid"))
    assert like._grid is not None
    w = 2 * np.pi * np.array([10.0, 37.3, 98.0])
    qx, qy = np.array([1e-5 + 2e-5j, -3e-6j, 4e-6]), np.array([2e-6 - 1e-6j, 5e-6, 1e-6 + 1e-6j])
    fast = like._drive_mean(w, qx, qy, like.x0, like.jac, like.hess)
    like._grid = None
    slow = like._drive_mean(w, qx, qy, like.x0, like.jac, like.hess)
    # both round the phase w t (up to 6e5 rad here) to ~|w t| eps: the bound is that, not 1e-12
    phase_rounding = np.finfo(float).eps * w.max() * np.abs(t).max()
    assert np.abs(fast - slow).max() <= 4 * phase_rounding * np.ptp(slow)
    short = slice(0, 4000)  # where w t is small, the two agree to the level's ulps
    assert np.abs(fast[short] - slow[short]).max() <= 1e-10 * np.ptp(slow)


def test_camera_stamps_with_nine_significant_digits_are_a_uniform_grid():
    """Stamps printed with 9 significant digits (1e-8 s at 20 s) were refused as non-uniform."""
    problem = frame_problem(SNR10)
    s = problem.series
    rounded = np.array([float(f"{v:.9g}") for v in s.time + 12.34567891])  # a clock started earlier
    assert np.max(np.abs(rounded - 12.34567891 - s.time)) > 1e-6 * s.dt  # off the grid by up to 5e-8 s
    ntsc = validate(np.array([float(f"{k / 29.97:.9g}") for k in range(3000)]), np.sin(np.arange(3000.0)), "ntsc")
    assert ntsc.uniform
    stamped = validate(rounded, s.intensity, "camera", s.scene)
    assert stamped.uniform
    values = problem.truth()
    exact = build_model(problem.model.base, validate(s.time + 12.34567891, s.intensity, "x")).log_likelihood(values)
    model = build_model(problem.model.base, stamped)
    # the same likelihood to the stamps' rounding (a phase error of w * 5e-7 s on the 10 Hz drive)
    assert model.log_likelihood({**values}) == pytest.approx(exact, abs=0.05)
    jittered = validate(s.time + np.random.default_rng(0).uniform(-0.2, 0.2, s.time.size) * s.dt, s.intensity, "j")
    assert not jittered.uniform
