"""One result type for every estimator: a summary (JSON) and an ArviZ InferenceData (netCDF)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.data import Series


def _safe(name: str) -> str:
    return name.replace(".", "__").replace("[", "_").replace("]", "")


def summarize(method: str, names: list[str], map_values: dict[str, float], draws: np.ndarray | None,
              sd: dict[str, float] | None, truth: dict[str, float | None], diagnostics: dict, timing: dict,
              data: dict, priors: list | None = None) -> dict[str, Any]:
    """The JSON summary: per parameter median, mean, sd, q05, q95, map, truth.

    `draws` (n, d) are posterior draws in value units; without them (spectral, MAP) the interval is
    MAP +- 1.645 sd from the Laplace approximation, or null when there is no sd.
    """
    params = {}
    for j, n in enumerate(names):
        if draws is not None:
            d = draws[:, j]
            q05, q50, q95 = np.percentile(d, [5, 50, 95])
            entry = {"median": q50, "mean": d.mean(), "sd": d.std(ddof=1), "q05": q05, "q95": q95}
        elif sd is not None and np.isfinite(sd.get(n, np.nan)):
            m, s = map_values[n], sd[n]
            entry = {"median": m, "mean": m, "sd": s, "q05": m - 1.645 * s, "q95": m + 1.645 * s}
        else:
            entry = {"median": map_values[n], "mean": map_values[n], "sd": None, "q05": None, "q95": None}
        entry["map"] = map_values[n]
        entry["truth"] = truth.get(n)
        params[n] = {k: (None if v is None else float(v)) for k, v in entry.items()}
        if priors is not None:
            params[n]["prior"] = str(priors[j])
            params[n]["prior_bounds"] = [float(b) for b in priors[j].bounds]
    return {"method": method, "parameters": params, "diagnostics": diagnostics, "timing": timing, "data": data}


def write_netcdf(path: Path, summary: dict, series: Series, chains: np.ndarray | None,
                 log_prob: np.ndarray | None, predictive: dict[str, np.ndarray]) -> None:
    """InferenceData: posterior (chain = walker, draw), sample_stats, observed_data, constant_data
    (time and the predictive bands), and the JSON summary in the attributes."""
    import arviz as az

    names = list(summary["parameters"])
    if chains is None:  # no sampler: one 'chain' of Laplace draws, or the point estimate
        chains = predictive.pop("_draws", None)
    posterior = None
    if chains is not None:
        posterior = {_safe(n): chains[..., j] for j, n in enumerate(names)}
    attrs = {"vibinverse_summary": json.dumps(summary), "parameter_names": json.dumps({_safe(n): n for n in names})}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        idata = az.from_dict(
            posterior=posterior,
            sample_stats={"lp": log_prob} if log_prob is not None else None,
            observed_data={"intensity": series.intensity},
            constant_data={"time": series.time, **predictive},
            coords={"time_index": np.arange(series.time.size)},
            dims={"intensity": ["time_index"], "time": ["time_index"], **{k: ["time_index"] for k in predictive}},
            attrs=attrs,
        )
        idata.to_netcdf(str(path), engine="h5netcdf")


def read_summary(path: Path) -> tuple[dict, Any]:
    """(summary dict, InferenceData) from a result netCDF."""
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        idata = az.from_netcdf(str(path), engine="h5netcdf")
    return json.loads(idata.observed_data.attrs["vibinverse_summary"]), idata
