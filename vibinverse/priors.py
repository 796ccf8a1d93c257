"""Named parameters: fixed or free with a prior, in an analyst's units.

A parameter is a dotted scene key (``surfaces.roof.motion.tilt_frequency``) or ``noise.sigma``.
Priors: uniform(a, b), loguniform(a, b), normal(mu, sd), truncnormal(mu, sd, a, b). The sampler
works on an unconstrained transform: logit for bounded priors, identity otherwise.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from forward.validation import expression
from vibinverse.errors import SceneError, scene_errors

_PRIOR = re.compile(r"^\s*(uniform|loguniform|normal|truncnormal)\s*\((.*)\)\s*$")
_NARGS = {"uniform": 2, "loguniform": 2, "normal": 2, "truncnormal": 4}


@dataclass(frozen=True)
class Prior:
    kind: str
    args: tuple[float, ...]

    @property
    def bounds(self) -> tuple[float, float]:
        if self.kind in ("uniform", "loguniform"):
            return self.args
        if self.kind == "truncnormal":
            return self.args[2], self.args[3]
        return -math.inf, math.inf

    def log_pdf(self, v: float) -> float:
        lo, hi = self.bounds
        if not lo <= v <= hi:
            return -math.inf
        if self.kind == "uniform":
            return -math.log(hi - lo)
        if self.kind == "loguniform":
            return -math.log(v) - math.log(math.log(hi / lo))
        mu, sd = self.args[:2]
        return -0.5 * ((v - mu) / sd) ** 2 - math.log(sd * math.sqrt(2 * math.pi))

    def to_unbounded(self, v: float) -> float:
        lo, hi = self.bounds
        if math.isfinite(lo) and math.isfinite(hi):
            if self.kind == "loguniform":
                u = (math.log(v) - math.log(lo)) / (math.log(hi) - math.log(lo))
            else:
                u = (v - lo) / (hi - lo)
            u = min(max(u, 1e-12), 1 - 1e-12)
            return math.log(u / (1 - u))
        return v

    def from_unbounded(self, z: float) -> float:
        lo, hi = self.bounds
        if math.isfinite(lo) and math.isfinite(hi):
            u = 0.5 * (1.0 + math.tanh(0.5 * z))  # logistic, overflow-free
            if self.kind == "loguniform":
                return math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
            return lo + u * (hi - lo)
        return z

    def log_jacobian(self, z: float) -> float:
        """log |d value / d z| of from_unbounded at z (for sampling in z)."""
        lo, hi = self.bounds
        if math.isfinite(lo) and math.isfinite(hi):
            log_u = -math.log1p(math.exp(-z)) if z > -700 else z
            log_1mu = -math.log1p(math.exp(z)) if z < 700 else -z
            if self.kind == "loguniform":
                return log_u + log_1mu + math.log(math.log(hi / lo)) + math.log(self.from_unbounded(z))
            return log_u + log_1mu + math.log(hi - lo)
        return 0.0

    def centre(self) -> float:
        """A central value: the geometric mean of a log-uniform range, the midpoint of a bounded one,
        else the mean of the normal."""
        lo, hi = self.bounds
        if self.kind == "loguniform":
            return float(math.sqrt(lo * hi))
        if math.isfinite(lo) and math.isfinite(hi):
            return 0.5 * (lo + hi)
        return float(self.args[0])

    def inside(self, v: float) -> float:
        """v moved just inside the prior's support (a start for an optimizer); the centre when v is not finite."""
        lo, hi = self.bounds
        span = hi - lo if math.isfinite(hi - lo) else 1.0
        return float(np.clip(v, lo + 1e-6 * span, hi - 1e-6 * span)) if np.isfinite(v) else self.centre()

    def __str__(self) -> str:
        return f"{self.kind}({', '.join(f'{a:g}' for a in self.args)})"


def parse_prior(text: str, key: str) -> Prior:
    """'uniform(1, 5)', 'loguniform(1e-4, 1e-2)', 'normal(10, 0.1)', 'truncnormal(3, 1, 0, 10)'."""
    m = _PRIOR.match(text)
    if not m:
        raise SceneError(
            f"{key}: prior {text!r} is not one of uniform(a,b), loguniform(a,b), normal(mu,sd), truncnormal(mu,sd,a,b)"
        )
    kind = m.group(1)
    with scene_errors():
        args = tuple(expression(a, key) for a in m.group(2).split(",")) if m.group(2).strip() else ()
    if len(args) != _NARGS[kind]:
        raise SceneError(f"{key}: {kind} takes {_NARGS[kind]} arguments, got {len(args)}")
    if kind in ("uniform", "loguniform", "truncnormal") and not args[-2] < args[-1]:
        raise SceneError(f"{key}: {kind} bounds must satisfy a < b, got {args[-2]:g}, {args[-1]:g}")
    if kind == "loguniform" and args[0] <= 0:
        raise SceneError(f"{key}: loguniform needs 0 < a < b, got a = {args[0]:g}")
    if kind in ("normal", "truncnormal") and not args[1] > 0:
        raise SceneError(f"{key}: {kind} needs sd > 0, got {args[1]:g}")
    return Prior(kind, args)


def parse_free(items: list[str], infer: dict | None) -> dict[str, Prior]:
    """Free parameters from the scene's [infer] table ({"free": {name: prior}}) overridden by
    --free NAME=PRIOR items."""
    free: dict[str, Prior] = {}
    table = (infer or {}).get("free", {})
    if not isinstance(table, dict):
        raise SceneError('infer.free: must be a table of name = "prior(...)"')
    for name, text in table.items():
        free[name] = parse_prior(str(text), f"infer.free.{name}")
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise SceneError(f"--free: expected NAME=PRIOR(args), got {item!r}")
        free[name.strip()] = parse_prior(text, f"--free {name.strip()}")
    return free


class ParameterSpace:
    """The free parameters in a fixed order, with transforms and the log prior."""

    def __init__(self, free: dict[str, Prior]):
        self.names = list(free)
        self.priors = [free[n] for n in self.names]

    def __len__(self) -> int:
        return len(self.names)

    def to_z(self, values: dict[str, float]) -> np.ndarray:
        return np.array([p.to_unbounded(values[n]) for n, p in zip(self.names, self.priors)])

    def from_z(self, z: np.ndarray) -> dict[str, float]:
        return {n: p.from_unbounded(float(v)) for n, p, v in zip(self.names, self.priors, z)}

    def gradient_z(self, z: np.ndarray, slope: dict[str, float]) -> np.ndarray:
        """d / dz of a function whose slope in each value is `slope` (0 for a name it lacks): the
        slope times d value / dz."""
        out = np.zeros(len(self.names))
        for i, (name, prior) in enumerate(zip(self.names, self.priors)):
            if name in slope:
                out[i] = slope[name] * math.exp(prior.log_jacobian(float(z[i])))
        return out

    def log_prior_gradient_z(self, z: np.ndarray) -> np.ndarray:
        """d / dz of `log_prior_z`: each coordinate's own term by a central difference (a few
        scalar evaluations; no likelihood)."""
        out = np.zeros(len(self.names))
        for i, (p, v) in enumerate(zip(self.priors, z)):
            v = float(v)
            h = 1e-6 * max(1.0, abs(v))
            up, down = v + h, v - h
            term_up = p.log_pdf(p.from_unbounded(up)) + p.log_jacobian(up)
            term_down = p.log_pdf(p.from_unbounded(down)) + p.log_jacobian(down)
            out[i] = (term_up - term_down) / (2.0 * h)
        return np.where(np.isfinite(out), out, 0.0)

    def log_prior_z(self, z: np.ndarray) -> float:
        """log prior density of the values plus the log Jacobian of the transform."""
        total = 0.0
        for p, v in zip(self.priors, z):
            total += p.log_pdf(p.from_unbounded(float(v))) + p.log_jacobian(float(v))
        return total


def casadi_value(p: Prior, z):
    """`Prior.from_unbounded` as a casadi expression of z."""
    import casadi as ca

    lo, hi = p.bounds
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return z
    u = 1.0 / (1.0 + ca.exp(-z))
    if p.kind == "loguniform":
        return ca.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
    return lo + u * (hi - lo)


def casadi_log_prior(p: Prior, z, v):
    """log prior density of v plus log |dv/dz| as a casadi expression (`Prior.log_pdf` +
    `Prior.log_jacobian`)."""
    import casadi as ca

    lo, hi = p.bounds
    bounded = math.isfinite(lo) and math.isfinite(hi)
    logistic = (-ca.log1p(ca.exp(-z)) - ca.log1p(ca.exp(z))) if bounded else 0.0
    if p.kind in ("uniform", "loguniform"):
        return logistic  # the density and the Jacobian's range factor cancel
    mu, sd = p.args[:2]
    dens = -0.5 * ((v - mu) / sd) ** 2 - math.log(sd * math.sqrt(2 * math.pi))
    return dens + (logistic + math.log(hi - lo) if bounded else 0.0)
