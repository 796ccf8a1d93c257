"""An imager: the scene's footprint as a field of view of nx x ny pixels, rendered to a cube.

Each pixel is its own footprint, sampled as a single-pixel scene is: `subpixels` (default: the
scene's `footprint.resolution`) subpixel centres per pixel side, at the very coordinates
`Footprint.subpixels` gives for that pixel's rectangle. So pixel (iy, ix) of the cube is the
signal `forward.sensor.observe` computes for the scene whose footprint is that pixel
(`pixel_scene`) with the same seed, within `rtol` - the same subpixel density instead (resolution
over the whole field of view) would leave a 64-pixel-wide image with a quarter of a subpixel per
pixel in the example scenes.

A pixel's signal is eq. (22), x_p(t) = (1/N) sum_n B_n w_n, times the irradiance; grouped by surface,
x_p(t) = irradiance * sum_k c_pk X_pk(t), with c_pk the fraction of the pixel's subpixels on
surface k (its coverage: exact counts of subpixel centres, so equal to the area fraction of an
axis-aligned rectangle whose edges fall on the subpixel lattice) and X_pk the mean facet signal
(eq. (23) for Fresnel lobes, eq. (5) for Lambertian, `forward.radiance.facet_signal`) over them.
Each surface is evaluated by the cheapest accurate model, as the scene compiler
(`forward.reduce`) does for one pixel, but for all pixels at once (pixels x time as matrix products):

- static (no motion): c_pk times the facet value at rest, exact;
- rigid (a modal motion whose slope shapes are one normal everywhere, e.g. the frame roof):
  X_k(t) is the facet signal of that one normal and the same in every pixel, so the cube is the
  product coverage (P x S) by X (S x T), exact;
- elastic (shapes that vary over the surface): per pixel the second-order Taylor model
  X0 + J_p q + q'H_p q / 2 from the facet derivatives at rest and the pixel's footprint moments of
  the slope shapes, accepted where a bound on the omitted terms is below rtol times that pixel's
  peak-to-peak; else a Chebyshev interpolant in the modal coordinates (1 or 2 coordinates),
  refined until the coarser grid predicts the finer one within rtol; else every subpixel at every
  sample (dense).

Motions are realized once (`Scene.realize_motions`) and shared by all pixels; the sensor noise
(`forward.sensor.add_noise`: shot, read, ADC) is drawn per pixel from independent streams of the
seed, with one ADC full scale for the whole sensor.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from math import comb, factorial

import numpy as np
from numpy.polynomial import chebyshev as cheb
from numpy.typing import NDArray

from forward.errors import SceneError
from forward.geometry import normals_from_slopes
from forward.motion.base import ModalMotion, Motion
from forward.radiance import facet_signal
from forward.reduce import DEFAULT_RTOL, surface_derivatives
from forward.scene import Footprint, MemoryEstimate, Noise, Scene, Surface, memory_estimate
from forward.sensor import add_noise
from forward.validation import seed as check_seed

MAX_PIXELS_PER_SIDE = 4096
BLOCK_POINTS = 1 << 20  # subpixels evaluated together (a few float64 arrays of this size at a time)
SHAPE_CACHE = 1 << 23  # float64 slope-shape values kept between the Taylor and Chebyshev passes (64 MB)
_CHUNK = 1 << 21  # facets per vectorized call
_FLOAT64_FLOOR = 100 * np.finfo(float).eps  # what float64 resolves of a value, relative to it
_CHEB_DEGREES = {1: (4, 8, 16, 32, 64, 128), 2: (4, 8, 16, 32)}  # refinement levels per coordinate count
_CUBE_COPIES = 3  # float64 values per pixel-sample: clean, noisy and one temporary


@dataclass(frozen=True)
class PixelGrid:
    """The imager's field of view (the scene's footprint rectangle) divided into nx x ny pixels,
    each sampled by `subpixels` x `subpixels` subpixel centres. Pixel (iy, ix) covers
    [x_edges[ix], x_edges[ix + 1]] x [y_edges[iy], y_edges[iy + 1]] (m); y grows with the row."""

    x_edges: NDArray[np.float64]
    y_edges: NDArray[np.float64]
    subpixels: int

    @property
    def nx(self) -> int:
        return self.x_edges.size - 1

    @property
    def ny(self) -> int:
        return self.y_edges.size - 1

    @property
    def x(self) -> NDArray[np.float64]:
        """Pixel centres along x (m), shape (nx,)."""
        return 0.5 * (self.x_edges[:-1] + self.x_edges[1:])

    @property
    def y(self) -> NDArray[np.float64]:
        """Pixel centres along y (m), shape (ny,)."""
        return 0.5 * (self.y_edges[:-1] + self.y_edges[1:])

    def footprint(self, iy: int, ix: int) -> Footprint:
        """The footprint of pixel (iy, ix): the scene a single-pixel render of it would use."""
        return Footprint(
            (float(self.x_edges[ix]), float(self.x_edges[ix + 1])),
            (float(self.y_edges[iy]), float(self.y_edges[iy + 1])),
            self.subpixels,
        )

    def subpixel_axes(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Subpixel centre coordinates per pixel column (nx, r) and per pixel row (ny, r), computed
        exactly as `Footprint.subpixels` computes them for one pixel (bit for bit)."""
        r = self.subpixels
        k = np.arange(r) + 0.5
        xs = self.x_edges[:-1, None] + k * np.diff(self.x_edges)[:, None] / r
        ys = self.y_edges[:-1, None] + k * np.diff(self.y_edges)[:, None] / r
        return xs, ys


def pixel_grid(scene: Scene, nx: int, ny: int, subpixels: int | None = None) -> PixelGrid:
    """The scene's footprint divided into nx x ny pixels (SceneError for a count outside
    [1, MAX_PIXELS_PER_SIDE]); `subpixels` per pixel side, default `scene.footprint.resolution`."""
    nx = _count(nx, "nx", MAX_PIXELS_PER_SIDE)
    ny = _count(ny, "ny", MAX_PIXELS_PER_SIDE)
    r = _count(scene.footprint.resolution if subpixels is None else subpixels, "subpixels", 4096)
    (x0, x1), (y0, y1) = scene.footprint.x, scene.footprint.y
    xe = x0 + np.arange(nx + 1) * ((x1 - x0) / nx)
    ye = y0 + np.arange(ny + 1) * ((y1 - y0) / ny)
    xe[-1], ye[-1] = x1, y1
    return PixelGrid(xe, ye, r)


def pixel_scene(scene: Scene, grid: PixelGrid, iy: int, ix: int) -> Scene:
    """The single-pixel scene whose footprint is pixel (iy, ix) of `grid`: what `observe` renders
    for that pixel alone (the reference of the cube)."""
    return dataclasses.replace(scene, footprint=grid.footprint(iy, ix))


@dataclass(frozen=True)
class CubeObservation:
    """A rendered image cube: intensity[t, iy, ix] is the pixel at (x[ix], y[iy]) at time[t]."""

    time: NDArray[np.float64]  # (T,) s, the scene's sampling times
    fs: float  # Hz, the scene's sampling rate (the imager's frame rate)
    intensity: NDArray[np.float64]  # (T, ny, nx), with sensor noise
    intensity_clean: NDArray[np.float64]  # (T, ny, nx), noise-free
    x: NDArray[np.float64]  # (nx,) pixel centres, m
    y: NDArray[np.float64]  # (ny,) pixel centres, m
    grid: PixelGrid
    coverage: dict[str, NDArray[np.float64]]  # surface name (and "background") -> (ny, nx) fraction
    sensitivity: NDArray[np.float64]  # (ny, nx), eq. (21) of each clean pixel; NaN for a dark pixel
    error_bound: NDArray[np.float64]  # (ny, nx), estimated max |clean - exact| (signal units)
    evaluation: dict[str, dict[str, int]] = field(default_factory=dict)  # surface -> {model: pixels}
    rtol: float | None = DEFAULT_RTOL

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.intensity.shape

    def explain(self) -> str:
        """One line per surface: how its pixels were evaluated."""
        t, ny, nx = self.shape
        lines = [
            f"cube of {ny} x {nx} pixels ({self.grid.subpixels}^2 subpixels each), {t} samples, "
            f"rtol = {self.rtol if self.rtol is not None else 'dense'} (relative to each pixel's peak-to-peak):"
        ]
        for name, kinds in self.evaluation.items():
            cov = self.coverage[name]
            lines.append(
                f"  {name:<12} {', '.join(f'{k} {n} px' for k, n in kinds.items())}; "
                f"seen by {np.count_nonzero(cov)} px, mean coverage {cov.mean():6.1%}"
            )
        return "\n".join(lines)


def cube_memory(scene: Scene, grid: PixelGrid) -> MemoryEstimate:
    """What `render_cube` needs: the motions' realization (as one pixel), the cube itself
    (clean, noisy and a temporary per pixel-sample) and one block of subpixels."""
    n_t, n_p = scene.sampling.n_samples, grid.nx * grid.ny
    sampling = ("sampling.duration", "sampling.fs")
    block = min(BLOCK_POINTS, n_p * grid.subpixels**2)
    one = memory_estimate(dataclasses.replace(scene, footprint=grid.footprint(0, 0)))
    return MemoryEstimate(
        (
            *one.terms,
            (n_t * n_p * _CUBE_COPIES, f"{n_t} samples x {n_p} pixels x {_CUBE_COPIES} float64", (*sampling, "nx, ny")),
            (block * 24, f"{block} subpixels x 24 float64 (one block)", ("footprint.resolution",)),
        )
    )


def render_cube(
    scene: Scene,
    nx: int,
    ny: int,
    seed: int | None = None,
    rtol: float | None = DEFAULT_RTOL,
    *,
    subpixels: int | None = None,
) -> CubeObservation:
    """Render the scene's footprint as an nx x ny-pixel image cube on the scene's sampling times.

    Pixel (iy, ix) equals `observe(pixel_scene(scene, grid, iy, ix), seed)`'s clean series within
    `rtol` of its peak-to-peak (rtol=None: elastic surfaces at every subpixel and sample). Motions
    come from `SeedSequence(seed).spawn(2)[0]` as in `observe`; the noise of pixel (iy, ix) from
    stream iy * nx + ix of `SeedSequence(seed).spawn(2)[1].spawn(nx * ny)`. An ADC full scale of 0
    ([noise] adc_full_scale) means twice the clean cube's maximum, one range for the whole sensor.

    SceneError (one line, naming the value) for a bad nx, ny, seed or rtol, a cube whose memory
    estimate is above `forward.scene.memory_limit()` (checked before allocating), and a clean cube
    that is not finite."""
    seed = check_seed(seed)
    if rtol is not None and not (isinstance(rtol, (int, float)) and 0 < rtol < np.inf):
        raise SceneError(f"rtol: {rtol!r} is outside the allowed range (0, inf)")
    grid = pixel_grid(scene, nx, ny, subpixels)
    cube_memory(scene, grid).check()
    t = scene.sampling.times()
    motion_seed, sensor_seed = np.random.SeedSequence(seed).spawn(2)
    motions = scene.realize_motions(t, motion_seed)
    n_p = grid.nx * grid.ny
    layers = (*scene.surfaces, scene.background)
    counts = _coverage_counts(scene, grid)  # (S + 1, P): subpixels of each pixel on each surface
    weights = counts / grid.subpixels**2
    irr = scene.sun.irradiance
    clean = np.zeros((t.size, n_p))
    bound = np.zeros(n_p)
    evaluation: dict[str, dict[str, int]] = {}
    with np.errstate(over="ignore", invalid="ignore"):
        for k, surface in enumerate(layers):
            seen = np.flatnonzero(counts[k])
            if seen.size == 0:
                continue
            facet = _facet(surface, scene)
            motion = motions[k] if k < len(scene.surfaces) else None
            if motion is None:  # static: the facet at rest, exact
                clean += weights[k] * float(facet(0.0, 0.0))
                evaluation[surface.name] = {"static": seen.size}
                continue
            part = _Surface(k, surface, motion, facet, t, weights[k], counts[k], seen)
            kinds = part.render(scene, grid, clean, bound, rtol)
            evaluation[surface.name] = kinds
        clean *= irr
    if not np.all(np.isfinite(clean)):
        p = int(np.flatnonzero(~np.all(np.isfinite(clean), axis=0))[0])
        raise SceneError(
            f"scene: the clean cube is not finite at pixel (iy, ix) = {divmod(p, grid.nx)}; "
            "reduce sun.irradiance or the motions' amplitudes"
        )
    noisy = _add_noise(clean, scene.noise, sensor_seed)
    shape = (t.size, grid.ny, grid.nx)
    names = [s.name for s in layers]
    return CubeObservation(
        time=t,
        fs=scene.sampling.fs,
        intensity=noisy.reshape(shape),
        intensity_clean=clean.reshape(shape),
        x=grid.x,
        y=grid.y,
        grid=grid,
        coverage={n: weights[k].reshape(grid.ny, grid.nx) for k, n in enumerate(names)},
        sensitivity=_sensitivity(clean).reshape(grid.ny, grid.nx),
        error_bound=(irr * bound).reshape(grid.ny, grid.nx),
        evaluation=evaluation,
        rtol=rtol,
    )


# ----------------------------------------------------------------------------- helpers


def _count(value: object, key: str, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise SceneError(f"{key}: must be an integer in the allowed range [1, {hi}], got {value!r}")
    if not 1 <= int(value) <= hi:
        raise SceneError(f"{key}: {int(value)} is outside the allowed range [1, {hi}]")
    return int(value)


def _facet(surface: Surface, scene: Scene) -> Callable:
    """F(g): B times the radiometric weight of a facet with slopes g = (h_x, h_y), eq. (23)
    (Fresnel lobe) or eq. (5) (Lambertian), via `forward.radiance.facet_signal`."""
    sun = scene.sun.direction

    def facet(gx, gy):
        return facet_signal(normals_from_slopes(gx, gy), surface, sun, scene.sensor)

    return facet


def _pixel_blocks(pixels: NDArray[np.int64], per_pixel: NDArray[np.int64]) -> Iterator[slice]:
    """Consecutive runs of `pixels` whose subpixels (per_pixel of them each) stay within BLOCK_POINTS."""
    total = np.cumsum(per_pixel)
    a = 0
    while a < pixels.size:
        base = total[a - 1] if a else 0
        b = max(a + 1, int(np.searchsorted(total, base + BLOCK_POINTS, side="right")))
        yield slice(a, b)
        a = b


def _block_points(
    grid: PixelGrid, axes: tuple[NDArray, NDArray], pixels: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Subpixel centres of `pixels` (flat indices iy * nx + ix), shape (len(pixels), r^2) each, in
    the order of `Footprint.subpixels` (x-major)."""
    xs, ys = axes
    r = grid.subpixels
    iy, ix = np.divmod(pixels, grid.nx)
    return np.repeat(xs[ix], r, axis=1), np.tile(ys[iy], (1, r))


def _coverage_counts(scene: Scene, grid: PixelGrid) -> NDArray[np.float64]:
    """(S + 1, P): how many of each pixel's subpixel centres each surface owns (`Scene.owners`;
    the last row is the background)."""
    n_p = grid.nx * grid.ny
    axes = grid.subpixel_axes()
    pixels = np.arange(n_p)
    out = np.zeros((len(scene.surfaces) + 1, n_p))
    for block in _pixel_blocks(pixels, np.full(n_p, grid.subpixels**2)):
        x, y = _block_points(grid, axes, pixels[block])
        owner = scene.owners(x, y)
        for k in range(len(scene.surfaces)):
            out[k, block] = np.count_nonzero(owner == k, axis=1)
        out[-1, block] = np.count_nonzero(owner == -1, axis=1)
    return out


def _add_noise(clean: NDArray[np.float64], noise: Noise, sensor_seed: np.random.SeedSequence) -> NDArray[np.float64]:
    """Each pixel's column through `add_noise` with its own stream; one ADC full scale."""
    if noise.sigma == 0.0 and noise.photons_per_unit == 0.0 and noise.adc_bits == 0:
        return clean.copy()
    if noise.adc_bits > 0 and noise.adc_full_scale <= 0.0:
        noise = dataclasses.replace(noise, adc_full_scale=2.0 * float(np.max(clean)))
    out = np.empty_like(clean)
    for p, stream in enumerate(sensor_seed.spawn(clean.shape[1])):
        out[:, p] = add_noise(clean[:, p], noise, np.random.default_rng(stream))
    return out


def _sensitivity(clean: NDArray[np.float64]) -> NDArray[np.float64]:
    """S = (max x - min x) / max x per pixel, eq. (21); NaN where the maximum is not positive."""
    top, low = clean.max(axis=0), clean.min(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(top > 0, (top - low) / np.where(top > 0, top, 1.0), np.nan)


def _order_term(d: dict[tuple[int, int], float], order: int, gx: NDArray, gy: NDArray) -> NDArray:
    """(1/order!) sum_a C(order, a) d_(a, order-a) gx^a gy^(order-a): the facet function's Taylor
    term of that order at slopes (gx, gy)."""
    px, py = [np.ones_like(gx)], [np.ones_like(gy)]
    for _ in range(order):
        px.append(px[-1] * gx)
        py.append(py[-1] * gy)
    return sum(comb(order, a) * d[(a, order - a)] * px[a] * py[order - a] for a in range(order + 1)) / factorial(order)


def _segments(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Start of each row's run in mask[mask] (row-major) and the run lengths (every row non-empty)."""
    n = mask.sum(axis=1)
    return np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64), n.astype(float)


class _Surface:
    """One moving surface over the pixels that see it: rigid, Taylor, Chebyshev or dense."""

    def __init__(self, k, surface, motion: Motion, facet, t, weight, count, seen):
        self.k, self.surface, self.motion, self.facet, self.t = k, surface, motion, facet, t
        self.weight, self.count, self.seen = weight, count, seen
        self.value0 = float(facet(0.0, 0.0))
        self.cache: dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None

    def blocks(self, scene: Scene, grid: PixelGrid, pixels: NDArray[np.int64]):
        """(slice into pixels, subpixel x, y on this surface (pixel-major), run starts, run lengths)."""
        axes = grid.subpixel_axes()
        for block in _pixel_blocks(pixels, self.count[pixels].astype(np.int64)):
            x, y = _block_points(grid, axes, pixels[block])
            mask = scene.owners(x, y) == self.k
            starts, n = _segments(mask)
            yield block, x[mask], y[mask], starts, n

    def render(self, scene, grid, clean, bound, rtol) -> dict[str, int]:
        if not isinstance(self.motion, ModalMotion):
            self.dense(scene, grid, self.seen, clean)
            return {"dense": self.seen.size}
        q = self.motion.coefficients(self.t)  # (T, K), the modal coordinates shared by all pixels
        shapes = self.moments(scene, grid, q, rtol is not None)
        if shapes is not None:  # rigid: one normal, X_k(t) the same for every pixel, exact
            gx, gy = q @ shapes[:, 0], q @ shapes[:, 1]
            x_t = self.facet(gx, gy)
            clean[:, self.seen] += np.outer(x_t, self.weight[self.seen])
            return {"rigid": self.seen.size}
        kinds = {"taylor2": 0, "chebyshev": 0, "dense": 0}
        todo = self.seen
        if rtol is not None:
            todo = self.taylor(q, clean, bound, rtol)
            kinds["taylor2"] = self.seen.size - todo.size
            if todo.size and q.shape[1] in _CHEB_DEGREES:
                left = self.chebyshev(scene, grid, q, todo, clean, bound, rtol)
                kinds["chebyshev"] = todo.size - left.size
                todo = left
        if todo.size:
            self.dense(scene, grid, todo, clean)
        kinds["dense"] = todo.size
        return {k: n for k, n in kinds.items() if n}

    # -- the footprint moments of the slope shapes (one pass over the subpixels)

    def moments(self, scene, grid, q, taylor: bool) -> NDArray[np.float64] | None:
        """Per pixel, the moments of the modal slope shapes S_n (K x 2 per subpixel) over the
        pixel's subpixels on this surface, and the Taylor error bound's terms. Returns the one shape
        (K, 2) when it is the same at every subpixel (a rigid surface), else None."""
        kk = q.shape[1]
        n_p = self.seen.size
        self.m1 = np.zeros((2, n_p, kk))  # sum of sx, sy
        self.m2 = np.zeros((3, n_p, kk, kk))  # sum of sx sx', sy sy', sx sy'
        self.cubic = np.zeros(n_p)
        self.quartic = np.zeros(n_p)
        self.d = surface_derivatives(self.surface, scene) if taylor else None
        qmax = np.abs(q).max(axis=0)
        first, rigid = None, True
        self.cache = {} if self.count[self.seen].sum() * kk * 2 <= SHAPE_CACHE else None
        for block, x, y, starts, n in self.blocks(scene, grid, self.seen):
            s = self.motion.shapes(x, y)  # (K, 2, m)
            if first is None:
                first = s[:, :, :1].copy()
            if rigid and np.all(s == first):
                continue
            if self.cache is not None:  # the Chebyshev pass reuses them
                sx, sy = s[:, 0].T, s[:, 1].T
                for p, a, m in zip(self.seen[block], starts, n.astype(np.int64)):
                    self.cache[int(p)] = (sx[a : a + m], sy[a : a + m])
            if rigid:  # the blocks before this one were uniform: their moments are those of `first`
                rigid = False
                if block.start:
                    self.uniform_moments(first[:, :, 0], slice(0, block.start), qmax)
            self.accumulate(block, s[:, 0].T, s[:, 1].T, starts, n, qmax)
        return first[:, :, 0] if rigid else None

    def uniform_moments(self, shape, block, qmax) -> None:
        n = self.count[self.seen[block]]
        sx, sy = np.tile(shape[:, 0], (n.size, 1)), np.tile(shape[:, 1], (n.size, 1))
        starts = np.arange(n.size)
        # one representative subpixel per pixel, weighted by the pixel's count
        self.accumulate(block, sx, sy, starts, np.ones(n.size), qmax, scale=n)

    def accumulate(self, block, sx, sy, starts, n, qmax, scale=None) -> None:
        """Add the subpixels' moments (sx, sy: (m, K)) to pixels `block` (runs `starts`, `n`)."""
        w = 1.0 if scale is None else scale[:, None]
        seg = lambda a: np.add.reduceat(a, starts, axis=0)
        self.m1[0, block] += w * seg(sx)
        self.m1[1, block] += w * seg(sy)
        w2 = w if scale is None else scale[:, None, None]
        self.m2[0, block] += w2 * seg(sx[:, :, None] * sx[:, None, :])
        self.m2[1, block] += w2 * seg(sy[:, :, None] * sy[:, None, :])
        self.m2[2, block] += w2 * seg(sx[:, :, None] * sy[:, None, :])
        if self.d is None:
            return
        d, kk = self.d, qmax.size
        dabs = {key: abs(v) for key, v in d.items()}
        ax, ay = np.abs(sx) @ qmax, np.abs(sy) @ qmax
        if kk <= 3:  # the footprint mean of the cubic term at the extreme modal coordinates
            corners = np.array(np.meshgrid(*([[-1.0, 0.0, 1.0]] * kk), indexing="ij")).reshape(kk, -1).T * qmax
            term = _order_term(d, 3, corners @ sx.T, corners @ sy.T)  # (C, m)
            sums = np.add.reduceat(term, starts, axis=1) * (1.0 if scale is None else scale)  # (C, b)
            self.cubic[block] = np.abs(sums).max(axis=0)  # a sum: `taylor` divides by the pixel's count
        else:  # a per-subpixel bound (times the count, as the sum above)
            cub = np.maximum.reduceat(_order_term(dabs, 3, ax, ay), starts)
            self.cubic[block] = cub * self.count[self.seen[block]]
        self.quartic[block] = np.maximum.reduceat(_order_term(dabs, 4, ax, ay), starts)

    # -- Taylor, 2nd order, per pixel

    def taylor(self, q, clean, bound, rtol) -> NDArray[np.int64]:
        """X_p = X0 + J_p q + q'H_p q/2 with J_p, H_p from the pixel's moments; adds the accepted
        pixels to `clean` and returns the pixels left over."""
        d, n = self.d, self.count[self.seen]
        fx, fy, fxx, fxy, fyy = d[(1, 0)], d[(0, 1)], d[(2, 0)], d[(1, 1)], d[(0, 2)]
        jac = (fx * self.m1[0] + fy * self.m1[1]) / n[:, None]  # (P, K)
        cross = self.m2[2] + np.swapaxes(self.m2[2], 1, 2)
        hess = (fxx * self.m2[0] + fyy * self.m2[1] + fxy * cross) / n[:, None, None]  # (P, K, K)
        kk = q.shape[1]
        iu, ju = np.triu_indices(kk)
        features = np.concatenate([q, q[:, iu] * q[:, ju]], axis=1)  # (T, K + K(K+1)/2)
        coef = np.concatenate([jac, np.where(iu == ju, 0.5, 1.0) * hess[:, iu, ju]], axis=1)  # (P, F)
        ac = features @ coef.T  # (T, P): the AC part formed directly (keeps its digits)
        error = self.cubic / n + self.quartic
        ok = error <= np.maximum(rtol * np.ptp(ac, axis=0), _FLOAT64_FLOOR * abs(self.value0))
        w = self.weight[self.seen[ok]]
        clean[:, self.seen[ok]] += w * (self.value0 + ac[:, ok])
        bound[self.seen[ok]] += w * error[ok]
        return self.seen[~ok]

    # -- Chebyshev in the modal coordinates, per pixel

    def chebyshev(self, scene, grid, q, pixels, clean, bound, rtol) -> NDArray[np.int64]:
        """X_p(q) interpolated at Chebyshev points over the box q(t) visits, degree doubled until the
        coarser interpolant predicts the finer one's node values within rtol x their peak-to-peak.
        Adds the accepted pixels to `clean`; returns the pixels left over (for the dense path)."""
        kk = q.shape[1]
        lo, hi = q.min(axis=0), q.max(axis=0)
        span = np.where(hi > lo, hi - lo, 1.0)
        mid = (hi + lo) / 2
        u_t = (q - mid) * (2.0 / span)  # the series in [-1, 1]^K
        floor = _FLOAT64_FLOOR * abs(self.value0)
        left = []
        done: dict[int, list[tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]]] = {}
        for block, x, y, starts, n in self.blocks(scene, grid, pixels):
            pix = pixels[block]
            if self.cache is not None and all(int(p) in self.cache for p in pix):
                sx = np.concatenate([self.cache[int(p)][0] for p in pix])
                sy = np.concatenate([self.cache[int(p)][1] for p in pix])
            else:
                shapes = self.motion.shapes(x, y)
                sx, sy = shapes[:, 0].T, shapes[:, 1].T  # (m, K)
            active = np.ones(pix.size, bool)
            prev = None
            for deg in _CHEB_DEGREES[kk]:
                u = np.cos(np.pi * (np.arange(deg + 1) + 0.5) / (deg + 1))  # first-kind nodes
                nodes = np.stack([g.ravel() for g in np.meshgrid(*([u] * kk), indexing="ij")], axis=1)
                values = self.node_means(mid + nodes * span / 2, sx, sy, starts, n)  # (nodes, b)
                values = values.reshape((deg + 1,) * kk + (pix.size,))
                coef = _cheb_coefficients(values, u)
                if prev is not None:
                    err = np.abs(_cheb_at_nodes(prev, u) - values).reshape(-1, pix.size).max(axis=0)
                    ptp = np.ptp(values.reshape(-1, pix.size), axis=0)
                    ok = active & (err <= np.maximum(rtol * ptp, floor))
                    for i in np.flatnonzero(ok):
                        done.setdefault(deg, []).append((pix[i], coef[..., i], err[i]))
                    active &= ~ok
                    if not active.any():
                        break
                prev = coef
            left.extend(pix[active])
        for deg, items in done.items():
            pix = np.array([p for p, _, _ in items])
            coef = np.stack([c.reshape(-1) for _, c, _ in items], axis=1)  # ((deg+1)^K, b)
            vander = cheb.chebvander(u_t[:, 0], deg) if kk == 1 else cheb.chebvander2d(*u_t.T, [deg, deg])
            w = self.weight[pix]
            clean[:, pix] += w * (vander @ coef)
            bound[pix] += w * np.array([e for _, _, e in items])
        return np.array(left, dtype=np.int64)

    def node_means(self, nodes, sx, sy, starts, n) -> NDArray[np.float64]:
        """mean_n F(S_n q) over each pixel's subpixels, for each row q of `nodes` (M, K): (M, b)."""
        out = np.empty((nodes.shape[0], starts.size))
        step = max(1, _CHUNK // sx.shape[0])
        for a in range(0, nodes.shape[0], step):
            qq = nodes[a : a + step]
            out[a : a + step] = np.add.reduceat(self.facet(qq @ sx.T, qq @ sy.T), starts, axis=1) / n
        return out

    # -- every subpixel at every sample

    def dense(self, scene, grid, pixels, clean) -> None:
        """X_p(t) = mean over the pixel's subpixels of F(slopes(t)), eq. (22) restricted to the surface."""
        for block, x, y, starts, n in self.blocks(scene, grid, pixels):
            pix = pixels[block]
            step = max(1, _CHUNK // x.size)
            for a in range(0, self.t.size, step):
                gx, gy = self.motion.slopes(x, y, self.t[a : a + step])
                means = np.add.reduceat(self.facet(gx, gy), starts, axis=1) / n
                clean[a : a + step, pix] += self.weight[pix] * means


def _cheb_coefficients(values: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Chebyshev coefficients c[i, (j,) p] of the interpolant through `values` at nodes u (per axis)."""
    inv = np.linalg.inv(cheb.chebvander(u, u.size - 1))
    if values.ndim == 2:
        return inv @ values
    return np.einsum("ai,ijp,bj->abp", inv, values, inv)


def _cheb_at_nodes(coef: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The interpolant with coefficients `coef` evaluated at nodes u (per axis)."""
    v = cheb.chebvander(u, coef.shape[0] - 1)
    if coef.ndim == 2:
        return v @ coef
    return np.einsum("ai,ijp,bj->abp", v, coef, v)
