"""Building frame (11)-(16): linear modes, exact discretization, nonlinear quaternion dynamics."""

import math

import numpy as np
import pytest

from forward.errors import SceneError
from forward.motion.frame import (
    Drive,
    FrameMotion,
    FrameParameters,
    NonlinearFrame,
    linearize,
    mode_zoh,
    propagate_zoh,
    simulate_linear,
    slopes_of_attitude,
)
from forward.render import pixel_signal

PAPER = FrameParameters(1.0, 50.0, 50.0, (2 * np.pi) ** 2, 0.05, 4 * (2 * np.pi) ** 2, 0.05)
DRIVE = Drive(np.array([10.0]), np.array([1e-3]))


def test_paper_resonances():
    modal = PAPER.modal()
    expected = {"vertical": 2.0, "lateral": 4.0, "tilt": 2 * np.sqrt(3), "twist": 4 * np.sqrt(3)}
    for name, f in expected.items():
        assert modal[name][0] == pytest.approx(f, rel=1e-3)
    # the eigenvalues of A agree with the generalized stiffness and mass
    lin = linearize(PAPER)
    eig = lin.eigen_modes()
    np.testing.assert_allclose([eig[c][0] for c in ("x", "y", "z", "rx", "ry", "rz")], lin.frequencies_hz, rtol=1e-12)
    np.testing.assert_allclose([eig[c][1] for c in ("x", "y", "z", "rx", "ry", "rz")], lin.damping_ratios, rtol=1e-10)


def test_named_state_space():
    lin = linearize(PAPER)
    assert lin.a.shape == (12, 12) and lin.b_spring.shape == (12, 12) and lin.c.shape == (2, 12)
    assert lin.state_names[:6] == ("x", "y", "z", "rx", "ry", "rz") and lin.input_names[0] == "c0.x"
    assert lin.output_names == ("slope_x", "slope_y")


def test_modal_and_physical_parameters_convert_both_ways():
    modal = PAPER.modal()
    for pair in (("tilt", "lateral"), ("vertical", "twist")):
        back = FrameParameters.from_modal(50.0, 50.0, 1.0, **{k: modal[k] for k in pair})
        for name in ("k1", "b1", "k2", "b2"):
            assert getattr(back, name) == pytest.approx(getattr(PAPER, name), rel=1e-12)
    with pytest.raises(SceneError, match="exactly one"):
        FrameParameters.from_modal(50.0, 50.0, 1.0, tilt=(3.0, 0.01), vertical=(2.0, 0.01), lateral=(4.0, 0.01))


@pytest.mark.parametrize("field, value", [("mass", -1.0), ("k1", 0.0), ("k2", -5.0), ("b1", -0.1)])
def test_invalid_physical_parameters(field, value):
    kwargs = {"mass": 1.0, "lx": 50.0, "ly": 50.0, "k1": 1.0, "b1": 0.05, "k2": 1.0, "b2": 0.05}
    kwargs[field] = value
    with pytest.raises(SceneError, match=f"frame.{field}"):
        FrameParameters(**kwargs)


@pytest.mark.parametrize("f, zeta", [(3.46, 0.014), (0.05, 1e-4), (90.0, 0.5), (2.0, 1.5)])
def test_propagation_from_a_nonzero_start_equals_the_recursion(f, zeta):
    """x_{k+1} = Phi x_k + Gamma g_k from x_0 = x0, sample by sample: the IIR form's free response
    must be Phi^k x0 at row k (it was Phi^(k+1) x0 from row 1 on, a one-step jump of the stationary
    start that showed as a 5-30 sd one-step residual at the third sample of noise-free records)."""
    w = 2 * np.pi * f
    phi, gam = mode_zoh(w * w, 2 * zeta * w, 1.0, 1 / 200.0)
    rng = np.random.default_rng(1)
    g, x0 = rng.normal(size=400), np.array([0.7, -1.3 * w])
    x, xs = x0.copy(), np.empty((g.size, 2))
    for k in range(g.size):
        xs[k] = x
        x = phi @ x + gam * g[k]
    got = propagate_zoh(phi, gam, g, x0)
    for j in range(2):  # position and velocity, each to 1e-11 of its largest value
        np.testing.assert_allclose(got[:, j], xs[:, j], rtol=0, atol=1e-11 * np.abs(xs[:, j]).max())
    np.testing.assert_array_equal(propagate_zoh(phi, gam, g[:1], x0), x0[None, :])


def test_lfilter_propagation_equals_the_generic_exact_discretization():
    fs, n = 200.0, 3000
    rng = np.random.default_rng(0)
    noise = rng.normal(0, 1e-4, (n, 12))
    q, dq = simulate_linear(PAPER, None, 1e-4, fs, n, rng, base_noise=noise)
    phi, gam = linearize(PAPER).discretize(1 / fs)
    x, xs = np.zeros(12), np.empty((n, 12))
    for k in range(n):
        xs[k] = x
        x = phi @ x + gam @ noise[k]
    np.testing.assert_allclose(xs[:, :6], q, atol=1e-12 * np.abs(q).max())
    np.testing.assert_allclose(xs[:, 6:], dq, atol=1e-12 * np.abs(dq).max())


def test_nonlinear_and_linear_tilt_agree_at_1mm_drive_over_20s():
    fs = 200.0
    t = np.arange(4000) / fs
    q, dq = simulate_linear(PAPER, DRIVE, 0.0, fs, t.size, np.random.default_rng(0))
    nl = NonlinearFrame(PAPER)
    states = nl.simulate(t, nl.state_from_linear(q[0], dq[0]), DRIVE, rtol=1e-9, atol=1e-15)
    hx, hy = slopes_of_attitude(states)
    amp = np.abs(q[:, 3]).max()
    assert np.abs(hy - q[:, 3]).max() < 0.01 * amp
    assert np.abs(hx + q[:, 4]).max() < 0.01 * np.abs(q[:, 4]).max()


@pytest.mark.slow
def test_nonlinear_conserves_energy_through_the_flat_equilibrium():
    undamped = FrameParameters(1.0, 50.0, 50.0, (2 * np.pi) ** 2, 0.0, 4 * (2 * np.pi) ** 2, 0.0)
    nl = NonlinearFrame(undamped)
    # starts exactly flat (the Euler-angle singularity) and spins about all three axes
    s0 = np.concatenate([[1e-3, -2e-3, 3e-3], np.zeros(3), [1.0, 0.0, 0.0, 0.0], [0.02, -0.015, 0.01]])
    t = np.linspace(0.0, 25.0, 501)  # 50 periods and more: its modes lie at 2-4 Hz
    states = nl.simulate(t, s0, rtol=1e-9, atol=1e-15)
    energy = np.array([nl.energy(s) for s in states])
    assert np.abs(energy / energy[0] - 1).max() < 1e-6
    hx, hy = slopes_of_attitude(states)
    assert np.all(np.isfinite(hx)) and np.hypot(hx, hy).max() > 1e-3  # it really tilts, through 0 and back


@pytest.mark.parametrize("zeta", [1e-4, 0.99])
def test_extreme_damping_ratios_are_finite_and_stationary(zeta):
    params = FrameParameters.from_modal(50.0, 50.0, 1.0, tilt=(2 * np.sqrt(3), zeta), lateral=(4.0, 0.01))
    rng = np.random.default_rng(1)
    q, _ = simulate_linear(params, None, 1e-4, 200.0, 200_000, rng)
    assert np.all(np.isfinite(q))
    lin = linearize(params)
    # stationary variance of a ZOH-driven oscillator, against the simulation (started stationary)
    from scipy.linalg import solve_discrete_lyapunov

    from forward.motion.frame import mode_zoh

    phi, gam = mode_zoh(lin.stiffness[3], lin.damping[3], lin.mass[3], 1 / 200.0)
    var_g = 1e-8 * lin.force_spring[3] @ lin.force_spring[3]
    p = solve_discrete_lyapunov(phi, var_g * np.outer(gam, gam))
    if zeta > 0.5:  # many independent cycles: the sample variance is sharp
        assert q[:, 3].var() == pytest.approx(p[0, 0], rel=0.05)
    else:  # ~1 correlation time in the record: only the order of magnitude is testable
        assert 0.05 < q[:, 3].var() / p[0, 0] < 20


def test_drive_near_nyquist_and_noise_only():
    rng = np.random.default_rng(2)
    fs = 200.0
    q, _ = simulate_linear(PAPER, Drive(np.array([0.95 * fs / 2]), np.array([1e-3])), 0.0, fs, 4000, rng)
    spec = np.abs(np.fft.rfft(q[:, 3]))
    assert np.fft.rfftfreq(4000, 1 / fs)[spec.argmax()] == pytest.approx(95.0, abs=0.1)
    q, _ = simulate_linear(PAPER, None, 1e-4, fs, 4000, rng)
    assert np.all(np.isfinite(q)) and q[:, 3].std() > 0


def test_a_million_samples():
    q, dq = simulate_linear(PAPER, DRIVE, 1e-4, 200.0, 1_000_000, np.random.default_rng(3))
    assert q.shape == (1_000_000, 6) and np.all(np.isfinite(q)) and np.all(np.isfinite(dq))


def test_frame_needs_uniform_times():
    m = FrameMotion(PAPER, DRIVE, 1e-4)
    with pytest.raises(SceneError, match="uniform"):
        m.prepare(np.array([0.0, 0.1, 0.3]), np.random.default_rng(0))


def test_sec_4_2_signal_has_lines_at_tilt_resonance_and_drive(scene):
    from scipy.signal import periodogram

    s = scene("roof_frame")
    x = pixel_signal(s, seed=5)
    f, p = periodogram(x - x.mean(), s.sampling.fs)
    drive_line = p[np.argmin(abs(f - 10.0))]
    band = (f > 3.2) & (f < 3.75)
    assert drive_line > 100 * np.median(p)
    assert p[band].max() > 100 * np.median(p)
    assert 3.3 < f[band][np.argmax(p[band])] < 3.65  # the tilt resonance 2 sqrt(3) = 3.46 Hz, noise-broadened
    assert np.median(p[(f > 20)]) < drive_line / 1e3


def test_seeded_frame_signal_is_reproducible(scene):
    s = scene("roof_frame", "sampling.duration=2")
    np.testing.assert_array_equal(pixel_signal(s, seed=1), pixel_signal(s, seed=1))
    assert not np.array_equal(pixel_signal(s, seed=1), pixel_signal(s, seed=2))


def test_nonlinear_model_runs_in_a_scene(scene):
    lin = pixel_signal(scene("roof_frame", "sampling.duration=1", "surfaces.roof.motion.noise_rms=0"))
    nonlin = pixel_signal(
        scene(
            "roof_frame",
            "sampling.duration=1",
            "surfaces.roof.motion.noise_rms=0",
            "surfaces.roof.motion.model='nonlinear'",
        )
    )
    ac = lin - lin.mean()
    assert np.abs(nonlin - lin).max() < 0.01 * np.abs(ac).max()


@pytest.mark.parametrize(
    "override, message",
    [
        ("surfaces.roof.motion.mass=-1", "mass"),
        ("surfaces.roof.motion.k_vertical=-3", "k_vertical"),
        ("surfaces.roof.motion.drive_frequency=[100.0]", "Nyquist"),
        ("surfaces.roof.motion.drive_amplitude=[1e-3, 1e-3]", "one amplitude per drive_frequency"),
        ("surfaces.roof.motion.drive_plane=[[1,0,0],[1,0,0]]", "perpendicular"),
    ],
)
def test_invalid_frame_scenes(scene, override, message):
    with pytest.raises(SceneError, match=message):
        scene("roof_frame", override)


def test_mode_zoh_closed_form_equals_the_matrix_exponential():
    from scipy.linalg import expm

    from forward.motion.frame import mode_zoh

    for zeta in (0.0, 1e-6, 0.0138, 0.5, 0.9, 0.95, 1.0, 2.0):  # above 0.9: the matrix exponential path
        for f, dt in ((3.46, 1 / 200), (99.0, 1 / 200), (0.1, 1e-3)):
            w, mass = 2 * math.pi * f, 2.0
            k, c = mass * w * w, 2 * zeta * w * mass
            aug = np.zeros((3, 3))
            aug[0, 1], aug[1, 0], aug[1, 1], aug[1, 2] = dt, -k / mass * dt, -c / mass * dt, dt / mass
            ref = expm(aug)
            phi, gam = mode_zoh(k, c, mass, dt)
            assert np.abs(phi - ref[:2, :2]).max() <= 1e-12 * np.abs(ref[:2, :2]).max()
            assert np.abs(gam - ref[:2, 2]).max() <= 1e-12 * np.abs(ref[:2, 2]).max()
