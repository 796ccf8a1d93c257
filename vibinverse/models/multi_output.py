"""Several outputs, one source each: the r-dimensional statistic of pixels that see r sources in
different mixtures (`vibinverse.imaging.joint_fit.estimate_sources`), fitted by one Kalman filter
with vector observations (`MultiOutputModel`, registered as "multi_output").

    Z_j(t) = level_j + s_j(t) + n_j(t),    j = 0 .. r - 1,    n(t) ~ N(0, scale^2 C) white,

with C the known noise covariance of the statistic, (G^T S^-1 G)^-1 (the joint fit's), and s_j
the source of output j: a stochastic resonance of the modal model (`modes[i].frequency`,
`.damping_ratio`, `.rms`: q'' + 2 zeta w q' + w^2 q = xi, two states) or a deterministic line
(`lines[i].frequency`, `.amplitude`, `.phase`: the mean), the modes and lines numbered in the
order of their outputs. `outputs[j].level` is output j's level; `noise.scale` (1: C as estimated,
not free by default) scales the noise. The sources are independent: the transition is block
diagonal, one 2 x 2 block per mode, each block's exact discretization (Phi, Q) and stationary P0
taken from the modal model (`ModalModel.tables` of a one-mode model of that output), and a line's
mean from a one-line modal model (`ModalModel.tables`), so that both models share one
discretization.

The likelihood, exactly: with C = L L^T (Cholesky), the whitened observation L^-1 (Z_t - m_t) =
L^-1 H x_t + N(0, scale^2 I) has independent components, so the update by the vector
observation is r sequential scalar updates (rows of L^-1 H, unit noise variance x scale^2), and

    log p(Z) = sum_t [log N(L^-1 (Z_t - m_t); L^-1 H x_t|t-1, L^-1 H P L^-T H^T + scale^2 I)]
               - T_obs log det L,

the second term the Jacobian of the whitening (the engine's `vibinverse.engines.kalman.vector_filter`, numba nogil,
O(T (n^2 + r n^2)) for n = 2 x modes states). A sample with NaN outputs observes the others only
(the Cholesky factor of their block of C); an all-NaN sample is a gap; irregular stamps use the
modal model's table of distinct steps (`ModalModel.steps`, `.idx`).

The data: a `MultiSeries`, a `Series` whose `intensity` is output 0 (what a result file shows as
the observed series) carrying all outputs (`outputs`, time x r) and C (`covariance`). The table:
`{"multi_output": {"sources": ["mode", "line", ...], "start": {name: value}, "values": {name:
value}}}` (one kind per output; `start`: the first starting point; `values`: fixed values of
parameters that are not free); the model writes `data`, the outputs' fingerprint, into its copy of
the table (the sampler's checkpoint compares the table before resuming).

Per output, the default priors and the spectral starts are the modal model's for that output alone
(a one-mode or one-line modal model of Z_j); there is no sorted-frequency constraint: each source
is tied to its own output, so the labels do not switch. The Fisher information is the observed
information by central differences of the exact likelihood (as the modal model's).
"""

from __future__ import annotations

import copy
import hashlib
import math
import threading
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from vibinverse.engines.kalman import vector_filter
from vibinverse.errors import SceneError
from vibinverse.io.series import Series, validate
from vibinverse.kalman import simulate
from vibinverse.models.base import LineTest, SignalModel, observed_information, register_model
from vibinverse.models.modal import ModalModel
from vibinverse.priors import Prior

_LOG_2PI = math.log(2.0 * math.pi)


# ------------------------------------------------------------------ the data


@dataclass(frozen=True)
class MultiSeries(Series):
    """A series of r outputs on one time axis: `intensity` is output 0, `outputs` (time, r) all of
    them (NaN = missing), `covariance` (r, r) their white noise's covariance (known)."""

    outputs: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    covariance: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))

    @property
    def n_outputs(self) -> int:
        return int(self.outputs.shape[1])

    def output(self, j: int) -> Series:
        """Output j as a plain `Series` (same stamps and notes)."""
        return validate(self.time, self.outputs[:, j], f"{self.source} (output {j})", None, list(self.notes))


def multi_series(
    time: np.ndarray,
    outputs: np.ndarray,
    covariance: np.ndarray,
    source: str = "outputs",
    notes: list[str] | None = None,
) -> MultiSeries:
    """Check and build a `MultiSeries`: every output a valid series (`validate`), the covariance
    symmetric positive definite of the outputs' number; one-line SceneError otherwise."""
    z = np.asarray(outputs, dtype=np.float64)
    cov = np.asarray(covariance, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] < 1:
        raise SceneError(f"outputs: shape {z.shape}; (time, r) with r >= 1 is needed")
    r = z.shape[1]
    if cov.shape != (r, r) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T, rtol=1e-10, atol=0.0):
        raise SceneError(f"covariance: must be a finite symmetric {r} x {r} matrix, got shape {cov.shape}")
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise SceneError("covariance: the outputs' noise covariance is not positive definite") from None
    first = validate(time, z[:, 0], source, None, notes)
    for j in range(1, r):
        validate(time, z[:, j], source, None, notes)
    return MultiSeries(
        first.time,
        first.intensity,
        first.source,
        None,
        list(first.notes),
        outputs=z.copy(),
        covariance=0.5 * (cov + cov.T),
    )


# ------------------------------------------------------------------ the sources


class Source:
    """A kind of source of one output: its name in the table (`multi_output.sources`), the modal
    model's component it is (`base`: its parameters `{base}[i].{field}`), the states it adds to the
    filter (observed by its first) and the parameter whose zero removes it (its line test)."""

    kind: ClassVar[str]
    base: ClassVar[str]
    fields: ClassVar[tuple[str, ...]]
    states: ClassVar[int]
    null: ClassVar[str]
    #: a line of fixed amplitude (`LineTest.deterministic`)
    deterministic: ClassVar[bool] = False

    @classmethod
    def names(cls, i: int) -> list[str]:
        """The parameters of the i-th source of this kind."""
        return [f"{cls.base}[{i}].{f}" for f in cls.fields]

    @classmethod
    def order(cls) -> dict[str, int]:
        """The one-component modal model's `modes` and `lines` of this kind."""
        return {**dict.fromkeys(SOURCE_BASES, 0), cls.base: 1}

    @classmethod
    def damping_name(cls, i: int) -> str | None:
        """The i-th source's damping ratio, None for a kind without one (a line)."""
        return f"{cls.base}[{i}].damping_ratio" if "damping_ratio" in cls.fields else None

    @classmethod
    def line_test(cls, i: int, free: list[str], damping: float | None = None, hz: float | None = None) -> LineTest:
        """The test of the i-th source of this kind: its `null` parameter to 0 (`damping`: a
        resonance's damping ratio at the tested point, `hz` its frequency there)."""
        f = f"{cls.base}[{i}].frequency"
        return LineTest(
            f"{cls.kind}_{i}",
            {f"{cls.base}[{i}].{cls.null}": 0.0},
            f if f in free else None,
            cls.deterministic,
            damping=damping,
            hz=hz,
        )


class ModeSource(Source):
    """A stochastic resonance (two states: q, q')."""

    kind = "mode"
    base = "modes"
    fields = ("frequency", "damping_ratio", "rms")
    states = 2
    null = "rms"


class LineSource(Source):
    """A deterministic line (the mean; no state)."""

    kind = "line"
    base = "lines"
    fields = ("frequency", "amplitude", "phase")
    states = 0
    null = "amplitude"
    deterministic = True


#: the kinds of source by their table name
SOURCES: dict[str, type[Source]] = {c.kind: c for c in (ModeSource, LineSource)}
SOURCE_KINDS = tuple(SOURCES)
SOURCE_BASES = tuple(c.base for c in SOURCES.values())


# ------------------------------------------------------------------ the model


@register_model
class MultiOutputModel(SignalModel):
    """r outputs, each one source (a mode or a line) in white noise of known covariance, one Kalman
    filter with vector observations (module docstring)."""

    name = "multi_output"
    releases_gil = True  # numba nogil kernel; per-thread scratch arrays

    @classmethod
    def describes(cls, table: dict) -> bool:
        """The table has a `multi_output` table."""
        return isinstance(table, dict) and "multi_output" in table

    def __init__(self, table: dict, series: Series):
        self.base = copy.deepcopy(dict(table))
        spec = self.base.get("multi_output")
        if not isinstance(spec, dict):
            raise SceneError("multi_output: must be a table, e.g. {sources = ['mode', 'mode']}")
        unknown = set(spec) - {"sources", "start", "values", "data"}
        if unknown:
            raise SceneError(f"multi_output.{sorted(unknown)[0]}: unknown key; allowed: sources, start, values")
        if not isinstance(series, MultiSeries):
            raise SceneError(
                "multi_output: the model fits the outputs of a multi-source joint fit "
                "(vibinverse.imaging.joint_fit, sources >= 2), not a single series"
            )
        kinds = spec.get("sources")
        if not isinstance(kinds, (list, tuple)) or len(kinds) != series.n_outputs:
            raise SceneError(f"multi_output.sources: one kind per output ({series.n_outputs}), e.g. ['mode', 'line']")
        for k in kinds:
            if k not in SOURCE_KINDS:
                raise SceneError(f"multi_output.sources: {k!r}; allowed: {', '.join(map(repr, SOURCE_KINDS))}")
        # the data's fingerprint in the table (the sampler's checkpoint compares it before resuming)
        digest = hashlib.sha256(series.outputs.tobytes() + series.covariance.tobytes()).hexdigest()[:16]
        spec["data"] = digest
        self.kinds = [str(k) for k in kinds]
        self.sources = [SOURCES[k] for k in self.kinds]
        self.series = series
        self.r = series.n_outputs
        self.t = np.ascontiguousarray(series.time, dtype=float)
        self.z = np.ascontiguousarray(series.outputs, dtype=float)
        self.cov = np.ascontiguousarray(series.covariance, dtype=float)
        self.good = np.isfinite(self.z)
        self.sd = float(np.nanstd(self.z)) or 1.0
        # per output: its index among its kind, its states in the filter (None: none), and a
        # one-component modal model of that output alone
        self.index: list[int] = []
        self.blocks: list[slice | None] = []
        self.inner: list[ModalModel] = []
        counts = dict.fromkeys(SOURCES.values(), 0)
        states = 0
        for j, src in enumerate(self.sources):
            self.index.append(counts[src])
            counts[src] += 1
            self.blocks.append(slice(states, states + src.states) if src.states else None)
            states += src.states
            order = {**src.order(), "drift": False, "noise": "white"}
            self.inner.append(ModalModel({"modal": order}, series.output(j)))
        self.n_modes, self.n_lines = counts[ModeSource], counts[LineSource]
        self.steps, self.idx = self.inner[0].steps, np.ascontiguousarray(self.inner[0].idx, dtype=np.int64)
        self.states = states
        self.n = max(states, 1)  # one dummy state nobody sees when no source has a state
        self.h = np.zeros((self.r, self.n))
        self.lo = np.zeros(self.n, dtype=np.int64)
        self.hi = np.ones(self.n, dtype=np.int64)
        for j, blk in enumerate(self.blocks):
            if blk is not None:
                self.h[j, blk.start] = 1.0
                self.lo[blk], self.hi[blk] = blk.start, blk.stop
        if states == 0:
            self.lo[0], self.hi[0] = 0, 1
        self._names = self._all_names()
        self._fixed = {k: float(v) for k, v in (spec.get("values") or {}).items()}
        self._start = {k: float(v) for k, v in (spec.get("start") or {}).items()}
        self._defaults: dict[str, float] | None = None
        self._buffers: dict[int, tuple[np.ndarray, ...]] = {}

    # -------------------------------------------------------------- names
    def _all_names(self) -> list[str]:
        out = [f"outputs[{j}].level" for j in range(self.r)]
        for src, i in zip(self.sources, self.index):
            out += src.names(i)
        return [*out, "noise.scale"]

    def _output_names(self, j: int) -> dict[str, str]:
        """This model's names of output j's parameters -> its one-component modal model's names."""
        src = self.sources[j]
        out = {f"outputs[{j}].level": "level"}
        out.update(zip(src.names(self.index[j]), src.names(0)))
        return out

    def output_of(self, name: str) -> int | None:
        """The output a parameter belongs to (None: `noise.scale`)."""
        for j in range(self.r):
            if name in self._output_names(j):
                return j
        return None

    def value(self, values: dict[str, float], name: str) -> float:
        """A parameter's value: from `values`, else fixed by the table, else its start, else the
        spectral guess."""
        if name in values:
            return values[name]
        if name in self._fixed:
            return self._fixed[name]
        if name == "noise.scale":
            return 1.0
        if self._defaults is None:
            self._defaults = {**self._spectral_guess(), **self._start, **self._fixed}
        return self._defaults[name]

    def _inner_values(self, values: dict[str, float], j: int) -> dict[str, float]:
        inner = {m: self.value(values, n) for n, m in self._output_names(j).items()}
        inner["noise.sigma"] = 1.0  # not read: the noise is the outputs' covariance
        return inner

    # -------------------------------------------------------------- the tables
    def _scratch(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        key = threading.get_ident()
        out = self._buffers.get(key)
        if out is None:
            phis = np.zeros((self.steps.size, self.n, self.n))
            out = (phis, np.zeros_like(phis), np.zeros((self.n, self.n)), np.empty((self.t.size, self.r)))
            self._buffers[key] = out
        return out

    def tables(self, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(means (time, r), phis, qs, P0) at `values`: each mode's 2 x 2 blocks and each line's
        mean from the one-component modal model of its output (`ModalModel.tables`). The arrays
        are reused by the next call in this thread."""
        phis, qs, p0, means = self._scratch()
        if self.states == 0:
            phis[:, 0, 0] = 1.0
        for j, blk in enumerate(self.blocks):
            mean, ph, q, _, p = self.inner[j].tables(self._inner_values(values, j))
            means[:, j] = mean
            if blk is not None:
                phis[:, blk, blk] = ph
                qs[:, blk, blk] = q
                p0[blk, blk] = p
        return means, phis, qs, p0

    def _valid(self, values: dict[str, float]) -> bool:
        for n in self._names:
            val = self.value(values, n)
            if not math.isfinite(val):
                return False
            if n.endswith(("frequency", "damping_ratio", "noise.scale")) and not val > 0:
                return False
            if n.endswith(("rms", "amplitude")) and val < 0:
                return False
        return True

    def _run(self, values: dict[str, float], white: np.ndarray, lls: np.ndarray) -> float:
        means, phis, qs, p0 = self.tables(values)
        scale2 = self.value(values, "noise.scale") ** 2
        d = self.z - means
        return float(vector_filter(d, phis, qs, self.idx, self.lo, self.hi, self.h, self.cov, scale2, p0, white, lls))

    # -------------------------------------------------------------- SignalModel
    def fittable(self) -> set[str]:
        return set(self._names)

    def describe(self) -> dict[str, Any]:
        return {"kind": "multi_output", "sources": list(self.kinds), "outputs": self.r}

    def output_means(self, values: dict[str, float]) -> np.ndarray:
        """Each output's deterministic part (level, or level + line) at the data's stamps (time, r)."""
        return self.tables(values)[0].copy()

    def mean(self, values: dict[str, float]) -> np.ndarray:
        """Output 0's deterministic part (the series a result shows)."""
        return self.output_means(values)[:, 0]

    def log_likelihood(self, values: dict[str, float]) -> float:
        """The exact Gaussian log-likelihood of all outputs (module docstring); -inf outside what
        the model allows (a frequency, damping ratio or noise scale <= 0, a negative rms or
        amplitude)."""
        if not self._valid(values):
            return -math.inf
        ll = self._run(values, np.empty((0, 0)), np.empty(0))
        return ll if math.isfinite(ll) else -math.inf

    def pointwise_log_likelihood(self, values: dict[str, float]) -> np.ndarray:
        """Each sample's one-step predictive log density of all its outputs (NaN at gaps)."""
        out = np.empty(self.t.size)
        self._run(values, np.empty((0, 0)), out)
        return out

    def output_residuals(self, values: dict[str, float]) -> np.ndarray:
        """The standardized innovations of the whitened sequential updates (time, r): all
        independent N(0, 1) when the model describes the data; NaN where not observed."""
        out = np.empty((self.t.size, self.r))
        self._run(values, out, np.empty(0))
        return out

    def residuals(self, values: dict[str, float]) -> np.ndarray:
        """One standardized residual per sample: the sum of its outputs' standardized innovations
        over the square root of their number (N(0, 1), independent between samples, when the
        model fits; `output_residuals` has each)."""
        e = self.output_residuals(values)
        count = np.sum(np.isfinite(e), axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.nansum(e, axis=1) / np.sqrt(count)
        out[count == 0] = np.nan
        return out

    def replicate_outputs(self, values: dict[str, float], rng: np.random.Generator) -> np.ndarray:
        """A draw of all outputs at the data's stamps (modes from their stationary law, noise of
        covariance scale^2 C), NaN where the data miss."""
        means, phis, qs, p0 = self.tables(values)
        out = means.copy()
        for j, blk in enumerate(self.blocks):
            if blk is not None:
                out[:, j] += simulate(phis[:, blk, blk], qs[:, blk, blk], self.idx, [1.0, 0.0], 0.0, p0[blk, blk], rng)
        chol = np.linalg.cholesky(self.cov) * self.value(values, "noise.scale")
        out += rng.standard_normal((self.t.size, self.r)) @ chol.T
        out[~self.good] = np.nan
        return out

    def replicate(self, values: dict[str, float], rng: np.random.Generator) -> np.ndarray:
        """Output 0 of a draw of all outputs (`replicate_outputs`)."""
        return self.replicate_outputs(values, rng)[:, 0]

    def units(self, name: str) -> tuple[str, str]:
        """The one-component modal model's units of the parameter (intensity units for levels,
        rms and amplitudes); `noise.scale` is a ratio."""
        if name == "noise.scale":
            return "1", "scale of the outputs' noise covariance (1: as estimated from the pixels)"
        j = self.output_of(name)
        if j is None:
            return "1", name
        units, long_name = self.inner[j].units(self._output_names(j)[name])
        return units, f"output {j} {long_name}"

    def default_priors(self) -> dict[str, Prior]:
        """Per output, the one-component modal model's default priors of that output (the level,
        the mode's or line's parameters); `noise.scale` is not free by default."""
        out: dict[str, Prior] = {}
        for j in range(self.r):
            priors = self.inner[j].default_priors()
            for n, m in self._output_names(j).items():
                out[n] = priors[m]
        return {n: out[n] for n in self._names if n in out}

    def _spectral_guess(self) -> dict[str, float]:
        """The first spectral start of each output's one-component modal model."""
        out: dict[str, float] = {"noise.scale": 1.0}
        for j in range(self.r):
            inner = self.inner[j]
            g = inner.guesses(inner.default_priors())[0]
            out.update({n: float(g[m]) for n, m in self._output_names(j).items()})
        return out

    def guesses(self, bounds: dict[str, tuple[float, float]]) -> list[dict[str, float]]:
        """The table's `start` over the spectral starts of each output (`_spectral_guess`)."""
        return [{**self._spectral_guess(), **self._start}]

    def line_tests(self, values: dict[str, float], free: list[str]) -> list[LineTest]:
        """Each line (its amplitude to 0) and each mode (its rms to 0, with its damping ratio):
        `Source.line_test`."""
        return [
            src.line_test(
                i,
                free,
                self.value(values, n) if (n := src.damping_name(i)) else None,
                self.value(values, f"{src.base}[{i}].frequency"),
            )
            for src, i in zip(self.sources, self.index)
        ]

    def fisher(self, values: dict[str, float], names: list[str]) -> np.ndarray:
        """The observed information -d^2 log L / d theta^2 at `values` by central differences of
        the exact log-likelihood, each step a tenth of the parameter's sd (from a first pass at
        1e-4 of its scale), at most half its value for a positive parameter."""
        v0 = {**{n: self.value(values, n) for n in self._names}, **values}

        def scale(n: str) -> float:
            if n.endswith("level"):
                return self.sd
            return max(1.0 if n.endswith("phase") else abs(v0[n]), 1e-6 * self.sd)

        return observed_information(
            lambda d: self._run({**v0, **d}, np.empty((0, 0)), np.empty(0)),
            v0,
            names,
            scale,
            lambda n: not n.endswith(("phase", "level")),
        )

    def components(self, values: dict[str, float]) -> list[dict[str, Any]]:
        """The fitted sources at `values`, JSON-able, one per output: its kind, output, index and
        parameters, and the output's level."""
        v = lambda n: float(self.value(values, n))
        out: list[dict[str, Any]] = []
        for j, (src, i) in enumerate(zip(self.sources, self.index)):
            row: dict[str, Any] = {"kind": src.kind, "output": j, "index": i, "level": v(f"outputs[{j}].level")}
            row.update({f: v(n) for f, n in zip(src.fields, src.names(i))})
            out.append(row)
        out.append({"kind": "white noise", "covariance": self.cov.tolist(), "scale": v("noise.scale")})
        return out
