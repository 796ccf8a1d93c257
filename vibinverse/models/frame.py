"""The likelihood of a pixel series from a roof on a resonant frame (paper sec. 4.2).

The forward model supplies every piece; nothing here re-implements physics:
- `forward.reduce.rigid_observation`: x = x0 + J g + g^T H g / 2 for the roof slopes g = (-ry, rx);
- `forward.motion.frame`: the linearized frame and the exact steady-state response to the drive.

The drive gives a deterministic mean; the white base noise gives a random tilt, so the exact
likelihood of the residual is a Kalman filter on the two tilt modes (4 states, O(T)). The
observation is linearized in the random part (its quadratic term is ~g/m ~ 1e-4 of the linear one
at the paper's tilts). Gaps (NaN samples) are skipped by the filter.

Any time stamps. The base noise is a white motion of RMS noise_rms held over each frame of the
series' median step, exactly as `forward` simulates it (`kalman.held_oscillator_fill`; a step of
several frames, dropped frames, holds one value per frame). Continuous white noise of the same
intensity has the same resonance but not the same high-frequency part: the one-step prediction
error of a 3.46 Hz tilt at 200 Hz is then 1.5x larger in variance, and on a one-hour record that
pulled the damping ratio to 0.58x and noise_rms to 0.8x their true values, far outside the
intervals. Each tilt mode is discretized exactly over each time step (closed form): a uniform grid
has one step and the fast filter; irregular stamps (jitter, dropped frames) a table of (Phi, Q) per
distinct step, rounded to 1e-9 of the median step, and the per-step filter. The drive mean is
evaluated at the stamps.
"""

from __future__ import annotations

import contextlib
import copy
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from forward.errors import SceneError as ForwardSceneError
from forward.motion import MOTION_KINDS
from forward.motion.frame import FrameMotion, FrameParameters, linearize
from forward.reduce import rigid_observation
from vibinverse.engines.state_space import Components
from vibinverse.errors import DataError, NumericalError, SceneError, Unsupported
from vibinverse.fisher import frame_fisher
from vibinverse.io.scenes import scene_of
from vibinverse.io.series import MIN_CYCLES, Series, with_sampling
from vibinverse.kalman import (
    held_oscillator_fill,
    held_stationary,
    log_likelihood,
    log_likelihood_steps,
    njit,
    pointwise_log_likelihood,
    simulate,
    unique_steps,
    whiten,
    whiten_steps,
)
from vibinverse.models.base import LineTest, SignalModel, intensity_units, observed_information, register_model
from vibinverse.models.frame_spectral import frame_guess, frame_guesses
from vibinverse.priors import Prior
from vibinverse.scene_keys import get_value, numeric_keys, set_value
from vibinverse.terms.base import DataFacts
from vibinverse.terms.nuisance import NuisanceState

if TYPE_CHECKING:
    from vibinverse.posterior import Posterior

TILT_MODES = (3, 4)  # generalized coordinates rx, ry


def motion_class(surface: dict) -> type | None:
    """The forward model's class of a scene file's surface motion: the class whose `from_table`
    `forward.motion.MOTION_KINDS` registers under the motion's kind (None: no motion, or a kind
    not registered)."""
    kind = (surface.get("motion") or {}).get("kind")
    build = MOTION_KINDS.get(kind) if isinstance(kind, str) else None
    return getattr(build, "__self__", None)


def frame_surface(table: dict) -> str:
    """Name of the (single) surface whose motion is a frame."""
    names = [n for n, s in table.get("surfaces", {}).items() if motion_class(s) is FrameMotion]
    if len(names) != 1:
        raise SceneError(f"fit: the scene needs exactly one surface with motion kind 'frame', found {len(names)}")
    return names[0]


def modal_table(table: dict) -> dict:
    """A copy of the scene table whose frame motion is written in modal form (tilt_* and lateral_*),
    so that resonance frequencies and damping ratios are addressable by name."""
    out = copy.deepcopy(table)
    name = frame_surface(out)
    motion = out["surfaces"][name]["motion"]
    if "k_vertical" in motion:
        scene = scene_of(table)
        params = next(s for s in scene.surfaces if s.name == name).motion.params
        modal = params.modal()
        for k in ("k_vertical", "b_vertical", "k_lateral", "b_lateral"):
            motion.pop(k, None)
        motion["tilt_frequency"], motion["tilt_damping_ratio"] = map(float, modal["tilt"])
        motion["lateral_frequency"], motion["lateral_damping_ratio"] = map(float, modal["lateral"])
    return out


@register_model
class FrameModel(SignalModel):
    """A roof on a resonant frame (sec. 4.2): drive lines give a deterministic mean, white base
    noise a random tilt; the exact likelihood is a Kalman filter on the tilt modes."""

    name = "frame"
    releases_gil = True  # numba nogil kernels, and `components` allocates per call (no shared scratch)
    map_start_margin = 50.0  # a swapped drive/resonance assignment starts far below the best
    casadi_bytes_per_sample = 25e3  # MX graph over SX blocks and IPOPT: 9-21 kB a sample measured (12000, 4000)
    accepts_nuisance = True

    @classmethod
    def describes(cls, table: dict) -> bool:
        """A surface of the scene moves as a frame (noise-driven: the state-space likelihood)."""
        return any(motion_class(s) is FrameMotion for s in (table.get("surfaces") or {}).values())

    @classmethod
    def truth_table(cls, table: dict) -> dict:
        return modal_table(table)

    @classmethod
    def default_targets(cls, table: dict) -> list[str]:
        """Tilt resonance and damping ratio, and the first drive line's frequency and amplitude."""
        k = f"surfaces.{frame_surface(table)}.motion."
        out = [k + "tilt_frequency", k + "tilt_damping_ratio"]
        if table["surfaces"][frame_surface(table)]["motion"].get("drive_frequency") or []:
            out += [k + "drive_frequency", k + "drive_amplitude"]
        return out

    def __init__(self, table: dict, series: Series, *, per_step: bool | None = None, facts: DataFacts | None = None):
        """`per_step`: the per-step filter even on a uniform grid (None: on irregular stamps only);
        `facts`: the data facts the nuisance terms span (default: the series'; `head` keeps the
        whole record's)."""
        self.base = modal_table(table)
        self.roof = frame_surface(self.base)
        others = [n for n, s in self.base["surfaces"].items() if n != self.roof and (s.get("motion") or {})]
        if others:
            raise SceneError(
                f"fit: surfaces.{others[0]}.motion: a frame scene's likelihood holds every other surface at "
                "rest; remove that motion (or fit it in a scene without the frame)"
            )
        self.series = series
        self.t = series.time
        self.dt = series.dt
        self.key = f"surfaces.{self.roof}.motion."
        scene = scene_of(with_sampling(self.base, series))
        self.roof_surface = next(s for s in scene.surfaces if s.name == self.roof)
        self.x0, self.jac, self.hess = rigid_observation(scene, self.roof)
        m = self.base["surfaces"][self.roof]["motion"]
        self.mass = float(m.get("mass", 1.0))
        self.lx = self.roof_surface.x[1] - self.roof_surface.x[0]
        self.ly = self.roof_surface.y[1] - self.roof_surface.y[0]
        self._unit = linearize(FrameParameters(self.mass, self.lx, self.ly, 1.0, 1.0, 1.0, 1.0))
        check = linearize(FrameParameters(self.mass, self.lx, self.ly, 2.0, 3.0, 5.0, 7.0))
        rows = list(TILT_MODES)
        if not (
            np.allclose(check.stiffness[rows], 2.0 * self._unit.stiffness[rows])
            and np.allclose(check.force_spring[rows], 2.0 * self._unit.force_spring[rows])
            and np.allclose(check.damping[rows], 3.0 * self._unit.damping[rows])
            and np.allclose(check.force_damper[rows], 3.0 * self._unit.force_damper[rows])
        ):
            raise RuntimeError("frame likelihood: the tilt rows are not linear in (k1, b1)")
        self._fixed: dict[str, float] = {}  # scene values read once (a likelihood call is a hot path)
        self._geometry = self._geometry_names()
        self.n_lines = len(m.get("drive_frequency", []) or [])
        plane = np.array(m.get("drive_plane", [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), dtype=float)
        d1, d2 = plane[0] / np.linalg.norm(plane[0]), plane[1] / np.linalg.norm(plane[1])
        corner = slice(3 * int(m.get("drive_corner", 0)), 3 * int(m.get("drive_corner", 0)) + 3)
        # unit-frame force rows at the drive corner, applied to d1 - i d2 (`Drive.phasors`)
        self._corner_force = {
            i: (
                self._unit.force_spring[i, corner] @ (d1 - 1j * d2),
                self._unit.force_damper[i, corner] @ (d1 - 1j * d2),
            )
            for i in TILT_MODES
        }
        step = (self.t[-1] - self.t[0]) / max(self.t.size - 1, 1)  # the grid's step, to the last ulp
        on_grid = np.max(np.abs(self.t - (self.t[0] + np.arange(self.t.size) * step))) <= 1e-9 * step
        self._grid = float(step) if on_grid and self.t.size > 1 else None
        # time steps: one on a uniform grid (UNIFORM_RTOL); else the distinct ones (rounded to 1e-9 of
        # the median step), the nominal step appended last (components' phi and q)
        self.per_step = (not series.uniform) if per_step is None else bool(per_step)
        if self.per_step:
            steps, self._idx = unique_steps(self.t, rtol=1e-9)
            self._steps = np.append(steps, self.dt)
        else:
            self._steps, self._idx = np.array([self.dt]), None
        self._observed: tuple[tuple, tuple] | None = None  # the last re-formed observation, by its values
        # nuisance terms beside the tilt modes (`vibinverse.terms`): the sensor noise stays the
        # scene's noise.sigma (absent when the spec has no white noise)
        self.nuisance = NuisanceState(self.base, DataFacts.of(series) if facts is None else facts)
        # with nuisance terms the default posterior is the importance-sampled Laplace approximation, emcee
        # where its check fails (the modal model's rule): emcee alone took 60-680 s a fit on the robustness
        # bench's AR(1) and 1/f scene data
        self.importance_first = bool(self.nuisance) or not self.nuisance.white

    def with_nuisance(self, nuisance: dict[str, Any]) -> FrameModel:
        """This model with other nuisance terms: the scene's observation and the tilt rows are shared."""
        out = copy.copy(self)
        out.base = {**self.base, "nuisance": nuisance}
        out.nuisance = NuisanceState(out.base, self.nuisance.facts)
        return out

    @property
    def steps(self) -> np.ndarray:
        """The distinct time steps (s) the filter discretizes for, the nominal step last."""
        return self._steps

    @property
    def step_index(self) -> np.ndarray | None:
        """Per sample, the index into `steps` of the step before it (None on a uniform grid)."""
        return self._idx

    def components(self, values: dict[str, float]) -> Components:
        """Mean signal and state-space matrices at the given parameter values (others from the base)."""
        val = lambda name, default=None: values.get(
            self.key + name, default if default is not None else self.base_value(self.key + name)
        )
        m = self.base["surfaces"][self.roof]["motion"]
        tilt = self._tilt_rows(val("tilt_frequency"), val("tilt_damping_ratio"))
        x0, jac, hs = self.observation(values)
        if self.n_lines:
            f, a, ph = (
                np.array([self.line_value(values, name, i) for i in range(self.n_lines)])
                for name in ("drive_frequency", "drive_amplitude", "drive_phase")
            )
            w = 2 * np.pi * f
            qx, qy = self._tilt_phasors(tilt, w, a * np.exp(1j * ph))
            mean = self._drive_mean(w, qx, qy, x0, jac, hs)
        else:
            mean = np.full(self.t.shape, x0)
        rms = val("noise_rms", float(m.get("noise_rms", 0.0)))
        # g_x = -ry and g_y = rx; a tilt mode the pixel does not see at first order is left out
        gains = {3: jac[1], 4: -jac[0]}
        seen = [i for i in TILT_MODES if abs(gains[i]) > 1e-9 * np.abs(jac).max()]
        n = 2 * len(seen)
        u = self._steps.size
        phis, qs = np.zeros((u, n, n)), np.zeros((u, n, n))
        p0, h = np.zeros((n, n)), np.zeros(n)
        filled = (0.0, 0.0, 0.0)
        for b, i in enumerate(seen):
            mass = tilt["mass"][i]
            w_i = math.sqrt(tilt["stiffness"][i] / mass)
            a_i = tilt["damping"][i] / (2.0 * mass)  # zeta w
            # the base force's white-noise intensity: (RMS of the held motion)^2 x the nominal step
            kappa = float(rms**2 * self.dt * (tilt["force_spring"][i] @ tilt["force_spring"][i]) / mass**2)
            if b and (w_i, a_i) == filled[:2] and filled[2]:  # the other tilt mode, the same oscillator
                phis[:, 2 * b :, 2 * b :] = phis[:, :2, :2]
                qs[:, 2 * b :, 2 * b :] = qs[:, :2, :2] * (kappa / filled[2])
            else:
                held_oscillator_fill(w_i, a_i, kappa, self._steps, self.dt, phis, qs, 2 * b)
            filled = (w_i, a_i, kappa)
            if kappa:  # the stationary covariance at the frame step (infinite undamped: no stationary state)
                block = slice(2 * b, 2 * b + 2)
                p0[block, block] = held_stationary(phis[-1, block, block], qs[-1, block, block])
            h[2 * b] = gains[i]
        sigma = values.get("noise.sigma", self.base_value("noise.sigma") if "noise" in self.base else 0.0)
        if not self.nuisance.white:
            sigma = 0.0
        if self.nuisance:
            return self._composed(values, mean, phis, qs, p0, h, float(sigma) ** 2)
        phi, q = phis[-1], qs[-1]
        if self.per_step:
            return Components(mean, phi, q, h, float(sigma) ** 2, p0, phis, qs, self._idx)
        return Components(mean, phi, q, h, float(sigma) ** 2, p0)

    def _composed(
        self,
        values: dict[str, float],
        mean: np.ndarray,
        phis: np.ndarray,
        qs: np.ndarray,
        p0: np.ndarray,
        h: np.ndarray,
        r: float,
    ) -> Components:
        """The tilt modes' blocks first, the nuisance terms' after them (`NuisanceState.compose`), a
        gain drift multiplying the mean and the tilt's observation."""
        blocks = [2] * (h.size // 2)
        ss, valid = self.nuisance.compose(values, self._steps, (phis, qs, p0, h), blocks, r, self.t.size)
        if ss.hm.size:
            mean = mean * ss.hm
        idx = self._idx if self.per_step else np.zeros(self.t.size, dtype=np.int64)
        return Components(mean, ss.phis[-1], ss.qs[-1], ss.h, r, ss.p0, ss.phis, ss.qs, idx, ss, h.size, valid)

    def _engine(self, c: Components, white: np.ndarray | None = None, lls: np.ndarray | None = None) -> float:
        """The engine on the composed state (`NuisanceState.run`); -inf outside the terms' domain."""
        if not c.valid:
            return -math.inf
        return self.nuisance.run(self.series.intensity - c.mean, c.state, c.idx, white=white, lls=lls)

    def _geometry_names(self) -> set[str]:
        """Scene values the observation depends on and the frame's dynamics do not: sun, view,
        optics, footprint, the other surfaces, the gain sun.irradiance. (The roof's own extents set
        its inertia and are not among them.)"""
        skip = (
            "sampling.",
            "infer.",
            "nuisance.",
            "title",
            "noise.",
            "footprint.resolution",
            f"surfaces.{self.roof}.motion.",
            f"surfaces.{self.roof}.x",
            f"surfaces.{self.roof}.y",
        )
        return {n for n in numeric_keys(self.base) if not n.startswith(skip)} | {"sun.irradiance"}

    def observation(self, values: dict[str, float]) -> tuple[float, np.ndarray, np.ndarray]:
        """(x0, J, H) of the roof's tilt: built once at the scene's geometry, re-formed from the
        scene (`rigid_observation`) when a geometry or optics value is among `values`."""
        geo = tuple(sorted((n, v) for n, v in values.items() if n in self._geometry))
        if not geo:
            return self.x0, self.jac, self.hess
        if self._observed is None or self._observed[0] != geo:
            table = copy.deepcopy(self.base)
            for n, v in geo:
                set_value(table, n, v)
            scene = scene_of(with_sampling(table, self.series))
            self._observed = (geo, rigid_observation(scene, self.roof))
        return self._observed[1]

    def geometry_free(self, names: list[str]) -> list[str]:
        """Which of `names` are geometry or optics values (re-forming the observation)."""
        return [n for n in names if n in self._geometry]

    def _tilt_rows(self, f_tilt: float, zeta: float) -> dict[str, dict[int, Any]]:
        """The linear frame's tilt rows (eqs. (11)-(16) linearized) at this resonance: every one is
        linear in the corner spring k1 and dashpot b1, so they are scaled from a unit frame built
        once (`linearize` at k = b = 1; the scaling is verified at construction)."""
        params = FrameParameters.from_modal(self.lx, self.ly, self.mass, tilt=(f_tilt, zeta), lateral=(1.0, 0.0))
        k1, b1 = params.k1, params.b1
        u = self._unit
        return {
            "k1": k1,
            "b1": b1,
            "stiffness": {i: k1 * u.stiffness[i] for i in TILT_MODES},
            "damping": {i: b1 * u.damping[i] for i in TILT_MODES},
            "mass": {i: u.mass[i] for i in TILT_MODES},
            "force_spring": {i: k1 * u.force_spring[i] for i in TILT_MODES},
            "force_damper": {i: b1 * u.force_damper[i] for i in TILT_MODES},
        }

    def _tilt_phasors(self, tilt: dict, w: np.ndarray, amp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Complex steady-state amplitudes of rx and ry per drive line (exact, as
        `forward.motion.frame.steady_state` for the two rows the pixel sees): the base phasor
        A e^{i phase} (d1 - i d2) at the drive corner through H(i w) of each tilt mode."""
        out = []
        for i in TILT_MODES:
            spring, damper = self._corner_force[i]
            force = (tilt["k1"] * spring + 1j * w * tilt["b1"] * damper) * amp
            out.append(force / (tilt["stiffness"][i] - w * w * tilt["mass"][i] + 1j * w * tilt["damping"][i]))
        return out[0], out[1]

    def _drive_mean(
        self, w: np.ndarray, qx: np.ndarray, qy: np.ndarray, x0: float, jac: np.ndarray, hs: np.ndarray
    ) -> np.ndarray:
        """x0 + J g + g'Hg/2 with g = (-ry, rx), r = Re(q e^{i w t}) summed over the lines."""
        if self._grid is not None:  # uniform grid: the compiled kernel (rotations, re-anchored)
            out = np.empty(self.t.size)
            _drive_mean_kernel(self.t, self._grid, w, qx, qy, x0, jac[0], jac[1], hs[0, 0], hs[0, 1], hs[1, 1], out)
            return out
        out = np.empty(self.t.size)  # any stamps: each sinusoid at each stamp
        _drive_mean_at(self.t, w, qx, qy, x0, jac[0], jac[1], hs[0, 0], hs[0, 1], hs[1, 1], out)
        return out

    def fittable(self) -> set[str]:
        """The names this likelihood reads: frame dynamics, drive lines, base noise, sensor noise,
        and the geometry and optics of the observation (`observation`)."""
        k = self.key
        names = (
            {
                k + n
                for n in (
                    "tilt_frequency",
                    "tilt_damping_ratio",
                    "lateral_frequency",
                    "lateral_damping_ratio",
                    "noise_rms",
                )
            }
            | {"noise.sigma"}
            | self._geometry
        )
        lines = len(self.base["surfaces"][self.roof]["motion"].get("drive_frequency", []) or [])
        for n in ("drive_frequency", "drive_amplitude", "drive_phase"):
            names |= {f"{k}{n}[{i}]" for i in range(lines)} | ({k + n} if lines else set())
        names |= set(self.nuisance.names())
        return names if self.nuisance.white else names - {"noise.sigma"}

    def line_value(self, values: dict[str, float], name: str, i: int) -> float:
        """Drive line i's value: "name[i]" (or plain "name" for line 0) from `values`, else the base."""
        for k in (f"{self.key}{name}[{i}]", *((f"{self.key}{name}",) if i == 0 else ())):
            if k in values:
                return values[k]
        try:
            return self.base_value(f"{self.key}{name}[{i}]")
        except ForwardSceneError:
            return 0.0  # an absent drive_phase

    def base_value(self, key: str) -> float:
        """A scene value by dotted name (read once: a likelihood call is a hot path)."""
        if key not in self._fixed:
            self._fixed[key] = get_value(self.base, key)
        return self._fixed[key]

    def mean(self, values: dict[str, float]) -> np.ndarray:
        """The drive's deterministic response x(t) at the given values."""
        return self.components(values).mean

    def log_likelihood(self, values: dict[str, float]) -> float:
        c = self.components(values)
        if not math.isfinite(c.p0.sum()):  # undamped and driven: no stationary start
            return -math.inf
        if c.composed:
            return self._engine(c)
        if c.idx is not None:
            return log_likelihood_steps(self.series.intensity - c.mean, c.phis, c.qs, c.idx, c.h, c.r, c.p0)
        return log_likelihood(self.series.intensity - c.mean, c.phi, c.q, c.h, c.r, c.p0)

    def head(self, n: int) -> FrameModel:
        """The frame model of the first n samples (the same scene and filter: per-step on a stretch
        of irregular stamps that happens to be uniform)."""
        # the whole record's facts: a gain drift's cosines, the 1/f states and the starts span it
        return FrameModel(self.base, self.series.head(n), per_step=self.per_step, facts=self.nuisance.facts)

    def pointwise_log_likelihood(self, values: dict[str, float]) -> np.ndarray:
        """Each sample's one-step predictive log density log p(y_k | y_1..y_{k-1}) (the Kalman
        filter's innovation density), NaN at gaps; `np.nansum` of it is `log_likelihood(values)`."""
        c = self.components(values)
        if c.composed:
            out = np.empty(self.t.size)
            self._engine(c, lls=out)
            return out
        return pointwise_log_likelihood(self.series.intensity - c.mean, *c.tables(), c.h, c.r, c.p0)

    def residuals(self, values: dict[str, float]) -> np.ndarray:
        """Standardized innovations of the Kalman filter: independent N(0, 1) when the model
        describes the data; NaN at gaps."""
        c = self.components(values)
        y = self.series.intensity - c.mean
        if c.composed:
            out = np.empty(self.t.size)
            self._engine(c, white=out)
            return out
        if c.idx is not None:
            return whiten_steps(y, c.phis, c.qs, c.idx, c.h, c.r, c.p0)
        return whiten(y, c.phi, c.q, c.h, c.r, c.p0)

    def replicate(self, values: dict[str, float], rng: np.random.Generator) -> np.ndarray:
        """A series the model at `values` produces at the data's stamps: the drive mean plus a draw
        of the tilt process (started in its stationary state) through the observation, plus the
        sensor noise; NaN where the data have gaps."""
        c = self.components(values)
        if not np.all(np.isfinite(c.p0)):
            raise NumericalError(
                f"replicate: {self.key}tilt_damping_ratio = 0 with base noise has no stationary state to start from"
            )
        if c.composed:
            out = c.mean + self.nuisance.simulate(c.state, c.idx, rng)
        else:
            out = c.mean + simulate(*c.tables(), c.h, c.r, c.p0, rng)
        out[self.series.gaps] = np.nan
        return out

    # ------------------------------------------------------------------ what the estimators need
    def default_priors(self) -> dict[str, Prior]:
        """Tilt resonance and damping, the drive line's frequency, amplitude and phase, both noise
        levels. Frequencies from MIN_CYCLES (1) cycle in the record (at least 0.2 Hz) to Nyquist."""
        nyq = 0.5 * self.series.fs
        lo = max(0.2, MIN_CYCLES / (self.t[-1] - self.t[0]) * (1.0 + 1e-9))
        k = self.key
        return {
            k + "tilt_frequency": Prior("uniform", (lo, nyq)),
            k + "tilt_damping_ratio": Prior("loguniform", (1e-3, 0.5)),
            k + "drive_frequency": Prior("uniform", (lo, nyq)),
            # uniform, not log-uniform: a log-uniform prior puts half its mass on amplitudes too small
            # to see, where the drive frequency is free, and walkers drift onto that plateau
            k + "drive_amplitude": Prior("uniform", (0.0, 0.05)),
            k + "drive_phase": Prior("uniform", (-np.pi, np.pi)),
            k + "noise_rms": Prior("loguniform", (1e-7, 1e-1)),
            **({"noise.sigma": Prior("loguniform", (1e-8, 1e3))} if self.nuisance.white else {}),
            **self.nuisance.priors(),
        }

    def guesses(self, bounds: dict[str, tuple[float, float]]) -> list[dict[str, float]]:
        """One start per plausible drive line, most steady first (`frame_spectral.frame_guesses`),
        the nuisance terms' from their spectral starts (`Term.starts`), a gain drift's constant
        from the intensity at rest (`NuisanceState.complete`)."""
        return self.nuisance.complete(frame_guesses(self.series, self, bounds), lambda g: self.observation(g)[0])

    def line_tests(self, values: dict[str, float], free: list[str]) -> list[LineTest]:
        """The drive line (its amplitude to 0) and the tilt resonance (the base noise to 0)."""
        k = self.key
        out = []
        for label, name, freq, deterministic in (
            ("drive", "drive_amplitude", "drive_frequency", True),
            ("resonance", "noise_rms", "tilt_frequency", False),
        ):
            if k + name in values:
                out.append(LineTest(label, {k + name: 0.0}, k + freq, deterministic))
        return out

    def fisher(self, values: dict[str, float], names: list[str]) -> np.ndarray:
        """Mean term through the Kalman filter plus Whittle's covariance term (`vibinverse.fisher`);
        with nuisance terms the observed information (finite differences of the exact likelihood)."""
        if not self.nuisance:
            return frame_fisher(self, values, names)
        v0 = {n: values[n] if n in values else self._value(n) for n in names}
        return observed_information(
            lambda d: self.log_likelihood({**values, **d}),
            v0,
            names,
            lambda n: max(abs(v0[n]), 1e-12) if not n.endswith("phase") else 1.0,
            lambda n: not n.endswith(("phase", "level")) and not n.startswith("gain."),
        )

    def nuisance_priors(self) -> dict[str, Prior]:
        """The nuisance terms' default priors (`Term.priors`)."""
        return self.nuisance.priors()

    def _value(self, name: str) -> float:
        """A parameter's value when not given: a nuisance term's start, else the scene's."""
        return self.nuisance.value({}, name) if name in self.nuisance.names() else self.base_value(name)

    def describe(self) -> dict[str, Any] | None:
        """The nuisance terms beside the tilt modes, when there are any."""
        if not self.nuisance and self.nuisance.white:
            return None
        return {"kind": "frame", "nuisance": self.nuisance.spec.table(), "terms": self.nuisance.spec.describe()}

    def units(self, name: str) -> tuple[str, str]:
        """A nuisance term's own units (`Term.units`), else by the name (`SignalModel.units`)."""
        found = self.nuisance.terms.units(name, intensity_units(self.series))
        return found if found is not None else super().units(name)

    def casadi_objective(self, posterior: Posterior) -> Any:
        """`frame_casadi.CasadiFrameObjective`; Unsupported when a geometry value is free (the
        casadi form holds the observation fixed)."""
        if self.nuisance or not self.nuisance.white:
            raise Unsupported(f"the casadi MAP has no nuisance terms ({self.nuisance.spec.describe()}) yet")
        geometry = self.geometry_free(posterior.space.names)
        if geometry:
            raise Unsupported(f"the casadi MAP holds the observation fixed; {', '.join(geometry)} re-form it")
        from vibinverse.models.frame_casadi import CasadiFrameObjective

        return CasadiFrameObjective(posterior)

    def alternatives(self, values: dict[str, float], free: list[str]) -> list[tuple[str, dict[str, float]]]:
        """The tilt resonance and the first drive line exchanged: a very lightly damped resonance is
        as steady as a drive over a short record, so the spectrum alone cannot tell them apart."""
        k = self.key
        names = (k + "tilt_frequency", k + "drive_frequency")
        if not all(n in free for n in names) or not self.n_lines:
            return []
        f_tilt, f_drive = values[names[0]], values[names[1]]
        swapped = {**values, **self.calibrated_guess(f_tilt, (f_drive, values.get(k + "tilt_damping_ratio", 0.01)))}
        swapped[names[0]], swapped[names[1]] = f_drive, f_tilt
        return [("the tilt resonance and the drive line exchanged", swapped)]

    def calibrated_guess(self, drive_frequency: float | None, resonance: tuple[float, float]) -> dict[str, float]:
        """Spectral values of the drive and noise levels given the resonance (frequency, damping
        ratio), calibrated through the forward model (`frame_spectral.frame_guess`)."""
        bounds = {self.key + "tilt_frequency": (resonance[0], resonance[0])}
        return frame_guess(self.series, self, bounds, drive_frequency, resonance=resonance)

    def drive_frequencies(self, values: dict[str, float]) -> list[float]:
        """Every drive line's frequency at `values` (others from the scene)."""
        return [self.line_value(values, "drive_frequency", i) for i in range(self.n_lines)]

    def resonance_values(self) -> dict[str, float]:
        """Scene values of the resonance, base noise, sensor noise and first drive frequency (what
        an identification of the tilt mode reads besides the free parameters)."""
        out = {}
        k = self.key
        for n in (k + "tilt_frequency", k + "tilt_damping_ratio", k + "noise_rms", "noise.sigma"):
            with contextlib.suppress(ForwardSceneError):
                out[n] = self.base_value(n)
        if self.n_lines:
            out[k + "drive_frequency"] = self.line_value({}, "drive_frequency", 0)
        return out

    def first_order_ratio(self, values: dict[str, float]) -> float:
        """How much the pixel's first-order term exceeds its second-order term at the typical tilt
        (x = x0 + J g + g^T H g / 2, the Taylor form of eq. (23) at rest): |J| g / (|H| g^2 / 2),
        g the tilt's stationary rms plus the drive's tilt amplitude, at `values` (others from the
        scene). Small on the specular lobe centre or over a symmetric footprint (J -> 0)."""
        c = self.components({**values, self.key + "drive_amplitude": 0.0})
        n = c.n_own if c.composed else c.h.size
        g_noise = float(np.sqrt(max(np.trace(c.p0[:n, :n]) / max(n // 2, 1), 0.0)))
        drive = self.components({**values, self.key + "noise_rms": 0.0}).mean
        j = float(np.linalg.norm(self.jac))
        g_drive = float(np.ptp(drive)) / 2 / j if j > 0 else 0.0
        g = max(g_noise + g_drive, 1e-12)
        h = float(np.linalg.norm(self.hess, 2))
        return j * g / max(0.5 * h * g * g, 1e-300)

    def check_first_order(self, readings: list[dict[str, float]]) -> None:
        """DataError when the pixel sees the random tilt mostly at second order under every
        reading of the data (`first_order_ratio` below FIRST_ORDER_MIN): the Kalman likelihood keeps
        only the first-order term J g of the random tilt (the drive's mean is exact to second order),
        so there it would fit a wrong resonance and damping with confident intervals."""
        if not readings:
            return
        ratio = max(self.first_order_ratio(v) for v in readings)
        if ratio < FIRST_ORDER_MIN:
            raise DataError(
                f"fit: the pixel sees the roof's tilt mostly at second order (first/second order = {ratio:.2g}, "
                f"below {FIRST_ORDER_MIN:g}: a view near the specular lobe's centre), which the frame model's "
                "linearized observation cannot describe; check sensor.inclination and sun.inclination, or fit "
                "without --scene (the modal model, in intensity units: a tilt seen at second order shows at twice "
                "its frequency)"
            )


# first/second-order ratio below which a frame fit is refused: at the paper's roof (seed 3, sec. 4.2
# noise levels) the tilt frequency's bias grows from 0.1 sd at a ratio of 8.5 to 0.3 sd at 3.7, 0.65 sd
# at 2.1, and leaves the 90 % interval at 1 (4 % off on the lobe centre, ratio 0.47; 36 % at 0.33)
FIRST_ORDER_MIN = 3.0


_ANCHOR = 64  # samples between exact re-anchors of the rotation recurrence


@njit(cache=True, nogil=True)
def _drive_mean_kernel(t, dt, w, qx, qy, x0, jx, jy, hxx, hxy, hyy, out):  # pragma: no cover - compiled
    """out[k] = x0 + J g + g'Hg/2 at t[k] on a uniform grid of step dt, g = (-ry, rx), (rx, ry) =
    Re((qx, qy) e^{i w t}). e^{i w t} advances by a rotation of w dt per sample and is recomputed
    exactly at t[k] every _ANCHOR samples, so the rounding never grows past ~_ANCHOR ulps (and the
    grid's deviation, <= 1e-9 dt, past w * _ANCHOR * 1e-9 dt); one pass, no temporaries."""
    n_lines = w.shape[0]
    c = np.empty(n_lines)
    s = np.empty(n_lines)
    rc = np.cos(w * dt)
    rs = np.sin(w * dt)
    for k in range(out.shape[0]):
        if k % _ANCHOR == 0:
            for m in range(n_lines):
                c[m] = np.cos(w[m] * t[k])
                s[m] = np.sin(w[m] * t[k])
        rx = 0.0
        ry = 0.0
        for m in range(n_lines):
            rx += qx[m].real * c[m] - qx[m].imag * s[m]
            ry += qy[m].real * c[m] - qy[m].imag * s[m]
            c[m], s[m] = c[m] * rc[m] - s[m] * rs[m], s[m] * rc[m] + c[m] * rs[m]
        gx = -ry
        gy = rx
        out[k] = x0 + jx * gx + jy * gy + 0.5 * (hxx * gx * gx + 2.0 * hxy * gx * gy + hyy * gy * gy)


@njit(cache=True, nogil=True)
def _drive_mean_at(t, w, qx, qy, x0, jx, jy, hxx, hxy, hyy, out):  # pragma: no cover - compiled
    """out[k] = x0 + J g + g'Hg/2 at any stamps t[k] (each sinusoid evaluated at each stamp)."""
    for k in range(out.shape[0]):
        rx = 0.0
        ry = 0.0
        for m in range(w.shape[0]):
            c = math.cos(w[m] * t[k])
            s = math.sin(w[m] * t[k])
            rx += qx[m].real * c - qx[m].imag * s
            ry += qy[m].real * c - qy[m].imag * s
        gx = -ry
        gy = rx
        out[k] = x0 + jx * gx + jy * gy + 0.5 * (hxx * gx * gx + 2.0 * hxy * gx * gy + hyy * gy * gy)


def warm_up() -> None:
    """Compile (or load from the on-disk cache) every compiled kernel a frame fit calls: the
    likelihood, its per-sample and per-step forms, the replicate simulator and the drive mean, on a
    64-sample series of the built-in frame scene (the same argument types as a real fit). `vibinverse
    demo` runs it in a second process while the first one simulates, so that a fresh install's
    compilation overlaps other work."""
    from forward.scene_file import read_table
    from vibinverse.io.builtin import builtin_scene
    from vibinverse.io.series import validate

    table = read_table(builtin_scene("roof_frame.toml"))
    t = np.arange(64) / 200.0
    y = np.random.default_rng(0).normal(size=t.size)
    for times in (t, t + np.r_[0.0, np.full(t.size - 1, 1e-3)]):  # uniform and irregular stamps
        model = FrameModel(table, validate(times, y, "warm-up"))
        values = {"noise.sigma": 1.0}  # the rest from the scene
        model.log_likelihood(values)
        model.pointwise_log_likelihood(values)
        model.replicate(values, np.random.default_rng(0))
