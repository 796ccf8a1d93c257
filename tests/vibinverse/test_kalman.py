"""The Kalman likelihood against two oracles: the dense multivariate normal and celerite2; the
per-step filter (irregular stamps) against the fixed-step one, its numpy reference and the dense
normal at irregular times; the oscillator's closed-form discretization against the Van Loan matrix
exponential."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import multivariate_normal

from tests.conftest import held_reference
from vibinverse.kalman import (
    discretize_continuous,
    filter_steps,
    filter_two_states,
    held_oscillator_fill,
    held_stationary,
    hold_samples,
    log_likelihood,
    log_likelihood_reference,
    log_likelihood_steps,
    log_likelihood_steps_reference,
    oscillator_stationary,
    oscillator_tables,
    pointwise_log_likelihood,
    simulate,
    stationary_covariance,
    unique_steps,
    whiten,
    whiten_steps,
)


def small_model():
    a = np.array([[0.0, 1.0], [-((2 * np.pi * 3) ** 2), -0.4]])
    phi, q = discretize_continuous(a, np.array([0.0, 1.0]), 50.0, 0.02)
    phi = np.kron(np.eye(2), phi) + 0.0
    phi[2:, 2:] *= 0.97
    q = np.kron(np.eye(2), q)
    return phi, q, np.array([0.7, 0.0, -1.3, 0.1]), 0.05, stationary_covariance(phi, q)


def test_kalman_equals_the_dense_multivariate_normal_with_gaps():
    phi, q, h, r, p0 = small_model()
    n = 60
    # explicit covariance of y: Cov(x_i, x_j) = Phi^(i-j) P0 for the stationary process
    powers = [np.eye(4)]
    for _ in range(n):
        powers.append(phi @ powers[-1])
    cov = np.array(
        [[h @ (powers[i - j] @ p0 if i >= j else p0 @ powers[j - i].T) @ h for j in range(n)] for i in range(n)]
    ) + r * np.eye(n)
    y = np.random.default_rng(0).multivariate_normal(np.zeros(n), cov)
    y[[5, 17, 18, 40]] = np.nan
    keep = np.isfinite(y)
    dense = multivariate_normal(np.zeros(keep.sum()), cov[np.ix_(keep, keep)]).logpdf(y[keep])
    assert log_likelihood(y, phi, q, h, r, p0) == pytest.approx(dense, abs=1e-8)
    assert log_likelihood_reference(y, phi, q, h, r, p0) == pytest.approx(dense, abs=1e-8)


def test_kalman_equals_celerite2_sho():
    celerite2 = pytest.importorskip("celerite2")
    s0, w0, qf, dt, sig = 0.7, 2 * np.pi * 3.46, 20.0, 0.005, 0.3
    a = np.array([[0.0, 1.0], [-(w0**2), -w0 / qf]])
    phi, q = discretize_continuous(a, np.array([0.0, 1.0]), 2 * s0 * w0**4, dt)  # k(0) = S0 w0 Q
    t = np.arange(4000) * dt
    gp = celerite2.GaussianProcess(celerite2.terms.SHOTerm(S0=s0, w0=w0, Q=qf))
    gp.compute(t, yerr=sig)
    # any series compares the two likelihoods; an oscillating one exercises the model
    rng = np.random.default_rng(1)
    y = 20 * np.sin(w0 * t + rng.uniform(0, 6)) * np.exp(-0.01 * t) + rng.normal(0, sig, t.size)
    ours = log_likelihood(y, phi, q, np.array([1.0, 0.0]), sig**2, stationary_covariance(phi, q))
    assert ours == pytest.approx(gp.log_likelihood(y), abs=1e-6)


def test_compiled_kernels_are_cached_outside_the_package(tmp_path):
    """numba's cache goes to the user's cache directory: a cache inside an installed package
    outlives an uninstall and shadows a later editable install."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    import vibinverse

    package = Path(vibinverse.__file__).parent
    before = set(package.rglob("*.nbi"))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    code = (
        "import numpy as np\n"
        "from vibinverse.kalman import log_likelihood\n"
        "print(log_likelihood(np.zeros(8), np.eye(2) * 0.5, np.eye(2), np.ones(2), 1.0, np.eye(2)))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert set(package.rglob("*.nbi")) == before
    assert list((tmp_path / "vibinverse" / "numba").rglob("*.nbi"))


# ------------------------------------------------------------------ irregular stamps: per-step (Phi, Q)

W3 = 2 * np.pi * 3.46  # the paper's tilt resonance (rad/s)


def _scaled_errors(phi, q, ref_phi, ref_q, w):
    """Phi's error normwise in the states (q, q' / w), each Q entry's relative to its own scale
    (Q12 to sqrt(Q11 Q22): it crosses zero at half periods)."""
    d = np.diag([1.0, 1.0 / w])
    di = np.diag([1.0, w])
    e_phi = np.abs(d @ (phi - ref_phi) @ di).max() / np.abs(d @ ref_phi @ di).max()
    e_q = max(
        abs(q[0, 0] - ref_q[0, 0]) / ref_q[0, 0],
        abs(q[1, 1] - ref_q[1, 1]) / ref_q[1, 1],
        abs(q[0, 1] - ref_q[0, 1]) / np.sqrt(ref_q[0, 0] * ref_q[1, 1]),
    )
    return e_phi, e_q


WDT = np.array([1e-3, 0.05, 0.3, 0.49, 0.51, 1.0, np.pi / 2, np.pi, 2 * np.pi * 0.99, 2 * np.pi])  # w dt
ZETAS = [0.0, 1e-6, 1e-3, 0.0138, 0.3, 0.999, 0.999999, 1.0, 1.000001, 1.5]


@pytest.mark.parametrize("zeta", ZETAS)
def test_oscillator_tables_equal_the_van_loan_matrix_exponential(zeta):
    """Closed form against scipy's expm of the Van Loan block matrix to 1e-12, from w dt = 1e-3 (where
    Q11's closed form would cancel to 1e-10 and its series takes over) through the series' edge
    (w dt = 0.5) to a whole period: undamped, near-undamped, critically and over-damped. (Over-damped
    past w dt = pi, scipy's expm itself errs by 1e-11 and more; the 150-digit oracle below covers it.)"""
    wdt = WDT if zeta <= 1 else WDT[: int(np.searchsorted(WDT, np.pi, side="right"))]
    dts = wdt / W3
    phis, qs = oscillator_tables(W3, zeta, dts, kappa=2.5)
    a = np.array([[0.0, 1.0], [-(W3**2), -2 * zeta * W3]])
    for k, dt in enumerate(dts):
        ref_phi, ref_q = discretize_continuous(a, np.array([0.0, 1.0]), 2.5, dt)
        e_phi, e_q = _scaled_errors(phis[k], qs[k], ref_phi, ref_q, W3)
        assert e_phi < 1e-12 and e_q < 1e-12, (zeta, wdt[k], e_phi, e_q)


@pytest.mark.parametrize("zeta", [0.0, 1e-4, 0.0138, 0.3, 0.999, 1.0, 1.5])
@pytest.mark.parametrize("hz", [0.02, 3.46, 99.0])
def test_held_force_tables_equal_the_augmented_matrix_exponential(zeta, hz):
    """The held force's (Phi, Q) (`held_oscillator_fill`, the frame model's base noise) against the
    augmented exponential composed frame by frame, for one frame, two and seven (dropped frames),
    a jittered 1.2 frames and 1000 frames (squaring), from 0.02 Hz (w dt 6e-4, the integral's
    series) to 99 Hz at 200 frames a second (near Nyquist), undamped to over-damped: 1e-9 in the
    scaled norm of `_scaled_errors`; the stationary covariance against scipy's Lyapunov solver."""
    from scipy.linalg import solve_discrete_lyapunov

    w, frame = 2 * np.pi * hz, 0.005
    steps = np.array([frame, 2 * frame, 7 * frame, 1.2 * frame, 1000 * frame])
    phis, qs = np.zeros((steps.size, 2, 2)), np.zeros((steps.size, 2, 2))
    held_oscillator_fill(w, zeta * w, 2.5, steps, frame, phis, qs, 0)
    for k, step in enumerate(steps):
        ref_phi, ref_q = held_reference(w, zeta, frame, step)
        if (zeta - np.sqrt(max(zeta * zeta - 1, 0.0))) * w * step > 30:  # Phi decayed to e^-30 (slowest rate)
            assert np.abs(phis[k]).max() < 1e-9 * max(1.0, w)
            continue
        e_phi, e_q = _scaled_errors(phis[k], qs[k], ref_phi, 2.5 * ref_q, w)
        assert e_phi < 1e-9 and e_q < 1e-9, (zeta, hz, step, e_phi, e_q)
    stationary = held_stationary(phis[0], qs[0])
    if zeta > 0:
        ref = solve_discrete_lyapunov(phis[0], qs[0])
        d = np.diag([1.0, 1.0 / w])
        assert np.abs(d @ (stationary - ref) @ d).max() <= 1e-8 * np.abs(d @ ref @ d).max()
    else:
        assert np.all(np.isinf(stationary))


def test_oscillator_tables_equal_a_150_digit_van_loan_exponential():
    """The same Van Loan block matrix exponentiated in 150-digit arithmetic (mpmath): the closed form
    is within 2e-14 everywhere on the grid, also where scipy's double-precision expm is not (the
    worst, 1e-14, is e^{-a dt} at a dt = 20: the rounding of its argument; and Q11 when overdamped
    at zeta = 5, where the series stops at R dt = 1/2 before w dt is large)."""
    mpmath = pytest.importorskip("mpmath")
    mpmath.mp.dps = 150  # the Van Loan block cancels e^{+-2 a dt}: up to 1e87 at a dt = 100
    worst = 0.0
    for zeta in [*ZETAS, 5.0]:
        for wdt in [*WDT, 20.0]:
            w, z, dt = mpmath.mpf(W3), mpmath.mpf(zeta), mpmath.mpf(wdt) / mpmath.mpf(W3)
            m = mpmath.matrix([[0, -1, 0, 0], [w * w, 2 * z * w, 0, 2.5], [0, 0, 0, -w * w], [0, 0, 1, -2 * z * w]])
            e = mpmath.expm(m * dt)  # [[-A, G G^T qc], [0, A^T]]
            ref_phi = e[2:4, 2:4].T
            ref = (np.array(ref_phi.tolist(), dtype=float), np.array((ref_phi * e[0:2, 2:4]).tolist(), dtype=float))
            phis, qs = oscillator_tables(W3, zeta, np.array([wdt / W3]), kappa=2.5)
            worst = max(worst, *_scaled_errors(phis[0], qs[0], *ref, W3))
    assert worst < 2e-14


def test_oscillator_tables_compose_over_steps_and_keep_the_stationary_covariance():
    """Exact discretizations compose: (Phi, Q) over a + b equal those over b then a (what makes a
    dropped frame the same as a NaN gap); and P_inf = Phi P_inf Phi^T + Q at any step."""
    for zeta in (1e-3, 0.2, 0.9):
        (pa, pb, pab), (qa, qb, qab) = oscillator_tables(W3, zeta, np.array([0.0041, 0.0067, 0.0108]))
        np.testing.assert_allclose(pa @ pb, pab, rtol=0, atol=1e-14)
        composed = pa @ qb @ pa.T + qa
        assert np.abs(composed - qab).max() <= 1e-13 * np.abs(qab).max()
        p_inf = oscillator_stationary(W3, zeta)
        for phi, q in zip(*oscillator_tables(W3, zeta, np.array([1e-4, 0.005, 0.3, 2.0]))):
            assert np.abs(phi @ p_inf @ phi.T + q - p_inf).max() <= 1e-12 * p_inf.max()


def test_unique_steps_round_to_1e_9_of_the_median_step():
    t = np.concatenate([np.arange(10) * 0.005, 0.05 + 0.010 + np.arange(5) * 0.005]) * (1 + 1e-14)
    steps, idx = unique_steps(t)
    assert steps.size == 2 and idx[0] == 0 and idx.size == t.size
    np.testing.assert_allclose(steps[idx[1:]], np.diff(t), rtol=1e-9)
    uniform = np.arange(4000) * 0.005 + 12.3
    assert unique_steps(uniform)[0].size == 1  # one step: the uniform grid's cost


def _irregular_model(seed=0, n=80):
    """Two oscillators (one seen at gain 1.3, one at -0.4) at irregular times with dropped frames."""
    rng = np.random.default_rng(seed)
    frames = np.cumsum(np.where(rng.random(n) < 0.1, 2, 1))
    t = (frames + rng.uniform(-0.2, 0.2, n)) * 0.005
    steps, idx = unique_steps(t)
    pa, qa = oscillator_tables(W3, 0.05, steps, kappa=3.0)
    pb, qb = oscillator_tables(2 * W3, 0.2, steps, kappa=1.0)
    phis, qs = np.zeros((steps.size, 4, 4)), np.zeros((steps.size, 4, 4))
    phis[:, :2, :2], phis[:, 2:, 2:], qs[:, :2, :2], qs[:, 2:, 2:] = pa, pb, qa, qb
    p0 = np.zeros((4, 4))
    p0[:2, :2], p0[2:, 2:] = oscillator_stationary(W3, 0.05, 3.0), oscillator_stationary(2 * W3, 0.2, 1.0)
    h = np.array([1.3, 0.0, -0.4, 0.0])
    return t, phis, qs, idx, h, 1e-7, p0


def test_per_step_kalman_equals_the_dense_normal_at_irregular_times():
    """The stationary process at irregular times: Cov(x(t_i), x(t_j)) = Phi(t_i - t_j) P_inf, the
    dense normal's log density of the observed samples (gaps skipped)."""
    t, phis, qs, idx, h, r, p0 = _irregular_model()
    n = t.size
    lag_phi = {}
    cov = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            d = t[i] - t[j]
            if d not in lag_phi:
                pa = oscillator_tables(W3, 0.05, np.array([d]))[0][0] if d > 0 else np.eye(2)
                pb = oscillator_tables(2 * W3, 0.2, np.array([d]))[0][0] if d > 0 else np.eye(2)
                lag_phi[d] = np.block([[pa, np.zeros((2, 2))], [np.zeros((2, 2)), pb]])
            cov[i, j] = cov[j, i] = h @ lag_phi[d] @ p0 @ h
    cov += r * np.eye(n)
    y = np.random.default_rng(1).multivariate_normal(np.zeros(n), cov)
    y[[3, 40, 41]] = np.nan
    keep = np.isfinite(y)
    dense = multivariate_normal(np.zeros(keep.sum()), cov[np.ix_(keep, keep)]).logpdf(y[keep])
    assert log_likelihood_steps(y, phis, qs, idx, h, r, p0) == pytest.approx(dense, abs=1e-8)
    assert log_likelihood_steps_reference(y, phis, qs, idx, h, r, p0) == pytest.approx(dense, abs=1e-8)


def test_per_step_kernel_with_one_step_is_the_fixed_step_kernel():
    """A uniform grid through the per-step kernel (one table entry) is the fast kernel, bit for bit;
    the pointwise densities sum to it and are NaN at gaps, the innovations are the same."""
    phi, q, h, r, p0 = small_model()
    y = np.random.default_rng(2).normal(size=500)
    y[[7, 8, 300]] = np.nan
    idx = np.zeros(y.size, dtype=np.int64)
    fixed = log_likelihood(y, phi, q, h, r, p0)
    assert log_likelihood_steps(y, phi[None], q[None], idx, h, r, p0) == fixed
    pointwise = pointwise_log_likelihood(y, phi[None], q[None], idx, h, r, p0)
    assert np.array_equal(np.isnan(pointwise), np.isnan(y))
    assert np.nansum(pointwise) == pytest.approx(fixed, rel=1e-12)
    np.testing.assert_array_equal(whiten_steps(y, phi[None], q[None], idx, h, r, p0), whiten(y, phi, q, h, r, p0))


def test_simulate_draws_the_stationary_process_at_irregular_times():
    """The ensemble of 4000 draws: Var(y_k) = h P_inf h + r at every stamp, and the lag-1 covariance
    h Phi(dt_k) P_inf h at each step, within 5 standard errors of the ensemble means."""
    t, phis, qs, idx, h, r, p0 = _irregular_model(n=40)
    rng = np.random.default_rng(3)
    draws = np.array([simulate(phis, qs, idx, h, r, p0, rng) for _ in range(4000)])
    var = h @ p0 @ h + r
    lag = np.array([h @ phis[idx[k]] @ p0 @ h for k in range(1, t.size)])
    v_stat = np.mean(draws**2, axis=1) / var  # per draw: mean over stamps of y^2 / Var
    l_stat = np.mean(draws[:, 1:] * draws[:, :-1] / lag, axis=1)
    for stat in (v_stat, l_stat):
        assert abs(stat.mean() - 1.0) < 5 * stat.std() / np.sqrt(stat.size), (stat.mean(), stat.std())


# ------------------------------------------------------------------------------ the held gain
def _oscillator(f=3.46, zeta=0.014, fs=200.0, sigma=0.6):
    """The sec. 4.2 tilt mode at the demo's SNR, sampled at 200 Hz (the frame model's states)."""
    w = 2 * np.pi * f
    phis, qs = oscillator_tables(w, zeta, np.array([1.0 / fs]))
    return phis, qs, np.array([1.0, 0.0]), sigma**2, oscillator_stationary(w, zeta)


def test_hold_spans_one_period_of_the_slowest_oscillation():
    """hold_samples: one period of the slowest mode in steps, plus one (3.46 Hz at 200 Hz: 57.8
    steps -> 59); 2 for states that do not oscillate."""
    phis, *_ = _oscillator()
    assert hold_samples(phis) == 59
    fast, _ = oscillator_tables(2 * np.pi * 20.0, 0.05, np.array([0.005]))
    assert hold_samples(np.concatenate([phis, fast])) == 59
    assert hold_samples(np.array([[[0.9]]])) == 2


def test_the_held_gain_gives_the_full_recursion_to_rounding_on_a_long_record_with_gaps():
    """200 000 samples (1000 s at 200 Hz) with gaps: the filter that holds its converged gain
    (O(n) a step) equals the full Riccati recursion at every step to 1e-9 of the log-likelihood
    (the hold is the recursion's fixed point to ~1e-14; summed over 2e5 samples), and so do the
    innovations (1e-9) and the pointwise densities; the hold resumes after every gap."""
    phis, qs, h, r, p0 = _oscillator()
    y = simulate(phis, qs, np.zeros(200_000, dtype=np.int64), h, r, p0, np.random.default_rng(4))
    y[[10, 11, 5000, 120_000, 120_001, 199_000]] = np.nan
    y[60_000:60_400] = np.nan
    empty, idx = np.empty(0), np.zeros(0, dtype=np.int64)

    def run(freeze, white=None, lls=None):
        return filter_steps(
            y, phis, qs, idx, h, r, p0, np.empty(0) if white is None else white,
            np.empty(0) if lls is None else lls, freeze,
        )  # fmt: skip

    full = run(0)
    assert log_likelihood(y, phis[0], qs[0], h, r, p0) == pytest.approx(full, abs=1e-9 * abs(full))
    white_full, white_held = np.empty(y.size), np.empty(y.size)
    run(0, white=white_full)
    run(hold_samples(phis), white=white_held)
    np.testing.assert_allclose(white_held, white_full, rtol=0, atol=1e-9, equal_nan=True)
    lls = np.empty(y.size)
    run(hold_samples(phis), lls=lls)
    assert np.nansum(lls) == pytest.approx(full, abs=1e-9 * abs(full))
    assert filter_steps(y[:300], phis, qs, idx, h, r, p0, empty, empty, 59) == pytest.approx(
        log_likelihood_reference(y[:300], phis[0], qs[0], h, r, p0), abs=1e-10
    )


@settings(max_examples=25, deadline=None)
@given(
    f=st.floats(0.02, 99.0),  # 1 cycle per 50 s record .. just below Nyquist (100 Hz)
    zeta=st.floats(1e-4, 0.9),
    sigma=st.floats(1e-4, 10.0),
    gap=st.integers(0, 9_000),
)
def test_the_held_likelihood_is_the_full_recursion_for_all_oscillators(f, zeta, sigma, gap):
    """For any oscillator (near one cycle per record to near Nyquist, damping ratio 1e-4 to 0.9,
    sensor noise from 1e-4 to 10 times the process), 10 000 samples with a run of 500 missing: the
    held gain gives the full recursion's log-likelihood to 1e-9 relative (the hold is the Riccati
    fixed point to ~1e-14 a sample)."""
    phis, qs, h, _, p0 = _oscillator(f, zeta)
    r = sigma**2 * float(p0[0, 0])
    y = simulate(phis, qs, np.zeros(10_000, dtype=np.int64), h, r, p0, np.random.default_rng(6))
    y[gap : gap + 500] = np.nan
    idx, empty = np.zeros(0, dtype=np.int64), np.empty(0)
    full = filter_steps(y, phis, qs, idx, h, r, p0, empty, empty, 0)
    held = filter_steps(y, phis, qs, idx, h, r, p0, empty, empty, hold_samples(phis))
    assert held == pytest.approx(full, rel=1e-9, abs=1e-9)


# ------------------------------------------------------------------ the two-state kernel
@settings(max_examples=40, deadline=None)
@given(
    f=st.floats(0.05, 99.0),  # one cycle per 20 s record .. just below Nyquist (100 Hz)
    zeta=st.sampled_from([1e-4, 0.0138, 0.3, 0.999, 1.0, 1.5]),
    sigma=st.floats(1e-3, 10.0),
    gap=st.integers(0, 3_500),
    irregular=st.booleans(),
    h1=st.sampled_from([0.0, 0.02]),
)
def test_the_two_state_kernel_is_the_general_filter_for_all_oscillators(f, zeta, sigma, gap, irregular, h1):
    """`filter_two_states` (one oscillator, scalars) against `filter_steps` (any n): the same
    log-likelihood (1e-12 relative: the same recursion, rounded in another order), innovations and
    pointwise densities (1e-9), with and without the held gain, on a uniform grid and on jittered
    stamps with dropped frames, with a run of 200 missing samples."""
    n = 4_000
    rng = np.random.default_rng(7)
    if irregular:
        frames = np.cumsum(np.where(rng.random(n) < 0.1, 2, 1))
        steps, idx = unique_steps(np.round((frames + rng.uniform(-0.2, 0.2, n)) * 20) / 20 * 0.005)
    else:
        steps, idx = np.array([0.005]), np.zeros(0, dtype=np.int64)
    w = 2 * np.pi * f
    phis, qs = oscillator_tables(w, zeta, steps)
    p0 = oscillator_stationary(w, zeta)
    h = np.array([1.0, h1 / w])
    r = sigma**2 * float(p0[0, 0])
    y = simulate(phis, qs, idx if irregular else np.zeros(n, dtype=np.int64), h, r, p0, rng)
    y[gap : gap + 200] = np.nan
    for freeze in (0, hold_samples(phis)):
        outs = []
        for kernel in (filter_steps, filter_two_states):
            white, lls = np.empty(n), np.empty(n)
            ll = kernel(y, phis, qs, idx, h, r, p0, white, lls, freeze)
            outs.append((ll, white, lls))
        (ll_g, white_g, lls_g), (ll_2, white_2, lls_2) = outs
        assert ll_2 == pytest.approx(ll_g, rel=1e-12)
        np.testing.assert_allclose(white_2, white_g, rtol=0, atol=1e-9, equal_nan=True)
        np.testing.assert_allclose(lls_2, lls_g, rtol=0, atol=1e-9, equal_nan=True)


def test_the_likelihood_of_one_oscillator_takes_the_two_state_kernel():
    """`log_likelihood` and the per-step forms of a two-state model equal the numpy reference (the
    dispatch to `filter_two_states`), and an undefined innovation variance gives -inf."""
    phis, qs, h, r, p0 = _oscillator()
    y = simulate(phis, qs, np.zeros(600, dtype=np.int64), h, r, p0, np.random.default_rng(8))
    y[[5, 300, 301]] = np.nan
    ref = log_likelihood_reference(y, phis[0], qs[0], h, r, p0)
    assert log_likelihood(y, phis[0], qs[0], h, r, p0) == pytest.approx(ref, rel=1e-12)
    idx = np.zeros(y.size, dtype=np.int64)
    assert np.nansum(pointwise_log_likelihood(y, phis, qs, idx, h, r, p0)) == pytest.approx(ref, rel=1e-12)
    assert log_likelihood(y, phis[0], qs[0], h, 0.0, np.zeros((2, 2))) == -np.inf


@settings(max_examples=60, deadline=None)
@given(f=st.floats(1e-4, 99.9), zeta=st.floats(0.0, 0.99), dt=st.sampled_from([0.001, 0.005, 0.05]))
def test_the_hold_of_one_oscillator_is_the_eigenvalue_period(f, zeta, dt):
    """`hold_samples` of a 2 x 2 table in closed form: one period of the eigenvalues' rotation
    from `np.linalg.eigvals`, plus one (or 2 when they do not turn), for any damped oscillator
    below Nyquist."""
    w = 2 * np.pi * min(f, 0.499 / dt)
    phis, _ = oscillator_tables(w, zeta, np.array([dt]))
    angles = np.abs(np.angle(np.linalg.eigvals(phis)))
    turning = angles[angles > 1e-12]
    expect = 2 if turning.size == 0 else int(min(2**62, np.ceil(2 * np.pi / turning.min()) + 1))
    assert abs(hold_samples(phis) - expect) <= max(1, 1e-9 * expect)
