"""`vibinverse.inference_data` against the installed ArviZ major (0.x: InferenceData, 1.x: DataTree):
groups round-trip through the object and netCDF with their attributes, PSIS-LOO equals its hand
computation, R-hat and ESS are sane and those of `arviz.summary`, PSIS weights keep zero weights."""

import arviz as az
import numpy as np
import pytest
import xarray as xr
from scipy.special import logsumexp

from vibinverse import inference_data as idata_io

C, D, N = 4, 500, 40


def _groups(rng: np.random.Generator) -> dict[str, xr.Dataset]:
    draws = {"chain": np.arange(C), "draw": np.arange(D)}
    # thinned pointwise groups: their own draw coordinate, as `FitResult.to_inference_data` writes them
    kept = {"chain": np.arange(C), "draw": np.arange(0, D, 5), "time_index": np.arange(N)}
    log_lik = rng.normal(-1.0, 0.05, size=(C, D // 5, N)) + rng.normal(0.0, 0.3, size=N)
    return {
        "posterior": xr.Dataset(
            {"f": (("chain", "draw"), rng.normal(5.0, 0.1, (C, D)), {"units": "Hz", "long_name": "frequency"})},
            coords=draws,
        ),
        "sample_stats": xr.Dataset({"lp": (("chain", "draw"), rng.normal(size=(C, D)))}, coords=draws),
        "log_likelihood": xr.Dataset({"intensity": (("chain", "draw", "time_index"), log_lik)}, coords=kept),
        "observed_data": xr.Dataset(
            {"intensity": ("time_index", rng.normal(size=N), {"units": "1"})},
            coords={"time_index": np.arange(N)},
            attrs={"vibinverse_summary": '{"method": "mcmc"}'},
        ),
        "constant_data": xr.Dataset({"time": ("time_index", np.arange(N) / 100.0, {"units": "s"})}),
    }


def _same(a: xr.Dataset, b: xr.Dataset) -> None:
    assert set(a.data_vars) == set(b.data_vars) and a.attrs == b.attrs
    for k in a.data_vars:
        np.testing.assert_array_equal(a[k].values, b[k].values)
        assert a[k].dims == b[k].dims and a[k].attrs == b[k].attrs
        for dim in a[k].dims:
            if dim in a.coords:
                np.testing.assert_array_equal(a[dim].values, b[dim].values)


def test_the_object_is_the_installed_majors_own():
    assert idata_io.arviz_major() == int(az.__version__.split(".")[0])
    built = idata_io.build(_groups(np.random.default_rng(0)))
    assert isinstance(built, xr.DataTree if idata_io.arviz_major() >= 1 else az.InferenceData)


def test_groups_round_trip_through_the_object_and_netcdf(tmp_path):
    groups = _groups(np.random.default_rng(1))
    built = idata_io.build(groups)
    assert set(idata_io.group_names(built)) == set(groups)
    assert idata_io.group(built, "approximate_posterior") is None
    back = idata_io.from_netcdf(idata_io.to_netcdf(built, tmp_path / "r.nc"))
    assert set(idata_io.group_names(back)) == set(groups)
    for name, ds in groups.items():
        _same(ds, idata_io.group(built, name))
        _same(ds, idata_io.group(back, name))


def test_loo_equals_its_hand_computation():
    """Log-likelihoods that vary little over the draws: the Pareto k are small, smoothing moves
    nothing much, and elpd_i is the plain importance-sampling LOO log(S) - logsumexp(-ll); p_loo is
    lppd - elpd and the standard error sqrt(n var(elpd_i)) exactly (var with ddof 0: ArviZ 0.x and
    arviz-stats 1.0; ddof 1: arviz-stats 1.3)."""
    groups = _groups(np.random.default_rng(2))
    r = idata_io.loo(idata_io.build(groups))
    ll = groups["log_likelihood"]["intensity"].values.reshape(-1, N)
    s = ll.shape[0]
    assert np.all(np.isfinite(r.elpd_i)) and np.isfinite(r.elpd) and np.isfinite(r.se) and np.isfinite(r.p)
    assert r.elpd_i.shape == r.pareto_k.shape == (N,) and r.pareto_k.max() < 0.7 and not r.warning
    np.testing.assert_allclose(r.elpd_i, np.log(s) - logsumexp(-ll, axis=0), atol=1e-4)
    assert r.elpd == pytest.approx(r.elpd_i.sum(), rel=1e-12)
    lppd = float(np.sum(logsumexp(ll, axis=0) - np.log(s)))
    assert r.p == pytest.approx(lppd - r.elpd, abs=1e-9)
    se = [np.sqrt(N * np.var(r.elpd_i, ddof=ddof)) for ddof in (0, 1)]
    assert r.se == pytest.approx(se[0], rel=1e-9) or r.se == pytest.approx(se[1], rel=1e-9)


def test_rhat_and_ess_are_sane_and_arviz_summarys():
    """AR(1) chains (rho 0.9) of one stationary process: R-hat ~1 and bulk ESS near the AR(1)
    value n (1 - rho) / (1 + rho); chains shifted apart: R-hat well above 1. The numbers are
    `arviz.summary`'s."""
    rng = np.random.default_rng(3)
    rho, n = 0.9, 4000
    x = np.zeros((4, n))
    x[:, 0] = rng.normal(size=4) / np.sqrt(1 - rho**2)
    for t in range(1, n):
        x[:, t] = rho * x[:, t - 1] + rng.normal(size=4)
    chains = np.stack([x, x + np.arange(4)[:, None]], axis=-1)  # p0 converged, p1 four chains apart
    rhat, bulk, tail = idata_io.rank_diagnostics(chains)
    assert rhat[0] == pytest.approx(1.0, abs=0.01) and rhat[1] > 1.1
    assert bulk[0] == pytest.approx(4 * n * (1 - rho) / (1 + rho), rel=0.3)
    assert 0 < tail[0] < 4 * n and bulk[1] < bulk[0]
    table = idata_io.summary(xr.Dataset({f"p{j}": (("chain", "draw"), chains[..., j]) for j in range(2)}))
    for j in range(2):
        row = table[f"p{j}"]
        assert row["r_hat"] == pytest.approx(rhat[j], rel=1e-6)
        assert row["ess_bulk"] == pytest.approx(bulk[j], rel=1e-6)
        assert row["ess_tail"] == pytest.approx(tail[j], rel=1e-6)


def test_psis_weights_normalize_keep_zero_weights_and_flag_heavy_tails():
    rng = np.random.default_rng(4)
    light = rng.normal(0.0, 0.3, 2000)
    light[7] = -np.inf  # a draw where the posterior is zero
    smoothed, khat = idata_io.psislw(light)
    assert smoothed[7] == -np.inf and np.all(np.isfinite(np.delete(smoothed, 7)))
    assert logsumexp(smoothed) == pytest.approx(0.0, abs=1e-9)
    assert khat < 0.5
    _, heavy = idata_io.psislw(rng.exponential(size=2000))  # Pareto(1) weights: k = 1
    assert heavy > 0.7
