"""A new signal model through the same pipeline: a toy damped sinusoid in white noise.

    python examples/custom_model.py          # ~15 s, most of it emcee

    y(t) = A exp(-t / tau) cos(2 pi f t + phase) + N(0, sigma^2)

The model subclasses `vi.SignalModel`, implements its abstract methods and is registered with
`@vi.register_model`; `vi.fit` then runs it through spectral starts -> MAP (casadi does not cover
it, so the derivative-free MAP runs, and says so in the log) -> emcee, with the same detection test,
summary, netCDF and report as the built-in models. Its "scene" is a plain table.
"""

# ruff: noqa: T201  (an example prints its results)

import logging
import math
import tempfile
from pathlib import Path

import numpy as np

import vibinverse as vi
from vibinverse.models import LineTest


@vi.register_model
class DampedSine(vi.SignalModel):
    name = "damped_sine"

    def __init__(self, table, series):
        self.base = dict(table["toy"])
        self.series = series
        self.t = series.time - series.time[0]
        self.y = series.intensity
        self.ok = np.isfinite(self.y)  # NaN samples are gaps

    @classmethod
    def describes(cls, table):
        return "toy" in table

    def fittable(self):
        return {f"toy.{k}" for k in ("frequency", "amplitude", "decay_time", "phase", "sigma")}

    def default_priors(self):
        nyquist = 0.5 / np.median(np.diff(self.t))
        span = self.t[-1]
        return {
            "toy.frequency": vi.Prior("uniform", (3.0 / span, nyquist)),
            "toy.amplitude": vi.Prior("uniform", (0.0, 10.0 * np.nanstd(self.y) * math.sqrt(2))),
            "toy.decay_time": vi.Prior("loguniform", (0.1 * span, 100.0 * span)),
            "toy.phase": vi.Prior("uniform", (-math.pi, math.pi)),
            "toy.sigma": vi.Prior("loguniform", (1e-3 * np.nanstd(self.y), 10.0 * np.nanstd(self.y))),
        }

    def _get(self, values, key):
        return values.get(f"toy.{key}", self.base[key])

    def mean(self, values):
        f, a, tau, ph = (self._get(values, k) for k in ("frequency", "amplitude", "decay_time", "phase"))
        return a * np.exp(-self.t / tau) * np.cos(2 * math.pi * f * self.t + ph)

    def log_likelihood(self, values):
        sigma = self._get(values, "sigma")
        if not sigma > 0:
            return -math.inf
        r = (self.y - self.mean(values))[self.ok]
        return float(-0.5 * np.sum(r**2) / sigma**2 - r.size * math.log(sigma * math.sqrt(2 * math.pi)))

    def guesses(self, bounds):
        """The three highest periodogram peaks inside the frequency prior, amplitude and phase of a
        sinusoid fit there; the posterior picks."""
        y = np.where(self.ok, self.y, 0.0)
        spec = np.fft.rfft(y)
        freqs = np.fft.rfftfreq(y.size, np.median(np.diff(self.t)))
        lo, hi = bounds.get("toy.frequency", (0.0, np.inf))
        inside = np.flatnonzero((freqs > lo) & (freqs < hi))
        out = []
        for k in inside[np.argsort(-np.abs(spec[inside]))][:3]:
            out.append(
                {
                    "toy.frequency": float(freqs[k]),
                    "toy.amplitude": float(2 * np.abs(spec[k]) / y.size),
                    "toy.phase": float(np.angle(spec[k])),
                    "toy.decay_time": float(self.t[-1]),
                    "toy.sigma": float(np.nanstd(self.y)),
                }
            )
        return out

    def line_tests(self, values, free):
        return [LineTest("damped_sine", {"toy.amplitude": 0.0}, "toy.frequency" if "toy.frequency" in free else None)]

    def fisher(self, values, names):
        """White noise about the mean: J^T J / sigma^2 (central differences)."""
        sigma = self._get(values, "sigma")
        cols = []
        for n in names:
            h = 1e-6 * max(1.0, abs(values[n]))
            cols.append((self.mean({**values, n: values[n] + h}) - self.mean({**values, n: values[n] - h})) / (2 * h))
        jac = np.array(cols).T[self.ok]
        return jac.T @ jac / sigma**2


if __name__ == "__main__":
    logging.basicConfig(format="%(name)s: %(message)s")
    logging.getLogger("vibinverse").setLevel(logging.INFO)  # the pipeline's stages
    truth = {"frequency": 7.3, "amplitude": 0.8, "decay_time": 2.0, "phase": 0.4, "sigma": 0.3}
    table = {"title": "toy damped sinusoid", "toy": truth}
    t = np.arange(0.0, 4.0, 0.01)  # 4 s at 100 Hz
    rng = np.random.default_rng(1)
    f, a, tau, phase, sigma = (truth[k] for k in ("frequency", "amplitude", "decay_time", "phase", "sigma"))
    y = a * np.exp(-t / tau) * np.cos(2 * np.pi * f * t + phase) + rng.normal(0.0, sigma, t.size)
    y[100:120] = np.nan  # a gap
    series = vi.series(t, y, scene=table, source="toy")  # the scene: the summary reports the true values

    with tempfile.TemporaryDirectory(prefix="vibinverse-") as tmp:  # the emcee checkpoint, removed after
        chain = Path(tmp) / "chain.h5"  # default ./vibinverse-chain.h5
        result = vi.fit(series, table, model="damped_sine", method="auto", chain=chain, max_steps=3000)
    summary = result.summary()
    print(f"method {summary['method']}; " + ", ".join(f"{k} {v:.2f} s" for k, v in summary["timing"].items()))
    for name, p in summary["parameters"].items():
        print(f"  {name:<16} {p['median']:9.4g}  90% [{p['q05']:.4g}, {p['q95']:.4g}]  truth {p['truth']:.4g}")
    for d in result.detections:
        print(f"  {d.what}: gain {d.delta_loglike:.1f} vs threshold {d.threshold:.1f} -> detected {d.detected}")
