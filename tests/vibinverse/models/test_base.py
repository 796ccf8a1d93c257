"""A new signal model is one registered class: a toy damped sinusoid (a free decay), defined only
here, fits through the same pipeline as the built-in models with no change to library code."""

import math

import numpy as np
import pytest

import vibinverse as vi
from vibinverse.models import MODELS, LineTest, model_class_for
from vibinverse.spectrum import line_candidates

P = "toy."


@vi.register_model
class DampedSinusoid(vi.SignalModel):
    """y(t) = A exp(-gamma t) cos(2 pi f t + phase) + white noise of sd sigma."""

    name = "toy_damped_sinusoid"

    @classmethod
    def describes(cls, table):
        return "toy" in table

    def __init__(self, table, series):
        self.base, self.series = table, series
        self.t = series.time - series.time[0]
        self.good = np.isfinite(series.intensity)

    def _value(self, values, name):
        return values.get(name, self.base["toy"][name.split(".", 1)[1]] if name.startswith(P) else 0.0)

    def fittable(self):
        return {P + n for n in ("frequency", "decay", "amplitude", "phase")} | {"noise.sigma"}

    def default_priors(self):
        fs, span = self.series.fs, self.t[-1]
        return {
            P + "frequency": vi.Prior("uniform", (3 / span, fs / 2)),
            P + "decay": vi.Prior("loguniform", (1e-3, 10.0)),
            P + "amplitude": vi.Prior("uniform", (0.0, 10.0)),
            P + "phase": vi.Prior("uniform", (-math.pi, math.pi)),
            "noise.sigma": vi.Prior("loguniform", (1e-3, 10.0)),
        }

    def mean(self, values):
        f, g, a, ph = (self._value(values, P + n) for n in ("frequency", "decay", "amplitude", "phase"))
        return a * np.exp(-g * self.t) * np.cos(2 * np.pi * f * self.t + ph)

    def log_likelihood(self, values):
        sigma = values.get("noise.sigma", self.base["noise"]["sigma"])
        r = (self.series.intensity - self.mean(values))[self.good]
        return float(-0.5 * (r @ r / sigma**2 + r.size * math.log(2 * math.pi * sigma**2)))

    def guesses(self, bounds):
        y = self.series.intensity
        out = []
        for f in line_candidates(self.series, bounds[P + "frequency"], n_candidates=2):
            out.append(
                {
                    P + "frequency": f,
                    P + "decay": 0.1,
                    P + "amplitude": float(np.nanmax(np.abs(y))),
                    P + "phase": 0.0,
                    "noise.sigma": float(np.nanstd(np.diff(y)) / math.sqrt(2)),
                }
            )
        return out

    def line_tests(self, values, free):
        return [LineTest("decay", {P + "amplitude": 0.0}, P + "frequency" if P + "frequency" in free else None)]

    def fisher(self, values, names):
        d = []
        for n in names:
            h = 1e-6 * max(abs(values[n]), 1e-3)
            d.append((self.mean({**values, n: values[n] + h}) - self.mean({**values, n: values[n] - h})) / (2 * h))
        d = np.array(d)[:, self.good]
        return d @ d.T / values["noise.sigma"] ** 2


TABLE = {"toy": {"frequency": 7.3, "decay": 0.4, "amplitude": 2.0, "phase": 0.6}, "noise": {"sigma": 0.5}}


def _series(seed, amplitude=2.0):
    t = np.arange(2000) / 100.0
    table = {**TABLE, "toy": {**TABLE["toy"], "amplitude": amplitude}}
    clean = amplitude * np.exp(-0.4 * t) * np.cos(2 * np.pi * 7.3 * t + 0.6)
    y = clean + np.random.default_rng(seed).normal(0.0, 0.5, t.size)
    return table, vi.series(t, y, scene=table)


def test_the_registry_finds_the_toy_model_and_the_built_in_ones():
    assert MODELS["toy_damped_sinusoid"] is DampedSinusoid
    assert model_class_for(TABLE) is DampedSinusoid
    assert model_class_for({"surfaces": {"r": {"motion": {"kind": "frame"}}}}).name == "frame"
    assert model_class_for({"surfaces": {"r": {"motion": {"kind": "plate"}}}}).name == "deterministic"
    with pytest.raises(vi.SceneError, match="not one of"):
        model_class_for(TABLE, "nope")


def test_a_toy_model_fits_through_the_whole_pipeline(tmp_path):
    table, series = _series(seed=2)
    result = vi.fit(series, table, method="auto", chain=tmp_path / "c.h5", max_steps=4000)
    s = result.summary()
    assert s["method"] == "auto" and {"spectral_s", "map_s", "mcmc_s"} <= set(s["timing"])  # casadi declined: no form
    for name, p in s["parameters"].items():
        assert p["q05"] <= p["truth"] <= p["q95"], (name, p)
    assert s["parameters"][P + "frequency"]["sd"] < 0.01
    assert result.detections[0].detected
    idata = result.to_inference_data()
    assert idata.posterior["toy__frequency"].shape[0] == result.chains.shape[0]


def test_the_toy_models_detection_says_no_when_there_is_no_signal():
    table, series = _series(seed=5, amplitude=0.0)
    result = vi.fit(series, table, method="map")
    assert not result.detections[0].detected
