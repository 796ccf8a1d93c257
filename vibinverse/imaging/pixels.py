"""Which pixels, and what each one sees: the selection of pixels for a multi-pixel fit (all, a mask
image, a cluster of a detection map), the selected pixels as a (time, pixel) matrix read block by
block, and what the joint fit (`vibinverse.imaging.joint_fit`) needs of each: its noise level,
its gain (frequency-domain decomposition, or the optical-flow gradient).

- Selection (`select_pixels`): "all"; a mask file, `.npy` (a boolean or 0/1 array of the frame's
  shape) or `.png` (nonzero where selected, colour channels maxed, alpha ignored); `PATH.nc:K`,
  the pixels of a detection map (`vibinverse detect`) whose variable `cluster` (y, x) equals K
  (0 is "no cluster"); in Python also a boolean array or a list of (y, x) pairs.
- Access (`PixelMatrix`): the cube is read in slabs of whole rows, at most `block_bytes` of
  float64 each, and the selected pixels picked from them, so that a dask-backed cube is never read
  whole; when the selection fits in `memory_bytes` (default: MEMORY_BYTES, at most a quarter of
  VIBINVERSE_MEMORY_LIMIT) it is read once and kept. A larger selection is read again by every
  pass (6-12 of them), one band of rows at a time: cheap for netCDF, zarr and .npy, whose readers
  fetch only the band, costly for a compressed video, which decodes whole frames (extract a cube
  of the region first, `vibinverse extract`). A frame in which any
  selected pixel is missing (NaN) is a gap of every pass.
- Noise levels (`noise_levels`): each pixel's white-noise variance is the floor of its
  periodogram (the median over the upper half of the band / ln 2: the mean of an exponential
  variable is its median / ln 2).
- Gains (`choose_band`, `seed_gains`, `band_gains`): frequency-domain decomposition. The band is
  the one around the strongest excess of the whitened trace spectrum sum_i |Y_i(f)|^2 / sigma_i^2
  (the total SNR of all pixels per frequency), searched at several widths so that a resonance
  too weak to show in one bin is found by its width; the gains are sigma_i u_i, u the leading left
  singular vector of the whitened band coefficients [Re B, Im B] / sigma (the leading eigenvector
  of the real part of the whitened cross-spectral matrix summed over the band: rank one for one
  shared signal seen with real gains, u_i ~ g_i / sigma_i).
- Optical flow (`gradient_gains`): where edges move across pixels, I(x, t) = I0(x - u(t)), so to
  first order y_i = I0_i - u(t) dI0/dx_i: the gain of a displacement u along x is -dI0/dx of the
  mean frame (fourth-order central differences inside, second-order at the border).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.errors import DataError, InputError
from vibinverse.imaging.line_checks import VIBRATION
from vibinverse.imaging.whitening import LARGEST_VALUE

logger = logging.getLogger(__name__)

BLOCK_BYTES = 64 * 2**20  # a slab of rows read at once (float64)
MEMORY_BYTES = 512 * 2**20  # a selection up to this size (float64; and 1/4 of the memory limit) is read once, kept
MASK_SUFFIXES = (".npy", ".png")
BAND_WIDTHS = (1, 3, 9, 27, 81)  # the scales (periodogram bins) at which the seed band is looked for
MAX_BAND_BINS = 256  # the seed band's width, at most

PixelsLike = str | Path | np.ndarray | Sequence[tuple[int, int]]


# ------------------------------------------------------------------ the cube


def frame_axes(cube: Any) -> Any:
    """The cube as (time, y, x), a one-line InputError when it has not these three dimensions."""
    dims = getattr(cube, "dims", None)
    if dims is None or set(dims) != {"time", "y", "x"}:
        raise InputError(f"cube: an xarray.DataArray with dimensions (time, y, x) is needed, got {dims}")
    return cube.transpose("time", "y", "x")


def cube_time(cube: Any) -> np.ndarray:
    """The cube's time stamps in seconds (float64); datetime64 stamps as seconds since the first."""
    if "time" not in cube.coords:
        raise InputError("cube: no time coordinate (seconds); open it with vibinverse.io.cube.open_cube")
    t = np.asarray(cube["time"].values)
    if np.issubdtype(t.dtype, np.datetime64):
        t = (t - t[0]) / np.timedelta64(1, "s")
    return np.asarray(t, dtype=np.float64)


# ------------------------------------------------------------------ selection


def select_pixels(cube: Any, pixels: PixelsLike) -> np.ndarray:
    """The selected pixels as a boolean (y, x) mask of the cube's frame (module docstring for the
    forms); one-line InputError for a mask of the wrong shape, an empty selection, an unknown
    cluster or file."""
    cube = frame_axes(cube)
    shape = (cube.sizes["y"], cube.sizes["x"])
    if isinstance(pixels, str) and pixels == "all":
        mask = np.ones(shape, dtype=bool)
        what = "all"
    elif isinstance(pixels, (str, Path)):
        mask, what = read_selection(pixels, cube)
    else:
        arr = np.asarray(pixels)
        if arr.dtype == bool:
            mask = _check_shape(arr, shape, "the mask array")
        else:
            mask = _from_pairs(arr, shape)
        what = "the given pixels"
    if not mask.any():
        raise InputError(f"pixels: the selection is empty (no pixel of {what} is set)")
    return mask


def _from_pairs(arr: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if arr.ndim != 2 or arr.shape[1] != 2 or not np.issubdtype(arr.dtype, np.integer):
        raise InputError("pixels: give 'all', a mask file, PATH.nc:K, a boolean (y, x) array or (y, x) pairs")
    bad = (arr[:, 0] < 0) | (arr[:, 0] >= shape[0]) | (arr[:, 1] < 0) | (arr[:, 1] >= shape[1])
    if bad.any():
        y, x = arr[np.argmax(bad)]
        raise InputError(f"pixels: ({y}, {x}) is outside the frame; allowed y in [0, {shape[0]}), x in [0, {shape[1]})")
    mask = np.zeros(shape, dtype=bool)
    mask[arr[:, 0], arr[:, 1]] = True
    return mask


def _check_shape(mask: np.ndarray, shape: tuple[int, int], what: str) -> np.ndarray:
    if mask.shape != shape:
        dims = " x ".join(map(str, mask.shape))
        raise InputError(f"pixels: {what} is {dims}; the cube's frame is {shape[0]} x {shape[1]} (y x x)")
    return mask.astype(bool)


def parse_cluster(text: str) -> tuple[Path, int] | None:
    """(detection map path, cluster K) of `PATH.nc:K`, else None."""
    head, sep, tail = text.rpartition(":")
    if not sep or not head.lower().endswith(".nc"):
        return None
    try:
        return Path(head), int(tail)
    except ValueError:
        raise InputError(f"pixels: {text!r}: the cluster after ':' must be an integer, e.g. detection.nc:1") from None


def read_selection(path: str | Path, cube: Any) -> tuple[np.ndarray, str]:
    """(mask, what it is) of a mask file or a `PATH.nc:K` cluster of a detection map."""
    shape = (cube.sizes["y"], cube.sizes["x"])
    cluster = parse_cluster(str(path))
    if cluster is not None:
        return cluster_mask(cluster[0], cluster[1], cube), f"cluster {cluster[1]} of {cluster[0].name}"
    p = Path(path)
    if p.suffix.lower() == ".nc":
        raise InputError(f"pixels: {p}: name the cluster of the detection map, e.g. {p}:1")
    return read_mask(p, shape), p.name


def read_mask(path: str | Path, shape: tuple[int, int]) -> np.ndarray:
    """A boolean mask of `shape` from `.npy` (nonzero = selected) or `.png` (nonzero in any colour
    channel = selected; alpha ignored)."""
    from vibinverse.io.series import check_file

    p = Path(path)
    if p.suffix.lower() not in MASK_SUFFIXES:
        raise InputError(
            f"pixels: {p.name}: unknown mask format; give 'all', a {' or '.join(MASK_SUFFIXES)} mask, or PATH.nc:K"
        )
    check_file(p, "pixels")
    try:
        if p.suffix.lower() == ".npy":
            arr = np.load(p, allow_pickle=False)
        else:
            import imageio.v3 as iio

            arr = np.asarray(iio.imread(p))
            if arr.ndim == 3:
                arr = arr[..., : 3 if arr.shape[-1] >= 3 else 1].max(axis=-1)
    except (OSError, ValueError) as exc:
        raise DataError(f"pixels: cannot read the mask {p}: {str(exc).splitlines()[0] if str(exc) else exc}") from None
    if arr.ndim != 2 or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise InputError(f"pixels: the mask {p.name} must be a 2-D boolean or numeric image, got shape {arr.shape}")
    return _check_shape(arr != 0, shape, f"the mask {p.name}")


def cluster_mask(path: str | Path, cluster: int, cube: Any) -> np.ndarray:
    """The pixels of a detection map (`PATH.nc`, variable `cluster` (y, x): 0 none, k >= 1 the
    cluster id) equal to `cluster`; its frame must be the cube's (shape, and y/x coordinates when
    both have them)."""
    import xarray as xr

    from vibinverse.io.series import check_file

    p = check_file(path, "pixels")
    try:
        with xr.open_dataset(p) as ds:
            if "cluster" not in ds:
                raise InputError(f"pixels: {p.name} has no variable 'cluster' (y, x); is it a detection map?")
            var = ds["cluster"].load()
    except (OSError, ValueError) as exc:
        raise DataError(f"pixels: cannot read the detection map {p}: {str(exc).splitlines()[0]}") from None
    if set(var.dims) != {"y", "x"}:
        raise InputError(f"pixels: {p.name}: variable 'cluster' has dimensions {var.dims}, not (y, x)")
    var = var.transpose("y", "x")
    shape = (cube.sizes["y"], cube.sizes["x"])
    _check_shape(np.asarray(var.values), shape, f"the detection map {p.name}")
    for dim in ("y", "x"):
        if dim in var.coords and dim in cube.coords:
            a, b = np.asarray(var[dim].values), np.asarray(cube[dim].values)
            if a.shape == b.shape and not np.array_equal(a, b):
                raise InputError(f"pixels: {p.name} covers other {dim} coordinates than the cube (another crop?)")
    values = np.asarray(var.values)
    mask = values == cluster
    if cluster < 1 or not mask.any():
        ids = sorted(int(v) for v in np.unique(values[np.isfinite(values)]) if v >= 1)
        have = ", ".join(map(str, ids)) if ids else "none"
        raise InputError(f"pixels: {p.name} has no cluster {cluster}; its clusters: {have}")
    return mask


# ------------------------------------------------------------------ access


class PixelMatrix:
    """The selected pixels of a cube as a (time, pixel) float64 matrix, read in blocks of whole
    rows (module docstring); pixels in row-major order (`y`, `x`)."""

    def __init__(self, cube: Any, mask: np.ndarray, *, block_bytes: int = BLOCK_BYTES, memory_bytes: int | None = None):
        self.cube = frame_axes(cube)
        self.mask = np.asarray(mask, dtype=bool)
        self.y, self.x = (a.astype(np.int64) for a in np.nonzero(self.mask))
        self.time = cube_time(self.cube)
        self.n = int(self.y.size)
        self.n_frames = int(self.time.size)
        row_bytes = 8 * self.n_frames * self.cube.sizes["x"]
        self._rows_per_block = max(1, int(block_bytes // max(row_bytes, 1)))
        self._kept: np.ndarray | None = None
        if memory_bytes is None:
            from forward.scene import memory_limit

            memory_bytes = min(MEMORY_BYTES, memory_limit() // 4)
        if 8 * self.n_frames * self.n <= memory_bytes:
            self._kept = np.concatenate([b for _, b in self._read()], axis=1) if self.n else np.empty((0, 0))

    @property
    def units(self) -> str | None:
        """The cube's intensity units (attribute `units`), or None."""
        u = self.cube.attrs.get("units")
        return None if u is None else str(u)

    def row_offset(self) -> np.ndarray | None:
        """Each selected pixel's time offset in s (the cube's `row_offset` coordinate: rolling
        shutter), or None."""
        if "row_offset" not in self.cube.coords:
            return None
        return np.asarray(self.cube["row_offset"].values, dtype=float)[self.y]

    def blocks(self) -> Iterator[tuple[slice, np.ndarray]]:
        """(pixel slice, float64 (time, pixels) block) over the selection."""
        if self._kept is not None:
            step = max(1, BLOCK_BYTES // max(8 * self.n_frames, 1))
            for a in range(0, self.n, step):
                sl = slice(a, min(a + step, self.n))
                yield sl, self._kept[:, sl]
            return
        yield from self._read()

    def _read(self) -> Iterator[tuple[slice, np.ndarray]]:
        rows = np.unique(self.y)
        start = 0
        for a in range(0, rows.size, self._rows_per_block):
            band = rows[a : a + self._rows_per_block]
            sel = (self.y >= band[0]) & (self.y <= band[-1])
            count = int(sel.sum())
            ys, xs = self.y[sel], self.x[sel]
            x0, x1 = int(xs.min()), int(xs.max()) + 1
            slab = self.cube.isel(y=slice(int(band[0]), int(band[-1]) + 1), x=slice(x0, x1)).values
            block = np.asarray(slab[:, ys - band[0], xs - x0], dtype=np.float64)
            yield slice(start, start + count), block
            start += count


# ------------------------------------------------------------------ seeds


@dataclass(frozen=True)
class NoiseLevels:
    """What one pass over the pixels gives: the frames in which every pixel is observed (`valid`),
    each pixel's `mean` and noise level `sigma` (the periodogram's floor), the whitened trace
    spectrum sum_i |Y_i(f)|^2 / sigma_i^2 (`trace`, ~N where there is only noise) at `freqs`, and
    the `span` of those frames (s)."""

    valid: np.ndarray
    mean: np.ndarray
    sigma: np.ndarray
    freqs: np.ndarray
    trace: np.ndarray
    span: float


@dataclass(frozen=True)
class GainSeed:
    """The seed band (Hz) and its Fourier coefficients (pixel, frequency) of the de-meaned pixels,
    from which `band_gains` estimates the gains."""

    band: tuple[float, float]
    coef: np.ndarray


def _uniform(t: np.ndarray) -> bool:
    from vibinverse.io.file_basics import UNIFORM_RTOL

    step = (t[-1] - t[0]) / (t.size - 1)
    return bool(np.max(np.abs(t - (t[0] + np.arange(t.size) * step))) <= UNIFORM_RTOL * step)


def periodograms(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies, power (pixel, frequency)) of the de-meaned columns of y (time, pixel) on
    (0, Nyquist]: |sum y e^{-i w t}|^2 / T, an rfft on a uniform grid, nifty-ls's batched
    Lomb-Scargle in its "psd" normalization (the same on a uniform grid) on irregular stamps."""
    y = y - y.mean(axis=0)
    if _uniform(t):
        power = np.abs(np.fft.rfft(y, axis=0)) ** 2 / t.size
        return np.fft.rfftfreq(t.size, (t[-1] - t[0]) / (t.size - 1))[1:], power[1:].T
    import nifty_ls

    df = 1.0 / (t[-1] - t[0])
    nf = max(int(0.5 / float(np.median(np.diff(t))) / df), 2)
    res = nifty_ls.lombscargle(
        np.ascontiguousarray(t), np.ascontiguousarray(y.T), fmin=df, fmax=nf * df, Nf=nf, normalization="psd"
    )
    return res.freq(), np.atleast_2d(np.asarray(res.power, dtype=float))


def noise_floor(power: np.ndarray) -> np.ndarray:
    """Each pixel's white-noise variance from its periodogram (pixel, frequency): the median over
    the upper half of the band / ln 2."""
    upper = power[:, power.shape[1] // 2 :]
    return np.median(upper, axis=1) / math.log(2.0)


def noise_levels(matrix: PixelMatrix) -> NoiseLevels:
    """Two passes over the pixels: the frames every pixel observes, then the periodograms of those
    frames (`NoiseLevels`)."""
    t = matrix.time
    valid = np.ones(t.size, dtype=bool)
    for _, block in matrix.blocks():
        valid &= np.isfinite(block).all(axis=1)
    if valid.sum() < 16:
        raise DataError(f"cube: only {int(valid.sum())} frames in which every selected pixel is valid; 16 are needed")
    tv = t[valid]
    sigma, mean = np.empty(matrix.n), np.empty(matrix.n)
    trace: np.ndarray | None = None
    freqs = np.empty(0)
    largest = 0.0
    for sl, block in matrix.blocks():
        b = block[valid]
        big = float(np.max(np.abs(b))) if b.size else 0.0
        if big > LARGEST_VALUE:  # its squares, summed over the frames, leave float64
            raise DataError(
                f"cube: values up to {big:.3g} overflow the periodogram's float64 arithmetic (allowed up to "
                f"{LARGEST_VALUE:g}); rescale the data"
            )
        mean[sl] = b.mean(axis=0)
        largest = max(largest, float(np.max(b.var(axis=0))) if b.size else 0.0)
        freqs, power = periodograms(tv, b)
        floor = noise_floor(power)
        tiny = 1e-30 * max(float(np.max(b.var(axis=0))), 1e-300)  # a constant pixel: no noise, no weight
        floor = np.maximum(floor, tiny)
        sigma[sl] = np.sqrt(floor)
        with np.errstate(invalid="ignore", divide="ignore"):  # a block of constant pixels: refused below
            part = (power / floor[:, None]).sum(axis=0)
        trace = part if trace is None else trace + part
    assert trace is not None
    if not largest > 0.0:
        raise DataError(
            "cube: every selected pixel is constant over the frames they all observe: nothing varies to fit"
        )
    return NoiseLevels(valid, mean, sigma, freqs, trace, float(tv[-1] - tv[0]))


def choose_band(
    levels: NoiseLevels, n: int, band: tuple[float, float] | None = None, *, exclude: np.ndarray | None = None
) -> slice:
    """The bins of the strongest excess of the whitened trace spectrum (`NoiseLevels.trace`) inside
    `band` (Hz; default: above 3 cycles per record). Its centre: at the scale where it is most
    significant, for each width W in BAND_WIDTHS bins the running mean of trace / n - 1 (~0 on
    noise, with sd 1 / sqrt(W n): a mean of W n unit exponentials) times sqrt(W n): a line wins at
    W = 1, a resonance at about its width. Its extent: the bins around the centre where the excess,
    smoothed over max(W, 5) bins (a resonance's periodogram is as spiky in every pixel: the signal
    is shared), stays above half its value at the centre, widened by max(W, 2) bins on each side,
    at most MAX_BAND_BINS. `exclude` (a boolean per frequency): bins already taken by another
    source's band, which count as noise (excess 0)."""
    freqs = levels.freqs
    lo, hi = band if band is not None else (3.0 / levels.span, float(freqs[-1]))
    if not (0 <= lo < hi):
        raise InputError(f"band: ({lo:g}, {hi:g}) Hz; allowed 0 <= fmin < fmax")
    inside = np.flatnonzero((freqs >= lo) & (freqs <= hi))
    if inside.size == 0:
        raise InputError(f"band: ({lo:g}, {hi:g}) Hz holds no frequency of the data (0, {freqs[-1]:g}] Hz")
    from vibinverse.models.modal import smooth

    excess = levels.trace[inside] / n - 1.0
    if exclude is not None:
        excess[np.asarray(exclude, dtype=bool)[inside]] = 0.0
    best = (-np.inf, 0, 1)
    for width in BAND_WIDTHS:
        if width > inside.size:
            break
        score = smooth(excess, width) * math.sqrt(width * n)
        k = int(np.argmax(score))
        if score[k] > best[0]:
            best = (float(score[k]), k, width)
    _, k, width = best
    level = smooth(excess, max(width, 5))
    a, b = k, k
    while a > 0 and level[a - 1] > 0.5 * level[k] and b - a < MAX_BAND_BINS:
        a -= 1
    while b < inside.size - 1 and level[b + 1] > 0.5 * level[k] and b - a < MAX_BAND_BINS:
        b += 1
    half = max(width, 2)
    a, b = max(a - half, 0, k - MAX_BAND_BINS // 2), min(b + half, inside.size - 1, k + MAX_BAND_BINS // 2)
    return slice(int(inside[a]), int(inside[b]) + 1)


def seed_gains(matrix: PixelMatrix, levels: NoiseLevels, band: tuple[float, float] | None = None) -> GainSeed:
    """The seed band (`choose_band`) and one pass over the pixels for its Fourier coefficients (a
    direct DFT at the band's frequencies: any stamps)."""
    return seed_bands(matrix, levels, [choose_band(levels, matrix.n, band)])[0]


def seed_bands(matrix: PixelMatrix, levels: NoiseLevels, bands: Sequence[slice]) -> list[GainSeed]:
    """The Fourier coefficients of the de-meaned pixels at the frequencies of each band (slices of
    `levels.freqs`), all in one pass over the pixels (a direct DFT: any stamps)."""
    valid, mean = levels.valid, levels.mean
    parts = [levels.freqs[b] for b in bands]
    f = np.concatenate(parts)
    tv = matrix.time[valid]
    coef = np.zeros((matrix.n, f.size), dtype=complex)
    step = max(1, BLOCK_BYTES // (16 * f.size))  # the DFT's basis (time, K) a stretch of time at a time
    for sl, block in matrix.blocks():
        d = block[valid] - mean[sl]
        for a in range(0, tv.size, step):
            basis = np.exp(-2j * np.pi * np.outer(tv[a : a + step] - tv[0], f))
            coef[sl] += d[a : a + step].T @ basis
    out, start = [], 0
    for part in parts:
        logger.debug("gain seeds from the band %.4g-%.4g Hz (%d bins)", part[0], part[-1], part.size)
        out.append(GainSeed((float(part[0]), float(part[-1])), coef[:, start : start + part.size]))
        start += part.size
    return out


def choose_bands(
    levels: NoiseLevels,
    n: int,
    count: int,
    *,
    bands: Sequence[tuple[float, float]] | None = None,
    centres: Sequence[float] | None = None,
) -> list[slice]:
    """The bands of `count` sources (slices of `levels.freqs`): the given `bands` (Hz), each
    narrowed to its strongest excess (`choose_band`); else around the given `centres` (Hz, e.g. the
    lines of a detection map's cluster, strongest first), each searched between the midpoints to
    its neighbours; else the strongest excess of the whitened trace spectrum, then the strongest
    outside it, and so on, each found band and as many bins again on each side excluded from the
    next searches (separated peaks: a strong resonance's skirts are not a second source). Found
    bands are returned in increasing frequency, given ones in their order. One-line InputError when
    fewer bands are given or found than sources."""
    if bands is not None:
        if len(bands) != count:
            raise InputError(f"bands: {len(bands)} given for {count} sources; give one (fmin, fmax) per source")
        return [choose_band(levels, n, tuple(b)) for b in bands]
    freqs = levels.freqs
    if centres is not None:
        cs = [float(c) for c in centres][:count]
        if len(cs) < count:
            raise InputError(f"sources: {count}; the detection map's cluster carries only {len(cs)} line(s)")
        order = sorted(cs)
        out = []
        for c in cs:
            k = order.index(c)
            lo = 0.5 * (order[k - 1] + c) if k > 0 else 0.0
            hi = 0.5 * (order[k + 1] + c) if k + 1 < len(order) else float(freqs[-1])
            out.append(choose_band(levels, n, (lo, hi)))
        return out
    taken = np.zeros(freqs.size, dtype=bool)
    lo = 3.0 / levels.span
    out = []
    for j in range(count):
        if taken[freqs >= lo].all():
            raise InputError(f"sources: {count}; the spectrum holds only {j} separated bands")
        b = choose_band(levels, n, exclude=taken)
        width = b.stop - b.start
        taken[max(b.start - width, 0) : b.stop + width] = True
        out.append(b)
    return sorted(out, key=lambda b: b.start)


def cluster_lines(path: str | Path, cluster: int) -> list[float]:
    """The frequencies (Hz) of the vibration lines a detection map's cluster carries (its
    `cluster_lines`, less those whose `line_kind` says they are not vibration: frame patterns,
    frame-wide flicker...), strongest line first; [] when the map has none."""
    return [f for f, kind, _ in carried_lines(path, cluster) if kind == VIBRATION]


def cluster_slow_lines(path: str | Path, cluster: int) -> list[float]:
    """The frequencies (Hz) of the slow lines (`line_slow`: 1-4 cycles per record, `slow_lines`)
    claimed as vibration that a detection map's cluster carries; [] when none."""
    return [f for f, kind, slow in carried_lines(path, cluster) if slow and kind == VIBRATION]


def carried_lines(path: str | Path, cluster: int) -> list[tuple[float, str, bool]]:
    """(frequency, kind, slow) of every line a detection map's cluster carries, strongest first
    ([] when the map has no lines or no such cluster)."""
    import xarray as xr

    from vibinverse.io.series import check_file

    p = check_file(path, "pixels")
    try:
        with xr.open_dataset(p) as ds:
            if "cluster_lines" not in ds or "line_frequency" not in ds:
                return []
            carried = ds["cluster_lines"].sel(cluster_id=cluster).values
            freqs = np.asarray(ds["line_frequency"].values, dtype=float)
            kinds = [str(k) for k in ds["line_kind"].values] if "line_kind" in ds else ["vibration"] * freqs.size
            slow = np.asarray(ds["line_slow"].values, dtype=bool) if "line_slow" in ds else np.zeros(freqs.size, bool)
    except KeyError:
        return []
    except (OSError, ValueError) as exc:
        raise DataError(f"pixels: cannot read the detection map {p}: {str(exc).splitlines()[0]}") from None
    return [(float(f), k, bool(w)) for f, c, k, w in zip(freqs, np.asarray(carried), kinds, slow) if c]


def band_gains(coef: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Real gains (any scale) from the band's Fourier coefficients (pixel, frequency): sigma_i u_i,
    u the leading left singular vector of the whitened real matrix [Re B, Im B] / sigma, i.e. the
    leading eigenvector of Re(B B^H) whitened (the cross-spectral matrix summed over the band,
    rank one for one shared signal seen with real gains; frequency-domain decomposition). The sign
    is that of the largest entry."""
    whitened = coef / sigma[:, None]
    u = np.linalg.svd(np.concatenate([whitened.real, whitened.imag], axis=1), full_matrices=False)[0][:, 0]
    u = u * np.sign(u[int(np.argmax(np.abs(u)))])
    return sigma * u


def mean_frame(cube: Any) -> np.ndarray:
    """The time mean of the cube's frames (y, x), float64, computed chunk by chunk."""
    return np.asarray(frame_axes(cube).astype(np.float64).mean("time", skipna=True).values, dtype=np.float64)


def gradient_gains(frame: np.ndarray, axis: str, scale: float = 1.0) -> np.ndarray:
    """The optical-flow gain of every pixel (y, x) for a displacement along `axis` ("x" or "y") in
    units of `scale` (metres per pixel; 1: pixels): -dI/dx / scale of the mean frame (module
    docstring), by fourth-order central differences ((8 (f1 - f-1) - (f2 - f-2)) / 12) inside and
    `numpy.gradient`'s second-order differences in the two pixels next to the border."""
    if axis not in ("x", "y"):
        raise InputError(f"displacement: {axis!r}; allowed: 'x' or 'y'")
    if not (scale > 0 and math.isfinite(scale)):
        raise InputError(f"scale: {scale:g} metres per pixel; allowed range (0, inf)")
    ax = 1 if axis == "x" else 0
    f = np.asarray(frame, dtype=np.float64)
    if f.shape[ax] < 3:
        raise InputError(f"displacement: the frame has {f.shape[ax]} pixels along {axis}; at least 3 are needed")
    grad = np.gradient(f, axis=ax, edge_order=2)
    if f.shape[ax] >= 5:
        m = np.moveaxis(f, ax, 0)
        inner = (8.0 * (m[3:-1] - m[1:-3]) - (m[4:] - m[:-4])) / 12.0
        g = np.moveaxis(grad, ax, 0)
        g[2:-2] = inner
    return -grad / scale
