"""The result as ArviZ InferenceData: `posterior` holds real draws only, `log_likelihood` and
`posterior_predictive` make `az.loo` work, every variable carries CF units, and the summary's
R-hat and ESS are `az.summary`'s."""

import json
import warnings
from pathlib import Path

import arviz as az
import numpy as np
import pytest

import vibinverse as vi
from vibinverse import inference_data as idata_io
from vibinverse.io.builtin import builtin_scene
from vibinverse.models.base import parameter_units


@pytest.fixture(scope="module")
def plate():
    scene = vi.load_scene(builtin_scene("roof_elastic"))
    obs = vi.simulate(scene, seed=3)
    return scene, vi.series(obs.time, obs.intensity, scene=scene)


@pytest.fixture(scope="module")
def mcmc_file(plate, tmp_path_factory) -> tuple[vi.FitResult, Path]:
    scene, series = plate
    result = vi.fit(series, scene, method="mcmc", max_steps=600, progress=False)
    return result, result.to_netcdf(tmp_path_factory.mktemp("r") / "result.nc")


def _open(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return az.from_netcdf(str(path), engine="h5netcdf")


@pytest.mark.slow
def test_an_mcmc_result_has_the_groups_loo_needs_and_units_everywhere(mcmc_file, plate):
    result, path = mcmc_file
    idata = _open(path)
    assert {"posterior", "log_likelihood", "posterior_predictive", "observed_data", "constant_data"} <= set(
        idata_io.group_names(idata)
    )
    assert "approximate_posterior" not in idata_io.group_names(idata)
    loo = idata_io.loo(idata)
    # elpd_loo is the sum of leave-one-out densities: a few less than the whole log-likelihood at
    # the MAP (by about the number of parameters, p_loo)
    n_free = len(result.names)
    assert 0.5 * n_free < loo.p < 3 * n_free
    ll = idata.log_likelihood["intensity"]
    assert ll.shape[-1] == result.series.time.size and ll.sizes["draw"] * ll.sizes["chain"] <= 200
    # the pointwise log-likelihood of a draw sums to the model's log-likelihood at that draw
    draw = int(ll["draw"][0])
    values = dict(zip(result.names, result.chains[0, draw]))
    model = vi.posterior(result.series, plate[0]).model  # the model the fit used
    assert np.nansum(ll.values[0, 0]) == pytest.approx(model.log_likelihood(values), rel=1e-9)
    for group in ("posterior", "observed_data", "constant_data", "posterior_predictive", "log_likelihood"):
        for name, var in idata[group].data_vars.items():
            assert var.attrs.get("units") and var.attrs.get("long_name"), (group, name)
    assert idata.constant_data["time"].attrs["units"] == "s"


@pytest.mark.slow
def test_summary_r_hat_and_ess_are_arviz_summary_values(mcmc_file):
    _, path = mcmc_file
    idata = _open(path)
    summary, _ = vi.read_result(path)
    table = az.summary(idata.posterior, round_to="none")
    names = {v: k for k, v in json.loads(idata.observed_data.attrs["parameter_names"]).items()}
    for name, entry in summary["parameters"].items():
        row = table.loc[names[name]]
        # the same ArviZ functions; 1e-4 because ArviZ's numba and numpy paths differ in rounding (4e-6 seen
        # in a whole-suite run), far below the 3 decimals the report prints
        assert entry["rhat"] == pytest.approx(row["r_hat"], rel=1e-4)
        assert entry["ess_bulk"] == pytest.approx(row["ess_bulk"], rel=1e-4)
        assert entry["ess_tail"] == pytest.approx(row["ess_tail"], rel=1e-4)
        assert entry["units"] == parameter_units(name)[0]
    assert summary["approximation"] is None
    checks = summary["diagnostics"]["residual_checks"]
    assert checks["white"] and checks["normal"]  # the model is the one that made the data


def test_a_map_result_has_no_posterior_group_only_a_labelled_approximation(plate, tmp_path):
    scene, series = plate
    result = vi.fit(series, scene, method="casadi")
    idata = _open(result.to_netcdf(tmp_path / "map.nc"))
    assert "posterior" not in idata_io.group_names(idata)
    assert idata.approximate_posterior.attrs["approximation"] == "laplace"
    assert idata.posterior_predictive.attrs["approximation"] == "laplace"
    summary, _ = vi.read_result(tmp_path / "map.nc")
    assert summary["approximation"] == "laplace"
    assert all(p["rhat"] is None and p["ess_bulk"] is None for p in summary["parameters"].values())
    # residuals at the MAP are standardized: unit variance to the sampling error of 500 samples
    e = idata.constant_data["residual"].values
    assert abs(np.nanstd(e) - 1.0) < 4 / np.sqrt(2 * np.isfinite(e).sum())


def test_the_pointwise_groups_are_computed_once_when_first_needed_and_travel_with_a_pickle(plate, monkeypatch):
    import pickle

    import vibinverse.estimators.base as estimators_base

    calls = []
    counted = estimators_base.pointwise
    monkeypatch.setattr(estimators_base, "pointwise", lambda *a, **k: calls.append(1) or counted(*a, **k))
    scene, series = plate
    result = vi.fit(series, scene, method="casadi")
    # the pipeline ran spectral, then casadi: neither computed them (each took ~0.35 s on 4000 samples)
    assert calls == [] and result.pointwise == {}
    groups = result.pointwise_groups()
    assert calls == [1] and groups["log_likelihood"].shape == groups["replicates"].shape
    assert groups["log_likelihood"].shape[-1] == series.time.size
    assert result.pointwise_groups() is groups and calls == [1]  # once
    # a result pickled to another process carries them, computed, not their source
    fresh = vi.fit(series, scene, method="casadi")
    back = pickle.loads(pickle.dumps(fresh))
    assert back.pointwise_source is None
    np.testing.assert_array_equal(back.pointwise["log_likelihood"], groups["log_likelihood"])


def test_replicates_have_the_data_s_noise_level(plate):
    scene, series = plate
    post = vi.posterior(series, scene)
    truth = {n: v for n, v in post.truth().items() if v is not None}
    values = {n: truth.get(n, p.centre) for n, p in zip(post.space.names, post.space.priors)}
    model = post.model
    rng = np.random.default_rng(0)
    reps = np.array([model.replicate(values, rng) for _ in range(200)])
    sigma = values["noise.sigma"]
    spread = (reps - model.mean(values)).std()
    # 200 x 500 draws of N(0, sigma^2): the sd is known to 0.2 %
    assert spread == pytest.approx(sigma, rel=0.01)
    assert np.nansum(model.pointwise_log_likelihood(values)) == pytest.approx(model.log_likelihood(values), rel=1e-12)
