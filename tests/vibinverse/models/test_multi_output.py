"""The multi-output model (vibinverse.models.multi_output): its vector Kalman likelihood against the
dense joint Gaussian of the stacked outputs, on uniform and irregular stamps with gaps; the
pointwise densities and residuals; the priors, starts and line tests; one-line errors; a MAP."""

import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from vibinverse.errors import SceneError
from vibinverse.io.series import validate
from vibinverse.models import build_model, model_class_for
from vibinverse.models.multi_output import MultiOutputModel, MultiSeries, multi_series

VALUES = {
    "outputs[0].level": 0.3,
    "outputs[1].level": -0.2,
    "outputs[2].level": 0.1,
    "modes[0].frequency": 2.0,
    "modes[0].damping_ratio": 0.05,
    "modes[0].rms": 1.2,
    "modes[1].frequency": 3.1,
    "modes[1].damping_ratio": 0.1,
    "modes[1].rms": 0.8,
    "lines[0].frequency": 4.4,
    "lines[0].amplitude": 0.7,
    "lines[0].phase": 0.5,
    "noise.scale": 1.0,
}
KINDS = ["mode", "line", "mode"]  # output 0: modes[0], output 1: lines[0], output 2: modes[1]
COV = np.array([[0.30, 0.05, -0.04], [0.05, 0.20, 0.02], [-0.04, 0.02, 0.25]])


def mode_covariance(t: np.ndarray, f: float, zeta: float, rms: float) -> np.ndarray:
    """The stationary autocovariance of a damped oscillator driven by white noise (closed form,
    independent of any filter): rms^2 e^{-zeta w tau} (cos(w_d tau) + zeta w / w_d sin(w_d tau))."""
    w = 2 * np.pi * f
    wd = w * math.sqrt(1 - zeta * zeta)
    tau = np.abs(t[:, None] - t[None, :])
    return rms**2 * np.exp(-zeta * w * tau) * (np.cos(wd * tau) + zeta * w / wd * np.sin(wd * tau))


def dense(t: np.ndarray, z: np.ndarray, v: dict) -> float:
    """log N of the stacked outputs (time-major), NaN entries dropped: the modes' autocovariances on
    their outputs' diagonal blocks plus scale^2 C at every time; the levels and the line in the mean."""
    r = len(KINDS)
    mean = np.empty((t.size, r))
    cov = np.kron(np.eye(t.size), COV * v["noise.scale"] ** 2)
    for j, (kind, i) in enumerate(zip(KINDS, [0, 0, 1])):
        mean[:, j] = v[f"outputs[{j}].level"]
        if kind == "mode":
            k = mode_covariance(t, *(v[f"modes[{i}].{p}"] for p in ("frequency", "damping_ratio", "rms")))
            e = np.zeros((r, r))
            e[j, j] = 1.0
            cov += np.kron(k, e)
        else:
            f, a, ph = (v[f"lines[{i}].{p}"] for p in ("frequency", "amplitude", "phase"))
            mean[:, j] += a * np.cos(2 * np.pi * f * t + ph)
    keep = np.isfinite(z.ravel())
    x, m = z.ravel()[keep], mean.ravel()[keep]
    return float(multivariate_normal(m, cov[np.ix_(keep, keep)]).logpdf(x))


def draw(t: np.ndarray, seed: int) -> np.ndarray:
    """Outputs drawn from the dense model itself."""
    rng = np.random.default_rng(seed)
    out = np.empty((t.size, 3))
    for j, (kind, i) in enumerate(zip(KINDS, [0, 0, 1])):
        if kind == "mode":
            k = mode_covariance(t, *(VALUES[f"modes[{i}].{p}"] for p in ("frequency", "damping_ratio", "rms")))
            out[:, j] = np.linalg.cholesky(k + 1e-10 * np.eye(t.size)) @ rng.normal(size=t.size)
        else:
            out[:, j] = 0.7 * np.cos(2 * np.pi * 4.4 * t + 0.5)
    return out + rng.normal(size=(t.size, 3)) @ np.linalg.cholesky(COV).T


def replicate(t: np.ndarray, values: dict, kinds: list[str], cov: np.ndarray, seed: int) -> np.ndarray:
    """Outputs drawn by the model's own simulator (a model on placeholder data draws them)."""
    placeholder = np.random.default_rng(seed + 1000).normal(size=(t.size, len(kinds)))
    m = build_model({"multi_output": {"sources": list(kinds)}}, multi_series(t, placeholder, cov))
    return m.replicate_outputs(values, np.random.default_rng(seed))


def model(t: np.ndarray, z: np.ndarray, kinds=KINDS) -> MultiOutputModel:
    return build_model({"multi_output": {"sources": list(kinds)}}, multi_series(t, z, COV, "test"))


@pytest.mark.parametrize("stamps", ["uniform", "irregular with gaps and a half-observed sample"])
def test_the_vector_kalman_likelihood_is_the_dense_joint_gaussian(stamps):
    """Three outputs (two modes, one line; correlated noise) at 80 stamps: the filter's
    log-likelihood equals scipy's multivariate normal of the 240 stacked values, at two different
    parameter sets (so that the dependence on the parameters is what matches), to 1e-9 relative:
    both are float64 sums of ~240 terms of order 1 (rounding ~1e-13 relative); the dense Cholesky
    of the near-singular mode blocks loses a few more digits."""
    rng = np.random.default_rng(5)
    t = np.arange(80) * 0.05
    if stamps != "uniform":
        t = np.sort(np.cumsum(rng.uniform(0.03, 0.07, 80)))
    z = draw(t, 2)
    if stamps != "uniform":
        z[[7, 30, 31]] = np.nan  # gaps of all outputs
        z[50, 1] = np.nan  # one output missing: the others are observed
    m = model(t, z)
    other = {**VALUES, "modes[0].frequency": 2.3, "modes[1].damping_ratio": 0.03, "lines[0].phase": -1.0}
    other["noise.scale"] = 1.3
    for v in (VALUES, other):
        assert m.log_likelihood(v) == pytest.approx(dense(t, z, v), rel=1e-9)
    assert m.log_likelihood(VALUES) - m.log_likelihood(other) == pytest.approx(
        dense(t, z, VALUES) - dense(t, z, other), rel=1e-7
    )
    point = m.pointwise_log_likelihood(VALUES)
    assert np.nansum(point) == pytest.approx(m.log_likelihood(VALUES), rel=1e-12)
    assert np.isnan(point).sum() == (3 if stamps != "uniform" else 0)


def test_standardized_innovations_are_white_and_replicates_have_the_model_moments():
    """At the true values on 4000 samples: the innovations of every output have mean ~0 and sd ~1
    (standard errors 0.016 and 0.011; tolerances 4 x), and the per-sample residual too; replicated
    outputs have each output's variance (mode rms^2 + C_jj, or line a^2 / 2 + C_jj) within 10 %
    (a lightly damped mode's variance estimate over 4000 samples scatters by ~5 %)."""
    t = np.arange(4000) * 0.05
    z = replicate(t, VALUES, KINDS, COV, 8)
    m = model(t, z)
    e = m.output_residuals(VALUES)
    assert np.all(np.abs(e.mean(axis=0)) < 0.065) and np.all(np.abs(e.std(axis=0) - 1) < 0.045)
    assert abs(np.corrcoef(e[1:, 0], e[:-1, 0])[0, 1]) < 0.065
    res = m.residuals(VALUES)
    assert res.shape == (t.size,) and abs(res.std() - 1) < 0.045
    want = [1.2**2 + COV[0, 0], 0.7**2 / 2 + COV[1, 1], 0.8**2 + COV[2, 2]]
    assert z.var(axis=0) == pytest.approx(want, rel=0.1)
    assert m.replicate(VALUES, np.random.default_rng(1)).shape == (t.size,)


def test_names_priors_starts_units_and_line_tests():
    """The parameters are each output's (level, then its mode or line), indexed within their kind;
    the priors are the one-component modal model's of that output; the starts find each output's
    frequency (a mode's within its peak's half-power half-width zeta f, the line's within a
    resolution bin); noise.scale is fittable, not free."""
    t = np.arange(4000) * 0.05
    z = replicate(t, VALUES, KINDS, COV, 9)
    m = model(t, z)
    assert model_class_for({"multi_output": {"sources": KINDS}}) is MultiOutputModel
    priors = m.default_priors()
    assert set(priors) == set(VALUES) - {"noise.scale"} and "noise.scale" in m.fittable()
    assert priors["modes[1].frequency"].bounds[1] == pytest.approx(10.0)  # Nyquist of 20 Hz sampling
    start = m.guesses(m.default_priors())[0]
    for n, zeta in (("modes[0].frequency", 0.05), ("modes[1].frequency", 0.1)):
        assert start[n] == pytest.approx(VALUES[n], rel=zeta)  # inside the peak's half-power half-width
    assert start["lines[0].frequency"] == pytest.approx(4.4, abs=0.005)  # 1 / span
    assert m.units("outputs[1].level")[1].startswith("output 1")
    assert m.units("modes[0].damping_ratio")[0] == "1"
    tests = {lt.label: lt for lt in m.line_tests(VALUES, list(priors))}
    assert set(tests) == {"mode_0", "mode_1", "line_0"} and tests["line_0"].null == {"lines[0].amplitude": 0.0}
    # a mode's test carries its damping ratio (a broad hump is not claimed), a line's none
    assert (tests["mode_0"].damping, tests["mode_1"].damping, tests["line_0"].damping) == (0.05, 0.1, None)
    assert m.log_likelihood({**VALUES, "modes[0].rms": 0.0}) < m.log_likelihood(VALUES) - 100
    assert m.log_likelihood({**VALUES, "modes[0].damping_ratio": -0.1}) == -math.inf
    comps = m.components(VALUES)
    assert [c["kind"] for c in comps] == ["mode", "line", "mode", "white noise"]
    fisher = m.fisher(VALUES, ["modes[0].frequency", "lines[0].amplitude"])
    assert np.all(np.linalg.eigvalsh(fisher) > 0)


def test_bad_tables_and_data_are_one_line():
    t = np.arange(100) * 0.05
    z = np.random.default_rng(0).normal(size=(100, 2))
    good = multi_series(t, z, np.eye(2))
    assert isinstance(good, MultiSeries) and good.intensity == pytest.approx(z[:, 0])
    with pytest.raises(SceneError, match="one kind per output"):
        build_model({"multi_output": {"sources": ["mode"]}}, good)
    with pytest.raises(SceneError, match="'wave'"):
        build_model({"multi_output": {"sources": ["mode", "wave"]}}, good)
    with pytest.raises(SceneError, match="unknown key"):
        build_model({"multi_output": {"sources": ["mode", "mode"], "modes": 2}}, good)
    with pytest.raises(SceneError, match="not a single series"):
        build_model({"multi_output": {"sources": ["mode", "mode"]}}, validate(t, z[:, 0]))
    with pytest.raises(SceneError, match="positive definite"):
        multi_series(t, z, np.ones((2, 2)))
    with pytest.raises(SceneError, match="symmetric 2 x 2"):
        multi_series(t, z, np.eye(3))


def test_the_map_recovers_two_modes_from_their_outputs():
    """Two modes on two outputs with correlated noise, 4000 samples at 20 Hz: the scipy MAP of the
    pipeline finds both frequencies within 1 % and each true value inside its 90 % Laplace interval
    but for the rarest draws (seed fixed)."""
    from vibinverse.fitting import fit_series

    cov = np.array([[0.3, 0.1], [0.1, 0.4]])
    t = np.arange(4000) * 0.05
    v = {k: VALUES[k] for k in VALUES if not k.startswith(("lines", "outputs[2]"))}
    z = replicate(t, v, ["mode", "mode"], cov, 4)
    res = fit_series(multi_series(t, z, cov), {"multi_output": {"sources": ["mode", "mode"]}}, method="map")
    params = res.summary()["parameters"]
    assert "noise.scale" not in params
    for name in ("modes[0].frequency", "modes[1].frequency"):
        assert res.point[name] == pytest.approx(v[name], rel=0.01)
    for name in ("modes[0].frequency", "modes[1].frequency", "modes[0].damping_ratio", "modes[1].damping_ratio"):
        assert params[name]["q05"] <= v[name] <= params[name]["q95"], name
