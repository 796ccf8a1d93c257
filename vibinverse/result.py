"""One result type for every estimator: `FitResult`, with its JSON summary, ArviZ InferenceData and
netCDF file."""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.errors import DataError
from vibinverse.io.series import Series
from vibinverse.priors import Prior


@dataclass(frozen=True)
class Detection:
    """One line's detection test: the log-likelihood gain of the fit with it over the fit without
    it, against the threshold it must pass (`vibinverse.detection`)."""

    what: str
    delta_loglike: float
    threshold: float
    detected: bool


@dataclass
class FitResult:
    """What an estimator returns.

    `point` is its point estimate (the MAP for MAP and MCMC results); `sd` the Laplace (or
    jackknife) standard deviations when there is no sampler; `chains` real posterior draws
    (walker, draw, parameter) in value units; `approximate_draws` draws of the Laplace
    approximation (draw, parameter); `z`, `cov_z` the point and covariance in the samplers'
    unconstrained space; `starts` the candidate starting points the next stage may use, best first.
    """

    method: str
    names: list[str]
    priors: list[Prior]
    point: dict[str, float]
    series: Series
    sd: dict[str, float] | None = None
    z: np.ndarray | None = None
    cov_z: np.ndarray | None = None
    log_post: float | None = None
    chains: np.ndarray | None = None
    log_prob: np.ndarray | None = None
    approximate_draws: np.ndarray | None = None
    starts: list[dict[str, float]] = field(default_factory=list)
    diagnostics: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)
    truth: dict[str, float | None] = field(default_factory=dict)
    predictive: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def draws(self) -> np.ndarray | None:
        """Posterior draws flattened over walkers (draw, parameter), or None without a sampler."""
        return None if self.chains is None else self.chains.reshape(-1, self.chains.shape[-1])

    @property
    def detections(self) -> list[Detection]:
        """Every line tested, from the diagnostics."""
        return detections(self.diagnostics)

    def summary(self) -> dict[str, Any]:
        """The JSON summary: per parameter median, mean, sd, q05, q95, map, truth, prior.

        With posterior draws the numbers are their quantiles; without them (spectral, SINDy, MAP)
        the interval is MAP +- 1.645 sd from the Laplace approximation, or null without an sd.
        """
        draws = self.draws
        params = {}
        for j, n in enumerate(self.names):
            if draws is not None:
                d = draws[:, j]
                q05, q50, q95 = np.percentile(d, [5, 50, 95])
                entry = {"median": q50, "mean": d.mean(), "sd": d.std(ddof=1), "q05": q05, "q95": q95}
            elif self.sd is not None and np.isfinite(self.sd.get(n, np.nan)):
                m, s = self.point[n], self.sd[n]
                entry = {"median": m, "mean": m, "sd": s, "q05": m - 1.645 * s, "q95": m + 1.645 * s}
            else:
                m = self.point[n]
                entry = {"median": m, "mean": m, "sd": None, "q05": None, "q95": None}
            entry["map"] = self.point[n]
            entry["truth"] = self.truth.get(n)
            params[n] = {k: (None if v is None else float(v)) for k, v in entry.items()}
            params[n]["prior"] = str(self.priors[j])
            params[n]["prior_bounds"] = [float(b) for b in self.priors[j].bounds]
        return {
            "method": self.method,
            "parameters": params,
            "diagnostics": self.diagnostics,
            "timing": self.timing,
            "data": self.data,
        }

    def to_inference_data(self) -> Any:
        """ArviZ InferenceData: posterior (chain = walker, draw; without a sampler one 'chain' of
        Laplace draws), sample_stats (lp), observed_data, constant_data (time and the predictive
        bands), and the JSON summary in the observed data's attributes."""
        import arviz as az

        chains = (
            self.chains
            if self.chains is not None
            else (None if self.approximate_draws is None else self.approximate_draws[None, ...])
        )
        posterior = None if chains is None else {_safe(n): chains[..., j] for j, n in enumerate(self.names)}
        attrs = {
            "vibinverse_summary": json.dumps(self.summary()),
            "parameter_names": json.dumps({_safe(n): n for n in self.names}),
        }
        series = self.series
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return az.from_dict(
                posterior=posterior,
                sample_stats={"lp": self.log_prob} if self.log_prob is not None else None,
                observed_data={"intensity": series.intensity},
                constant_data={"time": series.time, **self.predictive},
                coords={"time_index": np.arange(series.time.size)},
                dims={
                    "intensity": ["time_index"],
                    "time": ["time_index"],
                    **{k: ["time_index"] for k in self.predictive},
                },
                attrs=attrs,
            )

    def to_netcdf(self, path: str | Path) -> Path:
        """Write `to_inference_data()` as netCDF (h5netcdf); opens with `arviz.from_netcdf`."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.to_inference_data().to_netcdf(str(path), engine="h5netcdf")
        return Path(path)


def detections(diagnostics: dict[str, Any]) -> list[Detection]:
    """Every line tested in `diagnostics` (keys `{what}_detected`, `{what}_delta_loglike`, `{what}_threshold`)."""
    from vibinverse.detection import DETECTION_GAIN

    out = []
    for key, detected in diagnostics.items():
        if key.endswith("_detected"):
            what = key[: -len("_detected")]
            out.append(
                Detection(
                    what.replace("_", " "),
                    diagnostics[f"{what}_delta_loglike"],
                    diagnostics.get(f"{what}_threshold", DETECTION_GAIN),
                    bool(detected),
                )
            )
    return out


def read_result(path: str | Path) -> tuple[dict[str, Any], Any]:
    """(summary dict, InferenceData) from a result netCDF."""
    import arviz as az

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            idata = az.from_netcdf(str(path), engine="h5netcdf")
        return json.loads(idata.observed_data.attrs["vibinverse_summary"]), idata
    except (OSError, ValueError, KeyError, AttributeError) as exc:
        raise DataError(
            f"result: cannot read {path}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
        ) from None


def _safe(name: str) -> str:
    return name.replace(".", "__").replace("[", "_").replace("]", "")
