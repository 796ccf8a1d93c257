"""The posterior of a deterministic scene (plate roof, ground waves) as a casadi expression, for the
casadi MAP (`vibinverse.estimators.casadi_map`): exact gradients and Hessian through the reduced model.

Every modal motion here is a sum of lines whose modal coordinates are
    q_j(t) = sum_l A_l (alpha_jl cos(w_l t + phase_l) + beta_jl sin(w_l t + phase_l)),
with shapes that do not depend on A, w or the phase. (alpha, beta) are read off the motion's own
`coefficients` at construction, and the form is verified there at a second amplitude, frequency
and phase. A parameter that breaks it (a Rayleigh frequency changes the wave's shape; a plate driven
through its boundary, eq. (10), has q ~ w^2) raises `vibinverse.errors.Unsupported`, and the fit uses the scipy MAP.
The mean is then the Taylor model of `forward.reduce` (eq. (23) to second order, summed over the
footprint), X = irradiance (rest + sum_k w_k (J_k q + q'H_k q / 2)), exactly as `DeterministicModel`
forms it (a test checks the two posteriors agree to 1e-9).
"""

from __future__ import annotations

import math
from typing import Protocol

import casadi as ca
import numpy as np

from forward.reduce import modal_points, taylor_coefficients
from vibinverse.errors import Unsupported
from vibinverse.posterior import Posterior
from vibinverse.priors import casadi_log_prior, casadi_value


class Line(Protocol):
    """A vibration line's parameter names (`vibinverse.models.deterministic.Line`)."""

    surface: str
    frequency: str
    amplitude: str
    phase: str

    def names(self) -> tuple[str, str, str]: ...


class CasadiResponseObjective:
    """-log posterior of a deterministic-scene Posterior as a casadi Function of z, y, mask."""

    def __init__(self, problem: Posterior):
        like = problem.model  # a DeterministicModel (`vibinverse.models.deterministic`)
        self.problem, self.like = problem, like
        if like.reduction != "taylor2":
            raise Unsupported("the mean needs the compiled (Chebyshev) model")
        noise = like.scene.noise
        if noise.adc_bits > 0:
            raise Unsupported("ADC quantization noise")
        for n in problem.space.names:
            if like.kinds.get(n) == "scene":
                raise Unsupported(f"{n} re-forms the scene")
        self.lines = like.lines()
        self.surfaces = self._surfaces()
        self.function = self._build()

    # ------------------------------------------------------------------ the motion's form
    def _surfaces(self) -> list[dict]:
        """Per moving surface: coverage, Taylor (J, H) of its unit shapes, and per coordinate the
        (alpha, beta) of each of its lines, verified against `coefficients`."""
        like = self.like
        t = like.t
        out = []
        for k, x, y, weight, derivs in like.layout.moving:
            surface = like.scene.surfaces[k]
            lines = [ln for ln in self.lines if ln.surface == surface.name]
            if not lines:
                raise Unsupported(f"surfaces.{surface.name}.motion has no frequency and amplitude")
            sx, sy, w = modal_points(surface.motion, x, y, like.shape_cache)
            jac, hess = taylor_coefficients(derivs, sx, sy, w)
            form = [self._line_form(surface, ln, t) for ln in lines]
            self._verify(surface, lines, form, t)
            out.append({"weight": weight, "jac": jac, "hess": hess, "lines": lines, "form": form})
        return out

    def _line_form(self, surface, line: Line, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(alpha, beta) per coordinate of one line: its coordinates alone, at unit amplitude and
        phase 0, regressed on cos(w t), sin(w t)."""
        like = self.like
        alone = {ln.amplitude: 0.0 for ln in self.lines if ln.surface == surface.name and ln != line}
        q = like.motion_with(surface, {**alone, line.amplitude: 1.0, line.phase: 0.0}).coefficients(t)
        wt = 2 * math.pi * like.base_value(line.frequency) * t
        basis = np.stack([np.cos(wt), np.sin(wt)], axis=1)
        coef = np.linalg.lstsq(basis, q, rcond=None)[0]  # (2, K)
        if np.abs(basis @ coef - q).max() > 1e-9 * max(np.abs(q).max(), 1e-300):
            raise Unsupported(f"{line.frequency}: the coordinates are not a sinusoid of that line")
        return coef[0], coef[1]

    def _verify(self, surface, lines: list[Line], form: list, t: np.ndarray) -> None:
        """The form holds away from the scene's values for every free motion value, and the shapes
        do not move: checked at 1.3x the amplitude, 1.01x the frequency and phase + 0.7."""
        like = self.like
        free = set(self.problem.space.names)
        probe = {}
        for ln in lines:
            for name, value in (
                (ln.amplitude, 1.3 * (like.base_value(ln.amplitude) or 1e-3)),
                (ln.frequency, 1.01 * like.base_value(ln.frequency)),
                (ln.phase, like.base_value(ln.phase) + 0.7),
            ):
                if name in free or (name.endswith("[0]") and name[:-3] in free):
                    probe[name] = value
        if not probe:
            return
        for name, v in probe.items():
            if like.motion_with(surface, {name: v}).shape_key() != surface.motion.shape_key():
                raise Unsupported(f"{name}: the motion's shapes depend on it")
        moved = like.motion_with(surface, probe)
        expected = self._coordinates(
            lines, form, {**{n: like.base_value(n) for ln in lines for n in ln.names()}, **probe}, t, np
        )
        actual = moved.coefficients(t)
        if np.abs(expected - actual).max() > 1e-9 * max(np.abs(actual).max(), 1e-300):
            raise Unsupported(f"{', '.join(probe)}: the coordinates are not A (alpha cos + beta sin)(w t + phase)")

    @staticmethod
    def _coordinates(lines: list[Line], form: list, values: dict, t, lib):
        """q_j(t) of one surface from its lines' values, with numpy (checks) or casadi."""
        cols = None
        for ln, (alpha, beta) in zip(lines, form):
            arg = 2 * math.pi * values[ln.frequency] * t + values[ln.phase]
            c, s = lib.cos(arg), lib.sin(arg)
            q = [values[ln.amplitude] * (a * c + b * s) for a, b in zip(alpha, beta)]
            cols = q if cols is None else [u + v for u, v in zip(cols, q)]
        return np.stack(cols, axis=1) if lib is np else cols

    # ------------------------------------------------------------------ the objective
    def _build(self) -> ca.Function:
        like, space = self.like, self.problem.space
        z = ca.MX.sym("z", len(space))
        free = {n: casadi_value(p, z[i]) for i, (n, p) in enumerate(zip(space.names, space.priors))}
        log_prior = sum(casadi_log_prior(p, z[i], free[n]) for i, (n, p) in enumerate(zip(space.names, space.priors)))
        value = lambda n: free.get(n, free.get(n[:-3]) if n.endswith("[0]") else None)
        t = ca.DM(like.t)
        ac = 0.0
        for s in self.surfaces:
            values = {
                n: (value(n) if value(n) is not None else like.base_value(n)) for ln in s["lines"] for n in ln.names()
            }
            q = self._coordinates(s["lines"], s["form"], values, t, ca)
            part = 0.0
            for i, qi in enumerate(q):
                part = part + s["jac"][i] * qi
                for j, qj in enumerate(q):
                    if s["hess"][i, j] != 0.0:
                        part = part + 0.5 * s["hess"][i, j] * qi * qj
            ac = ac + s["weight"] * part
        irr = free.get("sun.irradiance", like.scene.sun.irradiance)
        level = irr * like.layout.rest
        y = ca.MX.sym("y", like.t.size)
        mask = ca.MX.sym("mask", like.t.size)
        # as ResponseLikelihood: residuals about the data's mean level, the AC part added last
        r = (y - like.ref_level) - ((level - like.ref_level) + irr * ac)
        sigma = free.get("noise.sigma", like.scene.noise.sigma)
        var = sigma * sigma
        if like.scene.noise.photons_per_unit > 0:
            var = var + ca.fmax(level + irr * ac, 0.0) / like.scene.noise.photons_per_unit
        ll = -0.5 * ca.sum1(mask * (r * r / var + ca.log(2 * math.pi * var)))
        return ca.Function("neg_log_post", [z, y, mask], [-(log_prior + ll)])

    def data(self, series=None) -> ca.DM:
        """(y with gaps zeroed, mask) of `series` (default: the problem's) as one parameter vector."""
        y = (series or self.like.series).intensity
        return ca.vertcat(ca.DM(np.where(np.isfinite(y), y, self.like.ref_level)), ca.DM(np.isfinite(y).astype(float)))

    def __call__(self, z) -> float:
        n = self.like.t.size
        d = self.data()
        return float(self.function(z, d[:n], d[n:]))
