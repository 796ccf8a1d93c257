"""Are the modal fit's 90 % intervals calibrated? Simulation-based calibration over the prior.

    python examples/modal_calibration.py --draws 160 --workers 2   # ~10 min on 2 cores

Each draw takes a resonance from the priors below (frequency, damping ratio, RMS), simulates 20 s
at 200 Hz of it in white noise (sd 0.6, level 2: both far better determined by 4000 samples than
by their wide priors) with the robustness bench's exact oscillator, and fits it at the true order
with the same priors (`vi.fit(..., free=PRIORS)`), once by each method. Averaged over draws from
the prior, an exact posterior's 90 % interval holds the truth in 90 % of them whatever the draw
(a fixed truth, as in `bench --robustness`, need not), so coverage off 0.90 by more than its
standard error here is the approximation's (or the sampler's) fault, not the prior's.

By default it fits by MAP + Laplace (`map`) and by emcee (`mcmc`); `--methods` also takes the
Laplace approximation importance-sampled (`importance`, which falls back to emcee where the weights
fail their checks). It prints each method's coverage per parameter with its standard error. This
script compares the methods on one prior; the measured coverage of the default fit, over the
bench's simulated cases, comes from `vibinverse bench --calibration` and is kept in
docs/validation/calibration.md.

    python examples/modal_calibration.py --methods importance,map   # ~5 min on 2 cores
"""

# ruff: noqa: T201  (an example prints its results)

from __future__ import annotations

import argparse
import logging
import math
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

import vibinverse as vi
from vibinverse.bench.robustness_cases import Mode, oscillator

PRIORS = {
    "modes[0].frequency": "uniform(2, 6)",
    "modes[0].damping_ratio": "loguniform(0.005, 0.05)",
    "modes[0].rms": "loguniform(0.15, 0.6)",
    "level": "uniform(-5, 9)",
    "noise.sigma": "loguniform(0.06, 6)",
}
ORDER = {"modal": {"modes": 1, "lines": 0, "drift": False, "noise": "white", "gain": False}}
FS, DURATION, LEVEL, SIGMA = 200.0, 20.0, 2.0, 0.6


def draw(seed: int) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """(t, y, truth): one resonance drawn from PRIORS, simulated in white noise."""
    rng = np.random.default_rng([seed, 777])
    f = rng.uniform(2.0, 6.0)
    zeta = math.exp(rng.uniform(math.log(0.005), math.log(0.05)))
    rms = math.exp(rng.uniform(math.log(0.15), math.log(0.6)))
    t = np.arange(round(FS * DURATION)) / FS
    y = LEVEL + oscillator(t, Mode(f, zeta, rms), rng) + SIGMA * rng.standard_normal(t.size)
    return t, y, {"modes[0].frequency": f, "modes[0].damping_ratio": zeta, "modes[0].rms": rms}


def fit_draw(seed: int, methods: tuple[str, ...] = ("map", "mcmc")) -> dict:
    """One draw fitted by each method: {"seed", "truth", method: {name: (q05, q95)}, "seconds":
    {method: s}, "approximation": {method: the summary's approximation (None: posterior draws)}}."""
    t, y, truth = draw(seed)
    out: dict = {"seed": seed, "truth": truth, "seconds": {}, "approximation": {}}
    for method in methods:
        t0 = time.perf_counter()
        summary = vi.fit(vi.series(t, y), ORDER, method=method, free=PRIORS).summary()
        out["seconds"][method] = time.perf_counter() - t0
        out["approximation"][method] = summary["approximation"]
        p = summary["parameters"]
        out[method] = {k: (p[k]["q05"], p[k]["q95"]) for k in truth}
    return out


def coverage(records: list[dict], methods: tuple[str, ...]) -> list[dict]:
    """Per parameter and method: the fraction of draws whose 90 % interval holds the truth, its
    binomial standard error at 0.90, and how the others miss (truth above, below)."""
    rows = []
    for name in records[0]["truth"]:
        for m in methods:
            lo = np.array([r[m][name][0] for r in records])
            hi = np.array([r[m][name][1] for r in records])
            true = np.array([r["truth"][name] for r in records])
            rows.append(
                {
                    "parameter": name,
                    "method": m,
                    "coverage90": float(np.mean((lo <= true) & (true <= hi))),
                    "se": math.sqrt(0.09 / len(records)),
                    "truth_above": float(np.mean(true > hi)),
                    "truth_below": float(np.mean(true < lo)),
                }
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=160)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--methods", default="map,mcmc")
    args = ap.parse_args()
    methods = tuple(args.methods.split(","))
    logging.disable(logging.WARNING)  # the fits' progress, in this process and the workers it forks
    with ProcessPoolExecutor(args.workers) as pool:
        records = list(pool.map(fit_draw, range(args.draws), [methods] * args.draws))
    for r in coverage(records, methods):
        print(
            f"{r['parameter']:<24} {r['method']:<10} coverage {r['coverage90']:.3f} +- {r['se']:.3f}"
            f"  (truth above {r['truth_above']:.2f}, below {r['truth_below']:.2f})"
        )
    for m in methods:
        kinds = [str(r["approximation"][m]) for r in records]
        counts = ", ".join(f"{k} {kinds.count(k)}" for k in dict.fromkeys(kinds))
        seconds = np.median([r["seconds"][m] for r in records])
        print(f"{m:<10} median {seconds:.1f} s a fit; intervals from: {counts} (None: posterior draws)")


if __name__ == "__main__":
    main()
