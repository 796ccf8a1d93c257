"""Likelihood speed, side by side in one run: our frame log-likelihood (T = 4000) and celerite2's SHO
log-likelihood on a series of the same length; the deterministic-scene likelihood against dense
rendering; and the demo's MCMC wall time to convergence."""

from __future__ import annotations

import json
import logging
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

from forward.scene_file import load_scene
from forward.sensor import observe
from vibinverse.io.series import validate
from vibinverse.kalman import log_likelihood
from vibinverse.models import build_model
from vibinverse.pipeline import run as run_pipeline
from vibinverse.posterior import Posterior

LOG = logging.getLogger(__name__).info

KEY = "surfaces.roof.motion."


def _problem(scene_path: Path) -> Posterior:
    scene, table = load_scene(scene_path, ["noise.sigma=0.6"])
    o = observe(scene, seed=3)
    series = validate(o.time, o.intensity, "bench", table)
    return Posterior(build_model(table, series))


def _best(fn, number: int = 100, repeat: int = 5) -> float:
    """Microseconds per call: the best of `repeat` timings of `number` calls, after a warm-up
    (a noisy machine only ever adds time)."""
    fn()
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def likelihood_row(scene_path: Path, log=LOG) -> dict:
    prob = _problem(scene_path)
    values = prob.truth()
    ours = _best(lambda: prob.model.log_likelihood(values))
    c = prob.model.components(values)
    resid = prob.series.intensity - c.mean
    filt = _best(lambda: log_likelihood(resid, c.phi, c.q, c.h, c.r, c.p0))
    row = {"samples": int(prob.series.time.size), "ours_us": ours, "ours_filter_only_us": filt}
    try:
        import celerite2
    except ImportError:
        log("  celerite2 not installed (pip install '.[test]'): no side-by-side row")
        row.update({"celerite2_us": None, "ratio": None})
        return row
    t = prob.series.time
    gp = celerite2.GaussianProcess(celerite2.terms.SHOTerm(S0=1.0, w0=2 * np.pi * 3.46, Q=36.0))
    y = np.random.default_rng(0).normal(size=t.size)

    def cel():
        gp.compute(t, yerr=0.6)
        return gp.log_likelihood(y)

    theirs = _best(cel)
    row.update({"celerite2_us": theirs, "ratio": ours / theirs, "filter_ratio": filt / theirs})
    log(
        f"  T = {t.size}: ours {ours:.0f} us (mean + Kalman; filter alone {filt:.0f} us), "
        f"celerite2 SHO {theirs:.0f} us;"
        f" ratio {ours / theirs:.2f} (filter alone {filt / theirs:.2f})"
    )
    return row


def demo_mcmc_row(scene_path: Path, log=LOG) -> dict:
    prob = _problem(scene_path)
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        summary = run_pipeline(prob, "auto", backend=Path(d) / "c.h5", max_steps=7000, progress=False).summary()
        wall = time.perf_counter() - t0
    diag = summary["diagnostics"]
    log(
        f"  demo fit: {wall:.1f} s ({summary['timing']['mcmc_s']:.1f} s MCMC), {diag['n_steps']} steps, "
        f"converged {diag['converged']}, R-hat {diag['rhat_max']:.3f}"
    )
    return {
        "wall_s": wall,
        "mcmc_s": summary["timing"]["mcmc_s"],
        "n_steps": diag["n_steps"],
        "converged": diag["converged"],
        "rhat_max": diag["rhat_max"],
        "ess_min": diag["ess_min"],
    }


def response_fit_row(scene_path: Path, log=LOG) -> dict:
    """The deterministic-scene likelihood (elastic roof, sec. 4.1): one evaluation of ours (Taylor
    mean re-formed for new motion values) against rendering every subpixel at every sample, the
    error of ours against that reference relative to the noise, and a MAP fit's time and errors."""
    from forward.render import pixel_signal
    from forward.scene_file import scene_from_table
    from vibinverse.scene_keys import set_value

    scene, table = load_scene(scene_path, [])
    o = observe(scene, seed=1)
    series = validate(o.time, o.intensity, "bench", table)
    prob = Posterior(build_model(table, series))
    values = {**prob.truth(), "surfaces.roof.motion.frequency": 40.3, "surfaces.roof.motion.center_deflection": 1.2e-3}
    ours = _best(lambda: prob.model.log_likelihood(values))
    other = json.loads(json.dumps(table))
    for n, v in values.items():
        if n != "noise.sigma":
            set_value(other, n, v)
    t0 = time.perf_counter()
    dense = pixel_signal(scene_from_table(other), series.time)
    dense_us = (time.perf_counter() - t0) * 1e6
    error = float(np.abs(prob.model.mean(values) - dense).max()) / scene.noise.sigma
    t0 = time.perf_counter()
    summary = run_pipeline(prob, "map", progress=False).summary()
    map_s = time.perf_counter() - t0
    z = {n: (p["median"] - p["truth"]) / p["sd"] for n, p in summary["parameters"].items() if p["sd"]}
    log(
        f"  elastic roof, {series.time.size} samples: ours {ours:.0f} us per log-likelihood, dense rendering "
        f"{dense_us / 1e3:.0f} ms ({dense_us / ours:.0f}x); max error {error:.1e} x sigma; MAP {map_s:.1f} s, "
        f"errors {min(z.values()):+.1f} .. {max(z.values()):+.1f} sd"
    )
    return {
        "samples": int(series.time.size),
        "ours_us": ours,
        "dense_us": dense_us,
        "speedup": dense_us / ours,
        "max_error_over_sigma": error,
        "map_s": map_s,
        "map_error_sd": z,
    }
