"""The modal model (`vibinverse.models.modal`): exact discretization of every block against the
matrix exponential, the block filter against the plain numpy Kalman filter (gaps, irregular stamps,
the held gain), the per-sample densities, label switching, replicates, units and the Fisher
information of a case with a closed form."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

import vibinverse as vi
from vibinverse import detection
from vibinverse.engines.kalman import block_filter
from vibinverse.errors import SceneError
from vibinverse.kalman import log_likelihood_steps_reference
from vibinverse.models import MODELS, model_class_for
from vibinverse.models.modal import (
    ModalModel,
    ModalSpec,
    _fill_tables,
    _oscillator,
    flicker_terms,
)
from vibinverse.posterior import Posterior
from vibinverse.terms.noise import FLICKER_MIN_TERMS


def van_loan(a: np.ndarray, gq: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, Q) of x' = A x + w, E[w w^T] = gq delta, over dt, by scipy's expm (Van Loan 1978)."""
    n = a.shape[0]
    m = np.zeros((2 * n, 2 * n))
    m[:n, :n], m[:n, n:], m[n:, n:] = -a, gq, a.T
    e = expm(m * dt)
    phi = e[n:, n:].T
    return phi, phi @ e[:n, n:]


@pytest.mark.parametrize(
    ("f", "zeta", "dt"),
    [
        (2.0, 0.01, 0.05),  # the test series' modes at 20 Hz
        (1.6, 0.03, 0.05),
        (9.9, 0.001, 0.05),  # near Nyquist, lightly damped
        (0.015, 0.2, 0.05),  # 3 cycles in 200 s: w dt = 5e-3, the series branch of Q11
        (0.5, 0.9, 0.001),  # heavily damped, short step
        (3.0, 1.0, 0.05),  # critical
        (3.0, 1.7, 0.05),  # overdamped
        (1.0, 1e-4, 0.3),
        (0.49 / (2 * math.pi * 0.05), 0.05, 0.05),  # just inside the series branch (rate dt = 0.49)
        (0.51 / (2 * math.pi * 0.05), 0.05, 0.05),  # just inside the closed form
        (0.2, 2.5, 0.05),  # overdamped, its fast rate decides the branch
    ],
)
def test_oscillator_discretization_matches_expm(f, zeta, dt):
    w, rms = 2 * math.pi * f, 0.7
    a = zeta * w
    kappa = 4 * a * w * w * rms * rms
    phi, q = np.zeros((2, 2)), np.zeros((2, 2))
    _oscillator(w, a, kappa, dt, phi, q, 0)
    ref_phi, ref_q = van_loan(np.array([[0.0, 1.0], [-w * w, -2 * a]]), np.diag([0.0, kappa]), dt)
    assert np.abs(phi - ref_phi).max() <= 1e-10 * np.abs(ref_phi).max()
    assert np.abs(q - ref_q).max() <= 1e-10 * np.abs(ref_q).max()
    assert abs(q[0, 0] - ref_q[0, 0]) <= 1e-10 * ref_q[0, 0]  # the element that cancels at short steps


def test_every_block_matches_expm():
    """Modes, the random walk, the integrated walk and an Ornstein-Uhlenbeck state, filled in one
    call for two steps, against the Van Loan exponential of the stacked system."""
    kinds = np.array([0, 1, 2, 3], dtype=np.int64)
    offsets = np.array([0, 2, 3, 5], dtype=np.int64)
    w, a, rms, rate2, tau, var = 2 * math.pi * 2.1, 0.02 * 2 * math.pi * 2.1, 0.8, 0.09, 0.4, 1.7
    pars = np.array([[w, a, rms], [rate2, 0, 0], [rate2, 0, 0], [tau, var, 0]], dtype=float)
    steps = np.array([0.05, 0.13])
    phis, qs, p0 = np.zeros((2, 6, 6)), np.zeros((2, 6, 6)), np.zeros((6, 6))
    _fill_tables(kinds, pars, offsets, steps, phis, qs, p0)
    big = np.zeros((6, 6))
    big[:2, :2] = [[0, 1], [-w * w, -2 * a]]
    big[3, 4] = 1.0
    big[5, 5] = -1 / tau
    gq = np.diag([0, 4 * a * w * w * rms * rms, rate2, 0, rate2, 2 * var / tau])
    for u, dt in enumerate(steps):
        ref_phi, ref_q = van_loan(big, gq, dt)
        assert np.allclose(phis[u], ref_phi, rtol=0, atol=1e-10 * np.abs(ref_phi).max())
        for blk in (slice(0, 2), slice(2, 3), slice(3, 5), slice(5, 6)):
            r = ref_q[blk, blk]
            assert np.abs(qs[u][blk, blk] - r).max() <= 1e-10 * np.abs(r).max()
    assert np.allclose(np.diag(p0), [rms**2, (w * rms) ** 2, 0, 0, 0, var])


def series_of(n=3000, fs=20.0, seed=0, gaps=0.0, jitter=0.0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    if jitter:
        t = t + rng.uniform(0, jitter / fs, n)
        t[rng.random(n) < 0.02] += 0.3 / fs  # a few late frames
        t = np.sort(t)
    y = 2.0 + np.cos(2 * np.pi * 2.1 * t) * 0.5 + rng.normal(size=n)
    y[rng.random(n) < gaps] = np.nan
    return vi.series(t, y)


SPEC = {"modes": 2, "lines": 1, "drift": True, "noise": "ar1"}
VALUES = {
    "level": 2.0,
    "modes[0].frequency": 1.3,
    "modes[0].damping_ratio": 0.02,
    "modes[0].rms": 0.4,
    "modes[1].frequency": 3.7,
    "modes[1].damping_ratio": 0.05,
    "modes[1].rms": 0.3,
    "lines[0].frequency": 2.1,
    "lines[0].amplitude": 0.5,
    "lines[0].phase": 0.3,
    "drift.rate": 0.01,
    "ar.rms": 0.3,
    "ar.time": 0.4,
    "noise.sigma": 0.8,
}


@pytest.mark.parametrize(
    ("spec", "gaps", "jitter"),
    [
        (SPEC, 0.0, 0.0),
        (SPEC, 0.1, 0.0),
        ({**SPEC, "noise": "1/f", "drift": "integrated"}, 0.05, 0.0),
        (SPEC, 0.05, 0.2),  # irregular stamps: a (Phi, Q) per distinct step
        ({"modes": 0, "lines": 0}, 0.0, 0.0),
    ],
)
def test_filter_matches_the_numpy_kalman_filter(spec, gaps, jitter):
    """The compiled block filter, with and without the held gain, against the plain numpy filter of
    `vibinverse.kalman` on the same tables; the per-sample densities sum to the likelihood."""
    s = series_of(gaps=gaps, jitter=jitter)
    m = ModalModel({"modal": spec}, s)
    values = {
        **{n: v for n, v in VALUES.items() if n in m.fittable()},
        "drift.rate": 0.01 if spec.get("drift") != "integrated" else 1e-3,
        "flicker.rms": 0.3,
        "flicker.corner": 2.0,
    }
    values = {n: values[n] for n in m.fittable()}
    assert s.uniform is (jitter == 0.0)
    mean, phis, qs, r, p0 = m.tables(values)
    ref = log_likelihood_steps_reference(s.intensity - mean, phis, qs, m.idx, m.h, r, p0)
    ll = m.log_likelihood(values)
    full = m._run(values, np.empty(0), np.empty(0), freeze=False)
    assert ll == pytest.approx(ref, rel=1e-10, abs=1e-7)
    assert full == pytest.approx(ref, rel=1e-12, abs=1e-8)
    point = m.pointwise_log_likelihood(values)
    assert np.isnan(point[s.gaps]).all() and np.isfinite(point[~s.gaps]).all()
    assert abs(np.nansum(point) - ll) <= 1e-9 * abs(ll)
    e = m.residuals(values)
    assert np.isnan(e[s.gaps]).all()


def test_held_gain_saves_work_and_keeps_the_numbers():
    """A long uniform record: the gain is held once the covariance has converged (O(T n) from
    there); the likelihood agrees with the full recursion to 1e-12 relative."""
    s = series_of(n=36000)
    m = ModalModel({"modal": {"modes": 3}}, s)
    values = {
        "level": 2.0,
        **{f"modes[{i}].frequency": f for i, f in enumerate((1.6, 2.1, 2.7))},
        **{f"modes[{i}].damping_ratio": 0.02 for i in range(3)},
        **{f"modes[{i}].rms": 0.5 for i in range(3)},
        "noise.sigma": 1.0,
    }
    mean, phis, qs, r, p0 = m.tables(values)
    e = np.empty(0)
    args = (s.intensity - mean, phis, qs, m.idx, m.lo, m.hi, m.h, r, p0)
    held, full = block_filter(*args, m.hold(values), e, e, e, 0), block_filter(*args, 0, e, e, e, 0)
    assert held == pytest.approx(full, rel=1e-12)


MODE_AND_LINE = {  # one mode at 1.3 Hz and a line at 2.1 Hz over a level of 2
    "level": 2.0,
    "modes[0].frequency": 1.3,
    "modes[0].damping_ratio": 0.04,
    "modes[0].rms": 0.6,
    "lines[0].frequency": 2.1,
    "lines[0].amplitude": 0.5,
    "lines[0].phase": 0.3,
}


def sho_covariance(t: np.ndarray, f: float, zeta: float, rms: float) -> np.ndarray:
    """The stationary autocovariance of q'' + 2 zeta w q' + w^2 q = white noise, variance rms^2:
    rms^2 e^{-zeta w |tau|} (cos w_d tau + zeta w / w_d sin w_d |tau|) (closed form, not the model's)."""
    w = 2 * np.pi * f
    wd = w * math.sqrt(1 - zeta * zeta)
    tau = np.abs(t[:, None] - t[None, :])
    return rms**2 * np.exp(-zeta * w * tau) * (np.cos(wd * tau) + zeta * w / wd * np.sin(wd * tau))


@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_gain_drift_likelihood_is_the_dense_gaussian(jitter):
    """y = (1 + g)(level + mode + line) + AR(1) + white, g = sum_j a_j cos(pi j u): the filter with a
    per-sample observation row against the dense Gaussian, mean (1 + g)(level + line) and covariance
    D K_mode D + K_ou + sigma^2 I (D = diag(1 + g)), from closed-form autocovariances. Equal to
    rounding (1e-9 relative), on uniform and on jittered stamps with gaps."""
    from scipy.stats import multivariate_normal

    s = series_of(n=160, gaps=0.05, jitter=jitter)
    m = ModalModel({"modal": {"modes": 1, "lines": 1, "noise": "ar1", "gain": 3}}, s)
    values = {
        **MODE_AND_LINE,
        "ar.rms": 0.3,
        "ar.time": 0.4,
        "gain.a1": 0.2,
        "gain.a2": -0.1,
        "gain.a3": 0.05,
        "noise.sigma": 0.5,
    }
    assert set(values) == m.fittable()
    t, y = s.time, s.intensity
    u = (t - t[0]) / (t[-1] - t[0])
    g = 0.2 * np.cos(np.pi * u) - 0.1 * np.cos(2 * np.pi * u) + 0.05 * np.cos(3 * np.pi * u)
    mean = (1 + g) * (2.0 + 0.5 * np.cos(2 * np.pi * 2.1 * t + 0.3))
    cov = (1 + g)[:, None] * sho_covariance(t, 1.3, 0.04, 0.6) * (1 + g)[None, :]
    cov += 0.3**2 * np.exp(-np.abs(t[:, None] - t[None, :]) / 0.4) + 0.25 * np.eye(t.size)
    ok = np.isfinite(y)
    ref = multivariate_normal(mean[ok], cov[np.ix_(ok, ok)]).logpdf(y[ok])
    assert m.log_likelihood(values) == pytest.approx(ref, rel=1e-9)
    assert m.mean(values) == pytest.approx(mean, rel=1e-12)
    # no gain drift at all coefficients 0: the model without the term, to rounding
    plain = ModalModel({"modal": {"modes": 1, "lines": 1, "noise": "ar1"}}, s)
    zero = {**values, "gain.a1": 0.0, "gain.a2": 0.0, "gain.a3": 0.0}
    assert m.log_likelihood(zero) == pytest.approx(plain.log_likelihood(zero), rel=1e-12)
    # 1 + g must stay positive
    assert (
        m.log_likelihood({**values, "gain.a1": 0.5, "gain.a2": -0.5, "gain.a3": 0.5}) == -math.inf
    )  # 1 + g = -0.5 at the end
    # the same g given as one curve (`gain_shapes`), a1 = 1: the same likelihood; a wrong shape refused
    spec1 = {"modal": {"modes": 1, "lines": 1, "noise": "ar1", "gain": 1}}
    shaped = ModalModel(spec1, s, gain_shapes=g[None, :])
    one = {**{k: v for k, v in values.items() if not k.startswith("gain.")}, "gain.a1": 1.0}
    assert shaped.log_likelihood(one) == pytest.approx(ref, rel=1e-9)
    with pytest.raises(SceneError, match=r"gain_shapes: shape \(2, 160\)"):
        ModalModel(spec1, s, gain_shapes=np.vstack([g, g]))


@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_coloured_noise_without_white_noise_is_the_dense_gaussian(jitter):
    """`white` false: y = level + mode + line + AR(1), no sensor noise (r = 0 in the filter), against
    the dense Gaussian from closed-form autocovariances (1e-9 relative), on uniform and jittered
    stamps with gaps; equal to the model with white noise at sigma = 0; noise.sigma is no parameter
    then, and `white` false without a coloured noise is refused, naming the key."""
    from scipy.stats import multivariate_normal

    s = series_of(n=160, gaps=0.05, jitter=jitter)
    table = {"modes": 1, "lines": 1, "noise": "ar1"}
    m = ModalModel({"modal": {**table, "white": False}}, s)
    values = {**MODE_AND_LINE, "ar.rms": 0.3, "ar.time": 0.4}
    assert set(values) == m.fittable() == set(m.default_priors())
    assert m.spec == ModalSpec(1, 1, noise="ar1", white=False) and m.spec.table()["white"] is False
    t, y = s.time, s.intensity
    mean = 2.0 + 0.5 * np.cos(2 * np.pi * 2.1 * t + 0.3)
    cov = sho_covariance(t, 1.3, 0.04, 0.6) + 0.3**2 * np.exp(-np.abs(t[:, None] - t[None, :]) / 0.4)
    ok = np.isfinite(y)
    ref = multivariate_normal(mean[ok], cov[np.ix_(ok, ok)]).logpdf(y[ok])
    assert m.log_likelihood(values) == pytest.approx(ref, rel=1e-9)
    with_white = ModalModel({"modal": table}, s)
    assert with_white.log_likelihood({**values, "noise.sigma": 0.0}) == pytest.approx(ref, rel=1e-9)
    assert "white noise" not in {c["kind"] for c in m.components(values)}
    # two states without white noise (a walk and an AR(1) state: the two-state kernel) against the numpy filter
    walk = ModalModel({"modal": {"lines": 1, "drift": True, "noise": "ar1", "white": False}}, s)
    wv = {k: v for k, v in values.items() if not k.startswith("modes")} | {"drift.rate": 0.05}
    mu, phis, qs, r, p0 = walk.tables(wv)
    assert phis.shape[1:] == (2, 2) and r == 0.0
    ref2 = log_likelihood_steps_reference(y - mu, phis, qs, walk.idx, walk.h, r, p0)
    assert walk.log_likelihood(wv) == pytest.approx(ref2, rel=1e-10)
    with pytest.raises(vi.SceneError, match=r"modal\.white: false needs a coloured noise"):
        ModalSpec.from_table({"modal": {"modes": 1, "white": False}})
    with pytest.raises(vi.SceneError, match=r"modal\.white: 'no'"):
        ModalSpec.from_table({"modal": {"noise": "ar1", "white": "no"}})


@given(
    modes=st.integers(0, 20),
    lines=st.integers(0, 20),
    drift=st.sampled_from(["none", "walk", "integrated"]),
    noise=st.sampled_from(["white", "ar1", "1/f"]),
    gain=st.integers(0, 24),
    white=st.booleans(),
)
@settings(max_examples=200, deadline=None)
def test_every_order_survives_its_table_and_names_its_noise(modes, lines, drift, noise, gain, white):
    """For all orders: the table an order writes reads back as the same order, and `noise.sigma`
    is a parameter exactly when the white noise is there; no white noise without a coloured one."""
    if not white and noise == "white":
        with pytest.raises(SceneError, match=r"modal\.white"):
            ModalSpec(modes, lines, drift, noise, gain, white)
        return
    spec = ModalSpec(modes, lines, drift, noise, gain, white)
    assert ModalSpec.from_table({"modal": spec.table()}) == spec
    names = spec.names()
    assert ("noise.sigma" in names) is white and len(names) == len(set(names))
    assert len(names) == 1 + 3 * (modes + lines) + (drift != "none") + 2 * (noise != "white") + gain + white


def test_gain_drift_replicates_have_the_modulated_variance():
    """Replicates with a gain drift: the modes' part times 1 + g, the AR(1) and white noise not:
    over 200 replicates the variance at the ends (g = +-0.3 there) is (1 + g)^2 rms^2 + ar^2 + sigma^2
    within 10 % (the sd of a variance from 200 x 20 nearly independent draws is ~3 %)."""
    s = series_of(n=2000)
    m = ModalModel({"modal": {"modes": 1, "noise": "ar1", "gain": 1}}, s)
    values = {
        "level": 2.0,
        "modes[0].frequency": 2.0,
        "modes[0].damping_ratio": 0.1,
        "modes[0].rms": 1.0,
        "ar.rms": 0.3,
        "ar.time": 0.05,
        "gain.a1": 0.3,
        "noise.sigma": 0.2,
    }
    rng = np.random.default_rng(3)
    reps = np.array([m.replicate(values, rng) for _ in range(200)])
    for sl, g in ((slice(0, 20), 0.3), (slice(-20, None), -0.3)):
        assert np.var(reps[:, sl]) == pytest.approx((1 + g) ** 2 + 0.09 + 0.04, rel=0.1)
        assert np.mean(reps[:, sl]) == pytest.approx(2.0 * (1 + g), abs=0.1)


def test_modes_and_lines_are_ordered_by_frequency():
    s = series_of()
    m = ModalModel({"modal": SPEC}, s)
    assert math.isfinite(m.log_likelihood(VALUES))
    swapped = {**VALUES, "modes[0].frequency": 3.7, "modes[1].frequency": 1.3}
    assert m.log_likelihood(swapped) == -math.inf
    m2 = ModalModel({"modal": {"lines": 2}}, s)
    two = {"level": 2.0, "noise.sigma": 1.0, "lines[0].phase": 0.0, "lines[1].phase": 0.0}
    two |= {"lines[0].amplitude": 0.5, "lines[1].amplitude": 0.2}
    assert math.isfinite(m2.log_likelihood({**two, "lines[0].frequency": 2.1, "lines[1].frequency": 4.0}))
    assert m2.log_likelihood({**two, "lines[0].frequency": 4.0, "lines[1].frequency": 2.1}) == -math.inf


def test_registry_table_and_priors():
    assert MODELS["modal"] is ModalModel
    assert model_class_for({"modal": {"modes": 3}}) is ModalModel
    spec = ModalSpec.from_table({"modal": {"modes": 3, "drift": True, "noise": "ar1"}})
    assert spec == ModalSpec(3, 0, "walk", "ar1")
    with pytest.raises(vi.SceneError, match=r"modal\.noise"):
        ModalSpec.from_table({"modal": {"noise": "pink"}})
    with pytest.raises(vi.SceneError, match=r"modal\.modes"):
        ModalSpec.from_table({"modal": {"modes": -1}})
    s = series_of()
    m = ModalModel({"modal": SPEC}, s)
    priors = m.default_priors()
    assert list(priors) == ModalSpec(2, 1, "walk", "ar1").names()
    assert priors["modes[1].frequency"].bounds == pytest.approx(
        (1.0 / (s.time[-1] - s.time[0]), 10.0)
    )  # 1 cycle .. Nyquist
    assert priors["modes[0].damping_ratio"].bounds == (1e-4, 0.9)
    assert priors["lines[0].amplitude"].bounds[1] == pytest.approx(3 * np.nanstd(s.intensity))
    lo, hi = priors["lines[0].phase"].bounds  # a full period around the spectral guess's phase
    assert hi - lo == pytest.approx(2 * math.pi)
    assert 0.5 * (lo + hi) == pytest.approx(m.value({}, "lines[0].phase"))
    # a start's phase past pi (the order search's optimum) is the window's centre, as it is: the
    # MAP starts inside (a window wrapped to (-pi, pi) first clipped such a start to its edge)
    started = ModalModel({"modal": {**SPEC, "start": {"lines[0].phase": -3.18}}}, s)
    assert started.default_priors()["lines[0].phase"].bounds == pytest.approx((-3.18 - math.pi, -3.18 + math.pi))
    assert m.units("modes[0].rms")[0] == "1" and m.units("modes[0].frequency")[0] == "Hz"
    assert m.units("drift.rate")[0] == "1 s-0.5" and m.units("ar.time")[0] == "s"
    assert m.units("lines[0].amplitude") == ("1", "line amplitude")
    tests = m.line_tests(VALUES, list(priors))
    assert [t.label for t in tests] == ["line_0", "mode_0", "mode_1"]
    assert tests[0].null == {"lines[0].amplitude": 0.0} and tests[1].null == {"modes[0].rms": 0.0}
    assert [t.damping for t in tests] == [None, VALUES["modes[0].damping_ratio"], VALUES["modes[1].damping_ratio"]]
    # near the 2.1 Hz line (20 bins of 1 / 150 s plus 5 half-widths): neither the 1.3 nor the 3.7 Hz
    # mode; the broadband terms always; a broad mode (zeta 0.5 at 3.7 Hz) reaches it
    assert not any(n.startswith("modes[") for n in tests[0].near)
    assert {"level", "drift.rate", "ar.rms", "ar.time", "lines[0].phase"} <= set(tests[0].near)
    broad = m.line_tests({**VALUES, "modes[1].damping_ratio": 0.5}, list(priors))[0].near
    assert "modes[1].frequency" in broad and "modes[0].frequency" not in broad


def test_a_line_window_narrows_the_frequency_prior_of_the_line_inside_it():
    """`modal.windows`: the line whose start lies in a window gets that window (clipped to 1 cycle
    per record .. Nyquist) as its frequency prior, and the detection test's look-elsewhere term is
    the window's; a line outside every window keeps the whole band. Bad windows: one-line errors."""
    s = series_of()
    span = s.time[-1] - s.time[0]
    table = {"lines": 2, "start": {"lines[0].frequency": 2.0, "lines[1].frequency": 6.0}}
    m = ModalModel({"modal": {**table, "windows": [[5.5, 6.5], [9.0, 12.0]]}}, s)
    p = m.default_priors()
    assert p["lines[0].frequency"].bounds == pytest.approx((1.0 / span, 10.0))
    assert p["lines[1].frequency"].bounds == (5.5, 6.5)
    assert m.unused_windows() == [1]  # 9-12 Hz holds no line's start: it narrows nothing
    clipped = ModalModel({"modal": {**table, "windows": [[0.0, 2.5]]}}, s).default_priors()
    assert clipped["lines[0].frequency"].bounds == pytest.approx((1.0 / span, 2.5))
    post = Posterior(m, p)
    assert detection.threshold(post, "lines[1].frequency") == pytest.approx(12.5 + math.log(span + s.dt))
    whole = detection.threshold(post, "lines[0].frequency")  # the band 1 cycle .. 10 Hz: 10 - 1 / span times wider
    assert whole == pytest.approx(detection.threshold(post, "lines[1].frequency") + math.log(10.0 - 1.0 / span))
    for bad, where in (
        ([[3.0, 2.0]], r"modal\.windows\[0\]"),
        (["x"], r"modal\.windows\[0\]"),
        (2.0, r"modal\.windows:"),
    ):
        with pytest.raises(SceneError, match=where + r".*0 <= lo < hi"):
            ModalModel({"modal": {**table, "windows": bad}}, s)


def test_a_fit_warns_of_a_window_that_narrows_no_line(caplog):
    """A fixed order with one line (7.3 Hz, A 0.5, white noise 0.5, 20 s at 100 Hz) and two
    windows: the one holding the line becomes its frequency prior, the other is named in a warning
    (it narrows nothing) instead of being silently unused."""
    import logging

    rng = np.random.default_rng(1)
    t = np.arange(2000) / 100.0
    y = 0.5 * np.cos(2 * np.pi * 7.3 * t) + rng.normal(0.0, 0.5, t.size)
    modal = {"modes": 0, "lines": 1, "drift": False, "noise": "white", "gain": False, "windows": [[2, 3], [7, 8]]}
    with caplog.at_level(logging.WARNING, logger="vibinverse"):
        r = vi.fit(vi.series(t, y), {"modal": modal}, method="map")
    p = r.summary()["parameters"]["lines[0].frequency"]
    assert p["prior"] == "uniform(7, 8)" and abs(p["median"] - 7.3) < 0.01
    assert "modal.windows[0] (2 to 3 Hz) holds no line's start" in caplog.text
    assert "modal.windows[1]" not in caplog.text


def test_replicate_has_the_model_variance():
    """Replicates (compiled, one pass each) have the stationary variance sum rms^2 + sigma^2 and the
    data's gaps."""
    s = series_of(n=4000, gaps=0.05)
    m = ModalModel({"modal": {"modes": 2, "noise": "ar1"}}, s)
    values = {n: VALUES[n] for n in m.fittable()}
    rng = np.random.default_rng(5)
    reps = np.array([m.replicate(values, rng) for _ in range(40)])
    assert np.isnan(reps[:, s.gaps]).all()
    var = 0.4**2 + 0.3**2 + 0.3**2 + 0.8**2
    assert np.nanmean(reps) == pytest.approx(2.0, abs=0.03)
    assert np.nanvar(reps) == pytest.approx(var, rel=0.05)


def test_fisher_of_white_noise_has_its_closed_form():
    """White noise plus a level: -d2 ln L at the MLE is n / sigma^2 (level) and 2 n / sigma^2 (sigma)."""
    s = series_of(n=2000)
    y = s.intensity
    m = ModalModel({"modal": {}}, s)
    values = {"level": float(np.mean(y)), "noise.sigma": float(np.std(y))}
    f = m.fisher(values, ["level", "noise.sigma"])
    n, sig2 = y.size, values["noise.sigma"] ** 2
    assert f[0, 0] == pytest.approx(n / sig2, rel=1e-4)
    assert f[1, 1] == pytest.approx(2 * n / sig2, rel=1e-4)
    assert abs(f[0, 1]) < 1e-3 * f[0, 0]


def test_spectral_guesses_find_the_peaks():
    rng = np.random.default_rng(3)
    t = np.arange(4000) / 20.0
    y = 0.8 * np.cos(2 * np.pi * 4.2 * t + 1.0) + rng.normal(size=t.size)
    m = ModalModel({"modal": {"lines": 1}}, vi.series(t, y))
    g = m.guesses(m.default_priors())[0]
    assert g["lines[0].frequency"] == pytest.approx(4.2, abs=2e-3)
    assert g["lines[0].amplitude"] == pytest.approx(0.8, rel=0.1)
    assert g["noise.sigma"] == pytest.approx(1.0, rel=0.1)


def test_threads_evaluate_at_once_without_sharing_scratch():
    """`releases_gil`: two threads evaluating different values at the same time each get the
    likelihood a serial call gives (the tables' arrays are per thread)."""
    from concurrent.futures import ThreadPoolExecutor

    m = ModalModel({"modal": SPEC}, series_of())
    assert m.releases_gil
    names = m.fittable()
    points = [
        {n: v * (1 + 0.02 * k) if n.endswith(("rms", "sigma")) else v for n, v in VALUES.items() if n in names}
        for k in range(16)
    ]
    serial = [m.log_likelihood(p) for p in points]
    with ThreadPoolExecutor(2) as ex:
        for _ in range(5):
            assert list(ex.map(m.log_likelihood, points)) == serial


def test_a_line_whose_phase_lies_near_pi_keeps_its_frequency_interval():
    """The bench's clean data set 332: the line's phase is -2.73 rad (3.55 on the circle). In a
    (-pi, pi) window the logit's Jacobian held the MAP at 3.01 and, through the frequency-phase
    correlation (-0.87), the frequency's sd came out 1.65e-3 Hz with the truth 3.4 sd away. Centred
    on the spectral guess's phase, the window puts the MAP in its middle: the sd is the
    Cramer-Rao bound's 2.47e-3 Hz (unknown phase) within 10 %, and the truth within 2.5 sd."""
    from vibinverse.bench.robustness_cases import simulate

    data = simulate("clean", 332)
    table = {"modal": {"modes": 1, "lines": 1, "drift": "none", "noise": "white", "gain": 0}}
    p = vi.fit(vi.series(data.time, data.intensity), table, method="map").summary()["parameters"]
    f = p["lines[0].frequency"]
    assert f["sd"] == pytest.approx(2.47e-3, rel=0.1)
    assert abs(f["map"] - 10.0) < 2.5 * f["sd"]


def test_the_final_fit_starts_inside_the_phase_window_the_order_search_left():
    """The bench's clean data set 35: the order search ends with the 10 Hz line's phase at -3.18,
    past -pi. The final fit's phase window is centred on it as it is; a window centred on its
    wrapped value (3.10) clipped the start to its edge, and the MAP walked to a false line at
    9.05 Hz that failed its detection test. Now the line is at 10 Hz (its sd ~2e-3 Hz) and detected."""
    from vibinverse.bench.robustness_cases import simulate

    data = simulate("clean", 35)
    result = vi.fit(vi.series(data.time, data.intensity), method="map")
    f = result.summary()["parameters"]["lines[0].frequency"]
    assert f["map"] == pytest.approx(10.0, abs=1e-2)
    assert [d.detected for d in result.detections if "line" in d.what] == [True]


@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_one_mode_and_white_noise_take_the_two_state_kernel_and_keep_the_numbers(jitter):
    """Two states (one mode; or a random walk and an AR(1) state) take `kalman.filter_two_states`:
    one mode and a line in white noise equal the dense Gaussian (1e-9 relative), and both models
    equal the plain numpy filter of their own tables, on a uniform grid and on jittered stamps
    with gaps; the pointwise densities sum to the likelihood."""
    from scipy.stats import multivariate_normal

    s = series_of(n=400, gaps=0.05, jitter=jitter)
    t, y = s.time, s.intensity
    m = ModalModel({"modal": {"modes": 1, "lines": 1}}, s)
    values = {
        **MODE_AND_LINE,
        "noise.sigma": 0.9,
    }
    mean = 2.0 + 0.5 * np.cos(2 * np.pi * 2.1 * t + 0.3)
    cov = sho_covariance(t, 1.3, 0.04, 0.6) + 0.81 * np.eye(t.size)
    ok = np.isfinite(y)
    dense = multivariate_normal(mean[ok], cov[np.ix_(ok, ok)]).logpdf(y[ok])
    assert m.log_likelihood(values) == pytest.approx(dense, rel=1e-9)
    walk = ModalModel({"modal": {"modes": 0, "lines": 1, "drift": True, "noise": "ar1"}}, s)
    walk_values = {k: v for k, v in values.items() if not k.startswith("modes")}
    walk_values.update({"drift.rate": 0.05, "ar.rms": 0.3, "ar.time": 0.4})
    for model, v in ((m, values), (walk, walk_values)):
        mu, phis, qs, r, p0 = model.tables(v)
        assert phis.shape[1:] == (2, 2)
        ref = log_likelihood_steps_reference(y - mu, phis, qs, model.idx, model.h, r, p0)
        assert model.log_likelihood(v) == pytest.approx(ref, rel=1e-10)
        assert np.nansum(model.pointwise_log_likelihood(v)) == pytest.approx(ref, rel=1e-10)


@given(
    span=st.floats(0.5, 1e5),
    rate=st.floats(1.0, 1e4),
)
@settings(max_examples=200, deadline=None)
def test_the_flicker_term_has_a_state_for_each_decade_up_to_nyquist(span, rate):
    """One Ornstein-Uhlenbeck state for each decade from one cycle per record to Nyquist: at
    least three; with more, 10^(terms - 1) cycles per record lies below Nyquist, 10^terms above."""
    dt = 1.0 / rate
    terms = flicker_terms(span, dt)
    nyquist_cycles = max(span, dt) / (2 * dt)
    assert terms >= FLICKER_MIN_TERMS
    if terms > FLICKER_MIN_TERMS:
        assert 10.0 ** (terms - 1) <= nyquist_cycles * (1 + 1e-9) < 10.0**terms


@pytest.mark.parametrize("corner", [50.0, 16.0, 1.0])
def test_the_flicker_term_has_a_one_over_f_spectrum_up_to_its_corner(corner):
    """20 s at 200 Hz: four Ornstein-Uhlenbeck states, corners from one cycle per record to
    `flicker.corner`. The spectrum of the sampled AR(1)s the model's own tables hold,
    S(f) = sum_k v_k (1 - phi_k^2) / |1 - phi_k e^{-i w dt}|^2, falls as f^-1 from 3 cycles per
    record to corner / 3 (fitted log-log slope -1 +- 0.06; local slopes within +-0.3 of it, the
    ripple of corners up to a decade apart) and as f^-2 past 3 x corner (to -2 +- 0.15 where
    the sampling's aliasing allows: below Nyquist / 3); its variance is flicker.rms^2."""
    n, fs = 4000, 200.0
    s = vi.series(np.arange(n) / fs, np.random.default_rng(0).normal(size=n))
    m = ModalModel({"modal": {"noise": "1/f"}}, s)
    assert m.flicker_terms == 4
    _, phis, _, _, p0 = m.tables({"level": 0.0, "flicker.rms": 0.3, "flicker.corner": corner, "noise.sigma": 1.0})
    phi, var = np.diag(phis[0]), np.diag(p0)
    np.testing.assert_allclose(-np.log(phi) * fs / (2 * np.pi), np.geomspace(1 / m.span, corner, 4), rtol=1e-12)
    assert var.sum() == pytest.approx(0.09, rel=1e-12)

    def spectrum(f):
        z = np.exp(-2j * np.pi * f / fs)
        return sum(v * (1 - p * p) / np.abs(1 - p * z) ** 2 for p, v in zip(phi, var))

    f = np.geomspace(3 / m.span, corner / 3, 400)
    slope = np.polyfit(np.log(f), np.log(spectrum(f)), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.06)
    assert np.abs(np.gradient(np.log(spectrum(f)), np.log(f)) - slope).max() <= 0.3
    if 3 * corner < fs / 6:
        f = np.geomspace(3 * corner, fs / 6, 100)
        assert np.polyfit(np.log(f), np.log(spectrum(f)), 1)[0] == pytest.approx(-2.0, abs=0.15)


def test_a_head_keeps_the_whole_records_flicker_term():
    """`head` (the convergence checks' shorter stretch) keeps the record's 1/f states and lowest
    corner, so a parameter means the same on the stretch as on the record."""
    s = series_of(n=3000)
    m = ModalModel({"modal": {"noise": "1/f"}}, s)
    values = {"level": 2.0, "flicker.rms": 0.3, "flicker.corner": 5.0, "noise.sigma": 1.0}
    h = m.head(200)
    assert h.flicker_terms == m.flicker_terms == 4  # 150 s at 20 Hz: 1500 cycles per record to Nyquist
    np.testing.assert_array_equal(h.tables(values)[1][0], m.tables(values)[1][0])
    assert ModalModel({"modal": {"noise": "1/f"}}, s.head(200)).flicker_terms == FLICKER_MIN_TERMS


def test_spectral_start_finds_a_sway_of_under_two_cycles_in_the_first_fourier_bin():
    """A line of 1.6 cycles in the record peaks in the first Fourier bin (1 / (N dt), just under the
    frequency prior's edge of one cycle in the span): the spectral start took the strongest noise
    peak elsewhere (11.7 Hz) and the fixed-order fit stayed there."""
    from vibinverse.models.modal import ModalModel

    rng = np.random.default_rng(7)
    t = np.arange(192) / 24.0
    f = 0.2029  # 1.6 cycles in 7.96 s
    y = 2.0 + 0.5 * np.cos(2 * np.pi * f * t + 1.0) + 0.6 * rng.standard_normal(t.size)
    table = {"modal": {"modes": 0, "lines": 1, "drift": False, "noise": "white", "gain": False}}
    model = ModalModel(table, vi.series(t, y))
    (start,) = model.guesses(model.default_priors())
    lo, hi = model.default_priors()["lines[0].frequency"].bounds
    assert lo <= start["lines[0].frequency"] <= hi
    assert start["lines[0].frequency"] == pytest.approx(f, rel=0.15)
    fitted = vi.fit(vi.series(t, y), table, method="map").summary()["parameters"]["lines[0].frequency"]
    assert fitted["q05"] < f * 1.1 and fitted["q95"] > f * 0.9


def test_background_follows_a_power_law_and_leaves_a_line_standing():
    """`background`: on the expected periodogram of a random walk over white noise (1/f^2 + 1)
    it is within 20 % of the curve everywhere; a line one bin wide stands 50x above it."""
    from vibinverse.models.modal import background

    freqs = np.arange(1, 2001) * 0.05
    power = 1.0 + 40.0 / freqs**2
    power[200] *= 50.0
    bg = background(freqs, power)
    assert np.all(np.abs(np.delete(bg / (1.0 + 40.0 / freqs**2), 200) - 1.0) < 0.2)
    assert power[200] / bg[200] > 40.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_regression_spectral_start_on_a_random_walk_takes_the_mode_and_the_line_not_the_drift(seed):
    """Regression (calibration bench, drift case: 3 % of fixed-order fits put the line on the
    resonance, or exchanged mode and line): a random walk's power peaks in the first Fourier bins,
    and the spectral starts took them for a component. Over the walk's background the starts are
    the resonance and the 10 Hz line, and the MAP fit stays there."""
    from scipy.signal import lfilter

    from vibinverse.models.modal import ModalModel

    rng = np.random.default_rng(seed)
    dt, n, f0, zeta = 1 / 200.0, 4000, 3.0, 0.01
    t = np.arange(n) * dt
    w = 2 * np.pi * f0
    r = np.exp(-zeta * w * dt)
    mode = lfilter([1.0], [1.0, -2 * r * np.cos(w * dt * np.sqrt(1 - zeta**2)), r * r], rng.standard_normal(n))
    mode *= 0.3 / mode.std()
    walk = np.cumsum(rng.standard_normal(n)) * 0.06
    y = 5.0 + mode + 0.15 * np.cos(2 * np.pi * 10.0 * t + 0.3) + walk + 0.1 * rng.standard_normal(n)
    table = {"modal": {"modes": 1, "lines": 1, "drift": True, "noise": "white", "gain": False}}
    model = ModalModel(table, vi.series(t, y))
    start = model.guesses(model.default_priors())[0]
    assert start["lines[0].frequency"] == pytest.approx(10.0, rel=0.01)
    assert start["modes[0].frequency"] == pytest.approx(f0, rel=0.1)
    p = vi.fit(vi.series(t, y), table, method="map").summary()["parameters"]
    assert p["lines[0].frequency"]["median"] == pytest.approx(10.0, rel=0.002)
    assert p["modes[0].frequency"]["median"] == pytest.approx(f0, rel=0.05)
