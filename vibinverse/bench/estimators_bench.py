"""`vibinverse bench --estimators`: the estimators on two scenes at three noise levels each, against
the Cramer-Rao bound of the same model: spectral, SINDy, casadi and emcee on the sec. 4.2 frame
(a noise-driven resonance), spectral, casadi, the scipy MAP and emcee on the sec. 4.1 elastic roof
(a deterministic vibration).

Every dataset is simulated by the forward model (`forward.observe`, frame noise and sensor noise
from independent seeds) and fitted from scratch by `vibinverse.pipeline.run`, as `vibinverse fit`
would, the datasets of a method shared among `workers` processes (one fit per core; `time_s` is a
fit's own wall time). Rows: {"method", "param", "snr", "snr_actual", "bias", "rmse", "crlb_sd", "coverage90",
"time_s", "n", "n_failed", "n_declined", "n_undetected"}; coverage is the fraction of 90 % intervals
that contain the truth (Laplace for casadi, posterior quantiles for emcee, the jackknife sd for
SINDy; none for spectral). Bias, RMSE and coverage are over the fits that report a result: a SINDy
that declines, or a fit whose own detection test says a line is not in the data (the log-likelihood
gain is below its threshold), is counted in n_failed instead, because that is what it tells the
analyst.
"""

from __future__ import annotations

import logging
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from forward.scene_file import apply_overrides, read_table, scene_from_table
from forward.sensor import observe
from vibinverse.fisher import crlb_from_fisher
from vibinverse.io.series import Series
from vibinverse.models import build_model, model_class_for
from vibinverse.pipeline import CasadiMethod, fit_method
from vibinverse.pipeline import run as run_pipeline
from vibinverse.posterior import Posterior

LOG = logging.getLogger(__name__).info


@dataclass(frozen=True)
class Scenario:
    """A scene of the comparison: its file, the sensor noise per nominal line SNR, the parameters
    scored (under the moving surface's motion) and the methods run on every dataset (emcee apart)."""

    name: str
    scene: str
    sigmas: dict[int, float]
    params: tuple[str, ...]
    methods: tuple[str, ...]


SCENARIOS = {
    # sensor noise for drive-line SNR ~3, ~10, ~30 (`snr_actual` from design)
    "frame": Scenario(
        "frame",
        "roof_frame.toml",
        {3: 2.0, 10: 0.6, 30: 0.2},
        ("tilt_frequency", "tilt_damping_ratio", "drive_frequency", "drive_amplitude"),
        ("spectral", "sindy", "casadi"),
    ),
    # the 40 Hz line of the quadrant roof (amplitude 0.59 over 500 samples): sigma = 0.59 / (SNR sqrt(2/500))
    "plate": Scenario(
        "plate",
        "roof_elastic.toml",
        {3: 3.1, 10: 0.93, 30: 0.31},
        ("frequency", "center_deflection", "phase"),
        ("spectral", "casadi", "map"),
    ),
}
SIGMAS = SCENARIOS["frame"].sigmas
PARAMS = SCENARIOS["frame"].params
METHODS = ("spectral", "sindy", "casadi", "map", "importance", "mcmc")
#: the method whose coverage is scored on `n_coverage` data sets (the others on `n_seeds`)
COVERAGE_METHOD = CasadiMethod


def _table(scene_path: Path, sigma: float) -> dict:
    return apply_overrides(read_table(scene_path), [f"noise.sigma={sigma!r}"])


def _problem(table: dict, seed: int) -> Posterior:
    obs = observe(scene_from_table(table), seed)
    series = Series(obs.time, obs.intensity, f"seed {seed}", scene=table)
    return Posterior(build_model(table, series))


def _motion_key(table: dict) -> str:
    """The dotted prefix of the (single) moving surface's motion."""
    name = next(n for n, s in table["surfaces"].items() if s.get("motion"))
    return f"surfaces.{name}.motion."


def crlb(table: dict) -> dict[str, float]:
    """Cramer-Rao sd of the fitted parameters at the truth, all default-free parameters estimated jointly."""
    prob = _problem(table, 0)
    names = prob.space.names
    values = {n: (v if v is not None else 0.0) for n, v in prob.truth().items()}
    return crlb_from_fisher(prob.model.fisher(values, names), names)


def _fit(job: tuple) -> dict[str, Any]:
    """One dataset, one method: estimates, 90 % intervals and wall time (a worker's unit of work)."""
    table, seed, method, max_steps = job
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1), tempfile.TemporaryDirectory() as tmp:
        prob = _problem(table, seed)
        t0 = time.perf_counter()
        summary = run_pipeline(
            prob, method, seed=seed, backend=Path(tmp) / "chain.h5", progress=False, max_steps=max_steps
        ).summary()
        elapsed = time.perf_counter() - t0
    truth = prob.truth()
    failed = fit_method(method).may_decline and summary["method"] != method  # declined: the stage before it
    diag = summary["diagnostics"]
    out = {
        "method": method,
        "seed": seed,
        "time_s": elapsed,
        "failed": failed,
        "converged": diag.get("converged"),
        # the fit's own detection test (log-likelihood gain > threshold): an undetected line is reported as such
        "detected": all(v for k, v in diag.items() if k.endswith("_detected")),
    }
    for n, v in summary["parameters"].items():
        out[n] = {"est": v["median"], "q05": v["q05"], "q95": v["q95"], "truth": truth[n]}
    return out


def _quiet(fn, *args):
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        return fn(*args)


def run(
    scene_dir: Path,
    n_seeds: int = 20,
    n_coverage: int = 100,
    mcmc_seeds: int = 20,
    mcmc_snrs: tuple[int, ...] = (10,),
    snrs: tuple[int, ...] = (3, 10, 30),
    workers: int = 2,
    max_steps: int = 20000,
    scenarios: tuple[str, ...] = ("frame", "plate"),
    log=LOG,
) -> dict[str, Any]:
    """The comparison over `scenarios` (scene files from `scene_dir`); returns {"rows": [...],
    "settings": {...}, "seconds": total}. Rows carry their scenario's name in "scene"."""
    t_start = time.perf_counter()
    rows = []
    for name in scenarios:
        sc = SCENARIOS[name]
        scene_path = scene_dir / sc.scene
        log(f"{name} ({sc.scene}):")
        for snr in snrs:
            table = _table(scene_path, sc.sigmas[snr])
            bound = crlb(table)
            actual = _actual_snr(table)
            log(f"SNR ~{snr} (noise.sigma = {sc.sigmas[snr]:g}, line SNR {actual:.1f}):")
            fits: dict[str, list[dict]] = {}
            for method in sc.methods:
                n = max(n_seeds, n_coverage) if fit_method(method) is COVERAGE_METHOD else n_seeds
                fits[method] = _fits(table, n, method, workers, max_steps, log)
            if snr in mcmc_snrs and mcmc_seeds > 0:
                _quiet(_fit, (table, 0, "casadi", max_steps))  # compile the MAP once; forked workers inherit it
                for sampler in ("importance", "mcmc"):  # the posterior two ways, on the same data sets
                    fits[sampler] = _fits(table, mcmc_seeds, sampler, workers, max_steps, log, warm=False)
            for method, fl in fits.items():
                rows += [
                    {"scene": name, **r} for r in _rows(method, fl, snr, actual, bound, _motion_key(table), sc.params)
                ]
    return {
        "rows": rows,
        "seconds": time.perf_counter() - t_start,
        "settings": {
            "scenes": {n: SCENARIOS[n].scene for n in scenarios},
            "sigmas": {n: {str(k): v for k, v in SCENARIOS[n].sigmas.items() if k in snrs} for n in scenarios},
            "n_seeds": n_seeds,
            "n_coverage_casadi": n_coverage,
            "mcmc_seeds": mcmc_seeds,
            "mcmc_snrs": list(mcmc_snrs),
            "workers": workers,
        },
    }


def _fits(table: dict, n: int, method: str, workers: int, max_steps: int, log, warm: bool = True) -> list[dict]:
    """`method` on datasets 0..n-1 of `table`, on `workers` processes. With `warm`, dataset 0 runs
    first in this process, so that what it builds once per design (the casadi solver, numba's
    kernels) is inherited by the forked workers instead of being built in each; its time, like any
    first fit's, includes that."""
    t0 = time.perf_counter()
    first = [_quiet(_fit, (table, 0, method, max_steps))] if warm else []
    jobs = [(table, seed, method, max_steps) for seed in range(len(first), n)]
    if workers > 1 and len(jobs) > 1:
        import multiprocessing as mp

        with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as pool:
            rest = list(pool.map(_quiet_fit, jobs))
    else:
        rest = [_quiet(_fit, j) for j in jobs]
    label = fit_method(method).label
    log(f"  {label:<8} {n:>4} datasets in {time.perf_counter() - t0:6.1f} s ({workers} workers)")
    return first + rest


def _quiet_fit(job):
    return _quiet(_fit, job)


def _actual_snr(table: dict) -> float:
    """The first line's SNR as `vibinverse design` computes it."""
    from vibinverse.design.metrics import default_targets, evaluate

    row = evaluate(model_class_for(table).truth_table(table), default_targets(table)[:1], {})
    return float(next(v for k, v in row.items() if k.startswith("snr ")))


def _rows(
    method: str,
    fits: list[dict],
    snr: int,
    actual: float,
    bound: dict[str, float],
    key: str,
    params: tuple[str, ...] = PARAMS,
) -> list[dict]:
    out = []
    ok = [f for f in fits if not f["failed"] and f["detected"]]
    for p in params:
        name = key + p
        est = np.array([f[name]["est"] for f in ok]) if ok else np.array([])
        truth = np.array([f[name]["truth"] for f in ok]) if ok else np.array([])
        err = est - truth
        with_interval = [f for f in ok if f[name]["q05"] is not None]
        cover = (
            float(np.mean([f[name]["q05"] <= f[name]["truth"] <= f[name]["q95"] for f in with_interval]))
            if with_interval
            else None
        )
        out.append(
            {
                "method": method,
                "param": name,
                "snr": snr,
                "snr_actual": actual,
                "bias": float(err.mean()) if err.size else None,
                "rmse": float(np.sqrt(np.mean(err**2))) if err.size else None,
                "crlb_sd": bound.get(name),
                "coverage90": cover,
                "time_s": float(np.mean([f["time_s"] for f in fits])),
                "n": len(fits),
                "n_failed": len(fits) - len(ok),
                "n_declined": sum(bool(f["failed"]) for f in fits),
                "n_undetected": sum(not f["failed"] and not f["detected"] for f in fits),
                "n_converged": sum(bool(f.get("converged")) for f in ok)
                if fit_method(method).samples_by_emcee
                else None,
            }
        )
    return out


def plot_speed_error(rows: list[dict], path: Path) -> None:
    """One point per method and SNR: mean wall time against RMSE / Cramer-Rao sd of the frame's tilt
    resonance and drive frequency, and of the elastic roof's frequency. Every method with a reported
    fit is drawn; a point resting on fewer than 10 reported fits (a quick run's spectral, SINDy, MAP,
    importance sampling and emcee, or most fits declined or undetected) is an open marker, a noisier
    ratio. A point with no reported fit (the lowest SNR) has no RMSE: the table shows it. One legend
    for the figure, below the panels: colour the method, shape the SNR, filled or open the count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, NullFormatter

    panels = (("frame", "tilt_frequency"), ("frame", "drive_frequency"), ("plate", "frequency"))
    markers = {3: "v", 10: "o", 30: "^"}
    colors = {"spectral": "C0", "sindy": "C1", "casadi": "C2", "mcmc": "C3", "map": "C4", "importance": "C5"}
    names = {"mcmc": "emcee", "map": "scipy MAP", "importance": "importance sampling", "sindy": "SINDy"}
    with plt.rc_context({"font.size": 11}):  # read at the page's width, about 7 inches
        fig, axes = plt.subplots(1, len(panels), figsize=(10.5, 4.8), constrained_layout=True)
        seen_methods, seen_snrs, few = [], [], False
        for ax, (scene, p) in zip(axes, panels):
            for r in rows:
                if not (
                    r.get("scene", "frame") == scene
                    and r["param"].rsplit(".", 1)[-1] == p
                    and r["rmse"] is not None
                    and r["crlb_sd"]
                ):
                    continue
                filled = r["n"] - r["n_failed"] >= 10
                few |= not filled
                color = colors.get(r["method"], "0.3")
                ax.plot(
                    r["time_s"],
                    r["rmse"] / r["crlb_sd"],
                    markers.get(r["snr"], "s"),
                    color=color,
                    mfc=color if filled else "none",
                    mew=1.6,
                    ms=9,
                    alpha=0.9,
                )
                seen_methods += [r["method"]] if r["method"] not in seen_methods else []
                seen_snrs += [r["snr"]] if r["snr"] not in seen_snrs else []
            ax.axhline(1.0, color="k", lw=0.8)
            ax.axhline(1.5, color="k", lw=0.8, ls="--")
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_ylim(0, max(1.6, ax.get_ylim()[1]))
            ax.set_xlabel("wall time per fit (s)")
            ax.set_ylabel("RMSE / Cramer-Rao sd")
            ax.set_title(f"{scene}: {p.replace('_', ' ')}")
            ax.grid(True, which="major", alpha=0.3)
        handles = [
            Line2D([], [], ls="", marker="s", ms=9, color=colors.get(m, "0.3"), label=names.get(m, m))
            for m in [m for m in colors if m in seen_methods] + [m for m in seen_methods if m not in colors]
        ]
        handles += [
            Line2D([], [], ls="", marker=markers.get(s, "s"), ms=9, color="0.3", label=f"SNR {s}")
            for s in sorted(seen_snrs)
        ]
        handles += [
            Line2D([], [], color="k", lw=0.8, label="the bound"),
            Line2D([], [], color="k", lw=0.8, ls="--", label="1.5x the bound"),
        ]
        if few:
            handles.append(
                Line2D(
                    [], [], ls="", marker="o", ms=9, mew=1.6, color="0.3", mfc="none", label="open: < 10 reported fits"
                )
            )
        fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 6), frameon=False)
        fig.savefig(path, dpi=120, format="png")
    plt.close(fig)


def table(result: dict[str, Any]) -> str:
    """`run`'s result (estimators.json) as fixed-width text, one block per scene: per method, SNR
    and parameter the bias, RMSE, Cramer-Rao sd, RMSE / Cramer-Rao sd, 90 % coverage, seconds per
    fit and the fits that reported no result (failed = declined + undetected, over n). Pure."""
    fmt = lambda v, f: format("-", f">{f.split('.')[0]}") if v is None else format(v, f)
    head = (
        f"{'method':<11}{'SNR':>4} {'parameter':<20}{'bias':>11}{'rmse':>11}{'crlb_sd':>11}{'rmse/crlb':>10}"
        f"{'cover90':>8}{'time_s':>8}{'failed':>8}"
    )
    rows = result.get("rows", [])
    out: list[str] = []
    for scene in dict.fromkeys(r.get("scene", "frame") for r in rows):
        file = result.get("settings", {}).get("scenes", {}).get(scene)
        out += [*([""] if out else []), f"{scene}{f' ({file})' if file else ''}:", head]
        for r in (r for r in rows if r.get("scene", "frame") == scene):
            ratio = r["rmse"] / r["crlb_sd"] if r["rmse"] is not None and r["crlb_sd"] else None
            failed = f"{r['n_failed']}/{r['n']}"
            out.append(
                f"{r['method']:<11}{r['snr']:>4} {r['param'].rsplit('.', 1)[-1]:<20}{fmt(r['bias'], '11.3g')}"
                f"{fmt(r['rmse'], '11.3g')}{fmt(r['crlb_sd'], '11.3g')}{fmt(ratio, '10.2f')}"
                f"{fmt(r['coverage90'], '8.2f')}{r['time_s']:8.2f}{failed:>8}"
            )
    return "\n".join(out)
