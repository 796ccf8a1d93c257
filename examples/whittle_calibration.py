"""Calibration of fits by Whittle's likelihood (long uniform records, `vibinverse.engines.whittle`):
N records of one resonance, a random-walk drift and white noise (40,000 samples at 100 Hz), each
fitted with the order given (`vi.fit(series, {"modal": {"modes": 1, "drift": True}})`), and the
share of 90 % intervals that hold the truth, with its standard error.

    python examples/whittle_calibration.py [N] [method]     # N = 100, method = map (Laplace)
"""

# ruff: noqa: T201  (an example prints its results)
from __future__ import annotations

import math
import sys
import time

import numpy as np

import vibinverse as vi
from vibinverse.bench.robustness_cases import Mode, oscillator

TRUTH = {
    "modes[0].frequency": 3.0,
    "modes[0].damping_ratio": 0.02,
    "modes[0].rms": 1.0,
    "drift.rate": 0.3,
    "noise.sigma": 0.5,
}
FS, SAMPLES = 100.0, 40_000


def record(seed: int) -> vi.Series:
    rng = np.random.default_rng(seed)
    t = np.arange(SAMPLES) / FS
    mode = Mode(TRUTH["modes[0].frequency"], TRUTH["modes[0].damping_ratio"], TRUTH["modes[0].rms"])
    walk = np.cumsum(rng.normal(0.0, TRUTH["drift.rate"] / math.sqrt(FS), SAMPLES))
    y = 1.0 + oscillator(t, mode, rng) + walk + rng.normal(0.0, TRUTH["noise.sigma"], SAMPLES)
    return vi.series(t, y, source=f"whittle calibration {seed}")


def main(n: int = 100, method: str = "map") -> None:
    hits = dict.fromkeys(TRUTH, 0)
    start = time.perf_counter()
    for seed in range(n):
        result = vi.fit(record(seed), {"modal": {"modes": 1, "drift": True}}, method=method, seed=seed)
        pars = result.summary()["parameters"]
        for k, v in TRUTH.items():
            hits[k] += pars[k]["q05"] <= v <= pars[k]["q95"]
    seconds = (time.perf_counter() - start) / n
    print(f"{n} records of {SAMPLES} samples, method {method}, {seconds:.1f} s a fit")
    for k, h in hits.items():
        p = h / n
        print(f"  {k:<28} 90 % coverage {p:.3f} +- {math.sqrt(0.09 / n):.3f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100, sys.argv[2] if len(sys.argv) > 2 else "map")
