"""Per-pixel detection maps: calibrated false-alarm probabilities on white noise, no false line on
coloured noise or drift, an injected line found at its frequency with its cluster exactly the
pixels that carry it (uniform or irregular stamps, 8-bit counts), chunking within a memory budget,
and a cube several times larger than the memory given to the process."""

import json
import logging
import math
import os
import subprocess
import sys
import textwrap

import dask.array as da
import numpy as np
import pytest
import xarray as xr
from hypothesis import example, given
from hypothesis import strategies as st
from scipy import stats
from scipy.signal import lfilter

from vibinverse.errors import DataError, InputError
from vibinverse.imaging.detection_map import WORK_BYTES_PER_SAMPLE, detection_map, plan_chunks
from vibinverse.imaging.whitening import frequency_grid, periodogram, whiten

FS = 100.0  # Hz
F0 = 12.34  # Hz: 126.4 bins of 1024 samples at 100 Hz, between two Fourier frequencies (the worst case)
BLOCK = (slice(10, 14), slice(20, 25))  # 4 x 5 pixels carrying the line


def cube_of(data, time, **attrs):
    return xr.DataArray(data, dims=("time", "y", "x"), coords={"time": time}, name="intensity", attrs=attrs)


def with_line(rng, noise, time, amplitude, block=BLOCK, f0=F0):
    """noise + amplitude * g * sin(2 pi f0 t) in `block`, g = +-1 at random (facets tilting either way)."""
    gains = np.zeros(noise.shape[1:])
    gains[block] = rng.choice([-1.0, 1.0], gains[block].shape)
    return noise + amplitude * np.sin(2 * np.pi * f0 * time)[:, None, None] * gains


def block_mask(shape, block=BLOCK):
    m = np.zeros(shape, dtype=bool)
    m[block] = True
    return m


# ----------------------------------------------------------------------------- noise: no false line
def test_white_noise_false_alarm_probability_is_calibrated_and_no_line_is_found():
    rng = np.random.default_rng(2)
    nt, n = 1024, 64
    t = np.arange(nt) / FS
    result = detection_map(cube_of(rng.standard_normal((nt, n, n)), t), workers=2)
    p = result.maps["pixel_false_alarm_probability"].values.ravel()
    for level in (0.01, 0.1):
        sd = math.sqrt(level * (1 - level) / p.size)  # 4096 independent pixels: binomial error
        assert abs(np.mean(p < level) - level) < 3 * sd, (level, np.mean(p < level))
    assert result.lines == [] and result.maps["cluster"].values.max() == 0
    assert result.maps.sizes["line"] == 0 and result.maps.sizes["cluster_id"] == 0


def test_the_corrected_rate_of_false_lines_on_noise_is_at_most_alpha():
    """50 pure-noise maps at alpha = 0.1: the count with any line is within what Binomial(50, 0.1)
    allows (at most its 99.9 % quantile; a calibrated or conservative map passes)."""
    rng = np.random.default_rng(3)
    nt, n, runs, alpha = 512, 12, 50, 0.1
    t = np.arange(nt) / FS
    hits = sum(
        bool(detection_map(cube_of(rng.standard_normal((nt, n, n)), t), alpha=alpha, workers=1).lines)
        for _ in range(runs)
    )
    assert hits <= stats.binom.ppf(0.999, runs, alpha), hits


def test_coloured_noise_and_drift_give_no_line_and_the_real_line_is_still_found():
    """AR(1) phi = 0.9 noise (25 dB of colour), then white noise under a large illumination drift
    (quadratic, a slow swing and a random walk per pixel): no line at alpha = 1e-3; with a line in a
    block of the AR(1) cube, that line and its block exactly."""
    rng = np.random.default_rng(4)
    nt, n = 1024, 40
    t = np.arange(nt) / FS
    ar1 = lfilter([1.0], [1.0, -0.9], rng.standard_normal((nt, n, n)), axis=0)
    s = t / t[-1]
    drift = (50 * s + 30 * s**2 + 20 * np.sin(2 * np.pi * 0.7 * s))[:, None, None]
    walk = 0.3 * np.cumsum(rng.standard_normal((nt, n, n)), axis=0)
    drifting = rng.standard_normal((nt, n, n)) + drift + walk
    for data in (ar1, drifting):
        result = detection_map(cube_of(data, t), workers=2)
        assert result.lines == [], [(ln.frequency, ln.false_alarm_probability) for ln in result.lines]
    result = detection_map(cube_of(with_line(rng, ar1, t, 1.0), t), workers=2)
    assert len(result.lines) == 1 and abs(result.lines[0].frequency - F0) < 1 / t.size * FS
    assert np.array_equal(result.maps["cluster"].values == 1, block_mask((n, n)))


def test_pixels_that_change_in_a_few_frames_carry_no_line():
    """A codec holds 40 % of the pixels at one count but for 2-4 one-count spikes (as time-shuffled
    real video shows), the others 8-bit noise, 888 frames at 250 fps: their periodograms are
    deterministic patterns, which claimed lines at 1-3 Hz in 2 of these 10 data sets before such
    pixels were left out (`MIN_CHANGES`); now no line is claimed and they carry none."""
    hits = 0
    for seed in range(10):
        rng = np.random.default_rng(seed)
        nt, n = 888, 40
        frames = 200 + 1.5 * rng.standard_normal((nt, n, n))
        held = rng.random((n, n)) < 0.4
        for y, x in np.argwhere(held):
            series = np.full(nt, 205.0)
            series[rng.choice(nt, rng.integers(2, 5), replace=False)] += 1
            frames[:, y, x] = series
        counts = np.clip(np.round(frames), 0, 255).astype(np.uint8)
        result = detection_map(cube_of(counts, np.arange(nt) / 250.0, bit_depth=8), workers=1)
        hits += any(ln.claimed for ln in result.lines)
        assert (result.maps["peak_snr"].values[held] == 0).all()
        assert not (result.maps["carries_line"].values.astype(bool) & held).any()
    assert hits == 0, hits


# ------------------------------------------------------------------------------- a line in a block
def check_found(result, shape, f0=F0, resolution=FS / 1024):
    assert len(result.lines) == 1, [(ln.frequency, ln.snr) for ln in result.lines]
    line = result.lines[0]
    assert abs(line.frequency - f0) < resolution, line.frequency  # within the resolution 1/T
    cluster = result.maps["cluster"].values
    assert np.array_equal(cluster == 1, block_mask(shape)) and cluster.max() == 1  # exactly the block
    (part,) = line.clusters
    assert (part.cluster, part.n_pixels, part.bbox) == (1, 20, (10, 14, 20, 25))
    assert part.centroid == pytest.approx((11.5, 22.0))
    assert line.false_alarm_probability < 1e-3
    return line


def test_a_line_in_a_block_of_mixed_sign_pixels_is_found_with_its_block():
    """Amplitude 1, noise 1, 1024 samples: SNR N A^2 / 4 sigma^2 = 256 on a Fourier frequency,
    >= 104 between two (the 0.405 scalloping loss), far above the ~30 a map of 2400 pixels needs."""
    rng = np.random.default_rng(5)
    nt, ny, nx = 1024, 40, 60
    t = np.arange(nt) / FS
    result = detection_map(cube_of(with_line(rng, rng.standard_normal((nt, ny, nx)), t, 1.0), t), workers=2)
    line = check_found(result, (ny, nx))
    ds = result.maps
    inside = block_mask((ny, nx))
    assert np.all(np.abs(ds["peak_frequency"].values[inside] - F0) < FS / nt)
    assert ds["snr"].values[0][inside].min() > 50 and line.snr == ds["snr"].values[0].max()
    assert ds["false_alarm_probability"].values[inside].max() < 1e-3
    assert (ds["line_of_cluster"].values.tolist(), ds["cluster_lines"].values.tolist()) == ([0], [[1]])
    for name, var in ds.data_vars.items():  # CF: units and long_name on every variable
        assert var.attrs.get("units") and var.attrs.get("long_name"), name


def test_irregular_stamps_find_the_same_line():
    """20 % jitter (uniform within +-0.2 of a step) and 10 % of the frames dropped: Lomb-Scargle."""
    rng = np.random.default_rng(6)
    nt, ny, nx = 1140, 30, 40
    t = (np.arange(nt) + rng.uniform(-0.2, 0.2, nt)) / FS
    t = np.sort(np.delete(t, rng.choice(nt, nt // 10, replace=False)))
    result = detection_map(cube_of(with_line(rng, rng.standard_normal((t.size, ny, nx)), t, 1.0), t), workers=2)
    assert result.maps.attrs["uniform_time"] == 0
    check_found(result, (ny, nx), resolution=1 / (t[-1] - t[0]))


def test_stamps_rounded_by_a_container_count_as_uniform():
    """30 fps stamps rounded to the millisecond (a Matroska time base): within 2 % of a step of a
    uniform grid, so the rfft at the mean step (33.33 ms, not the median 33 ms) finds the line."""
    rng = np.random.default_rng(13)
    nt, ny, nx, fps = 1024, 20, 30, 30.0
    t = np.round(np.arange(nt) / fps, 3)
    result = detection_map(cube_of(with_line(rng, rng.standard_normal((nt, ny, nx)), t, 1.0, f0=7.7), t), workers=1)
    assert result.maps.attrs["uniform_time"] == 1
    check_found(result, (ny, nx), f0=7.7, resolution=fps / nt)


def test_an_8_bit_quantized_cube_works():
    """Counts around 100 with noise sd 0.8 count and a line of 1 count: quantization (1/12 count^2)
    adds white noise; the counts stay uint8 up to the detector."""
    rng = np.random.default_rng(7)
    nt, ny, nx = 1024, 30, 40
    t = np.arange(nt) / FS
    analog = with_line(rng, 100 + 0.8 * rng.standard_normal((nt, ny, nx)), t, 1.0)
    counts = np.clip(np.round(analog), 0, 255).astype(np.uint8)
    result = detection_map(cube_of(counts, t, units="counts", bit_depth=8), workers=2)
    check_found(result, (ny, nx))
    assert result.maps["mean_frame"].values.mean() == pytest.approx(100, abs=0.05)
    assert result.maps["mean_frame"].attrs["units"] == "counts"


def test_two_lines_on_shared_pixels_make_one_cluster_carrying_both():
    """A roof carries its tilt resonance and its drive; another patch the drive only: two clusters,
    the first carrying both lines, each line listing the clusters that carry it."""
    rng = np.random.default_rng(8)
    nt, n = 1024, 32
    t = np.arange(nt) / FS
    roof, patch = (slice(4, 10), slice(4, 10)), (slice(20, 24), slice(25, 28))
    data = with_line(rng, rng.standard_normal((nt, n, n)), t, 1.2, roof, 7.3)
    data = with_line(rng, data, t, 0.9, roof, 21.1)
    data = with_line(rng, data, t, 0.9, patch, 21.1)
    result = detection_map(cube_of(data, t), workers=2)
    freqs = sorted(ln.frequency for ln in result.lines)
    assert len(freqs) == 2 and abs(freqs[0] - 7.3) < FS / nt and abs(freqs[1] - 21.1) < FS / nt
    cluster = result.maps["cluster"].values
    assert np.array_equal(cluster == 1, block_mask((n, n), roof))  # the stronger (tilt) cluster first
    assert np.array_equal(cluster == 2, block_mask((n, n), patch))
    tilt = next(ln.index for ln in result.lines if abs(ln.frequency - 7.3) < 1)
    drive = 1 - tilt
    lines_of = result.maps["cluster_lines"].values
    assert lines_of[0].tolist() == [1, 1] and lines_of[1][drive] == 1 and lines_of[1][tilt] == 0
    assert result.maps["line_of_cluster"].values.tolist() == [tilt, drive]
    rows = {(r["line"], r["cluster"]): r for r in result.table()}
    assert set(rows) == {(tilt, 1), (drive, 1), (drive, 2)} and rows[(drive, 2)]["n_pixels"] == 12


def test_a_damped_resonance_is_one_line():
    """A noise-driven resonance (AR(2), poles at radius 0.99: a 3 dB width of ~3 bins) in a block:
    its hump dips below the threshold between bins, yet it is one line, at its frequency."""
    rng = np.random.default_rng(14)
    nt, n, f_res, radius = 1024, 24, 15.0, 0.99
    t = np.arange(nt) / FS
    a = [1.0, -2 * radius * math.cos(2 * math.pi * f_res / FS), radius**2]
    resonance = lfilter([1.0], a, rng.standard_normal(nt))
    data = rng.standard_normal((nt, n, n))
    data[:, 4:8, 4:8] += 0.15 * resonance[:, None, None] * rng.choice([-1, 1], (4, 4))
    result = detection_map(cube_of(data, t), workers=1)
    assert len(result.lines) == 1 and abs(result.lines[0].frequency - f_res) < 3 * FS / nt
    assert np.array_equal(result.maps["cluster"].values == 1, block_mask((n, n), (slice(4, 8), slice(4, 8))))


def test_row_offset_changes_nothing():
    """A rolling shutter's per-row offset shifts phases only: the maps are the same."""
    rng = np.random.default_rng(9)
    nt, n = 512, 16
    t = np.arange(nt) / FS
    cube = cube_of(with_line(rng, rng.standard_normal((nt, n, n)), t, 1.0, (slice(2, 5), slice(2, 5))), t)
    shifted = cube.assign_coords(row_offset=("y", np.arange(n) * 3e-4))
    a, b = (detection_map(c, workers=1).maps for c in (cube, shifted))
    for name in ("peak_snr", "peak_frequency", "snr", "cluster"):
        assert np.array_equal(a[name].values, b[name].values), name


def test_the_snr_maps_are_the_whitened_periodogram_at_the_lines_whichever_second_pass(caplog):
    """The second pass's SNR map, from the first pass's kept spectra (the default, when they fit in
    a quarter of the memory), by slabs of frames (float cube in memory) or by kept blocks (8-bit
    counts read in time pieces; both with 3 MiB, where the 1 MiB of spectra is not kept), is each
    pixel's largest whitened power within one bin of the line, as the whole computation
    (periodogram, then whitening) gives it: the same sums in another order (rounding, < 1e-9)."""
    rng = np.random.default_rng(15)
    nt, ny, nx = 1024, 12, 20
    t = np.arange(nt) / FS
    analog = with_line(rng, 100 + 0.8 * rng.standard_normal((nt, ny, nx)), t, 1.0, (slice(2, 6), slice(3, 8)))
    counts = np.clip(np.round(analog), 0, 255).astype(np.uint8)
    grid = frequency_grid(t)
    z = whiten(periodogram(counts, grid), grid).reshape(grid.n_freq, ny, nx)
    small = 3 * 2**20
    caplog.set_level(logging.DEBUG, logger="vibinverse.imaging.detection_map")
    maps = [
        detection_map(cube_of(counts.astype(np.float64), t), workers=2),  # the spectra kept
        detection_map(cube_of(counts.astype(np.float64), t), workers=2, memory=small),  # aligned blocks: slabs
        detection_map(cube_of(da.from_array(counts, chunks=(100, ny, nx)), t), workers=2, memory=small),  # kept blocks
    ]
    for result in maps:
        (line,) = result.lines
        b = round(line.bin_frequency / grid.df) - 1
        np.testing.assert_allclose(result.maps["snr"].values[0], z[b - 1 : b + 2].max(axis=0), rtol=1e-9)
        assert line.snr == result.maps["snr"].values[0].max()
    how = [r.getMessage().split(", ")[-1].split(":")[0] for r in caplog.records if "SNR maps of" in r.getMessage()]
    assert how == ["from the kept spectra", "second pass", "second pass"]
    for other in maps[1:]:
        np.testing.assert_allclose(
            maps[0].maps["peak_frequency"].values, other.maps["peak_frequency"].values, rtol=1e-12
        )


# ------------------------------------------------------------------------------ chunks and memory
@given(
    st.integers(64, 100_000),
    st.integers(1, 300),
    st.integers(1, 300),
    st.sampled_from([1, 2, 4, 8]),
    st.integers(1, 16),
    st.integers(2**20, 2**32),
    st.booleans(),
)
@example(64, 3, 43, 1, 1, 2**20, False)  # two blocks per thread cut the block below the batch
def test_the_chunk_plan_keeps_the_blocks_in_flight_within_memory(nt, ny, nx, itemsize, threads, memory, uniform):
    try:
        plan = plan_chunks((nt, ny, nx), itemsize, threads, memory, uniform)
    except InputError as exc:
        assert str(exc).startswith("--memory:")  # one pixel's series and its work do not fit
        assert 2 * WORK_BYTES_PER_SAMPLE[uniform] * nt * threads > memory - nt * ny * nx * itemsize
        return
    assert 1 <= plan.block_y <= ny and 1 <= plan.block_x <= nx and 1 <= plan.batch <= plan.block_y * plan.block_x
    block = 2 * itemsize * nt * plan.block_y * plan.block_x  # stored dtype, x2 while assembled
    work = WORK_BYTES_PER_SAMPLE[uniform] * nt * plan.batch  # the float64 batch
    kept = nt * ny * nx * itemsize if plan.keep else 0
    assert threads * (block + work) + kept <= memory


def test_a_cube_split_in_time_is_read_block_by_block_with_the_same_maps():
    """Frames in time pieces (as video and netCDF give them) and little memory: each block reads
    its pixels from every piece; the maps equal those of the cube in memory."""
    rng = np.random.default_rng(11)
    nt, n = 1024, 24
    t = np.arange(nt) / FS
    data = with_line(rng, rng.standard_normal((nt, n, n)), t, 1.0, (slice(3, 6), slice(7, 9)))
    lazy = cube_of(da.from_array(data, chunks=(100, n, n)), t)
    small = detection_map(lazy, workers=2, memory=3 * 2**20)  # not kept: 4.5 MiB cube > a quarter of 3 MiB
    whole = detection_map(cube_of(data, t), workers=1)
    for name in ("peak_snr", "peak_frequency", "mean_frame", "snr", "cluster", "false_alarm_probability"):
        np.testing.assert_allclose(small.maps[name].values, whole.maps[name].values, rtol=1e-12, err_msg=name)


MEMORY_RUN = textwrap.dedent(
    """
    import json, resource, sys
    import numpy as np, xarray as xr
    from vibinverse.imaging.detection_map import detection_map

    def vm_data():
        return next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmData"))

    path, out, head, memory = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    # warm up on a tiny cube: imports, dask's thread pool, BLAS and FFT buffers are the baseline
    t = np.arange(4096) / 200.0
    tiny = xr.DataArray(np.zeros((4096, 2, 2), np.float32), dims=("time", "y", "x"), coords={"time": t})
    detection_map(tiny.chunk({"time": 512}), workers=2, memory=memory)
    base = vm_data()
    resource.setrlimit(resource.RLIMIT_DATA, (base + head, base + head))
    cube = xr.open_dataarray(path, engine="h5netcdf", chunks={"time": 512})  # frames in time pieces
    result = detection_map(cube, workers=2, memory=memory)
    np.savez(out, **{k: result.maps[k].values for k in ("peak_snr", "peak_frequency", "cluster")})
    print(json.dumps({"base": base, "lines": [ln.frequency for ln in result.lines]}))
    """
)


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_DATA and /proc: Linux")
def test_a_cube_several_times_the_memory_given_is_processed(tmp_path):
    """A 256 MiB float32 cube (its float64 copy: 512 MiB) read from netCDF by a process told it has
    24 MiB, whose data segment may grow by 96 MiB only (RLIMIT_DATA over the measured baseline): it
    runs, and its maps equal those of an unlimited run on a subset of rows. The same limit stops a
    run told it has 2 GiB (whose blocks and slabs, sized for it, do not fit), so the limit does bind.
    Why 96: beside the 24 MiB of blocks and slabs, the file's 32 MiB time pieces being read and
    glibc's per-thread arenas (2 workers) take the data segment to 71-73 MiB over the baseline
    without a limit (52-54 with one arena, MALLOC_ARENA_MAX=1); under a 64 MiB limit the run passed
    only when freed arena memory was reused in time (it failed about one CI run in three), and under
    96 MiB with an arena per thread it still failed once in ~6 CI runs. So the run has one arena."""
    rng = np.random.default_rng(12)
    nt, ny, nx = 4096, 128, 128
    t = np.arange(nt) / 200.0
    data = rng.standard_normal((nt, ny, nx), dtype=np.float32)
    block = (slice(60, 70), slice(30, 40))
    data[:, block[0], block[1]] += (0.5 * np.sin(2 * np.pi * 23.1 * t)).astype(np.float32)[:, None, None]
    path = tmp_path / "big.nc"
    cube = cube_of(data, t)
    cube.to_netcdf(path, engine="h5netcdf")
    head = 96 * 2**20
    assert data.nbytes >= 2.5 * head
    script = tmp_path / "run.py"
    script.write_text(MEMORY_RUN)

    def run(memory):
        out = tmp_path / f"maps{memory}.npz"
        args = [sys.executable, str(script), str(path), str(out), str(head), str(memory)]
        env = {**os.environ, "MALLOC_ARENA_MAX": "1"}  # one glibc arena: see the docstring
        return subprocess.run(args, capture_output=True, text=True, timeout=600, env=env), out

    r, out = run(24 * 2**20)
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(r.stdout.strip().splitlines()[-1])
    assert len(doc["lines"]) == 1 and abs(doc["lines"][0] - 23.1) < 200.0 / nt
    limited = np.load(out)
    rows = slice(56, 74)
    subset = detection_map(cube[:, rows, :], workers=2)
    for name in ("peak_snr", "peak_frequency"):  # per-pixel quantities: independent of the other pixels
        np.testing.assert_allclose(limited[name][rows], subset.maps[name].values, rtol=1e-12, err_msg=name)
    assert np.array_equal(limited["cluster"] == 1, block_mask((ny, nx), block))
    r, _ = run(2**31)
    # the limit binds: numpy's MemoryError, or OpenBLAS's when its buffers are what no longer fit
    assert r.returncode != 0 and ("MemoryError" in r.stderr or "Memory allocation" in r.stderr), r.stderr[-500:]


# ------------------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize(
    ("change", "error", "message"),
    [
        (lambda c: c.rename({"x": "u"}), DataError, "cube: dimensions must be"),
        (lambda c: c.assign_coords(time=c.time.values[::-1]), DataError, "time: stamps must increase"),
        (lambda c: c.isel(time=slice(0, 30)), DataError, r"time: 30 frame\(s\) are too few"),
        (lambda c: c.isel(time=slice(0, 1)), DataError, r"time: 1 frame\(s\) are too few .* \(at least 35\)"),
        (lambda c: c.astype(complex), DataError, "cube: real numbers"),
        (lambda c: c + 1e308, DataError, r"cube: values up to 1e\+308 overflow"),
    ],
)
def test_bad_cubes_are_one_line_errors(change, error, message):
    t = np.arange(256) / FS
    with pytest.raises(error, match=message) as info:
        detection_map(change(cube_of(np.zeros((256, 4, 4)), t)), workers=1)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"band": (20.0, 10.0)}, r"--band: 20:10 is not a band; allowed 0 <= fmin < fmax <= 50 Hz"),
        ({"band": (1.0, 80.0)}, "--band: fmax 80 Hz is above Nyquist"),
        ({"band": (0.0, 0.5)}, "--band: no searched frequency in 0:0.5 Hz"),
        ({"alpha": 0.0}, r"--alpha: 0.0 is not a probability in \(0, 1\)"),
        ({"max_lines": 0}, "--max-lines: 0 is not an integer >= 1"),
        ({"workers": 0}, "--workers: 0 is not a number of threads"),
        ({"memory": 1000}, r"--memory: 0.98 kiB is too little for 1 thread\(s\) on 256-sample series"),
    ],
)
def test_bad_options_are_one_line_errors(kwargs, message):
    t = np.arange(256) / FS
    with pytest.raises(InputError, match=message):
        detection_map(cube_of(np.zeros((256, 4, 4)), t), **{"workers": 1, **kwargs})
