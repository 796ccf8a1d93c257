"""Which pixels of an image cube (time, y, x) carry a vibration: a per-pixel whitened periodogram,
its strongest peak and the peak's false-alarm probability, the lines seen anywhere in the frame,
and the clusters of pixels that carry them. Run chunk by chunk on Dask (`scheduler`).

Per pixel (float64, a batch of pixels at a time), items 1-4 in `vibinverse.imaging.whitening`:

1. The mean and a least-squares linear trend are removed.
2. The periodogram on the Fourier frequencies k / T (rfft on uniform stamps, Lomb-Scargle on
   irregular ones).
3. Whitening by a robust local noise floor (a cubic baseline in ln f, then the median of
   P / baseline over windows of 129 bins): z = P / floor is ~ Exp(1) on noise, a line's z its SNR.
4. The exact tail of z on white noise, P(z > s) (`log_tail`).
5. The peak of z in the band: its frequency (refined by a parabola through ln P at the three bins
   around it), its SNR, and its false-alarm probability corrected for the M frequencies searched
   (`pixel_false_alarm_probability`) and for the M frequencies AND the P pixels
   (`false_alarm_probability`): for independent tests of tail p, P(max > z) = 1 - (1 - p)^{M P},
   computed as -expm1(M P log1p(-p)).

Lines: per Fourier frequency, the largest z over all pixels; frequencies whose corrected
false-alarm probability 1 - (1 - p)^{M P} is below `alpha` are lines, merged when at most
`MERGE_GAP` = 2 bins apart (a strong line's sidelobes, a damped resonance's hump, which dips below
the threshold between its bins; so lines closer than 4 / T are one), the strongest `max_lines`
kept. Then every pixel's z within one bin of each line (the SNR map): the first pass keeps each
pixel's fitted floor (`whitening.Floor`, n_windows + 4 numbers), so only the powers at the lines'
bins are needed. When every pixel's powers fit in a quarter of `memory` (float64, n_freq per pixel:
half a float64 cube), the first pass keeps them and they are taken from there (the cube is read
once); else a second pass reads the cube again for them, by a direct DFT at those bins on uniform
stamps (`whitening.dft_power`: one matrix product per slab of frames; no whole transform, no
whitening).
A pixel carries a line when its p-value there (corrected for the <= 3 bins) passes the
Benjamini-Hochberg procedure over all pixels at level `alpha` (expected fraction of false pixels
<= alpha). Clusters are the connected components (8-neighbours, scipy.ndimage.label) of the
pixels that carry any line, numbered 1, 2, ... by decreasing peak SNR; `cluster` (y, x) holds the
number (0: none), `line_of_cluster` the cluster's strongest line, `cluster_lines` every line it
carries (a roof's pixels carry its tilt resonance and its drive together).

A pixel whose value changes in fewer than `MIN_CHANGES` frames (a codec holds it; a few spikes) has
too few events for its periodogram to be a noise's: its z is a deterministic pattern (two spikes a
frame apart leave no power near Nyquist) that the whitening cannot judge. Its z is 0 for the
peaks, the lines' maxima and the SNR maps (it carries no line); the counts of the recording's null
and of the frame-wide check keep it, as the frame's (on the three tuning-fork videos at 250 fps
shuffled in time, such pixels made claimed lines at 6-8 cycles per record in 6 of 60 orders).

Real recordings: every p-value above (a line's, a pixel's) is the larger of the white-noise one and
the recording's own (`empirical_null`: the pooled whitened powers away from the candidate lines,
and the exponential tail of the per-frequency maxima over the pixels), gathered in the first pass
as per-frequency histograms of z (added up in a tree as the blocks finish). Each line is then
classified (`line_checks`): "vibration" (claimed), or real power of the recording that is not a
structure's (frame-wide, frame-pattern, unlocated, scattered), reported with the reason; and its
other reading, fs - f (a line above Nyquist shows below it).

Slow lines: the first `LOW_BINS` Fourier frequencies (1-4 cycles per record, periods longer than
a quarter of it), where drifts and illumination live, are searched apart (`slow_lines`): each
pixel's coefficients there (kept from the first pass, LOW_BINS complex numbers and two white
floors a pixel), less its share of the picture's common light change, over its white floors,
against the bulk of the frame's pixels at the same bin, never pooled with the other frequencies'
null. A slow line passes at `alpha` over the pixels and the slow bins (a family of its own); its
frequency is its bin's, its note (`line_checks.Slow`) says so and that any slow change of a region
looks alike; the other checks see whether the whole picture, the camera's motion, a region's light
or clipped pixels make it. A rolling shutter's per-row time offset (coord "row_offset") shifts a
row's stamps by a constant: it changes each periodogram's phase, never its power, and is ignored
here.

Decoded frames (video, MRAW, TIFF: integer counts read in pieces of whole frames, too big to keep)
are decoded once into a scratch file per block (`spill`) on a local run, instead of once per block.

Chunks: the time axis whole, the frame cut into spatial blocks so that the blocks in flight and
their float64 work fit `memory` bytes less the kept spectra (`plan_chunks`), each of at most
`BLOCK_BYTES`. What every pixel keeps to the end (its floor, n_windows + 4 numbers, its slow
coefficients and floors, 10 more; the slow search's own statistics, ~0.1 kB a pixel, once the
blocks are done) is not counted in `memory`. A cube whose time axis is split in chunks (video
frames, netCDF read by frames) is read block by block (each block's reads are its own tasks, so
only its pixels are held), never rechunked whole. A second pass (spectra not kept) reads the frames
again in slabs (`SLAB_BYTES`, whole frames: the cheapest reads) and adds up the DFT sums of each
slab. Integer counts (decoded video, MRAW and TIFF frames, whose reads decode whole frames, so that
each block's read decodes the whole recording) are read once and kept for that pass when they fit
in a quarter of `memory`; float cubes (netCDF, zarr, npy, read by hyperslab) are read again, which
costs less than holding them.

No equation of the paper is used here (the paper stops at the sensitivity, eq. 21; sec. 5 asks for
combining pixels, which this map prepares).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import itertools
import logging
import math
import numbers
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from vibinverse.errors import DataError, InputError
from vibinverse.imaging.empirical_null import Z_EDGES, EmpiricalNull, z_counts
from vibinverse.imaging.line_checks import VIBRATION, LineEvidence, classify, frame_combs, notes
from vibinverse.imaging.scheduler import session
from vibinverse.imaging.slow_lines import MIN_CHANGES, SlowSearch, series_flags
from vibinverse.imaging.spill import Spill
from vibinverse.imaging.whitening import (
    LOW_BINS,
    TINY,
    Floor,
    FrequencyGrid,
    corrected,
    dft_basis,
    dft_power,
    dft_sums,
    frequency_grid,
    log_tail,
    refine,
    spectra_rows,
    white_floor,
    whiten_rows,
)
from vibinverse.io.file_basics import csv_cell

logger = logging.getLogger(__name__)

DEFAULT_MEMORY = 512 * 2**20  # bytes: the chunks in flight and their float64 work, all threads together
# float64 work per pixel and time sample in a batch (series, spectra, floor), measured with tracemalloc:
# 29 bytes with the rfft, 85 with nifty-ls (its oversampled NUFFT grid)
WORK_BYTES_PER_SAMPLE = {True: 32, False: 96}  # keyed by uniform stamps
LINE_MAP_VALUES = 2**21  # `line_maps` whitens at most this many powers at a time (16 MB of float64 a work array)
LINE_MAP_ARRAYS = 8  # ... and at most memory / (8 bytes x this) (its work arrays and whitening's temporaries)
LINE_MAP_FEWEST = 2**14  # ... and at least this many
LINE_BINS = 1  # a pixel's SNR at a line: its largest z within this many bins of the line's bin
MERGE_GAP = 2  # line frequencies at most 2 bins apart are one line (a damped resonance's hump dips between)
MIN_CHUNK_PIXELS = 64  # smaller blocks cost more in scheduling than they save
BATCH_BYTES = 2**20  # float64 series per batch: ~1 MiB stays in a core's cache (2x faster than 8 MiB)
# a block's float64 series, and a slab of frames of the second pass (stored dtype), at most: each read
# costs ~5 ms of fixed overhead through xarray and HDF5, and fresh pages cost too (measured, 64 x 64 x 4000)
BLOCK_BYTES = 32 * 2**20
SLAB_BYTES = 32 * 2**20
LABELLED_CLUSTERS = 12  # the plot labels the strongest clusters only (a real video may have hundreds)
SPLIT_EVERY = 4  # the second pass adds its slabs' sums 4 at a time


# ---------------------------------------------------------------------------------- one chunk's work
def _batches(block: Any, grid: FrequencyGrid, batch: int, ends: tuple[float, float] | None = None, flags=False):
    """(slice of the block's pixels, their means, their powers in rows (pixels, n_freq), their slow
    coefficients (pixels, LOW_BINS), with `flags` their `series_flags` at the range's `ends`, else
    None) for batches of `batch` pixels of a block (time, y, x), given whole or as its time pieces
    (a list, as read: each batch gathers its pixels' series from them, float64)."""
    pieces = [np.asarray(p) for p in block] if isinstance(block, (list, tuple)) else [np.asarray(block)]
    flats = [p.reshape(p.shape[0], -1) for p in pieces]
    for start in range(0, flats[0].shape[1], batch):
        sl = slice(start, min(start + batch, flats[0].shape[1]))
        y = np.concatenate([f[:, sl] for f in flats], axis=0, dtype=np.float64)
        flag = series_flags(y, ends) if flags else None
        if grid.uniform:  # a missing sample makes its column's sum (the rfft at f = 0) NaN: checked after
            mean, power, slow = spectra_rows(y, grid)
            if np.isfinite(mean).all():
                yield sl, mean, power, slow, flag
                continue
        bad = ~np.isfinite(y)
        if bad.any():  # missing samples: the pixel's mean; a pixel without samples: mean NaN, no power
            y[bad] = 0.0
            count = (~bad).sum(axis=0)
            fill = np.divide(y.sum(axis=0), count, out=np.zeros(y.shape[1]), where=count > 0)
            y[bad] = np.broadcast_to(fill[None, :], y.shape)[bad]
            mean, power, slow = spectra_rows(y, grid)
            mean[count == 0] = np.nan
        else:
            mean, power, slow = spectra_rows(y, grid)
        yield sl, mean, power, slow, flag


def _refined(power: np.ndarray, idx: np.ndarray, n_freq: int) -> np.ndarray:
    """Bin offsets of the peaks at bins idx (one per row of power (pixels, n_freq)): `refine`
    through ln P at idx - 1, idx, idx + 1; 0 at the first and last frequencies."""
    i = np.clip(idx, 1, n_freq - 2)
    rows = np.arange(idx.size)
    log_p = np.log(np.maximum(np.stack([power[rows, i + d] for d in (-1, 0, 1)]), TINY))
    return np.where(i == idx, refine(log_p), 0.0)


def first_pass(
    block: Any, grid: FrequencyGrid, batch: int, keep: bool = False, ends: tuple[float, float] | None = None
) -> dict[str, Any]:
    """A block (time, y, x; or its time pieces, a list) -> its maps (peak bin, peak frequency,
    peak SNR, mean frame; (y, x)), the largest z over its pixels at each frequency of the band, and
    its pixels' floors ("floor", a `Floor` over the block's pixels, for the second pass); with
    `keep`, also its pixels' powers ("power", (pixels, n_freq)), from which the second pass takes
    the powers at the lines' bins without reading the block again; how often its pixels' values
    change ("changes", (pixels,): one that changes in fewer than MIN_CHANGES samples has too few
    events for its spectrum to be a noise's, nor a line's: its z is 0 but in the counts). When
    slow bins are searched, its pixels' slow coefficients ("slow", (pixels, LOW_BINS)), white floors
    ("white", (pixels, 2)) and whether they reach the `ends` of the range ("clipped"), for
    `SlowSearch`; else those are None."""
    ny, nx = (block[0] if isinstance(block, (list, tuple)) else block).shape[1:]
    npix = ny * nx
    kept = np.empty((npix, grid.n_freq)) if keep else None
    searched = grid.slow_hi > grid.slow_lo
    slow_coef = np.zeros((npix, LOW_BINS), dtype=np.complex128) if searched else None
    white = np.zeros((npix, 2)) if searched else None
    clip = np.zeros(npix, dtype=bool) if searched else None
    changes = np.zeros(npix, dtype=np.int32)
    peak_bin = np.zeros(npix, dtype=np.int64)
    peak_f = np.zeros(npix)
    peak_z = np.zeros(npix)
    mean = np.zeros(npix)
    coef, scale = np.zeros((npix, grid.baseline_basis[0].shape[1])), np.zeros((npix, grid.windows[0].size))
    zmax = np.zeros(grid.n_searched)
    counts = np.zeros((grid.n_searched, Z_EDGES.size), dtype=np.int64)
    band = np.arange(grid.lo, grid.hi)
    for sl, m, power, slow, (edge, change) in _batches(block, grid, batch, ends, flags=True):
        changes[sl] = change
        if searched:
            slow_coef[sl], white[sl], clip[sl] = slow, white_floor(power, grid), edge
        z, floor = whiten_rows(power, grid, band)
        counts += z_counts(z)  # every pixel, as the frame (the frame-wide check) and the pooled null
        z[change < MIN_CHANGES] = 0.0
        rows = np.arange(z.shape[0])
        k = np.argmax(z, axis=1)
        idx = k + grid.lo
        peak_bin[sl] = idx
        peak_z[sl] = z[rows, k]
        peak_f[sl] = (idx + 1 + _refined(power, idx, grid.n_freq)) * grid.df
        mean[sl] = m
        coef[sl], scale[sl] = floor.coef, floor.scale
        np.maximum(zmax, z.max(axis=0), out=zmax)
        if kept is not None:
            kept[sl] = power
    shape = (ny, nx)
    return {
        "peak_bin": peak_bin.reshape(shape),
        "peak_frequency": peak_f.reshape(shape),
        "peak_snr": peak_z.reshape(shape),
        "mean_frame": mean.reshape(shape),
        "band_max": zmax,
        "z_counts": counts,
        "floor": Floor(coef, scale),
        "power": kept,
        "slow": slow_coef,
        "white": white,
        "clipped": clip,
        "changes": changes,
    }


def line_bins(grid: FrequencyGrid, bins: tuple[int, ...]) -> tuple[list[np.ndarray], np.ndarray]:
    """([the searched bins within LINE_BINS of each line's bin], every bin whose power the line
    pass needs: those and their neighbours, for the refined frequency)."""
    near = [np.arange(max(grid.lo, b - LINE_BINS), min(grid.hi, b + LINE_BINS + 1)) for b in bins]
    cols = np.unique(np.concatenate([np.r_[nb, nb - 1, nb + 1] for nb in near]))
    return near, cols[(cols >= 0) & (cols < grid.n_freq)]


def line_powers(block: Any, grid: FrequencyGrid, cols: np.ndarray, batch: int, mean: np.ndarray) -> np.ndarray:
    """A block (time, y, x) -> its pixels' powers (pixels, K) at the grid's K bins `cols`: by the
    DFT at those bins alone on uniform stamps (`dft_sums`, less the first pass's means `mean`),
    the periodogram's columns on irregular ones."""
    block = _whole(block)
    nt = block.shape[0]
    flat = block.reshape(nt, -1)
    power = np.zeros((flat.shape[1], cols.size))
    if grid.uniform:
        basis = dft_basis(grid, cols)
        for start in range(0, flat.shape[1], batch):
            sl = slice(start, min(start + batch, flat.shape[1]))
            power[sl] = dft_power(dft_sums(flat[:, sl], mean[sl], basis), grid, cols)
    else:
        for sl, _, p, _, _ in _batches(block, grid, batch):
            power[sl] = p[:, cols]
    return power


def slab_sums(
    slab: np.ndarray, frames: slice, grid: FrequencyGrid, cols: np.ndarray, mean: np.ndarray, batch: int
) -> np.ndarray:
    """The `dft_sums` (2 K + 1, y, x) at the grid's bins `cols` of a slab of frames (frames, y, x),
    the samples `frames` of the record, less the pixels' means `mean` (y, x): summed over the slabs,
    the record's (uniform stamps)."""
    basis = dft_basis(grid, cols, frames)
    nt, ny, nx = slab.shape
    flat, m = slab.reshape(nt, -1), mean.ravel()
    sums = np.empty((basis.shape[1], flat.shape[1]))
    step = max(batch, BATCH_BYTES // (8 * nt))
    for start in range(0, flat.shape[1], step):
        sl = slice(start, min(start + step, flat.shape[1]))
        sums[:, sl] = dft_sums(flat[:, sl], m[sl], basis)
    return sums.reshape(-1, ny, nx)


def line_maps(
    power: np.ndarray, floor: Floor, grid: FrequencyGrid, bins: tuple[int, ...], memory: float = DEFAULT_MEMORY
) -> tuple[np.ndarray, np.ndarray]:
    """(snr, frequency) (line, pixels) from the pixels' powers (pixels, K) at `line_bins`' bins and
    their floors: per line, each pixel's largest z within LINE_BINS of the line's bin and the
    frequency there, refined by the parabola through ln P at it and its neighbours. The pixels are
    whitened a slab at a time, its work arrays within `memory` (bytes; `line_map_values`)."""
    near, cols = line_bins(grid, bins)
    snr = np.zeros((len(bins), power.shape[0]))
    freq = np.zeros((len(bins), power.shape[0]))
    step = max(1, line_map_values(memory) // max(cols.size, 1))  # pixels at a time: the work arrays stay small
    for start in range(0, power.shape[0], step):
        sl = slice(start, min(start + step, power.shape[0]))
        z = floor.take(sl).whiten(power[sl], grid, cols)
        log_p = np.log(np.maximum(power[sl], TINY))
        rows = np.arange(z.shape[0])
        for k, nb in enumerate(near):
            at = np.searchsorted(cols, nb)
            j = np.argmax(z[:, at], axis=1)
            idx = nb[j]
            snr[k, sl] = z[rows, at[j]]
            inner = (idx >= 1) & (idx <= grid.n_freq - 2)  # else no parabola: the bin's own frequency
            around = [log_p[rows, np.searchsorted(cols, np.clip(idx + d, 0, grid.n_freq - 1))] for d in (-1, 0, 1)]
            freq[k, sl] = (idx + 1 + np.where(inner, refine(np.stack(around)), 0.0)) * grid.df
    return snr, freq


def line_map_values(memory: float) -> int:
    """How many powers `line_maps` whitens at a time: LINE_MAP_VALUES, fewer where `memory` (bytes)
    would not hold LINE_MAP_ARRAYS float64 arrays of them (a 24 MiB budget: 393,216 values, not 2**21:
    its work arrays took a process limited to 64 MiB above its baseline over the limit), at least
    LINE_MAP_FEWEST."""
    return int(min(LINE_MAP_VALUES, max(LINE_MAP_FEWEST, int(memory) // (8 * LINE_MAP_ARRAYS))))


def _whole(block: Any) -> np.ndarray:
    """A block given whole or as its time pieces (a list, as read), whole."""
    if isinstance(block, (list, tuple)):
        return block[0] if len(block) == 1 else np.concatenate(block, axis=0)
    return np.asarray(block)


# ------------------------------------------------------------------------------------------- chunks
@dataclasses.dataclass(frozen=True)
class ChunkPlan:
    """Spatial blocks (all time samples each) and the pixels processed at once inside a block."""

    block_y: int
    block_x: int
    batch: int  # pixels per float64 batch
    keep: bool  # the cube fits in a quarter of the memory: it may be read once and kept for the second pass


def plan_chunks(
    shape: tuple[int, int, int], itemsize: int, threads: int, memory: int, uniform: bool = True
) -> ChunkPlan:
    """Blocks so that `threads` blocks in flight (stored dtype, x2 while assembled from their time
    pieces) plus their float64 batches (WORK_BYTES_PER_SAMPLE per sample) fit in `memory` bytes,
    each block of at most BLOCK_BYTES of float64 series. A cube of at most a quarter of `memory`
    may be kept in memory between the two passes (`keep`)."""
    from dask.utils import format_bytes

    nt, ny, nx = (int(s) for s in shape)
    cube_bytes = nt * ny * nx * itemsize
    keep = cube_bytes <= memory // 4
    per_thread = (memory - (cube_bytes if keep else 0)) / max(threads, 1)
    work = WORK_BYTES_PER_SAMPLE[bool(uniform)]
    batch = int(per_thread / 2 // (work * nt))
    if batch < 1:
        need = 2 * work * nt * max(threads, 1) + (cube_bytes if keep else 0)
        raise InputError(
            f"--memory: {format_bytes(memory)} is too little for {threads} thread(s) on {nt}-sample series "
            f"(at least {format_bytes(need)})"
        )
    pixels = max(batch, int(per_thread / 2 // (2 * itemsize * nt)))
    batch = min(batch, max(1, BATCH_BYTES // (8 * nt)))
    total = ny * nx
    if total >= 2 * threads * MIN_CHUNK_PIXELS:  # at least two blocks per thread: balanced work
        pixels = min(pixels, max(MIN_CHUNK_PIXELS, -(-total // (2 * threads))))
    pixels = min(pixels, max(MIN_CHUNK_PIXELS, batch, BLOCK_BYTES // (8 * nt)))
    pixels = min(pixels, total)
    block_y, block_x = (min(ny, pixels // nx), nx) if pixels >= nx else (1, pixels)
    return ChunkPlan(block_y, block_x, min(batch, block_y * block_x), keep)


def _boundaries(chunks: tuple[int, ...]) -> set[int]:
    return set(np.cumsum((0, *chunks)).tolist())


def _cuts(shape: tuple[int, ...], plan: ChunkPlan) -> list[tuple[slice, slice]]:
    _, ny, nx = shape
    return [
        (slice(y, min(y + plan.block_y, ny)), slice(x, min(x + plan.block_x, nx)))
        for y in range(0, ny, plan.block_y)
        for x in range(0, nx, plan.block_x)
    ]


def aligned(data: Any, plan: ChunkPlan) -> bool:
    """Whether every chunk of the dask array `data` (time, y, x) lies inside one block of the plan."""
    cuts = _cuts(data.shape, plan)
    edges_y = {s.stop for s, _ in cuts} | {0}
    edges_x = {s.stop for _, s in cuts} | {0}
    return edges_y <= _boundaries(data.chunks[1]) and edges_x <= _boundaries(data.chunks[2])


def blocks_of(data: Any, plan: ChunkPlan) -> list[tuple[slice, slice, Any]]:
    """(y slice, x slice, dask array (time, y, x), one chunk in y and x) of every block of the plan,
    from a dask array.

    When every source chunk lies inside one block, or the cube is kept in memory anyway, the blocks
    are a rechunk of the source (whole). Otherwise (frames split in time pieces that span many
    blocks, as video and netCDF read by frames) a rechunk would hold every piece until the last
    block used it: the whole cube. There each block reads its own pixels of every piece in tasks of
    its own (`dask.graph_manipulation.clone`; dask fuses the slice into the read where the source
    allows), so only the blocks in flight are held; its time pieces are left as read (the first
    pass gathers each batch's series from them: no copy of the whole block)."""
    from dask.graph_manipulation import clone

    cuts = _cuts(data.shape, plan)
    # (method "tasks": dask's default choice would import distributed to look for a client)
    if aligned(data, plan) or plan.keep:
        whole = data.rechunk((-1, plan.block_y, plan.block_x), method="tasks")
        return [(ys, xs, whole[:, ys, xs]) for ys, xs in cuts]
    out = []
    for k, (ys, xs) in enumerate(cuts):
        block = clone(data, seed=k)[:, ys, xs]
        if len(block.chunks[1]) > 1 or len(block.chunks[2]) > 1:
            block = block.rechunk({1: -1, 2: -1}, method="tasks")
        out.append((ys, xs, block))
    return out


def _pieces(block: Any) -> list[Any]:
    """The time pieces (dask.delayed, in time order) of a block of `blocks_of`."""
    return block.to_delayed().ravel().tolist()


# ------------------------------------------------------------------------------------------ results
@dataclasses.dataclass(frozen=True)
class LineCluster:
    """The pixels of one cluster that carry one line."""

    line: int
    cluster: int
    n_pixels: int
    centroid: tuple[float, float]  # (y, x), pixel indices of the cube
    bbox: tuple[int, int, int, int]  # (y0, y1, x0, x1), half-open pixel index ranges
    mean_snr: float
    max_snr: float


@dataclasses.dataclass(frozen=True)
class Line:
    """A detected line: its frequency, largest SNR over the pixels, corrected false-alarm probability."""

    index: int
    frequency: float  # Hz: SNR-weighted mean of its pixels' refined peak frequencies
    bin_frequency: float  # Hz: the Fourier frequency of its strongest bin
    snr: float
    false_alarm_probability: float
    n_pixels: int  # pixels that carry it
    clusters: tuple[LineCluster, ...]
    kind: str = VIBRATION  # "vibration" (claimed) or what else it is (`line_checks`)
    reason: str = ""  # why it is not vibration, one sentence
    alias_frequency: float = math.nan  # Hz: the other reading, fs - frequency (uniform frames)
    slow: bool = False  # found by the slow search (1-4 cycles per record: `slow_lines`)
    note: str = ""  # what to know about it however it is classified (`line_checks.notes`), or empty

    @property
    def claimed(self) -> bool:
        """Whether the line is claimed as a structure's vibration."""
        return self.kind == VIBRATION


@dataclasses.dataclass
class DetectionMap:
    """Maps (`xarray.Dataset`, variables on (y, x), (line, y, x), (line,), (cluster_id,)) and lines."""

    maps: xr.Dataset
    lines: list[Line]

    def table(self) -> list[dict[str, Any]]:
        """One row per (line, cluster): frequency_hz, snr (mean over the cluster's pixels carrying the
        line), max_snr, false_alarm_probability (the line's), kind ("vibration" when claimed),
        alias_frequency_hz (the other reading, fs - f), cluster, n_pixels, centroid, bbox, note
        (e.g. a slow line's)."""
        rows = []
        for line in self.lines:
            for c in line.clusters:
                rows.append(
                    {
                        "line": line.index,
                        "frequency_hz": line.frequency,
                        "snr": c.mean_snr,
                        "max_snr": c.max_snr,
                        "false_alarm_probability": line.false_alarm_probability,
                        "kind": line.kind,
                        "alias_frequency_hz": line.alias_frequency,
                        "cluster": c.cluster,
                        "n_pixels": c.n_pixels,
                        "centroid_y": c.centroid[0],
                        "centroid_x": c.centroid[1],
                        "bbox_y0": c.bbox[0],
                        "bbox_y1": c.bbox[1],
                        "bbox_x0": c.bbox[2],
                        "bbox_x1": c.bbox[3],
                        "note": line.note,
                    }
                )
        return rows

    def cluster(self, k: int) -> np.ndarray:
        """The boolean (y, x) mask of cluster k (1, 2, ...: the `cluster` map), for
        `vi.fit(cube, pixels=found.cluster(k))`; a one-line InputError for a cluster not in the map."""
        labels = np.asarray(self.maps["cluster"].values)
        ids = sorted(int(c) for c in np.unique(labels) if c > 0)
        if int(k) not in ids:
            raise InputError(f"cluster: {k} is not in the detection map; its clusters are {ids or 'none'}")
        return labels == int(k)

    def to_netcdf(self, path: str | Path) -> None:
        self.maps.to_netcdf(str(path), engine="h5netcdf")

    def write_csv(self, path: str | Path) -> None:
        """lines.csv: '#' comment lines (units, alpha), a header, one row per (line, cluster)."""
        rows = self.table()
        names = list(rows[0]) if rows else list(LINE_TABLE_COLUMNS)
        with open(path, "w", encoding="utf-8", newline="") as fh:
            fh.write(
                f"# vibinverse detect: lines (false-alarm probability < {self.maps.attrs['alpha']:g}) and the "
                "pixel clusters that carry them\n"
            )
            fh.write(
                "# frequency_hz in Hz; snr = whitened power (noise floor 1); pixels: 0-based (y, x) indices, "
                "bbox half-open [y0, y1) x [x0, x1)\n"
            )
            writer = csv.DictWriter(fh, fieldnames=names, lineterminator="\n")
            writer.writeheader()
            for r in rows:
                writer.writerow({k: (f"{v:.10g}" if isinstance(v, float) else csv_cell(v)) for k, v in r.items()})

    def plot(self, path: str | Path) -> None:
        plot_detection(self, path)


LINE_TABLE_COLUMNS = (
    "line", "frequency_hz", "snr", "max_snr", "false_alarm_probability", "kind", "alias_frequency_hz", "cluster",
    "n_pixels",
    "centroid_y", "centroid_x", "bbox_y0", "bbox_y1", "bbox_x0", "bbox_x1", "note",
)  # fmt: skip


def plot_detection(result: DetectionMap, path: str | Path) -> None:
    """The detection map over the mean frame: the SNR of each pixel's strongest line where it
    carries one (else its peak's -log10 false-alarm probability, faint), clusters outlined and
    labelled with their lines' frequencies."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ds = result.maps
    ny, nx = ds.sizes["y"], ds.sizes["x"]
    fig, ax = plt.subplots(figsize=(7.0, 7.0 * ny / max(nx, 1) + 0.8), constrained_layout=True)
    ax.imshow(ds["mean_frame"].values, cmap="gray", interpolation="nearest")
    if result.lines:
        carries = ds["carries_line"].values.astype(bool)
        snr = np.where(carries, ds["snr"].values, np.nan)
        shown = np.where(carries.any(axis=0), np.nanmax(np.where(carries, snr, -np.inf), axis=0), np.nan)
        im = ax.imshow(np.ma.masked_invalid(shown), cmap="inferno", alpha=0.75, interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8, label="SNR of the pixel's strongest line (whitened power)")
        cluster = ds["cluster"].values
        ax.add_collection(_outlines(cluster))
        ids = ds["cluster_id"].values
        for k in ids[:LABELLED_CLUSTERS]:
            ys, xs = np.nonzero(cluster == k)
            carried = np.flatnonzero(ds["cluster_lines"].sel(cluster_id=k).values)
            label = ", ".join(f"{ds['line_frequency'].values[i]:.3g}" for i in carried)
            ax.annotate(
                f"{int(k)}: {label} Hz",
                (xs.mean(), ys.min() - 0.6),
                color="cyan",
                fontsize=8,
                ha="center",
                va="bottom",
                bbox={"facecolor": "black", "alpha": 0.5, "pad": 1.0, "linewidth": 0},
            )
        title = f"{len(result.lines)} line(s) detected (false-alarm probability < {ds.attrs['alpha']:g})"
        if ids.size > LABELLED_CLUSTERS:
            title += f"; clusters 1-{LABELLED_CLUSTERS} of {ids.size} labelled"
    else:
        with np.errstate(divide="ignore"):
            score = -np.log10(np.maximum(ds["pixel_false_alarm_probability"].values, 1e-300))
        im = ax.imshow(score, cmap="viridis", alpha=0.5, interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8, label="-log10 false-alarm probability of each pixel's peak")
        title = f"no line detected (false-alarm probability < {ds.attrs['alpha']:g})"
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (pixel)")
    ax.set_ylabel("y (pixel)")
    fig.savefig(str(path), dpi=120, format="png")
    plt.close(fig)


def _outlines(cluster: np.ndarray) -> Any:
    """The outlines of every cluster of the label map `cluster` (y, x; 0: none) along the pixels'
    edges, as one LineCollection: a segment wherever two neighbouring pixels (or a pixel and the
    frame's edge) differ in label and one of them is in a cluster. Memory O(pixels), whatever the
    number of clusters."""
    from matplotlib.collections import LineCollection

    padded = np.pad(cluster, 1)
    segments = []
    # vertical edges between columns j-1 and j (padded), at x = j - 1.5 in pixel coordinates
    diff = (padded[:, 1:] != padded[:, :-1]) & ((padded[:, 1:] > 0) | (padded[:, :-1] > 0))
    iy, jx = np.nonzero(diff)
    x = jx - 0.5
    segments.append(np.stack([np.stack([x, iy - 1.5], -1), np.stack([x, iy - 0.5], -1)], 1))
    diff = (padded[1:, :] != padded[:-1, :]) & ((padded[1:, :] > 0) | (padded[:-1, :] > 0))
    iy, jx = np.nonzero(diff)
    y = iy - 0.5
    segments.append(np.stack([np.stack([jx - 1.5, y], -1), np.stack([jx - 0.5, y], -1)], 1))
    return LineCollection(np.concatenate(segments), colors="cyan", linewidths=1.0)


# ------------------------------------------------------------------------------------- the whole map
def range_ends(cube: xr.DataArray) -> tuple[float, float] | None:
    """The ends of an integer cube's range, where a pixel is clipped: (the dtype's smallest, 2^bit_depth
    - 1 by the attribute bit_depth, else the dtype's largest); None for floats (no known range)."""
    if not np.issubdtype(cube.dtype, np.integer):
        return None
    info = np.iinfo(cube.dtype)
    bits = cube.attrs.get("bit_depth")
    top = float(2 ** int(bits) - 1) if isinstance(bits, numbers.Integral) and 0 < int(bits) < info.bits else info.max
    return float(info.min), float(top)


def _check_cube(cube: Any) -> xr.DataArray:
    if not isinstance(cube, xr.DataArray):
        raise InputError(f"cube: an xarray.DataArray (time, y, x) is needed, not {type(cube).__name__}")
    if set(cube.dims) != {"time", "y", "x"}:
        raise DataError(f"cube: dimensions must be (time, y, x), not {tuple(cube.dims)}")
    if "time" not in cube.coords:
        raise DataError("cube: the time coordinate (s) is missing")
    if not (np.issubdtype(cube.dtype, np.number) and not np.issubdtype(cube.dtype, np.complexfloating)):
        raise DataError(f"cube: real numbers or integer counts are needed, not {cube.dtype}")
    if cube.sizes["y"] < 1 or cube.sizes["x"] < 1:
        raise DataError(f"cube: the frame is empty ({cube.sizes['y']} x {cube.sizes['x']} pixels)")
    return cube.transpose("time", "y", "x")


def _lines_of(band_max: np.ndarray, grid: FrequencyGrid, n_pixels: int, alpha: float, max_lines: int, null=None):
    """[(peak bin, largest z, corrected FAP)] of the groups of band frequencies whose largest z over
    the pixels has corrected false-alarm probability < alpha (at most MERGE_GAP bins apart: one
    line), strongest first. The probability is the white-noise one, or with `null` (an
    `EmpiricalNull`) the larger of it and the recording's own."""
    fap = corrected(log_tail(band_max, grid.half_width), grid.n_searched * n_pixels)
    if null is not None:
        fap = np.maximum(fap, null.line_probability(band_max))
    return _runs(fap, band_max, band_max, grid.lo, alpha, max_lines)


def _runs(fap: np.ndarray, score: np.ndarray, value: np.ndarray, first: int, alpha: float, max_lines: int):
    """[(bin, value there, fap there)] of the groups of bins (first + index) whose fap < alpha, at most
    MERGE_GAP bins apart (one line), each at its largest `score`, the largest score first."""
    hit = np.flatnonzero(fap < alpha)
    groups = np.split(hit, np.flatnonzero(np.diff(hit) > MERGE_GAP + 1) + 1) if hit.size else []
    picked = sorted((int(g[np.argmax(score[g])]) for g in groups), key=lambda k: -score[k])
    if len(picked) > max_lines:
        logger.info(f"detect: {len(picked)} lines pass alpha = {alpha:g}; kept the {max_lines} strongest")
    return [(first + k, float(value[k]), float(fap[k])) for k in picked[:max_lines]]


def _slow_lines(slow: SlowSearch | None, alpha: float, max_lines: int, shape: tuple[int, int]):
    """(runs [(bin, largest z, fap)], snr, cycles, carries (lines, y, x), the cycles of every slow
    bin that passes) of the slow search: the slow bins that pass, MERGE_GAP apart at most (the 4 slow
    bins: one line), at the bin of largest power above the bulk's median summed over the pixels (a
    sway's fundamental spreads over more pixels than its harmonics); each pixel's largest z within
    LINE_BINS of it and whether it passes Benjamini-Hochberg at alpha (its smallest p-value there,
    corrected for those bins). The line's frequency is its bin's (cycles / T), known to about a bin."""
    empty = np.zeros((0, *shape))
    if slow is None:
        return [], empty, empty, empty.astype(bool), ()
    excess = np.maximum(slow.z - slow.tails[0].median[None, :], 0.0).sum(axis=0)
    fap = slow.line_probability()
    runs = _runs(fap, excess, slow.z.max(axis=0), int(slow.bins[0]), alpha, max_lines)
    snr, cycles, carries = (np.zeros((len(runs), shape[0] * shape[1])) for _ in range(3))
    for k, (b, _, _) in enumerate(runs):
        near = np.flatnonzero(np.abs(slow.bins - b) <= LINE_BINS)
        logs = np.stack([slow.log_p(j) for j in near]).min(axis=0)
        snr[k] = slow.z[:, near].max(axis=1)
        cycles[k] = b + 1
        carries[k] = _benjamini_hochberg(corrected(logs, near.size), alpha)
    passing = tuple(int(c) for c in slow.bins[fap < alpha] + 1)
    return runs, *(m.reshape(len(runs), *shape) for m in (snr, cycles)), carries.reshape(len(runs), *shape) > 0, passing


def _benjamini_hochberg(p: np.ndarray, alpha: float) -> np.ndarray:
    """Boolean mask of the p-values that the Benjamini-Hochberg procedure at level alpha keeps."""
    flat = p.ravel()
    order = np.sort(flat)
    ok = np.flatnonzero(order <= alpha * np.arange(1, flat.size + 1) / flat.size)
    if ok.size == 0:
        return np.zeros(p.shape, dtype=bool)
    return p <= order[ok[-1]]


def _clusters(snr: np.ndarray, carries: np.ndarray):
    """(cluster map (y, x) int32 numbered by decreasing peak SNR, [(id, pixel mask)])."""
    from scipy import ndimage

    union = carries.any(axis=0)
    labels, n = ndimage.label(union, structure=np.ones((3, 3), dtype=bool))
    strength = np.where(carries, snr, 0.0).max(axis=0, initial=0.0)
    peaks = ndimage.maximum(strength, labels, index=np.arange(1, n + 1)) if n else []
    order = np.argsort(-np.asarray(peaks, dtype=float), kind="stable")
    out = np.zeros(labels.shape, dtype=np.int32)
    masks = []
    for new, old in enumerate(order, start=1):
        mask = labels == old + 1
        out[mask] = new
        masks.append((new, mask))
    return out, masks


def _region(mask: np.ndarray) -> tuple[int, tuple[float, float], tuple[int, int, int, int]]:
    ys, xs = np.nonzero(mask)
    return (
        int(ys.size),
        (float(ys.mean()), float(xs.mean())),
        (int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1),
    )


def detection_map(
    cube: xr.DataArray,
    *,
    band: tuple[float, float] | None = None,
    alpha: float = 1e-3,
    max_lines: int = 8,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = False,
    memory: int = DEFAULT_MEMORY,
) -> DetectionMap:
    """The per-pixel detection map of `cube` (time, y, x; lazy or in memory; float or integer
    counts; coord "time" in s, uniform or not) and its lines (module docstring). `band` (Hz) limits
    the search; `alpha` is the false-alarm probability of the whole map (lines) and the false
    fraction of a line's pixels; `scheduler` None runs on `workers` local threads (default: the
    cores), an address on that dask.distributed cluster; `memory` bounds the chunks in flight (bytes)."""
    cube = _check_cube(cube)
    if not (0.0 < float(alpha) < 1.0):
        raise InputError(f"--alpha: {alpha!r} is not a probability in (0, 1)")
    if isinstance(max_lines, bool) or not isinstance(max_lines, int) or max_lines < 1:
        raise InputError(f"--max-lines: {max_lines!r} is not an integer >= 1")
    if isinstance(memory, bool) or not (isinstance(memory, numbers.Real) and memory > 0):
        raise InputError(f"--memory: {memory!r} is not a number of bytes > 0")
    grid = frequency_grid(cube["time"].values, band)
    _, ny, nx = cube.shape
    n_pixels = ny * nx
    # dask's threads run the blocks in parallel: BLAS threads inside them would only contend
    # the pixels' powers are kept from the first pass for the second when they fit in a quarter of
    # `memory` (the rest bounds the blocks in flight); else the second pass reads the cube again
    spectra = n_pixels * grid.n_freq * 8
    keep_spectra = spectra <= int(memory) // 4
    ends = range_ends(cube)
    with (
        session(scheduler, workers, progress=progress) as run,
        threadpool_limits(1, user_api="blas"),
        contextlib.ExitStack() as scratch,
    ):
        budget = int(memory) - (spectra if keep_spectra else 0)
        plan = plan_chunks(cube.shape, cube.dtype.itemsize, run.threads, budget, grid.uniform)
        if cube.chunks is None:  # in memory or a lazy file backend: each block reads its own hyperslab
            data = cube.chunk({"time": -1, "y": plan.block_y, "x": plan.block_x}).data
        else:
            data = cube.data
        # kept: integer counts (decoded frames) read in pieces that span several blocks (module docstring)
        keep = plan.keep and np.issubdtype(cube.dtype, np.integer) and not aligned(data, plan)
        plan = dataclasses.replace(plan, keep=bool(keep))
        blocks = blocks_of(data, plan)
        logger.debug(f"detect: {len(blocks)} blocks of {plan.block_y} x {plan.block_x} pixels, batches of {plan.batch}")
        clock = time.perf_counter()
        spilled = _spill_wanted(data, plan, scheduler, cube.dtype)
        if spilled:  # decoded frames, not kept: decoded once into a scratch file per block (`spill`)
            blocks = _spilled(
                run, data, plan, Path(scratch.enter_context(tempfile.TemporaryDirectory(prefix="vibinverse-")))
            )
            logger.debug(f"detect: decoded once into {len(blocks)} block files in {time.perf_counter() - clock:.2f} s")
        if plan.keep:
            arrays = run.persist(*[b for _, _, b in blocks])
            blocks = [(ys, xs, a) for (ys, xs, _), a in zip(blocks, arrays)]
            logger.debug(f"detect: cube read and kept in {time.perf_counter() - clock:.2f} s")
        passes = [_delayed(first_pass)(_pieces(b), grid, plan.batch, keep_spectra, ends) for _, _, b in blocks]
        # the histograms of z are added up as the blocks finish (a tree of sums), not held per block
        sums = [_delayed(_item)(f, "z_counts") for f in passes]
        while len(sums) > 1:
            sums = [_delayed(_add)(*sums[i : i + SPLIT_EVERY]) for i in range(0, len(sums), SPLIT_EVERY)]
        *first, counts = run.compute(*[_delayed(_without)(f, "z_counts") for f in passes], sums[0])
        logger.debug(f"detect: first pass (peaks) {time.perf_counter() - clock:.2f} s")
        maps = {
            k: np.zeros((ny, nx), dtype=first[0][k].dtype)
            for k in ("peak_bin", "peak_frequency", "peak_snr", "mean_frame")
        }
        coef = np.zeros((ny, nx, first[0]["floor"].coef.shape[1]))
        scale = np.zeros((ny, nx, first[0]["floor"].scale.shape[1]))
        band_max = np.zeros(grid.n_searched)
        searched = first[0]["slow"] is not None
        slow_coef = np.zeros((ny, nx, LOW_BINS), dtype=np.complex128) if searched else None
        white, clip = (np.zeros((ny, nx, 2)), np.zeros((ny, nx), dtype=bool)) if searched else (None, None)
        changes = np.zeros((ny, nx), dtype=np.int32)
        for i, ((ys, xs, _), part) in enumerate(zip(blocks, first)):
            first[i] = {"power": part["power"]}  # the rest is placed in the frame's arrays below: let go
            for k in maps:
                maps[k][ys, xs] = part[k]
            coef[ys, xs] = part["floor"].coef.reshape(*part["mean_frame"].shape, -1)
            scale[ys, xs] = part["floor"].scale.reshape(*part["mean_frame"].shape, -1)
            np.maximum(band_max, part["band_max"], out=band_max)
            if searched:
                slow_coef[ys, xs] = part["slow"].reshape(*part["mean_frame"].shape, -1)
                white[ys, xs] = part["white"].reshape(*part["mean_frame"].shape, 2)
                clip[ys, xs] = part["clipped"].reshape(part["mean_frame"].shape)
            changes[ys, xs] = part["changes"].reshape(part["mean_frame"].shape)
        # the recording's own null, away from the frequencies that pass on white noise
        candidates = [b - grid.lo for b, _, _ in _lines_of(band_max, grid, n_pixels, float(alpha), grid.n_searched)]
        null = EmpiricalNull.from_counts(counts, band_max, np.asarray(candidates, dtype=np.int64))
        runs = _lines_of(band_max, grid, n_pixels, float(alpha), max_lines, null)
        maps["band_max"] = band_max
        floor = Floor(coef.reshape(n_pixels, -1), scale.reshape(n_pixels, -1))
        slow = None
        if searched:  # the slow bins, judged against the frame's pixels at each (`slow_lines`)
            slow = SlowSearch.from_parts(
                slow_coef.reshape(n_pixels, -1),
                white.reshape(n_pixels, 2),
                maps["mean_frame"],
                (clip.ravel(), changes.ravel()),
                floor,
                grid,
            )
            slow_coef = None
        bins = tuple(r[0] for r in runs)
        snr = np.zeros((len(bins), ny, nx))
        freq = np.zeros((len(bins), ny, nx))
        if bins:
            cols = line_bins(grid, bins)[1]
            if keep_spectra:  # the powers at the lines' bins, from the first pass's
                power = np.zeros((ny, nx, cols.size))
                for (ys, xs, _), part in zip(blocks, first):
                    power[ys, xs] = part["power"][:, cols].reshape(power[ys, xs].shape)
                power = power.reshape(n_pixels, -1)
            else:
                power = _line_powers(run, data, blocks, grid, cols, plan, maps["mean_frame"], memory, spilled)
            snr, freq = (m.reshape(len(bins), ny, nx) for m in line_maps(power, floor, grid, bins, memory))
            snr[:, changes < MIN_CHANGES] = 0.0  # too few events to carry a line (`first_pass`)
            how = "from the kept spectra" if keep_spectra else "second pass"
            logger.debug(f"detect: SNR maps of {len(bins)} lines, {how}: {time.perf_counter() - clock:.2f} s")
    log_p = _log_p(maps["peak_snr"], grid, null)
    pixel_fap = corrected(log_p, grid.n_searched)
    fap = corrected(log_p, grid.n_searched * n_pixels)
    carries = np.zeros((len(bins), ny, nx), dtype=bool)
    for k, b in enumerate(bins):
        width = min(grid.hi, b + LINE_BINS + 1) - max(grid.lo, b - LINE_BINS)
        carries[k] = _benjamini_hochberg(corrected(_log_p(snr[k], grid, null), width), float(alpha))
    slow_runs, slow_snr, cycles, slow_carries, passing = _slow_lines(slow, float(alpha), max_lines, (ny, nx))
    snr = np.concatenate([snr, slow_snr])
    freq = np.concatenate([freq, cycles * grid.df])
    carries = np.concatenate([carries, slow_carries])
    cluster, masks = _clusters(snr, carries)
    lines = _make_lines(runs, slow_runs, grid, snr, freq, carries, masks, null, slow, passing)
    ds = _dataset(cube, grid, maps, pixel_fap, fap, lines, snr, carries, cluster, masks, float(alpha), band, null, slow)
    logger.info(
        f"detect: {n_pixels} pixels x {grid.n_searched} frequencies ({grid.frequencies[grid.lo]:.4g} to "
        f"{grid.frequencies[grid.hi - 1]:.4g} Hz) and {grid.slow_bins.size if slow else 0} slow ones: "
        f"{len(lines)} line(s), {len(masks)} cluster(s)"
    )
    return DetectionMap(ds, lines)


def _spill_wanted(data: Any, plan: ChunkPlan, scheduler: str | None, dtype: Any) -> bool:
    """Whether to decode the cube once into block files (`spill`): integer counts (decoded frames)
    in pieces of whole frames that span several blocks, not kept in memory, on this machine (a
    cluster's workers do not share its scratch directory), with room on the scratch disk."""
    if plan.keep or scheduler is not None or not np.issubdtype(dtype, np.integer) or aligned(data, plan):
        return False
    if len(data.chunks[1]) != 1 or len(data.chunks[2]) != 1:
        return False
    need = int(np.prod(data.shape)) * np.dtype(dtype).itemsize
    if not Spill.fits(Path(tempfile.gettempdir()), need):
        logger.warning(
            f"detect: no room for {need / 2**20:.0f} MiB of scratch in {tempfile.gettempdir()}: "
            "the frames are decoded once per block"
        )
        return False
    return True


def _spilled(run: Any, data: Any, plan: ChunkPlan, directory: Path) -> list[tuple[slice, slice, Any]]:
    """The blocks of `blocks_of`, each read from its scratch file, after one decode of the pieces."""
    import dask.array as da

    cuts = _cuts(data.shape, plan)
    spill = Spill.create(directory, cuts, data.shape[0], data.dtype)
    starts = np.cumsum((0, *data.chunks[0]))[:-1]
    pieces = data.to_delayed().ravel().tolist()
    run.compute(*[_delayed(spill.write)(piece, int(t0)) for piece, t0 in zip(pieces, starts)])
    return [
        (ys, xs, da.from_delayed(_delayed(spill.read)(k), spill.shape(k), dtype=spill.dtype))
        for k, (ys, xs) in enumerate(cuts)
    ]


def _log_p(z: np.ndarray, grid: FrequencyGrid, null: EmpiricalNull) -> np.ndarray:
    """ln of a pixel's p-value at whitened power z: the larger of the white-noise tail and the
    recording's own (`EmpiricalNull.log_tail`)."""
    return np.maximum(log_tail(z, grid.half_width), null.log_tail(z))


def _line_powers(run, data, blocks, grid, cols, plan, mean_frame, memory, spilled=False) -> np.ndarray:
    """Every pixel's powers (pixels, K) at the grid's bins `cols`: on uniform stamps, unless the
    cube is kept or spilled or the sums would not fit, by `slab_sums` over slabs of whole frames, each read
    once in tasks of its own (dask fuses the slice into the read: contiguous frames are the
    cheapest reads), added up SPLIT_EVERY at a time; else block by block (`line_powers`)."""
    from dask.graph_manipulation import clone

    _, ny, nx = data.shape
    k2 = 2 * cols.size + 1
    itemsize = data.dtype.itemsize
    frames = max(-(-k2 * 8 // itemsize), int(min(SLAB_BYTES, memory / (4 * run.threads)) // (itemsize * ny * nx)))
    cuts = np.cumsum((0, *data.chunks[0]))
    edges = sorted(
        {
            int(e)
            for t0, t1 in itertools.pairwise(cuts)
            for e in np.linspace(t0, t1, -(-(t1 - t0) // frames) + 1).round()
        }
    )
    # held at worst: every slab's sums (dask may read the slabs ahead of the adds), and per thread a
    # slab as read, its copy and its float64 batches
    held = (len(edges) - 1) * k2 * ny * nx * 8 + 3 * run.threads * frames * ny * nx * max(itemsize, 8)
    if grid.uniform and not plan.keep and not spilled and held <= memory / 2:
        parts = [
            _delayed(slab_sums)(clone(data, seed=i)[t0:t1], slice(t0, t1), grid, cols, mean_frame, plan.batch)
            for i, (t0, t1) in enumerate(itertools.pairwise(edges))
        ]
        while len(parts) > 1:
            parts = [_delayed(_add)(*parts[i : i + SPLIT_EVERY]) for i in range(0, len(parts), SPLIT_EVERY)]
        (total,) = run.compute(parts[0])
        return dft_power(total.reshape(k2, -1), grid, cols)
    parts = run.compute(
        *[_delayed(line_powers)(_pieces(b), grid, cols, plan.batch, mean_frame[ys, xs].ravel()) for ys, xs, b in blocks]
    )
    parts = list(parts)
    power = np.zeros((ny, nx, cols.size))
    for k, (ys, xs, _) in enumerate(blocks):
        power[ys, xs] = parts[k].reshape(power[ys, xs].shape)
        parts[k] = None  # each block's part let go as it is placed
    return power.reshape(ny * nx, -1)


def _add(*arrays: np.ndarray) -> np.ndarray:
    total = arrays[0].copy()
    for a in arrays[1:]:
        total += a
    return total


def _item(part: dict[str, Any], key: str) -> Any:
    return part[key]


def _without(part: dict[str, Any], key: str) -> dict[str, Any]:
    return {k: v for k, v in part.items() if k != key}


def _delayed(fn):
    import dask

    return dask.delayed(fn, pure=True)


def _make_lines(runs, slow_runs, grid, snr, freq, carries, masks, null, slow, passing=()) -> list[Line]:
    """The lines of the `runs` of `_lines_of`, then those of the slow search (`_slow_lines`),
    classified (`line_checks`) and noted."""
    lines = [_line(k, run, grid, snr, freq, carries, masks) for k, run in enumerate([*runs, *slow_runs])]
    regular = [ln.frequency for ln in lines[: len(runs)]]
    combs = frame_combs(regular, 2.0 * grid.nyquist, grid.df) if grid.uniform else [None] * len(runs)
    out = []
    for k, line in enumerate(lines):
        common = {
            "frequency": line.frequency,
            "df": grid.df,
            "nyquist": grid.nyquist,
            "uniform": grid.uniform,
            "cluster_sizes": tuple(c.n_pixels for c in line.clusters),
        }
        if k < len(runs):
            j = runs[k][0] - grid.lo
            evidence = LineEvidence(
                **common, frame_median=float(null.frame_median[j]), frame_wide=null.frame_wide(j), comb_period=combs[k]
            )
        else:
            b = slow_runs[k - len(runs)][0]
            j = int(np.searchsorted(slow.bins, b))
            member = carries[k].ravel()
            evidence = LineEvidence(
                **common,
                frame_median=float(slow.frame_median[j]),
                frame_wide=slow.frame_wide(j),
                cycles=float(b + 1),
                slow_passing=tuple(c for c in passing if c != b + 1),
                clipped_share=float(slow.clipped[member].mean()) if member.any() else 0.0,
                motion_share=slow.motion_share(j, member),
                light_share=slow.light_share(j, member),
            )
        kind, why = classify(evidence)
        alias = 2.0 * grid.nyquist - line.frequency if grid.uniform else math.nan
        out.append(
            dataclasses.replace(
                line, kind=kind, reason=why, alias_frequency=alias, slow=k >= len(runs), note=notes(evidence)
            )
        )
    return out


def _line(k, run, grid, snr, freq, carries, masks) -> Line:
    """Line k of the `runs` of `_lines_of`, unclassified: its frequency, SNR and clusters."""
    b, zmax, fap = run
    member = carries[k]
    w = snr[k][member]
    f = float(np.sum(w * freq[k][member]) / np.sum(w)) if w.size and np.sum(w) > 0 else (b + 1) * grid.df
    parts = []
    for cid, mask in masks:
        sel = mask & member
        if sel.any():
            n, centroid, bbox = _region(sel)
            vals = snr[k][sel]
            parts.append(LineCluster(k, cid, n, centroid, bbox, float(vals.mean()), float(vals.max())))
    # the line's SNR: its SNR map's largest (zmax to rounding: the map comes from the second pass)
    top = float(snr[k].max()) if snr[k].size else zmax
    return Line(k, f, float((b + 1) * grid.df), top, fap, int(member.sum()), tuple(parts))


# (dims, units, long_name) of every variable of detection.nc; units "1": dimensionless; None: the cube's;
# "": none (text)
VARIABLES = {
    "peak_frequency": (("y", "x"), "Hz", "frequency of the pixel's strongest whitened periodogram peak in the band"),
    "peak_snr": (("y", "x"), "1", "whitened power at the pixel's peak (noise floor = 1)"),
    "false_alarm_probability": (
        ("y", "x"),
        "1",
        "false-alarm probability of the pixel's peak, corrected for the frequencies and pixels searched",
    ),
    "pixel_false_alarm_probability": (
        ("y", "x"),
        "1",
        "false-alarm probability of the pixel's peak, corrected for the frequencies searched",
    ),
    "mean_frame": (("y", "x"), None, "mean intensity over time"),
    "line_frequency": (("line",), "Hz", "frequency of the detected line (SNR-weighted over its pixels)"),
    "line_snr": (("line",), "1", "largest whitened power of the line over the pixels"),
    "line_false_alarm_probability": (
        ("line",),
        "1",
        "false-alarm probability of the line, corrected for the frequencies and pixels searched",
    ),
    "line_kind": (
        ("line",),
        None,
        "what the line is: vibration (claimed), or frame-wide, frame-pattern, unlocated, scattered, local-light, "
        "clipped, drift",
    ),
    "line_reason": (("line",), None, "why the line is not claimed as vibration (empty when it is)"),
    "line_slow": (("line",), "1", "1 where the line is the slow search's (1-4 cycles per record: `slow_lines`)"),
    "line_note": (("line",), None, "what to know about the line however it is classified (a slow line's), or empty"),
    "line_alias_frequency": (
        ("line",),
        "Hz",
        "the line's other reading, frame rate - frequency (a vibration above Nyquist shows below it)",
    ),
    "band_max_snr": (("frequency",), "1", "largest whitened power over the pixels at each searched frequency"),
    "frame_median_snr": (("frequency",), "1", "median whitened power over the pixels at each searched frequency"),
    "slow_max_snr": (
        ("slow_frequency",),
        "1",
        "largest power left by the common mode / white floor over the pixels at each slow bin (NaN: not searched)",
    ),
    "slow_null_median": (("slow_frequency",), "1", "median of that power over the pixels (the slow null's m)"),
    "slow_null_scale": (("slow_frequency",), "1", "scale of the slow null's gamma tail (shape at most 1/2)"),
    "slow_frame_median_snr": (
        ("slow_frequency",),
        "1",
        "median over the pixels of the power left by the common mode, whitened by the pixels' floors",
    ),
    "snr": (("line", "y", "x"), "1", "largest whitened power within one Fourier bin of the line"),
    "carries_line": (("line", "y", "x"), "1", "1 where the pixel carries the line (Benjamini-Hochberg at alpha)"),
    "cluster": (("y", "x"), "1", "cluster of pixels carrying a line: 0 none, k >= 1 cluster k (cluster_id)"),
    "line_of_cluster": (("cluster_id",), "1", "index (line) of the cluster's strongest line (largest mean SNR)"),
    "cluster_lines": (("cluster_id", "line"), "1", "1 where the cluster carries the line"),
}


def _slow_values(slow: SlowSearch | None, grid: FrequencyGrid) -> dict[str, np.ndarray]:
    """The slow search's variables of detection.nc at the grid's slow bins (NaN without a search)."""
    if slow is None:
        nan = np.full(grid.slow_bins.size, np.nan)
        return dict.fromkeys(("slow_max_snr", "slow_null_median", "slow_null_scale", "slow_frame_median_snr"), nan)
    return {
        "slow_max_snr": slow.z.max(axis=0),
        "slow_null_median": slow.tails[0].median,
        "slow_null_scale": slow.tails[0].gamma_scale,
        "slow_frame_median_snr": slow.frame_median,
    }


def _dataset(cube, grid, maps, pixel_fap, fap, lines, snr, carries, cluster, masks, alpha, band, null, slow):
    n_lines, n_clusters = len(lines), len(masks)
    cluster_lines = np.zeros((n_clusters, n_lines), dtype=np.int8)
    line_of_cluster = np.zeros(n_clusters, dtype=np.int32)
    for i, (_, mask) in enumerate(masks):
        means = np.full(n_lines, -np.inf)
        for k in range(n_lines):
            sel = mask & carries[k]
            if sel.any():
                cluster_lines[i, k] = 1
                means[k] = snr[k][sel].mean()
        line_of_cluster[i] = int(np.argmax(means))
    values = {
        "peak_frequency": maps["peak_frequency"],
        "peak_snr": maps["peak_snr"],
        "false_alarm_probability": fap,
        "pixel_false_alarm_probability": pixel_fap,
        "mean_frame": maps["mean_frame"],
        "line_frequency": np.array([ln.frequency for ln in lines], dtype=np.float64),
        "line_snr": np.array([ln.snr for ln in lines], dtype=np.float64),
        "line_false_alarm_probability": np.array([ln.false_alarm_probability for ln in lines], dtype=np.float64),
        "line_kind": np.array([ln.kind for ln in lines], dtype=object),
        "line_reason": np.array([ln.reason for ln in lines], dtype=object),
        "line_slow": np.array([ln.slow for ln in lines], dtype=np.int8),
        "line_note": np.array([ln.note for ln in lines], dtype=object),
        "line_alias_frequency": np.array([ln.alias_frequency for ln in lines], dtype=np.float64),
        "band_max_snr": maps["band_max"],
        "frame_median_snr": null.frame_median,
        **_slow_values(slow, grid),
        "snr": snr,
        "carries_line": carries.astype(np.int8),
        "cluster": cluster.astype(np.int32),
        "line_of_cluster": line_of_cluster,
        "cluster_lines": cluster_lines,
    }
    units = str(cube.attrs.get("units", "1"))
    ds = xr.Dataset(
        {
            name: (dims, values[name], {"long_name": text} | ({"units": u or units} if u != "" else {}))
            for name, (dims, u, text) in VARIABLES.items()
        },
        coords={
            "line": ("line", np.arange(n_lines), {"units": "1", "long_name": "detected line, strongest first"}),
            "frequency": (
                "frequency",
                grid.frequencies[grid.lo : grid.hi],
                {"units": "Hz", "long_name": "searched Fourier frequency"},
            ),
            "cluster_id": (
                "cluster_id",
                np.array([c for c, _ in masks], dtype=np.int32),
                {"units": "1", "long_name": "cluster"},
            ),
            "slow_frequency": (
                "slow_frequency",
                grid.frequencies[grid.slow_bins],
                {"units": "Hz", "long_name": "slow Fourier frequency searched (1-4 cycles per record)"},
            ),
        },
    )
    for dim in ("y", "x"):
        if dim in cube.coords and cube.coords[dim].dims == (dim,):
            ds = ds.assign_coords({dim: cube.coords[dim].values})
            ds[dim].attrs.update({k: v for k, v in cube.coords[dim].attrs.items() if isinstance(v, str | int | float)})
    lo_f, hi_f = grid.frequencies[grid.lo], grid.frequencies[grid.hi - 1]
    ds.attrs.update(
        {
            "title": "vibinverse detection map",
            "alpha": alpha,
            "band_searched_hz": np.array([lo_f, hi_f]),
            "band_requested_hz": np.array(band if band is not None else [np.nan, np.nan], dtype=np.float64),
            "frequency_resolution_hz": grid.df,
            "n_frequencies": grid.n_searched,
            "n_pixels": int(cube.sizes["y"] * cube.sizes["x"]),
            "n_frames": int(cube.sizes["time"]),
            "uniform_time": int(grid.uniform),
            "periodogram": "rfft" if grid.uniform else "Lomb-Scargle (nifty-ls, floating mean, psd)",
            "floor_window_bins": 2 * grid.half_width + 1,
            "empirical_null": (
                "line and pixel p-values: the larger of the white-noise tail and the recording's own "
                "(pooled whitened powers off the lines; the exponential tail of the per-frequency maxima)"
            ),
            "null_tail_threshold_scale": np.array(null.tail if null.tail else [np.nan, np.nan]),
            "slow_search": (
                "the first 4 Fourier frequencies apart: the power left by the frame's common mode over each "
                "pixel's white floor, against the exponential tail of the pixels' bulk at each bin"
                if slow is not None
                else "not searched (outside the band, or too few pixels with power)"
            ),
            "row_offset": "ignored: a per-row time shift changes the phase of a periodogram, not its power",
            "source": str(cube.attrs.get("source", "")),
            "Conventions": "CF-1.8",
        }
    )
    return ds
