"""Shear buildings: the modes solve K phi = omega^2 M phi (and match the uniform chain's closed
form), the zero-order-hold discretization matches the closed-form SDOF responses, the filtered
recursion equals the plain one, and the simulated records have the analytic stationary variance per
mode and their spectral peaks at the modal frequencies (the oracle of the OMA bench's truth)."""

import math
import time

import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov
from scipy.signal import find_peaks, welch

from forward.errors import SceneError
from forward.motion import shear_building as sb
from forward.motion.shear_building import (
    ShearBuilding,
    TwoWayShearBuilding,
    modal_response,
    rayleigh_damping_ratios,
    simulate,
    stationary_modal_variance,
    unit_shapes,
    zoh,
)


def three_storey(zeta=0.02):
    return ShearBuilding.with_first_frequency(3, 2.0, zeta)


# ------------------------------------------------------------------ the modes


def test_modes_solve_the_generalized_eigenproblem_and_are_mass_normalized():
    b = ShearBuilding(4, [2.0e5, 1.8e5, 1.5e5, 1.0e5], [4e8, 3.5e8, 3e8, 2e8], [0.01, 0.012, 0.015, 0.02])
    m = b.modal()
    k, mm = b.stiffness_matrix, b.mass_matrix
    np.testing.assert_allclose(k @ m.shapes, mm @ m.shapes * m.omegas**2, rtol=1e-10, atol=1e-6)
    np.testing.assert_allclose(m.shapes.T @ mm @ m.shapes, np.eye(4), atol=1e-12)
    assert np.all(np.diff(m.frequencies) > 0)
    for col in m.shapes.T:  # sign convention: the largest-magnitude component positive
        assert col[np.argmax(np.abs(col))] > 0
    # classical damping: the damping matrix is diagonal in the modes, 2 zeta omega
    np.testing.assert_allclose(
        m.shapes.T @ b.damping_matrix @ m.shapes, np.diag(2 * m.damping_ratios * m.omegas), atol=1e-9
    )


def test_uniform_chain_matches_its_closed_form():
    """Equal masses m and storey stiffnesses k: omega_j = 2 sqrt(k / m) sin((2j - 1) pi / (2 (2n + 1)))."""
    n, mass, k = 6, 1.2e5, 3.0e8
    b = ShearBuilding(n, mass, k, 0.01)
    j = np.arange(1, n + 1)
    closed = 2 * np.sqrt(k / mass) * np.sin((2 * j - 1) * np.pi / (2 * (2 * n + 1))) / (2 * np.pi)
    np.testing.assert_allclose(b.frequencies, closed, rtol=1e-12)


def test_prescribed_first_frequency_and_rayleigh_anchors():
    b = ShearBuilding.with_first_frequency(5, 1.2, 0.015, stiffness_profile=[1.0, 0.9, 0.8, 0.7, 0.6])
    assert b.frequencies[0] == pytest.approx(1.2, rel=1e-12)
    f = b.frequencies
    z = rayleigh_damping_ratios(f, (f[0], 0.01), (f[-1], 0.02))
    assert z[0] == pytest.approx(0.01) and z[-1] == pytest.approx(0.02)
    assert np.all((z > 0.005) & (z < 0.02 + 1e-12))


def test_two_way_building_shares_channels_between_directions():
    x = ShearBuilding.with_first_frequency(4, 1.50, 0.01)
    y = ShearBuilding.with_first_frequency(4, 1.53, 0.012, stiffness_profile=[1.0, 1.0, 0.3, 0.18])
    b = TwoWayShearBuilding(x, y)
    m = b.modal()
    np.testing.assert_allclose(m.frequencies[:2], [1.50, 1.53], rtol=1e-12)
    obs, names = b.observation([(2, 0.0), (2, 90.0), (3, 45.0)])
    assert names == ("storey2x", "storey2y", "storey3@45deg")
    shapes = obs @ m.shapes
    assert shapes[1, 0] == 0.0 and shapes[0, 1] == 0.0  # an x sensor does not see a y mode, and back
    x_phi = x.modal().shapes[:, 0]
    assert shapes[2, 0] == pytest.approx(math.cos(math.pi / 4) * x_phi[2], rel=1e-12)
    with pytest.raises(SceneError, match="storey 5"):
        b.observation([5])


def test_unit_shapes_convention():
    s = unit_shapes(np.array([[1.0, -3.0, 0.0], [-2.0, 1.0, 0.0]]))
    np.testing.assert_allclose(np.linalg.norm(s[:, :2], axis=0), 1.0)
    np.testing.assert_allclose(s[:, 0], np.array([-1.0, 2.0]) / math.sqrt(5))
    np.testing.assert_allclose(s[:, 1], np.array([3.0, -1.0]) / math.sqrt(10))
    assert np.all(s[:, 2] == 0)


# ------------------------------------------------------------------ the exact discretization


def test_zoh_matches_the_closed_form_sdof_responses():
    """Phi's first column is the free response from unit displacement, Gamma the response to a unit
    force held from rest: q(h) = (1 - e^(-zeta w h) (cos wd h + zeta w / wd sin wd h)) / w^2."""
    f, zeta, h = 3.3, 0.017, 0.013
    w = 2 * math.pi * f
    wd = w * math.sqrt(1 - zeta**2)
    e = math.exp(-zeta * w * h)
    c, s = math.cos(wd * h), math.sin(wd * h)
    phi, gamma = zoh(f, zeta, h)
    np.testing.assert_allclose(phi[0], [e * (c + zeta * w / wd * s), e * s / wd], rtol=1e-12)
    np.testing.assert_allclose(phi[1], [-e * w * w / wd * s, e * (c - zeta * w / wd * s)], rtol=1e-12)
    np.testing.assert_allclose(gamma, [(1 - e * (c + zeta * w / wd * s)) / w**2, e * s / wd], rtol=1e-10)


@pytest.mark.parametrize("quantity", sb.QUANTITIES)
def test_filtered_response_equals_the_plain_recursion(quantity):
    m = three_storey().modal()
    rng = np.random.default_rng(1)
    forces, x0, fs = rng.standard_normal((400, 3)), rng.standard_normal((3, 2)), 40.0
    r, x_end = modal_response(m, fs, forces, x0, quantity)
    p = forces @ m.shapes
    for k in range(3):
        ph, g = zoh(m.frequencies[k], m.damping_ratios[k], 1 / fs)
        x, w, z = x0[k].copy(), m.omegas[k], m.damping_ratios[k]
        ref = []
        for n in range(400):
            ref.append(
                {"displacement": x[0], "velocity": x[1]}.get(quantity, -w * w * x[0] - 2 * z * w * x[1] + p[n, k])
            )
            x = ph @ x + g * p[n, k]
        np.testing.assert_allclose(r[:, k], ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
        np.testing.assert_allclose(x_end[k], x, rtol=1e-9)


def test_chunks_join_without_a_seam(monkeypatch):
    b = three_storey()
    args = (b, 50.0, 20.0, [1, 2, 3])
    for forcing in ("white", "coloured"):
        whole = simulate(*args, forcing=forcing, seed=4)[1]
        monkeypatch.setattr(sb, "_CHUNK", 97)
        pieces = simulate(*args, forcing=forcing, seed=4)[1]
        monkeypatch.undo()
        np.testing.assert_allclose(pieces, whole, rtol=1e-10, atol=1e-12 * np.abs(whole).max())


# ------------------------------------------------------------------ the oracle: variances and spectra


def _modal(values, building):
    """Modal coordinates from every floor's record: u = Phi q, so q = Phi^T M u."""
    m = building.modal()
    return values @ (building.mass_matrix @ m.shapes)


def _variance_se(phi, gamma, s2, h, n, lags=20000):
    """(stationary variance of q'' + feedthrough or of q / q', relative sd of a sample variance over n
    samples): P per mode by the discrete Lyapunov equation with noise Gamma Gamma^T s2, the
    autocovariance gamma_j = h Phi^j P h^T (+ s2 at lag 0 for the feedthrough), Var(s^2) ~ (2 / n)
    sum_j gamma_j^2."""
    p = solve_discrete_lyapunov(phi, np.outer(gamma, gamma) * s2)
    hv, feed = h
    acov, cur = [], p.copy()
    for _ in range(lags):
        acov.append(hv @ cur @ hv)
        cur = phi @ cur
    acov = np.array(acov)
    var = acov[0] + feed * s2
    acov[0] = var
    rel = math.sqrt(2.0 / n * (acov[0] ** 2 + 2 * np.sum(acov[1:] ** 2))) / var
    return var, rel


@pytest.mark.parametrize("quantity", sb.QUANTITIES)
def test_simulated_modal_variance_is_the_analytic_stationary_variance(quantity):
    """White held forcing of sd 1 N on each floor: mode k's force p_k = phi_k^T f has variance
    |phi_k|^2; the sample variance of each modal coordinate over a long record equals its stationary
    variance (discrete Lyapunov, computed here from `zoh` alone) within 4 sampling sd, and agrees with
    `stationary_modal_variance`; the displacement also with continuous white noise's
    s^2 dt |phi|^2 / (4 zeta omega^3) to O((omega dt)^2)."""
    b = three_storey()
    m = b.modal()
    fs, duration = 50.0, 4000.0
    _, y, _ = simulate(b, fs, duration, [1, 2, 3], quantity=quantity, seed=11)
    q = _modal(y, b)
    n = q.shape[0]
    module = stationary_modal_variance(b, fs, quantity)
    for k in range(3):
        ph, g = zoh(m.frequencies[k], m.damping_ratios[k], 1 / fs)
        w, z = m.omegas[k], m.damping_ratios[k]
        h = {
            "displacement": (np.array([1.0, 0.0]), 0.0),
            "velocity": (np.array([0.0, 1.0]), 0.0),
            "acceleration": (np.array([-w * w, -2 * z * w]), 1.0),
        }[quantity]
        s2 = float(np.sum(m.shapes[:, k] ** 2))
        var, rel = _variance_se(ph, g, s2, h, n, lags=min(n, int(20 * fs / (z * w))))
        assert module[k] == pytest.approx(var, rel=1e-9)
        assert abs(np.var(q[:, k]) / var - 1) < 4 * rel, (k, np.var(q[:, k]) / var, rel)
        if quantity == "displacement":
            continuous = s2 / fs / (4 * z * w**3)
            assert var == pytest.approx(continuous, rel=0.2 * (w / fs) ** 2 + 1e-3)


def test_coloured_records_start_stationary():
    """Over many short records the variance at the first and at the last sample are both the
    stationary one (no start-up transient); the forcing's AR(1) coefficient is exp(-2 pi fc / fs)."""
    b = ShearBuilding.with_first_frequency(2, 1.0, 0.02)
    fs = 20.0
    first, last = [], []
    for seed in range(400):
        _, y, truth = simulate(
            b, fs, 2.0, [2], quantity="acceleration", forcing="coloured", forcing_corner=1.5, seed=seed
        )
        first.append(y[0, 0])
        last.append(y[-1, 0])
    sd = truth["response_sd"][0]
    assert truth["forcing_ar"] == pytest.approx(math.exp(-2 * math.pi * 1.5 / fs))
    se = math.sqrt(2 / 400)  # relative sd of a variance over 400 independent draws
    assert abs(np.var(first) / sd**2 - 1) < 4 * se
    assert abs(np.var(last) / sd**2 - 1) < 4 * se


def test_periodogram_peaks_at_the_modal_frequencies():
    b = three_storey(0.015)
    _, y, truth = simulate(b, 50.0, 6000.0, [1, 2, 3], seed=2)
    f, p = welch(y[:, 2], fs=50.0, nperseg=4096)
    idx, props = find_peaks(np.log(p), prominence=1.0)
    top = np.sort(f[idx[np.argsort(props["prominences"])[::-1][:3]]])
    damped = truth["frequencies"] * np.sqrt(1 - truth["damping_ratios"] ** 2)
    # each within a quarter of its half-power band (2 zeta f wide) and 2 bins: a peak this broad
    # wanders over a few bins from one record to the next
    tol = np.maximum(0.5 * truth["damping_ratios"] * damped, 2 * (f[1] - f[0]))
    assert np.all(np.abs(top - damped) < tol), (top, damped, tol)


# ------------------------------------------------------------------ the record: truth, noise, drift


def test_truth_shapes_noise_and_drift():
    b = TwoWayShearBuilding(
        ShearBuilding.with_first_frequency(4, 1.5, 0.01), ShearBuilding.with_first_frequency(4, 2.5, 0.01)
    )
    ch = [(2, 0.0), (4, 0.0), (4, 90.0), (3, 45.0)]
    args = (b, 25.0, 600.0, ch)
    t, clean, truth = simulate(*args, seed=5)
    _, noisy, _ = simulate(*args, noise_rms=0.1, seed=5)
    _, drifting, tr_d = simulate(*args, drift=0.5, seed=5)
    assert t.shape == (15000,) and clean.shape == (15000, 4)
    assert truth["channels"] == ("storey2x", "storey4x", "storey4y", "storey3@45deg")
    obs, _ = b.observation(ch)
    np.testing.assert_allclose(truth["shapes"], unit_shapes(obs @ b.modal().shapes))
    np.testing.assert_allclose(np.linalg.norm(truth["shapes"], axis=0), 1.0)
    # the response sd is the record's (stationary), the noise and the drift are added on top of the same draw
    assert np.all(np.abs(clean.std(0) / truth["response_sd"] - 1) < 0.15)
    noise = noisy - clean
    np.testing.assert_allclose(noise.std(0) / (0.1 * truth["response_sd"]), 1.0, atol=0.03)
    walk = drifting - clean
    assert np.all(walk[0] == 0.0)
    steps = np.diff(walk, axis=0).std(0)
    np.testing.assert_allclose(steps, tr_d["drift_step_sd"], rtol=0.03)
    np.testing.assert_allclose(tr_d["drift_step_sd"], 0.5 * truth["response_sd"] * math.sqrt(2 / 14999), rtol=1e-12)


def test_acceleration_feedthrough_is_the_inverse_mass():
    """Phi Phi^T = M^-1 for a complete mass-normalized basis: a floor force's direct share of the
    floor accelerations."""
    b = ShearBuilding(3, [1.0, 2.0, 4.0], [10.0, 20.0, 30.0], 0.02)
    s = b.modal().shapes
    np.testing.assert_allclose(s @ s.T, np.diag([1.0, 0.5, 0.25]), atol=1e-12)


def test_bad_inputs_name_the_key():
    b = three_storey()
    with pytest.raises(SceneError, match="quantity"):
        simulate(b, 10.0, 10.0, [1], quantity="jerk")
    with pytest.raises(SceneError, match="forcing"):
        simulate(b, 10.0, 10.0, [1], forcing="pink")
    with pytest.raises(SceneError, match="damping_ratios"):
        ShearBuilding(3, 1.0, 1.0, [0.01, 0.02])
    with pytest.raises(SceneError, match="storey 4"):
        simulate(b, 10.0, 10.0, [4])


@pytest.mark.slow
def test_two_hours_at_200_hz_on_12_channels_take_seconds():
    x = ShearBuilding.with_first_frequency(6, 0.5, 0.01)
    y = ShearBuilding.with_first_frequency(6, 0.95, 0.015)
    ch = [(s, a) for s in range(1, 7) for a in (0.0, 90.0)]
    t0 = time.perf_counter()
    _, v, _ = simulate(TwoWayShearBuilding(x, y), 200.0, 7200.0, ch, forcing="coloured", noise_rms=0.1, drift=0.2)
    assert v.shape == (1_440_000, 12) and np.all(np.isfinite(v))
    assert time.perf_counter() - t0 < 60.0  # ~6 s on 2 shared cores
