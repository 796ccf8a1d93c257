"""ArviZ behind one small interface, whichever major is installed: 0.x keeps groups in an
`arviz.InferenceData` (Python 3.11 resolves it), 1.x in an xarray `DataTree` (3.12 and later resolve
only 1.x). Every other module builds, reads, saves and diagnoses inference data through here.

Groups go in and come out as `xarray.Dataset`s; the object itself is ArviZ's native one of the
installed major (what `az.loo`, `az.compare`, `az.summary` of that major take)."""

from __future__ import annotations

import functools
import logging
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

logger = logging.getLogger(__name__)


@functools.cache
def _arviz() -> Any:
    """The arviz module, imported on first use (it takes about a second)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import arviz

    logger.debug("arviz %s", arviz.__version__)
    return arviz


def arviz_major() -> int:
    """The installed ArviZ major version (0 or 1)."""
    return int(str(_arviz().__version__).split(".")[0])


def _is_tree(idata: Any) -> bool:
    tree = getattr(xr, "DataTree", None)
    return tree is not None and isinstance(idata, tree)


def build(groups: dict[str, xr.Dataset]) -> Any:
    """The inference-data object holding `groups` (name -> Dataset, attributes kept)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if arviz_major() >= 1:
            return xr.DataTree.from_dict(dict(groups))
        return _arviz().InferenceData(**groups)


def group_names(idata: Any) -> list[str]:
    """The names of the groups of `idata` (posterior, observed_data, ...)."""
    return [str(k) for k in idata.children] if _is_tree(idata) else list(idata.groups())


def group(idata: Any, name: str) -> xr.Dataset | None:
    """Group `name` of `idata` as a Dataset (with its attributes), or None without one."""
    if name not in group_names(idata):
        return None
    node = idata[name]
    return node.to_dataset() if _is_tree(node) else node


def to_netcdf(idata: Any, path: str | Path) -> Path:
    """Write `idata` as netCDF-4 (h5netcdf), one netCDF group per group, numbers zlib-compressed
    (as ArviZ 0.x's `InferenceData.to_netcdf` does)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if not _is_tree(idata):
            idata.to_netcdf(str(path), engine="h5netcdf")
            return Path(path)
        encoding = {
            node.path: {k: {"zlib": True} for k, v in node.data_vars.items() if v.dtype.kind in "biufc"}
            for node in idata.subtree
        }
        idata.to_netcdf(str(path), engine="h5netcdf", encoding=encoding)
    return Path(path)


def from_netcdf(path: str | Path) -> Any:
    """Inference data read from a netCDF file `to_netcdf` (of either major) wrote."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _arviz().from_netcdf(str(path), engine="h5netcdf")


def _draws_dataset(chains: np.ndarray) -> xr.Dataset:
    """(chain, draw, parameter) draws as a Dataset with variables p0, p1, ..."""
    return xr.Dataset({f"p{j}": (("chain", "draw"), chains[..., j]) for j in range(chains.shape[-1])})


def rank_diagnostics(chains: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank-normalized split R-hat, bulk ESS and tail ESS per parameter of (chain, draw,
    parameter) draws: the numbers `summary` gives."""
    az, ds = _arviz(), _draws_dataset(np.asarray(chains, dtype=float))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = [az.rhat(ds, method="rank"), az.ess(ds, method="bulk"), az.ess(ds, method="tail")]
    return tuple(np.array([float(d[f"p{j}"]) for j in range(len(ds.data_vars))]) for d in out)


def summary(posterior: xr.Dataset) -> dict[str, dict[str, float]]:
    """Per variable of a (chain, draw) Dataset its r_hat, ess_bulk and ess_tail (`arviz.summary`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = _arviz().summary(posterior, kind="diagnostics", round_to="none")
    return {str(k): {c: float(table.loc[k, c]) for c in ("r_hat", "ess_bulk", "ess_tail")} for k in table.index}


def psislw(log_w: np.ndarray) -> tuple[np.ndarray, float]:
    """(Pareto-smoothed log weights, Pareto k) of 1-D log importance weights (r_eff 1); a weight
    of -inf stays -inf (ArviZ 1.x would make every weight NaN)."""
    log_w = np.asarray(log_w, dtype=float)
    finite = np.isfinite(log_w)
    # zero weights rank below every other; far enough below that they stay 0 after smoothing
    filled = np.where(finite, log_w, np.min(log_w[finite]) - 1000.0) if finite.any() else log_w
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if arviz_major() >= 1:  # 1.x smooths the weights 1 / p of a log-likelihood (LOO): pass -log w
            smoothed, khat = xr.DataArray(-filled, dims=["sample"]).azstats.psislw(dim="sample")
        else:
            smoothed, khat = _arviz().psislw(filled)
    return np.where(finite, np.asarray(smoothed, dtype=float), -np.inf), float(khat)


@dataclass(frozen=True)
class Loo:
    """PSIS-LOO-CV: elpd (sum of pointwise), its standard error, the effective number of
    parameters p, and per observation the elpd and the Pareto k."""

    elpd: float
    se: float
    p: float
    elpd_i: np.ndarray
    pareto_k: np.ndarray
    warning: bool


def loo(idata: Any, var_name: str | None = None) -> Loo:
    """PSIS-LOO-CV of the log_likelihood group (`var_name` when it holds several variables)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = _arviz().loo(idata, pointwise=True, var_name=var_name)
    one = arviz_major() >= 1
    keys = ("elpd", "se", "p", "elpd_i") if one else ("elpd_loo", "se", "p_loo", "loo_i")
    elpd, se, p, elpd_i = (getattr(r, k) for k in keys)
    k = np.asarray(r.pareto_k, dtype=float)
    return Loo(float(elpd), float(se), float(p), np.asarray(elpd_i, dtype=float), k, bool(r.warning))
