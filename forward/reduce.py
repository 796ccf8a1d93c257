"""Evaluate only what a scene needs: a scene compiler with a measured error per surface.

Every subpixel of a flat surface shares one facet function F(g) of its slope g = (h_x, h_y)
(radiance times radiometric weight, eq. (23)). A motion that is fixed shapes times time
coefficients gives g_n(t) = S_n q(t), so a surface's mean contribution is X(q) = mean_n F(S_n q), a
smooth function of the few modal coordinates q. The compiler builds, per surface, the cheapest
evaluation of X that meets `rtol` (relative to that surface's peak-to-peak signal):

- ``static``: no motion; a constant, exact.
- ``taylor2``: X0 + J q + q^T H q / 2, from the gradient and Hessian of F at the flat facet and
  footprint moments of the shapes. Accepted when a bound on the omitted cubic term is below
  rtol * peak-to-peak. It computes the AC part directly, so it stays accurate where the AC
  signal is below float64 resolution of the mean (a centered footprint at 1e-9 m amplitude).
- ``chebyshev``: X interpolated on nested Chebyshev-Lobatto grids (1 or 2 coordinates) over the
  range q(t) visits, refined until the coarser grid predicts the finer one within rtol *
  peak-to-peak (the reported error). Handles large amplitudes where the lobe saturates.
- ``dense``: every subpixel at every sample (the reference), when nothing cheaper is accurate.

A rigid surface (every subpixel with the same shape: one normal) is evaluated at one point: N -> 1. Taylor and
Chebyshev models use only + and *, so `SurfaceModel.evaluate` works on numpy arrays and on casadi
symbols alike.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from forward.geometry import normals_from_slopes
from forward.materials import Fresnel
from forward.motion.base import ModalMotion
from forward.radiance import facet_signal
from forward.scene import Scene, Surface

DEFAULT_RTOL = 1e-5
_MAX_LEVEL = {1: 7, 2: 5}  # Chebyshev-Lobatto levels: 2^L + 1 points per coordinate
_CHUNK = 1 << 21
_FLOAT64_FLOOR = 100 * np.finfo(float).eps


@dataclass
class SurfaceModel:
    """How one surface's mean contribution X(q) is evaluated, and how well."""

    name: str
    kind: str  # static | taylor2 | chebyshev | dense
    weight: float  # fraction of footprint subpixels on this surface
    coords: NDArray[np.float64] | None  # modal coordinates q(t), shape (T, K)
    error: float = 0.0  # estimated max |error| of X (same units as X)
    ptp: float = 0.0  # peak-to-peak of X over the series
    value0: float = 0.0  # X at rest
    detail: str = ""
    _eval: Callable[..., Any] | None = field(default=None, repr=False)
    _ac: Callable[..., Any] | None = field(default=None, repr=False)

    @property
    def n_coords(self) -> int:
        return 0 if self.coords is None else self.coords.shape[1]

    def evaluate(self, *q: Any) -> Any:
        """X as a function of the modal coordinates (numpy arrays or casadi expressions)."""
        if self.kind == "static":
            return self.value0
        if self.kind == "dense":
            raise TypeError(f"surface {self.name}: the dense path has no closed form in modal coordinates")
        return self._eval(*q)

    def ac(self, *q: Any) -> Any:
        """X(q) - X(0). The Taylor model forms it directly, without subtracting the mean."""
        return self._ac(*q) if self._ac is not None else self.evaluate(*q) - self.value0

    def series(self) -> NDArray[np.float64]:
        if self.kind == "static":
            return np.array(self.value0)
        if self.kind == "dense":
            return self._eval()
        return self._eval(*self.coords.T)


@dataclass
class CompiledScene:
    """A scene reduced for fast evaluation on the times `t`."""

    t: NDArray[np.float64]
    irradiance: float
    surfaces: list[SurfaceModel]
    rtol: float

    def signal(self) -> NDArray[np.float64]:
        """x(t), as `forward.render.pixel_signal` but through the reduced models."""
        total = np.zeros(self.t.shape)
        for s in self.surfaces:
            total = total + s.weight * s.series()
        return self.irradiance * total

    def parts(self) -> tuple[float, NDArray[np.float64]]:
        """(x at rest, x(t) - x at rest): the AC part formed without subtracting the mean where the
        model allows (Taylor), so that it keeps its digits when it is ~1e-15 of the mean."""
        dc = sum(s.weight * s.value0 for s in self.surfaces)
        ac = np.zeros(self.t.shape)
        for s in self.moving():
            ac = ac + s.weight * (s.ac(*s.coords.T) if s.kind != "dense" else s.series() - s.value0)
        return self.irradiance * dc, self.irradiance * ac

    def observation(self, q: list[tuple[Any, ...]]) -> Any:
        """x as a function of every moving surface's modal coordinates, in the order of
        `moving()`: numpy arrays or casadi symbols."""
        total = sum(s.weight * s.value0 for s in self.surfaces if s.kind == "static")
        for s, qs in zip(self.moving(), q):
            total = total + s.weight * s.evaluate(*qs)
        return self.irradiance * total

    def moving(self) -> list[SurfaceModel]:
        return [s for s in self.surfaces if s.kind != "static"]

    def error_bound(self) -> float:
        """Bound on max |x_fast - x_exact| from the per-surface estimates."""
        return self.irradiance * sum(s.weight * s.error for s in self.surfaces)

    def explain(self) -> str:
        lines = [f"scene compiled for rtol = {self.rtol:g} (relative to each surface's peak-to-peak):"]
        for s in self.surfaces:
            rel = s.error / s.ptp if s.ptp > 0 else 0.0
            lines.append(
                f"  {s.name:<12} {s.kind:<10} coverage {s.weight:6.1%}  K={s.n_coords}  "
                f"est. error {rel:.1e} of p-p  {s.detail}"
            )
        return "\n".join(lines)


def compile_scene(
    scene: Scene,
    t: NDArray[np.float64] | None = None,
    rtol: float = DEFAULT_RTOL,
    seed: int | np.random.SeedSequence | None = None,
    force: str | None = None,
    shape_cache: dict | None = None,
) -> CompiledScene:
    """Reduce `scene` on times `t` (default: its sampling) to the cheapest models meeting `rtol`.

    `force` = "dense" | "taylor2" | "chebyshev" overrides the choice (for tests and benchmarks).
    `shape_cache`, a dict kept by the caller, reuses motion shapes across scenes that differ only
    in what the shapes do not depend on (a sweep over view angles, sun or sampling).
    """
    t = scene.sampling.times() if t is None else np.asarray(t, dtype=float)
    x, y = scene.footprint.subpixels()
    owner = scene.owners(x, y)
    motions = scene.realize_motions(t, seed)
    sun = scene.sun.direction
    models = []
    for k, surface in enumerate((*scene.surfaces, scene.background)):
        idx = np.flatnonzero(owner == (k if k < len(scene.surfaces) else -1))
        if idx.size == 0:
            continue
        weight = idx.size / x.size
        facet = _facet_function(surface, sun, scene)
        motion = motions[k] if k < len(scene.surfaces) else None
        if motion is None:
            models.append(SurfaceModel(surface.name, "static", weight, None, value0=float(facet(0.0, 0.0))))
            continue
        models.append(
            _compile_surface(
                surface.name,
                weight,
                motion,
                x[idx],
                y[idx],
                t,
                facet,
                rtol,
                surface_derivatives(surface, scene, shape_cache),
                force,
                shape_cache,
            )
        )
    return CompiledScene(t, scene.sun.irradiance, models, rtol)


def surface_derivatives(surface: Surface, scene: Scene, cache: dict | None = None) -> dict[tuple[int, int], float]:
    """The facet function's derivatives at rest (`facet_derivatives`) for `surface` in `scene`,
    kept in `cache` by optics, sun and sensor."""
    scale = _scale(surface, scene)
    facet = _facet_function(surface, scene.sun.direction, scene)
    return _cached(
        cache,
        ("facet", surface.material, surface.lobe_width, scene.sun, scene.sensor, scale),
        lambda: facet_derivatives(facet, scale),
    )


def _facet_function(surface: Surface, sun: NDArray[np.float64], scene: Scene) -> Callable:
    def facet(gx, gy):
        return facet_signal(normals_from_slopes(gx, gy), surface, sun, scene.sensor)

    return facet


def _scale(surface: Surface, scene: Scene) -> float:
    """Slope scale on which the facet function varies: lobe width, sun or view elevation."""
    s = min(np.sin(scene.sun.inclination), np.sin(scene.sensor.inclination), 0.5)
    if isinstance(surface.material, Fresnel):
        s = min(s, surface.lobe_width)
    return float(s)


def _cached(cache: dict | None, key: tuple | None, compute: Callable[[], Any]) -> Any:
    if cache is None or key is None:
        return compute()
    if key not in cache:
        cache[key] = compute()
    return cache[key]


def _shapes(motion: ModalMotion, x, y, cache: dict | None) -> NDArray[np.float64]:
    key = motion.shape_key()
    key = None if key is None else (key, x.size, hash(x.tobytes()), hash(y.tobytes()))
    return _cached(cache, key, lambda: motion.shapes(x, y))


def _compile_surface(name, weight, motion, x, y, t, facet, rtol, derivs, force, shape_cache=None) -> SurfaceModel:
    if not isinstance(motion, ModalMotion):
        return _dense_model(name, weight, motion, x, y, t, facet, "motion is not modal")
    sx, sy, w = modal_points(motion, x, y, shape_cache)
    coords = motion.coefficients(t)  # (T, K)
    k = sx.shape[1]
    mean_value = lambda q: _mean_facet(facet, sx, sy, w, q)  # q: (P, K) -> (P,)
    value0 = float(facet(0.0, 0.0))
    # what float64 can resolve of X at all: a model within this is as good as the dense reference
    floor = _FLOAT64_FLOOR * abs(value0)
    meets = lambda m: m.error <= max(rtol * m.ptp, floor)
    detail = f"rigid: one facet stands for all {x.size} subpixels" if sx.shape[0] == 1 else f"{x.size} subpixels"
    if force in (None, "taylor2"):
        model = _taylor2(name, weight, coords, sx, sy, w, derivs, value0)
        if force == "taylor2" or meets(model):
            model.detail = detail
            return model
    if force in (None, "chebyshev") and k <= 2:
        model = _chebyshev(name, weight, coords, mean_value, rtol, value0, floor)
        if force == "chebyshev" or meets(model):
            model.detail = f"{model.detail}; {detail}"
            return model
    return _dense_model(
        name, weight, motion, x, y, t, facet, "no reduced model met rtol" if force is None else "forced"
    )


def modal_points(
    motion: ModalMotion, x: NDArray[np.float64], y: NDArray[np.float64], cache: dict | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(sx, sy, w): slopes per unit modal coordinate at the distinct subpixels, shape (m, K) each,
    and their weights (m,). A rigid surface (one normal everywhere) collapses to m = 1."""
    shapes = _shapes(motion, x, y, cache)  # (K, 2, n)
    k = shapes.shape[0]
    flat = shapes.reshape(2 * k, -1).T
    if np.all(flat == flat[0]):
        uniq, counts = flat[:1], np.array([flat.shape[0]])
    else:
        uniq, counts = flat, np.ones(flat.shape[0])
    return uniq[:, 0::2], uniq[:, 1::2], counts / counts.sum()


def taylor_coefficients(
    d: dict[tuple[int, int], float], sx: NDArray[np.float64], sy: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(J, H) of X(q) = X0 + J q + q^T H q / 2 from the facet derivatives `d` at rest and the
    footprint moments of the modal slopes."""
    fx, fy = d[(1, 0)], d[(0, 1)]
    fxx, fxy, fyy = d[(2, 0)], d[(1, 1)], d[(0, 2)]
    jac = fx * (w @ sx) + fy * (w @ sy)  # (K,)
    wx, wy = w[:, None] * sx, w[:, None] * sy
    hess = fxx * sx.T @ wx + fyy * sy.T @ wy + fxy * (sx.T @ wy + sy.T @ wx)
    return jac, hess


def taylor_ac(jac: NDArray[np.float64], hess: NDArray[np.float64], q: Any) -> Any:
    """J q + q^T H q / 2 for modal coordinates q (a sequence of K arrays or casadi expressions)."""
    out = 0.0
    k = jac.size
    for i in range(k):
        out = out + jac[i] * q[i]
        for j in range(k):
            if hess[i, j] != 0.0:
                out = out + 0.5 * hess[i, j] * q[i] * q[j]
    return out


@dataclass
class FootprintLayout:
    """What the footprint sees at rest: x at rest without the irradiance (sum of coverage x facet
    value), and every moving surface's (index, subpixel x, y, coverage, facet derivatives)."""

    rest: float
    moving: list[tuple[int, NDArray[np.float64], NDArray[np.float64], float, dict[tuple[int, int], float]]]


def footprint_layout(scene: Scene, cache: dict | None = None) -> FootprintLayout:
    """The parts of the reduced model that depend on geometry and optics only, not on the motions:
    with them held, `taylor_surface_ac` re-forms a surface's signal for new motion parameters."""
    x, y = scene.footprint.subpixels()
    owner = scene.owners(x, y)
    rest, moving = 0.0, []
    for k, surface in enumerate((*scene.surfaces, scene.background)):
        idx = np.flatnonzero(owner == (k if k < len(scene.surfaces) else -1))
        if idx.size == 0:
            continue
        weight = idx.size / x.size
        rest += weight * float(_facet_function(surface, scene.sun.direction, scene)(0.0, 0.0))
        if k < len(scene.surfaces) and surface.motion is not None:
            moving.append((k, x[idx], y[idx], weight, surface_derivatives(surface, scene, cache)))
    return FootprintLayout(rest, moving)


def taylor_surface_ac(
    motion: ModalMotion,
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    derivs: dict[tuple[int, int], float],
    t: NDArray[np.float64],
    cache: dict | None = None,
) -> NDArray[np.float64]:
    """J q(t) + q(t)^T H q(t) / 2 of one modal surface on its subpixels (x, y): the Taylor model's
    AC part (without coverage and irradiance), from the facet derivatives at rest and the motion's
    shapes (kept in `cache`) and coordinates."""
    sx, sy, w = modal_points(motion, x, y, cache)
    jac, hess = taylor_coefficients(derivs, sx, sy, w)
    return taylor_ac(jac, hess, motion.coefficients(t).T)


def chebyshev_surface(
    surface: Surface,
    scene: Scene,
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    box: NDArray[np.float64],
    rtol: float = DEFAULT_RTOL,
    cache: dict | None = None,
) -> SurfaceModel:
    """X(q) of one modal surface on its subpixels (x, y), interpolated on Chebyshev-Lobatto grids
    over the modal-coordinate box [-box, box] (1 or 2 coordinates): built once, it evaluates any
    coordinates inside the box (`SurfaceModel.evaluate`), e.g. for new amplitudes and phases of
    the same shapes. Its `error` is the nested grids' disagreement, as in `compile_scene`."""
    facet = _facet_function(surface, scene.sun.direction, scene)
    sx, sy, w = modal_points(surface.motion, x, y, cache)
    value0 = float(facet(0.0, 0.0))
    corners = np.array([-np.asarray(box, dtype=float), np.asarray(box, dtype=float)])
    return _chebyshev(
        surface.name,
        1.0,
        corners,
        lambda q: _mean_facet(facet, sx, sy, w, q),
        rtol,
        value0,
        _FLOAT64_FLOOR * abs(value0),
    )


def _mean_facet(facet, sx, sy, w, q):
    """mean_n F(S_n q) for each row of q (P, K), chunked."""
    q = np.atleast_2d(q)
    out = np.empty(q.shape[0])
    step = max(1, _CHUNK // sx.shape[0])
    for a in range(0, q.shape[0], step):
        qq = q[a : a + step]
        out[a : a + step] = facet(qq @ sx.T, qq @ sy.T) @ w
    return out


def _dense_model(name, weight, motion, x, y, t, facet, why) -> SurfaceModel:
    def series():
        out = np.empty(t.size)
        step = max(1, _CHUNK // x.size)
        for a in range(0, t.size, step):
            gx, gy = motion.slopes(x, y, t[a : a + step])
            out[a : a + step] = facet(gx, gy).mean(axis=1)
        return out

    values = series()
    return SurfaceModel(
        name,
        "dense",
        weight,
        None,
        0.0,
        float(np.ptp(values)),
        float(facet(0.0, 0.0)),
        f"every subpixel, every sample ({why})",
        lambda: values,
    )


# ----------------------------------------------------------------------------- Taylor, 2nd order


def facet_derivatives(facet: Callable, scale: float) -> dict[tuple[int, int], float]:
    """Partial derivatives d^(a+b) F / dgx^a dgy^b at g = 0 up to order 4.

    From a least-squares fit of a total-degree-6 polynomial on an 11 x 11 Chebyshev grid of
    half-width 0.05 * scale: far better conditioned than finite differences with tiny steps.
    """
    from math import factorial

    h = 0.05 * scale
    nodes = h * np.cos(np.pi * (np.arange(11) + 0.5) / 11)
    gx, gy = np.meshgrid(nodes, nodes, indexing="ij")
    f = facet(gx.ravel(), gy.ravel())
    powers = [(a, d - a) for d in range(7) for a in range(d + 1)]
    basis = np.stack([(gx.ravel() / h) ** a * (gy.ravel() / h) ** b for a, b in powers], axis=1)
    coef = np.linalg.lstsq(basis, f, rcond=None)[0]
    return {(a, b): c * factorial(a) * factorial(b) / h ** (a + b) for (a, b), c in zip(powers, coef) if a + b <= 4}


def _order_term(d, order, gx, gy):
    """(1/order!) sum_a C(order, a) F_{a, order-a} gx^a gy^(order-a): the Taylor term of that order."""
    from math import comb, factorial

    px, py = [np.ones_like(gx)], [np.ones_like(gy)]
    for _ in range(order):  # powers by products: float ** is several times slower
        px.append(px[-1] * gx)
        py.append(py[-1] * gy)
    return sum(comb(order, a) * d[(a, order - a)] * px[a] * py[order - a] for a in range(order + 1)) / factorial(order)


def _taylor2(name, weight, coords, sx, sy, w, d, value0) -> SurfaceModel:
    jac, hess = taylor_coefficients(d, sx, sy, w)
    error = _taylor2_error(d, coords, sx, sy, w)
    ac = lambda *q: taylor_ac(jac, hess, q)

    series = ac(*coords.T)
    return SurfaceModel(
        name,
        "taylor2",
        weight,
        coords,
        error,
        float(np.ptp(series)),
        value0,
        "X0 + J q + q'Hq/2",
        lambda *q: value0 + ac(*q),
        ac,
    )


def _taylor2_error(d, coords, sx, sy, w) -> float:
    """Estimate of the omitted terms: the footprint mean of the cubic term at the extreme modal
    coordinates (it cancels on symmetric footprints, and so must the estimate), plus a
    per-subpixel bound on the quartic term."""
    qmax = np.abs(coords).max(axis=0)
    k = qmax.size
    if k <= 3:
        corners = np.array(np.meshgrid(*([[-1.0, 0.0, 1.0]] * k), indexing="ij")).reshape(k, -1).T * qmax
        cubic = float(np.abs(_order_term(d, 3, corners @ sx.T, corners @ sy.T) @ w).max())
    else:
        cubic = float(
            np.max(_order_term({key: abs(v) for key, v in d.items()}, 3, np.abs(sx) @ qmax, np.abs(sy) @ qmax))
        )
    quartic = float(np.max(_order_term({key: abs(v) for key, v in d.items()}, 4, np.abs(sx) @ qmax, np.abs(sy) @ qmax)))
    return cubic + quartic


# ----------------------------------------------------------------------------- Chebyshev


def _lobatto(level: int) -> NDArray[np.float64]:
    n = 2**level
    return np.cos(np.pi * np.arange(n + 1) / n)  # from +1 to -1


def _cheb_coefficients(values: NDArray[np.float64], axis: int) -> NDArray[np.float64]:
    """Chebyshev coefficients from values at Lobatto points cos(pi j / n) along `axis` (DCT-I)."""
    v = np.moveaxis(values, axis, 0)
    n = v.shape[0] - 1
    j = np.arange(n + 1)
    c = np.cos(np.pi * np.outer(j, j) / n)
    wts = np.ones(n + 1)
    wts[[0, -1]] = 0.5
    coef = (2.0 / n) * c @ (wts[:, None] * v.reshape(n + 1, -1))
    coef[[0, -1]] *= 0.5
    return np.moveaxis(coef.reshape(v.shape), 0, axis)


def _clenshaw(coef: Any, u: Any) -> Any:
    """sum_j coef[j] T_j(u) with + and * only (numpy arrays or casadi expressions)."""
    b1, b2 = 0.0, 0.0
    for c in coef[:0:-1]:
        b1, b2 = 2.0 * u * b1 - b2 + c, b1
    return u * b1 - b2 + coef[0]


def _chebyshev(name, weight, coords, mean_value, rtol, value0, floor) -> SurfaceModel:
    k = coords.shape[1]
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    mid = (hi + lo) / 2
    to_q = lambda u: mid + u * span / 2  # u in [-1, 1]^K
    cache: dict[tuple, float] = {}

    def grid_values(level):
        pts = _lobatto(level)
        grids = np.meshgrid(*([pts] * k), indexing="ij")
        u = np.stack([g.ravel() for g in grids], axis=1)
        keys = [tuple(np.round(r, 15)) for r in u]
        todo = [i for i, key in enumerate(keys) if key not in cache]
        if todo:
            vals = mean_value(to_q(u[todo]))
            for i, v in zip(todo, vals):
                cache[keys[i]] = v
        return np.array([cache[key] for key in keys]).reshape([pts.size] * k)

    def coefficients(values):
        c = values
        for ax in range(k):
            c = _cheb_coefficients(c, ax)
        return c

    def evaluator(coef):
        def ev(*q):
            u = [(q[i] - mid[i]) * (2.0 / span[i]) for i in range(k)]
            if k == 1:
                return _clenshaw(list(coef), u[0])
            return _clenshaw([_clenshaw(list(row), u[1]) for row in coef], u[0])

        return ev

    level, prev, error = 2, None, np.inf
    while True:
        values = grid_values(level)
        coef = coefficients(values)
        if prev is not None:
            pts = _lobatto(level)
            grids = np.meshgrid(*([pts] * k), indexing="ij")
            predicted = evaluator(prev)(*[mid[i] + g * span[i] / 2 for i, g in enumerate(grids)])
            error = float(np.abs(predicted - values).max())
        ptp = float(np.ptp(values))
        if (prev is not None and error <= max(rtol * ptp, floor)) or level >= _MAX_LEVEL[k]:
            break
        prev, level = coef, level + 1
    ev = evaluator(coef)
    series = ev(*coords.T)
    n = 2**level + 1
    return SurfaceModel(
        name,
        "chebyshev",
        weight,
        coords,
        error,
        float(np.ptp(series)),
        value0,
        f"{n}{'x' + str(n) if k == 2 else ''} Lobatto nodes",
        ev,
    )


def rigid_observation(scene: Scene, surface_name: str) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """x = x0 + J g + g^T H g / 2 for a rigid surface with slopes g = (h_x, h_y): the pixel's
    second-order observation model of that surface's tilt (the other surfaces held at rest).

    Independent of the motion's amplitude: it is the facet function's Taylor expansion at rest,
    weighted by the surface's share of the footprint, plus every other surface at rest.
    """
    x, y = scene.footprint.subpixels()
    owner = scene.owners(x, y)
    sun = scene.sun.direction
    names = [s.name for s in scene.surfaces]
    if surface_name not in names:
        raise ValueError(f"no surface named {surface_name!r}; surfaces: {', '.join(names)}")
    x0, jac, hess = 0.0, np.zeros(2), np.zeros((2, 2))
    for k, surface in enumerate((*scene.surfaces, scene.background)):
        weight = np.count_nonzero(owner == (k if k < len(scene.surfaces) else -1)) / x.size
        if weight == 0.0:
            continue
        facet = _facet_function(surface, sun, scene)
        if surface.name == surface_name and k < len(scene.surfaces):
            d = facet_derivatives(facet, _scale(surface, scene))
            jac = weight * np.array([d[(1, 0)], d[(0, 1)]])
            hess = weight * np.array([[d[(2, 0)], d[(1, 1)]], [d[(1, 1)], d[(0, 2)]]])
        x0 += weight * float(facet(0.0, 0.0))
    irr = scene.sun.irradiance
    return irr * x0, irr * jac, irr * hess
