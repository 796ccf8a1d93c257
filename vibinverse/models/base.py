"""The one interface every signal model implements, and the registry that finds a model for a scene.

A signal model is what the estimators need to know about the data's origin, and nothing of how
they estimate: named parameters with default priors for a series, the mean and the exact
log-likelihood, initial guesses from the spectrum, the lines to test for detection, and the Fisher
information. The frame model (a noise-driven resonance with drive lines; Kalman likelihood) and the
deterministic model (plate and ground vibrations; white-noise likelihood) are two implementations;
a new one is a subclass decorated with `register_model`, found by `model_class_for`, and fitted by
the same pipeline (`vibinverse.pipeline`) with no other change.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from vibinverse.errors import SceneError, Unsupported
from vibinverse.io.series import Series

if TYPE_CHECKING:
    from vibinverse.priors import Prior


@dataclass(frozen=True)
class LineTest:
    """One line the fit claims: `label` names it in the summary (`{label}_detected`, ...), `null`
    are the values that remove it from the model (an amplitude set to 0), and `frequency` is the
    name of its frequency when that is free (the look-elsewhere effect), else None; `deterministic`
    marks a line of fixed amplitude (`vibinverse.stationarity` checks it); `near` the parameters
    that can take back its power when it is removed (the components whose band reaches it and the
    broadband terms: `vibinverse.detection.null_optimum` refits these first), None for all;
    `damping` a resonance's damping ratio at the tested point (a hump too broad is not claimed as
    one: `vibinverse.detection.BROAD_DAMPING`), None for a line; `hz` the component's frequency
    there, when the model knows it (a tone at an integer combination of stronger ones is their
    product, not claimed: `vibinverse.detection.products`); `ring` marks a free decay."""

    label: str
    null: dict[str, float]
    frequency: str | None
    deterministic: bool = False  # a line of fixed amplitude (not a noise-driven resonance): its stationarity is checked
    near: tuple[str, ...] | None = None
    damping: float | None = None
    hz: float | None = None
    #: a free decay: its damping is a measured decay rate (a product of rings decays at the sum of
    #: theirs: `vibinverse.detection.products`), not a stationary resonance's bandwidth
    ring: bool = False


class SignalModel(ABC):
    """A model of a measured series: mean, likelihood, priors, starts, line tests, Fisher information.

    Parameters are addressed by dotted scene names (`surfaces.roof.motion.tilt_frequency`,
    `noise.sigma`); `values` passed to a method hold the free ones, the others come from the scene.
    """

    name: ClassVar[str]  # the registry key
    #: IPOPT runs from every start whose log posterior is within this margin of the best start's
    map_start_margin: ClassVar[float] = math.inf
    #: memory the casadi MAP's compiled objective takes per sample (measured peak, rounded up)
    casadi_bytes_per_sample: ClassVar[float] = 50e3
    #: values a scene file may leave out, with the value the forward model then uses
    scene_defaults: ClassVar[dict[str, float]] = {}
    #: the likelihood spends most of its time in compiled kernels that release the GIL (numba
    #: nogil), so the sampler's walkers are evaluated by threads (no fork, no pickling)
    releases_gil: ClassVar[bool] = False
    #: the default fit (`auto`) takes the posterior by importance sampling of the Laplace
    #: approximation (`estimators.importance`), emcee only when its check fails, at any record
    #: length (otherwise only past `pipeline.IMPORTANCE_RECORD` samples)
    importance_first: ClassVar[bool] = False
    #: nuisance terms (`vibinverse.terms`: coloured noise, drift, gain drift) sit beside the model's
    #: own state when its table's `nuisance` asks, and the fit searches them when it leaves one open
    #: (`vibinverse.selection.nuisance_search`)
    accepts_nuisance: ClassVar[bool] = False

    series: Series
    base: dict[str, Any]

    @classmethod
    @abstractmethod
    def describes(cls, table: dict[str, Any]) -> bool:
        """Whether this model describes the scene table (the registry's choice)."""

    @classmethod
    def truth_table(cls, table: dict[str, Any]) -> dict[str, Any]:
        """The scene table under the names this model's parameters use (the truth of simulated data)."""
        return table

    @classmethod
    def default_targets(cls, table: dict[str, Any]) -> list[str]:
        """The parameters an observer wants bounded (design of observation)."""
        return []

    @abstractmethod
    def fittable(self) -> set[str]:
        """Every name this model's likelihood reads."""

    @abstractmethod
    def default_priors(self) -> dict[str, Prior]:
        """The free parameters and priors an analyst fits when the scene names none."""

    @abstractmethod
    def mean(self, values: dict[str, float]) -> np.ndarray:
        """The deterministic part of the signal at `values`."""

    @abstractmethod
    def log_likelihood(self, values: dict[str, float]) -> float:
        """log p(data | values) (the exact likelihood; -inf outside what the model allows)."""

    def slope(self, values: dict[str, float], names: list[str]) -> dict[str, float] | None:
        """d log_likelihood / d value of each of `names` at `values` when the model has a cheaper way
        than a call per parameter; None: the optimizers take finite differences."""
        return None

    @abstractmethod
    def guesses(self, bounds: dict[str, tuple[float, float]]) -> list[dict[str, float]]:
        """Starting values of the free parameters (keys of `bounds`) from the spectrum, most
        plausible first; the posterior decides between them."""

    @abstractmethod
    def line_tests(self, values: dict[str, float], free: list[str]) -> list[LineTest]:
        """The lines the fit at `values` claims, each with the values that remove it."""

    @abstractmethod
    def fisher(self, values: dict[str, float], names: list[str]) -> np.ndarray:
        """Fisher information of `names` at `values`."""

    def with_nuisance(self, nuisance: dict[str, Any]) -> SignalModel:
        """The same model with the `nuisance` table given (`vibinverse.terms.nuisance`), its scene's
        work not done again where the model can help it (the nuisance search fits many)."""
        return type(self)({**self.base, "nuisance": nuisance}, self.series)

    def nuisance_priors(self) -> dict[str, Prior]:
        """Default priors of the nuisance terms' parameters (free beside any the analyst names)."""
        return {}

    def check_free(self, names: list[str]) -> None:
        """One-line SceneError when these free parameters cannot be fitted on this model."""
        fittable = self.fittable()
        for name in names:
            if name not in fittable:
                raise SceneError(
                    f"fit: {name} cannot be fitted (yet); free parameters of this scene: {', '.join(sorted(fittable))}"
                )

    def alternatives(self, values: dict[str, float], free: list[str]) -> list[tuple[str, dict[str, float]]]:
        """Other readings of the same spectrum the fit at `values` may have missed, each (what it
        changes, starting values): the pipeline runs the MAP from each, keeps the best, and reports
        a reading it cannot rule out (`vibinverse.pipeline.map_stage`)."""
        return []

    def head(self, n: int) -> SignalModel:
        """The same model on the first n samples of its series: its log-likelihood there is the sum
        of this model's first n pointwise log densities (a long record's MAP starts on a leading
        stretch: `vibinverse.pipeline`). Unsupported when the model cannot be cut so."""
        raise Unsupported(f"the {self.name} model is not fitted on a stretch of its record")

    def phase_period(self, name: str) -> float:
        """The period of a phase parameter as the data see it."""
        return 2 * math.pi

    def casadi_objective(self, posterior: Any) -> Any:
        """-log posterior (of a `vibinverse.posterior.Posterior` of this model) as a casadi Function
        of (z, y, mask) with `.function` and `.data(series)`;
        Unsupported names the value that leaves the casadi form."""
        raise Unsupported(f"no casadi form of the {self.name} model")

    def refine(self, values: dict[str, float]) -> tuple[dict[str, Any], str | None]:
        """Re-check the model's approximations at a fit: (facts for the summary's data.model, a
        message when the model changed how it evaluates the mean, so that the MAP must run again)."""
        return {}, None

    def describe(self) -> dict[str, Any] | None:
        """What the summary's data.model records (None: nothing)."""
        return None

    # ------------------------------------------------- checks of the model against the data
    def pointwise_log_likelihood(self, values: dict[str, float]) -> np.ndarray:
        """Each sample's log density given the samples before it (the one-step predictive
        density of a state-space model; the density of an independent sample otherwise), NaN at
        gaps: `np.nansum` of it is `log_likelihood(values)`. ArviZ's `log_likelihood` group holds
        it, so that `az.loo` and `az.compare` work. Unsupported when the model cannot split its
        likelihood by sample."""
        raise Unsupported(f"the {self.name} model does not split its likelihood by sample")

    def residuals(self, values: dict[str, float]) -> np.ndarray:
        """Standardized one-step residuals (innovations) at `values`: independent N(0, 1) when the
        model describes the data; NaN at gaps."""
        raise Unsupported(f"the {self.name} model has no standardized residuals")

    def replicate(self, values: dict[str, float], rng: np.random.Generator) -> np.ndarray:
        """A series the model at `values` could have produced at the data's time stamps (mean plus a
        draw of every random term), NaN where the data have gaps: one posterior-predictive draw."""
        raise Unsupported(f"the {self.name} model does not simulate replicate series")

    def units(self, name: str) -> tuple[str, str]:
        """(units, long name) of parameter `name`, CF-style ("1" for a ratio); the intensity's
        units are the data's (`Series.intensity_units`)."""
        return parameter_units(name, intensity_units(self.series))


#: units of parameters by the last part of their name, first match wins
_UNITS: tuple[tuple[str, str, str], ...] = (
    ("damping_ratio", "1", "damping ratio"),
    ("frequency", "Hz", "frequency"),
    ("phase", "rad", "phase"),
    ("inclination", "rad", "inclination"),
    ("azimuth", "rad", "azimuth"),
    ("lobe_width", "rad", "specular lobe width"),
    ("irradiance", "1", "relative irradiance (calibration gain)"),
    ("amplitude", "m", "amplitude"),
    ("deflection", "m", "deflection"),
    ("displacement", "m", "displacement"),
    ("noise_rms", "m", "RMS of the white base motion"),
)


def intensity_units(series: Series) -> str:
    """The data's intensity units as the reader recorded them, or "1" (arbitrary units)."""
    return series.intensity_units or "1"


def parameter_units(name: str, intensity: str = "1") -> tuple[str, str]:
    """(units, long name) of a dotted parameter name by its last part (`_UNITS`); `noise.sigma` in
    the intensity's units; "1" when nothing matches."""
    last = name.split(".")[-1].split("[")[0]
    if name == "noise.sigma":
        return intensity, "sensor noise standard deviation"
    for suffix, units, long_name in _UNITS:
        if last.endswith(suffix):
            what = last[: -len(suffix)].strip("_").replace("_", " ")
            return units, f"{what} {long_name}".strip()
    return "1", last.replace("_", " ")


MODELS: dict[str, type[SignalModel]] = {}


def observed_information(
    loglike: Callable[[dict[str, float]], float],
    v0: dict[str, float],
    names: list[str],
    scale: Callable[[str], float],
    positive: Callable[[str], bool],
) -> np.ndarray:
    """The observed information -d^2 log L / d theta^2 at `v0` by central finite differences of
    `loglike` (a function of the changed values): a first pass gives each parameter's curvature with
    a step of 1e-4 of its `scale`, the second uses a step of 0.1 / sqrt(curvature) (a tenth of the
    parameter's sd), at most half its value for a `positive` parameter, so that every step is small
    against the likelihood's width whatever the units. Its expectation is the Fisher information."""
    f0 = loglike({})
    steps = []
    for n in names:
        h = 1e-4 * scale(n)
        curv = -(loglike({n: v0[n] + h}) - 2 * f0 + loglike({n: v0[n] - h})) / h**2
        h2 = 0.1 / math.sqrt(curv) if curv > 0 and math.isfinite(curv) else h
        if positive(n) and v0[n] > 0:
            h2 = min(h2, 0.5 * v0[n])
        steps.append(h2)
    k = len(names)
    out = np.zeros((k, k))
    for a in range(k):
        na, ha = names[a], steps[a]
        out[a, a] = -(loglike({na: v0[na] + ha}) - 2 * f0 + loglike({na: v0[na] - ha})) / ha**2
        for b in range(a):
            nb, hb = names[b], steps[b]
            pp = loglike({na: v0[na] + ha, nb: v0[nb] + hb})
            pm = loglike({na: v0[na] + ha, nb: v0[nb] - hb})
            mp = loglike({na: v0[na] - ha, nb: v0[nb] + hb})
            mm = loglike({na: v0[na] - ha, nb: v0[nb] - hb})
            out[a, b] = out[b, a] = -(pp - pm - mp + mm) / (4 * ha * hb)
    return out


def register_model(cls: type[SignalModel]) -> type[SignalModel]:
    """Class decorator: make a model available to `model_class_for` (later registrations are asked first)."""
    MODELS[cls.name] = cls
    return cls


def model_class_for(table: dict[str, Any], name: str | None = None) -> type[SignalModel]:
    """The registered model that describes `table` (or the one registered as `name`)."""
    if name is not None:
        if name not in MODELS:
            raise SceneError(f"model: {name!r} is not one of {', '.join(MODELS)}")
        return MODELS[name]
    for cls in reversed(list(MODELS.values())):
        if cls.describes(table):
            return cls
    raise SceneError("fit: the scene has no vibrating surface (a plate, rayleigh or frame motion)")


def build_model(table: dict[str, Any], series: Series, name: str | None = None) -> SignalModel:
    """The model of `table` for `series` (`model_class_for`)."""
    return model_class_for(table, name)(table, series)
