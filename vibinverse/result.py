"""One result type for every estimator: `FitResult`, with its JSON summary, ArviZ InferenceData and
netCDF file."""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.errors import DataError, Unsupported
from vibinverse.io import jsonio
from vibinverse.io.file_basics import netcdf_format
from vibinverse.io.series import Series, check_file
from vibinverse.priors import Prior

logger = logging.getLogger(__name__)

#: approximations whose draws are of the posterior itself (resampled by importance weights), so that
#: the summary's intervals are their quantiles (`vibinverse.estimators.importance`)
WEIGHTED_APPROXIMATIONS = ("importance",)


@dataclass(frozen=True)
class Detection:
    """One line's detection test: the log-likelihood gain of the fit with it over the fit without
    it, against the threshold it must pass (`vibinverse.detection`); `broad`: a resonance too
    damped to be claimed as one (`vibinverse.detection.BROAD_DAMPING`); `product`: the combination
    of stronger tones it is a harmonic or intermodulation product of ("" for none,
    `vibinverse.detection.products`)."""

    what: str
    delta_loglike: float
    threshold: float
    detected: bool
    broad: bool = False
    product: str = ""


@dataclass
class FitResult:
    """What an estimator returns.

    `point` is its point estimate (the MAP for MAP and MCMC results); `sd` the Laplace (or
    jackknife) standard deviations when there is no sampler; `chains` real posterior draws
    (walker, draw, parameter) in value units; `approximate_draws` draws of the Laplace
    approximation (draw, parameter); `z`, `cov_z` the point and covariance in the samplers'
    unconstrained space; `starts` the candidate starting points the next stage may use, best first;
    `approximation` what the intervals are without real draws ("laplace", "jackknife", "spectral");
    `units` (units, long name) per parameter; `pointwise` the pointwise log-likelihood and
    replicate series (chain, draw, sample) of a thinned subset of the draws, with the `draw`
    indices kept (`vibinverse.estimators.base.pointwise`), computed when first asked for
    (`pointwise_groups`) from `pointwise_source`: a pipeline's earlier stages never need them.
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
    approximation: str | None = None
    units: dict[str, tuple[str, str]] = field(default_factory=dict)
    pointwise: dict[str, np.ndarray] = field(default_factory=dict)
    pointwise_source: Callable[[], dict[str, np.ndarray]] | None = field(default=None, repr=False, compare=False)

    def pointwise_groups(self) -> dict[str, np.ndarray]:
        """`pointwise`, computed from `pointwise_source` on the first call ({} when the model has no
        pointwise form)."""
        if self.pointwise_source is not None:
            source, self.pointwise_source = self.pointwise_source, None
            try:
                self.pointwise = source()
            except Unsupported as exc:
                logger.debug("no log_likelihood or posterior_predictive group: %s", exc)
        return self.pointwise

    def __getstate__(self) -> dict[str, Any]:
        """Pickled (to another process) with its pointwise groups computed, not their source."""
        self.pointwise_groups()
        return dict(self.__dict__)

    @property
    def draws(self) -> np.ndarray | None:
        """Posterior draws flattened over walkers (draw, parameter), or None without a sampler."""
        return None if self.chains is None else self.chains.reshape(-1, self.chains.shape[-1])

    @property
    def detections(self) -> list[Detection]:
        """Every line tested, from the diagnostics."""
        return detections(self.diagnostics)

    def summary(self) -> dict[str, Any]:
        """The JSON summary: per parameter median, mean, sd, q05, q95, map, truth, prior, units,
        long name, and with posterior draws the rank-normalized split R-hat and the bulk and tail
        ESS (`convergence`); `approximation` says what the intervals are without draws.

        With posterior draws (or the resampled draws of an importance-sampled approximation,
        WEIGHTED_APPROXIMATIONS) the numbers are their quantiles; without them (spectral, SINDy, MAP)
        the interval is the Laplace approximation's, formed in the unconstrained space
        (`_approximate_interval`), or null without an sd.
        """
        draws = self.draws
        if draws is None and self.approximation in WEIGHTED_APPROXIMATIONS:
            draws = self.approximate_draws  # draws of the posterior, resampled by importance weights
        convergence = self.convergence()
        params = {}
        for j, n in enumerate(self.names):
            if draws is not None:
                d = draws[:, j]
                q05, q50, q95 = np.percentile(d, [5, 50, 95])
                entry = {"median": q50, "mean": d.mean(), "sd": d.std(ddof=1), "q05": q05, "q95": q95}
            elif self.sd is not None and np.isfinite(self.sd.get(n, np.nan)):
                m, s = self.point[n], self.sd[n]
                q05, q95 = self._approximate_interval(j, m, s)
                entry = {"median": m, "mean": m, "sd": s, "q05": q05, "q95": q95}
            else:
                m = self.point[n]
                entry = {"median": m, "mean": m, "sd": None, "q05": None, "q95": None}
            entry["map"] = self.point[n]
            entry["truth"] = self.truth.get(n)
            params[n] = {k: (None if v is None else float(v)) for k, v in entry.items()}
            params[n].update({k: convergence.get(n, {}).get(k) for k in ("rhat", "ess_bulk", "ess_tail")})
            params[n]["prior"] = str(self.priors[j])
            params[n]["prior_bounds"] = [float(b) for b in self.priors[j].bounds]
            params[n]["units"], params[n]["long_name"] = self.units.get(n, ("1", n.split(".")[-1]))
        return {
            "method": self.method,
            "approximation": self.approximation if self.chains is None else None,
            "parameters": params,
            "diagnostics": self.diagnostics,
            "timing": self.timing,
            "data": self.data,
        }

    def convergence(self) -> dict[str, dict[str, float]]:
        """Per parameter the rank-normalized split R-hat and the bulk and tail ESS of the posterior
        draws (ArviZ, chain = walker; the numbers `arviz.summary` gives); {} without draws."""
        if self.chains is None:
            return {}
        cached = getattr(self, "_convergence", None)
        if cached is not None and cached[0] is self.chains:
            return cached[1]
        from vibinverse.inference_data import rank_diagnostics

        rhat, bulk, tail = rank_diagnostics(self.chains)
        out = {
            n: {"rhat": float(rhat[j]), "ess_bulk": float(bulk[j]), "ess_tail": float(tail[j])}
            for j, n in enumerate(self.names)
        }
        self._convergence = (self.chains, out)
        return out

    def _approximate_interval(self, j: int, m: float, s: float) -> tuple[float, float]:
        """The 90 % interval without draws: of the Laplace approximation in the samplers'
        unconstrained space (logit or log of a bounded prior), mapped back, so that it stays inside
        the prior (a positive parameter never gets a negative bound); without that covariance,
        m +- 1.645 s cut to the prior's support."""
        prior = self.priors[j]
        if self.z is not None and self.cov_z is not None and np.isfinite(self.cov_z[j, j]):
            half = 1.645 * float(np.sqrt(max(self.cov_z[j, j], 0.0)))
            z = float(self.z[j])
            return prior.from_unbounded(z - half), prior.from_unbounded(z + half)
        lo, hi = prior.bounds
        return max(m - 1.645 * s, lo), min(m + 1.645 * s, hi)

    def to_inference_data(self) -> Any:
        """ArviZ inference data (InferenceData on ArviZ 0.x, an xarray DataTree on 1.x; see
        `vibinverse.inference_data`) with CF-style `units` and `long_name` on every variable:

        - `posterior`: real posterior draws only (chain = walker, draw); the draws of an
          approximation (Laplace) go to `approximate_posterior` instead, labelled;
        - `log_likelihood` and `posterior_predictive` (variable `intensity`): the pointwise
          log-likelihood and a replicate series of an evenly thinned subset of the draws (their
          `draw` coordinate holds the indices kept), so that `az.loo` and `az.compare` work;
        - `sample_stats` (lp), `observed_data` (intensity), `constant_data` (time in seconds since
          the first sample's reference, the predictive band, the standardized residuals);
        - the JSON summary in the observed data's attributes (strict JSON: a non-finite number is
          null there, named in its "non_finite" record; `read_result` restores it).
        """
        import xarray as xr

        from vibinverse.inference_data import build

        series = self.series
        names = [_safe(n) for n in self.names]
        units = {_safe(n): self.units.get(n, ("1", n.split(".")[-1])) for n in self.names}
        intensity_units = str(self.data.get("intensity_units", "1"))
        attrs = {
            "vibinverse_summary": jsonio.dumps(self.summary()),
            "parameter_names": jsonio.dumps({_safe(n): n for n in self.names}),
        }
        groups: dict[str, Any] = {}
        if self.chains is not None:
            groups["posterior"] = _draws(self.chains, names, units)
        elif self.approximate_draws is not None:
            groups["approximate_posterior"] = _draws(self.approximate_draws[None], names, units)
            groups["approximate_posterior"].attrs["approximation"] = str(self.approximation or "laplace")
        if self.log_prob is not None:
            groups["sample_stats"] = xr.Dataset({"lp": (("chain", "draw"), np.asarray(self.log_prob))})
        n = series.time.size
        sample = {"time_index": np.arange(n)}
        if self.pointwise_groups():
            coords = {"chain": np.arange(self.pointwise["log_likelihood"].shape[0]), "draw": self.pointwise["draw"]}
            coords.update(sample)
            dims = ("chain", "draw", "time_index")
            groups["log_likelihood"] = xr.Dataset(
                {"intensity": (dims, self.pointwise["log_likelihood"], _cf("1", "pointwise log-likelihood"))},
                coords=coords,
            )
            groups["posterior_predictive"] = xr.Dataset(
                {"intensity": (dims, self.pointwise["replicates"], _cf(intensity_units, "replicate intensity"))},
                coords=coords,
            )
            if self.chains is None:
                for g in ("log_likelihood", "posterior_predictive"):
                    groups[g].attrs["approximation"] = str(self.approximation or "laplace")
        groups["observed_data"] = xr.Dataset(
            {"intensity": ("time_index", series.intensity, _cf(intensity_units, "pixel intensity"))},
            coords=sample,
            attrs=attrs,
        )
        time_attrs = _cf("s", "time")
        reference = self.data.get("time_reference")
        if reference:
            time_attrs["reference"] = str(reference)
        constant = {"time": ("time_index", series.time, time_attrs)}
        long_names = {
            "model_mean": ("model mean at the point estimate", intensity_units),
            "model_q05": ("model mean, 5 % quantile over the draws", intensity_units),
            "model_q95": ("model mean, 95 % quantile over the draws", intensity_units),
            "residual": ("standardized one-step residual at the point estimate", "1"),
        }
        for k, v in self.predictive.items():
            long_name, u = long_names.get(k, (k, intensity_units))
            constant[k] = ("time_index", v, _cf(u, long_name))
        groups["constant_data"] = xr.Dataset(constant, coords=sample)
        return build(groups)

    def to_netcdf(self, path: str | Path) -> Path:
        """Write `to_inference_data()` as netCDF (h5netcdf); opens with `arviz.from_netcdf`."""
        from vibinverse.inference_data import to_netcdf

        return to_netcdf(self.to_inference_data(), path)


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
                    diagnostics.get(f"{what}_delta_loglike", math.nan),
                    diagnostics.get(f"{what}_threshold", DETECTION_GAIN),
                    bool(detected),
                    diagnostics.get(f"{what}_broad") is True,
                    str(diagnostics.get(f"{what}_product") or ""),
                )
            )
    return out


def read_result(path: str | Path) -> tuple[dict[str, Any], Any]:
    """(summary dict, InferenceData) from a result netCDF written by `FitResult.to_netcdf`.

    A file that is missing, empty, not netCDF-4, truncated, corrupt, or not a vibinverse result
    (no summary, a summary that is not the one `FitResult.summary` writes, no data) raises
    DataError with one line naming the file and what is wrong.
    """
    from vibinverse.inference_data import from_netcdf, group, group_names

    p = check_file(path, "result")
    if netcdf_format(p, "result") != "hdf5":
        raise DataError(f"result: {p} is a netCDF-3 file, not a vibinverse result (those are netCDF-4/HDF5)")
    try:
        idata = from_netcdf(p)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RuntimeError) as exc:
        raise DataError(f"result: {p} is truncated or corrupt ({_hdf5_reason(exc)})") from None
    groups = set(group_names(idata))
    observed, constant, posterior = (group(idata, g) for g in ("observed_data", "constant_data", "posterior"))
    attrs = observed.attrs if observed is not None else {}
    if "vibinverse_summary" not in attrs:
        raise DataError(
            f"result: {p} is not a vibinverse result (it has no observed_data group with a vibinverse_summary "
            f"attribute; groups: {', '.join(sorted(groups)) or 'none'})"
        )
    summary = _parse(attrs["vibinverse_summary"], p, "vibinverse_summary")
    _check_summary(summary, p)
    for name, ds, var in (("observed_data", observed, "intensity"), ("constant_data", constant, "time")):
        if ds is None or var not in ds:
            raise DataError(f"result: {p} is not a complete vibinverse result (no {name} group with the {var})")
    n = observed["intensity"].size
    if observed["intensity"].ndim != 1 or constant["time"].shape != (n,):
        raise DataError(f"result: {p}: the observed intensity and the constant_data time are not 1-D of equal length")
    if posterior is not None:
        names = _parse(attrs.get("parameter_names", "{}"), p, "parameter_names")
        if not isinstance(names, dict):
            raise DataError(f"result: {p}: attribute parameter_names is not a JSON object")
        inv = {v: k for k, v in names.items() if isinstance(v, str)}
        for name in summary["parameters"]:
            if inv.get(name) not in posterior.data_vars:
                raise DataError(f"result: {p}: parameter {name!r} has no variable in the posterior group")
    return summary, idata


_NUMERIC = ("median", "mean", "sd", "q05", "q95", "map", "truth")


def _parse(text: Any, p: Path, what: str) -> Any:
    try:
        return jsonio.loads(text)
    except (ValueError, TypeError, RecursionError) as exc:
        raise DataError(f"result: {p}: attribute {what} is not JSON ({_hdf5_reason(exc)})") from None


def _check_summary(summary: Any, p: Path) -> None:
    """One-line DataError unless `summary` has the shape `FitResult.summary` gives it."""

    def bad(what: str) -> DataError:
        return DataError(f"result: {p}: vibinverse_summary {what}")

    def number(v: Any) -> bool:
        return v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))

    if not isinstance(summary, dict):
        raise bad(f"is a JSON {type(summary).__name__}, not an object")
    for key, kind in (("method", str), ("parameters", dict), ("diagnostics", dict), ("timing", dict), ("data", dict)):
        if not isinstance(summary.get(key), kind):
            raise bad(f"has no {key!r} {'string' if kind is str else 'object'}")
    if not summary["parameters"]:
        raise bad("has no parameters")
    for name, entry in summary["parameters"].items():
        if not isinstance(entry, dict):
            raise bad(f"parameter {name!r} is not an object")
        for key in _NUMERIC:
            if not number(entry.get(key)):
                raise bad(f"parameter {name!r}: {key} is {_short(entry.get(key))}; a number or null is needed")
        if not isinstance(entry.get("prior", ""), str):
            raise bad(f"parameter {name!r}: prior is {_short(entry.get('prior'))}; a string is needed")
        bounds = entry.get("prior_bounds", [None, None])
        if not (isinstance(bounds, list) and len(bounds) == 2 and all(number(b) for b in bounds)):
            raise bad(f"parameter {name!r}: prior_bounds is {_short(bounds)}; two numbers (or nulls) are needed")
    for key, value in summary["timing"].items():
        if not number(value):
            raise bad(f"timing {key!r} is {_short(value)}; a number or null is needed")
    for key in ("source", "description"):
        if not isinstance(summary["data"].get(key, ""), str):
            raise bad(f"data {key} is {_short(summary['data'].get(key))}; a string is needed")


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def _hdf5_reason(exc: BaseException) -> str:
    text = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    return re.sub(r"^\[Errno \d+\] ", "", re.sub(r"^Unable to synchronously open file \((.*)\)$", r"\1", text))


def _cf(units: str, long_name: str) -> dict[str, str]:
    return {"units": units, "long_name": long_name}


def _draws(chains: np.ndarray, names: list[str], units: dict[str, tuple[str, str]]) -> Any:
    """(chain, draw, parameter) draws as a Dataset, one variable per parameter, with units."""
    import xarray as xr

    c, d, _ = chains.shape
    return xr.Dataset(
        {n: (("chain", "draw"), chains[..., j], _cf(*units[n])) for j, n in enumerate(names)},
        coords={"chain": np.arange(c), "draw": np.arange(d)},
    )


def _safe(name: str) -> str:
    return name.replace(".", "__").replace("[", "_").replace("]", "")
