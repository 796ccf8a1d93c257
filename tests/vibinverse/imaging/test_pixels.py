"""Choosing pixels and what each sees (vibinverse.imaging.pixels): selections and their one-line
errors, block reading, periodograms and noise floors, the seed band, band gains, optical-flow
gradients."""

import math

import imageio.v3 as iio
import numpy as np
import pytest
import xarray as xr

from vibinverse.errors import DataError, InputError
from vibinverse.imaging.pixels import (
    PixelMatrix,
    band_gains,
    choose_band,
    choose_bands,
    cluster_lines,
    cube_time,
    frame_axes,
    gradient_gains,
    mean_frame,
    noise_floor,
    noise_levels,
    parse_cluster,
    periodograms,
    seed_bands,
    seed_gains,
    select_pixels,
)


def make_cube(nt=64, ny=5, nx=7, seed=0, t=None):
    rng = np.random.default_rng(seed)
    t = np.arange(nt) / 50.0 if t is None else t
    return xr.DataArray(rng.normal(size=(nt, ny, nx)), dims=("time", "y", "x"), coords={"time": t})


def write_detection(path, cluster, **coords):
    xr.Dataset({"cluster": (("y", "x"), np.asarray(cluster, dtype=np.int32))}, coords=coords).to_netcdf(
        path, engine="h5netcdf"
    )


# ------------------------------------------------------------------ selections


def test_selections_all_mask_files_pairs_and_clusters(tmp_path):
    cube = make_cube()
    assert select_pixels(cube, "all").all()
    mask = np.zeros((5, 7), bool)
    mask[1:3, 2:5] = True
    np.save(tmp_path / "m.npy", mask)
    assert np.array_equal(select_pixels(cube, tmp_path / "m.npy"), mask)
    np.save(tmp_path / "ints.npy", mask.astype(np.uint8) * 7)  # nonzero = selected
    assert np.array_equal(select_pixels(cube, str(tmp_path / "ints.npy")), mask)
    iio.imwrite(tmp_path / "m.png", mask.astype(np.uint8) * 255)
    assert np.array_equal(select_pixels(cube, tmp_path / "m.png"), mask)
    rgba = np.zeros((5, 7, 4), np.uint8)
    rgba[..., 3] = 255  # an opaque alpha everywhere is not a selection
    rgba[mask, 1] = 200  # green where selected
    iio.imwrite(tmp_path / "rgba.png", rgba)
    assert np.array_equal(select_pixels(cube, tmp_path / "rgba.png"), mask)
    assert np.array_equal(select_pixels(cube, mask), mask)
    pairs = select_pixels(cube, [(0, 0), (4, 6)])
    assert pairs.sum() == 2 and pairs[0, 0] and pairs[4, 6]
    write_detection(tmp_path / "detection.nc", np.where(mask, 2, 0) + np.eye(5, 7, dtype=int))
    assert np.array_equal(select_pixels(cube, f"{tmp_path / 'detection.nc'}:2"), mask & ~np.eye(5, 7, dtype=bool))
    assert parse_cluster("run/detection.nc:3") == (tmp_path.__class__("run/detection.nc"), 3)
    assert parse_cluster("mask.png") is None


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: np.save(d / "a.npy", np.ones((4, 4), bool)) or d / "a.npy", "the mask a.npy is 4 x 4; the cube"),
        (
            lambda d: iio.imwrite(d / "b.png", np.full((6, 6), 255, np.uint8)) or d / "b.png",
            "the mask b.png is 6 x 6",
        ),
        (lambda d: np.save(d / "z.npy", np.zeros((5, 7))) or d / "z.npy", "the selection is empty"),
        (lambda d: (d / "m.txt").write_text("1") and d / "m.txt", "unknown mask format"),
        (lambda d: d / "missing.npy", "file not found"),
        (
            lambda d: write_detection(d / "det.nc", np.ones((5, 7))) or f"{d / 'det.nc'}:3",
            "has no cluster 3; its clusters: 1",
        ),
        (lambda d: write_detection(d / "det.nc", np.ones((5, 7))) or f"{d / 'det.nc'}:0", "has no cluster 0"),
        (lambda d: write_detection(d / "det.nc", np.ones((5, 7))) or f"{d / 'det.nc'}", "name the cluster"),
        (lambda d: f"{d / 'det.nc'}:one", "must be an integer"),
        (
            lambda d: write_detection(d / "det.nc", np.ones((3, 3))) or f"{d / 'det.nc'}:1",
            "detection map det.nc is 3 x 3",
        ),
        (
            lambda d: write_detection(d / "det.nc", np.ones((5, 7)), y=np.arange(5) + 10) or f"{d / 'det.nc'}:1",
            "other y coordinates",
        ),
        (lambda d: [(9, 0)], r"\(9, 0\) is outside the frame"),
        (lambda d: np.ones((5, 7)), "a boolean \\(y, x\\) array or \\(y, x\\) pairs"),
    ],
)
def test_a_bad_selection_is_one_line(tmp_path, make, message):
    cube = make_cube().assign_coords(y=np.arange(5), x=np.arange(7))
    with pytest.raises(InputError, match=message) as err:
        select_pixels(cube, make(tmp_path))
    assert "\n" not in str(err.value) and str(err.value).startswith("pixels: ")


def test_a_detection_map_without_clusters_and_a_cube_without_frames_are_refused(tmp_path):
    xr.Dataset({"snr": (("y", "x"), np.ones((5, 7)))}).to_netcdf(tmp_path / "d.nc", engine="h5netcdf")
    with pytest.raises(InputError, match="has no variable 'cluster'"):
        select_pixels(make_cube(), f"{tmp_path / 'd.nc'}:1")
    with pytest.raises(InputError, match=r"dimensions \(time, y, x\)"):
        frame_axes(xr.DataArray(np.ones((3, 4)), dims=("y", "x")))
    (tmp_path / "bad.npy").write_bytes(b"not numpy")
    with pytest.raises(DataError, match="cannot read the mask"):
        select_pixels(make_cube(), tmp_path / "bad.npy")


# ------------------------------------------------------------------ access


def test_blocks_read_the_selected_pixels_in_row_major_order_from_numpy_and_dask():
    cube = make_cube(nt=40, ny=6, nx=5).assign_coords(row_offset=("y", np.arange(6) * 1e-4))
    cube.attrs["units"] = "counts"
    mask = np.random.default_rng(1).random((6, 5)) < 0.5
    want = cube.values[:, mask]
    for c, kw in ((cube, {}), (cube.chunk({"time": 7, "y": 2}), {"block_bytes": 1, "memory_bytes": 0})):
        m = PixelMatrix(c, mask, **kw)
        got = np.concatenate([b for _, b in m.blocks()], axis=1)
        assert np.array_equal(got, want) and got.dtype == np.float64
        assert [(sl.start, sl.stop) for sl, _ in m.blocks()][-1][1] == mask.sum()
        assert np.array_equal(m.y, np.nonzero(mask)[0]) and m.units == "counts"
        assert m.row_offset() == pytest.approx(np.nonzero(mask)[0] * 1e-4)
    cube = cube.transpose("x", "time", "y")  # any order of the dimensions
    assert np.array_equal(np.concatenate([b for _, b in PixelMatrix(cube, mask).blocks()], axis=1), want)


def test_datetime_stamps_become_seconds_and_the_mean_frame_is_chunked():
    t = np.datetime64("2024-05-01T12:00:00") + np.arange(10) * np.timedelta64(20, "ms")
    cube = make_cube(nt=10, t=t)
    assert cube_time(cube) == pytest.approx(np.arange(10) * 0.02)
    assert mean_frame(cube.chunk({"time": 3})) == pytest.approx(cube.values.mean(axis=0))


# ------------------------------------------------------------------ spectra and seeds


def test_periodograms_on_uniform_and_irregular_stamps_and_the_noise_floor():
    """A sinusoid of amplitude A over T samples has |sum y e^{-iwt}|^2 / T = A^2 T / 4 at its
    frequency, on a uniform grid (rfft) and on jittered stamps (nifty-ls; within 10 %: the jitter's
    0.5 ms at 10 Hz is 3 % of a radian); white noise of sd 2 has a floor of 4 within 10 % (the median
    of 500 exponential bins has a relative sd of ~4.5 %; 20 pixels averaged: 1 %)."""
    rng = np.random.default_rng(3)
    t = np.arange(1000) / 100.0
    y = np.stack([3 * np.cos(2 * np.pi * 10 * t), rng.normal(0, 2, t.size)], axis=1)
    f, p = periodograms(t, y)
    k = int(np.argmin(np.abs(f - 10)))
    assert p[0, k] == pytest.approx(9 * 1000 / 4, rel=1e-6)
    tj = t + rng.uniform(-5e-4, 5e-4, t.size)
    fj, pj = periodograms(tj, np.stack([3 * np.cos(2 * np.pi * 10 * tj)], axis=1))
    assert pj[0].max() == pytest.approx(9 * 1000 / 4, rel=0.1) and fj[np.argmax(pj[0])] == pytest.approx(10, abs=0.1)
    noise = rng.normal(0, 2, (2000, 20))
    floors = noise_floor(periodograms(np.arange(2000) / 100.0, noise)[1])
    assert np.all(np.abs(floors / 4 - 1) < 0.2) and floors.mean() == pytest.approx(4, rel=0.05)


def _resonance_pixels(sigma: float, seed: int) -> tuple[PixelMatrix, np.ndarray]:
    """16 pixels seeing one resonance (5 Hz, damping 0.05, rms 1; 40 s at 50 Hz) with gains
    +-(0.7..1.3), a third of them negative, in white noise of sd sigma."""
    from vibinverse.io.series import Series
    from vibinverse.models import build_model

    t = np.arange(2000) / 50.0
    model = build_model({"modal": {"modes": 1}}, Series(t, np.random.default_rng(0).normal(size=t.size), "shape"))
    rng = np.random.default_rng(seed)
    truth = {"level": 0, "modes[0].frequency": 5.0, "modes[0].damping_ratio": 0.05, "modes[0].rms": 1.0}
    s = model.replicate({**truth, "noise.sigma": 0.0}, rng)
    g = np.where(np.arange(16) % 3 == 0, -1.0, 1.0) * np.linspace(0.7, 1.3, 16)
    y = 40 + np.outer(s, g) + rng.normal(0, sigma, (t.size, 16))
    cube = xr.DataArray(y.reshape(-1, 4, 4), dims=("time", "y", "x"), coords={"time": t})
    return PixelMatrix(cube, np.ones((4, 4), bool)), g


def test_the_seed_band_finds_a_weak_broad_resonance_and_band_gains_recover_the_gains():
    """A resonance at 0.9 x the white noise's level at its peak in each of 16 pixels (noise sd 6):
    its ~20-bin width is found (the band overlaps the half-power width 4.75-5.25 Hz) and the band's
    gains have every sign right (40 of 40 seeds); at peak / noise 3.5 (sd 3) the gains, up to
    their scale, are within 0.4 of the truth (their sd ~0.07; measured max over 40 seeds of 16
    pixels 0.34). Noise levels (the periodograms' floors) within 15 % (median of 500 exponential
    bins: ~4.5 % sd; measured max 10 %)."""
    matrix, g = _resonance_pixels(6.0, 7)
    levels = noise_levels(matrix)
    assert levels.sigma == pytest.approx(np.full(16, 6.0), rel=0.15)
    band = levels.freqs[choose_band(levels, 16)]
    assert band[0] < 5.25 and band[-1] > 4.75 and band.size >= 9
    seed = seed_gains(matrix, levels)
    assert seed.band == (band[0], band[-1]) and seed.coef.shape == (16, band.size)
    assert np.array_equal(np.sign(band_gains(seed.coef, levels.sigma)), np.sign(g))
    matrix, g = _resonance_pixels(3.0, 8)
    levels = noise_levels(matrix)
    b = band_gains(seed_gains(matrix, levels).coef, levels.sigma)
    assert np.max(np.abs(b * (b @ g) / (b @ b) - g)) < 0.4
    with pytest.raises(InputError, match=r"band: .* holds no frequency"):
        choose_band(levels, 16, (30.0, 40.0))
    with pytest.raises(InputError, match="allowed 0 <= fmin < fmax"):
        choose_band(levels, 16, (8.0, 2.0))


def test_optical_flow_gains_are_the_negative_gradient_to_fourth_order():
    """I = 40 sin(2 pi x / 10) + 30 cos(2 pi y / 12): -dI/dx inside to (k h)^4 / 30 = 0.52 % of its
    amplitude (measured 0.50 % along x, 0.24 % along y), at the border to numpy.gradient's one-sided
    second order, (k h)^2 / 3 = 13 % (measured 11 %)."""
    yy, xx = np.mgrid[0:20, 0:24].astype(float)
    frame = 40 * np.sin(2 * np.pi * xx / 10) + 30 * np.cos(2 * np.pi * yy / 12)
    kx, ky = 2 * np.pi / 10, 2 * np.pi / 12
    gx, gy = gradient_gains(frame, "x"), gradient_gains(frame, "y", scale=0.5)
    want_x = -40 * kx * np.cos(kx * xx)
    want_y = 30 * ky * np.sin(ky * yy) / 0.5
    assert np.max(np.abs(gx - want_x)[:, 2:-2]) < kx**4 / 30 * 40 * kx
    assert np.max(np.abs(gy - want_y)[2:-2]) < ky**4 / 30 * 30 * ky / 0.5
    assert np.max(np.abs(gx - want_x)) < kx**2 / 3 * 40 * kx
    for bad, msg in (({"axis": "z"}, "displacement: 'z'"), ({"axis": "x", "scale": 0.0}, "scale: 0 metres")):
        with pytest.raises(InputError, match=msg):
            gradient_gains(frame, **bad)
    with pytest.raises(InputError, match="at least 3 are needed"):
        gradient_gains(frame[:, :2], "x")
    assert math.isfinite(gradient_gains(frame[:, :4], "x").sum())  # 3-4 pixels: second order only


def _two_line_pixels(seed: int) -> tuple[PixelMatrix, np.ndarray]:
    """12 pixels, 20 s at 50 Hz, noise sd 1: a strong line at 6.0 Hz (amplitude 1) through gains
    g[:, 0] and a weaker one at 13.0 Hz (amplitude 0.3) through g[:, 1] (mixed signs)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1000) / 50.0
    g = rng.choice([-1.0, 1.0], (12, 2)) * rng.uniform(0.5, 1.5, (12, 2))
    s = np.stack([np.cos(2 * np.pi * 6.0 * t), 0.3 * np.cos(2 * np.pi * 13.0 * t + 1)], axis=1)
    y = s @ g.T + rng.normal(size=(t.size, 12))
    cube = xr.DataArray(y.reshape(t.size, 3, 4), dims=("time", "y", "x"), coords={"time": t})
    return PixelMatrix(cube, np.ones((3, 4), bool)), g


def test_the_bands_of_several_sources_found_given_or_around_detected_lines():
    """Two lines (amplitude SNR per pixel ~22 and ~7 over 20 s): the two strongest separated bands
    hold 6.0 and 13.0 Hz, in increasing frequency, whatever their strength; given bands are kept
    in their order; around the centres of a detection map's lines too (strongest first). Each
    band's coefficients (`seed_bands`, one pass) give that line's gains with every sign right
    (amplitude SNR >= 3.5 a pixel). Fewer bands than sources: one-line errors."""
    matrix, g = _two_line_pixels(3)
    levels = noise_levels(matrix)
    found = choose_bands(levels, 12, 2)
    assert [levels.freqs[b][0] <= f <= levels.freqs[b][-1] for b, f in zip(found, (6.0, 13.0))] == [True, True]
    seeds = seed_bands(matrix, levels, found)
    for j, seed in enumerate(seeds):
        b = band_gains(seed.coef, levels.sigma)
        assert np.array_equal(np.sign(b * (b @ g[:, j])), np.sign(g[:, j]))
    given = choose_bands(levels, 12, 2, bands=[(12.0, 14.0), (5.0, 7.0)])
    assert levels.freqs[given[0]][0] > 12.0 and levels.freqs[given[1]][-1] < 7.0
    around = choose_bands(levels, 12, 2, centres=[13.0, 6.0])
    assert [levels.freqs[b][0] <= f <= levels.freqs[b][-1] for b, f in zip(around, (13.0, 6.0))] == [True, True]
    with pytest.raises(InputError, match="bands: 1 given for 2 sources"):
        choose_bands(levels, 12, 2, bands=[(5.0, 7.0)])
    with pytest.raises(InputError, match="carries only 1 line"):
        choose_bands(levels, 12, 2, centres=[6.0])


def test_the_lines_of_a_detection_cluster_strongest_first(tmp_path):
    path = tmp_path / "detection.nc"
    xr.Dataset(
        {
            "cluster": (("y", "x"), np.array([[1, 1], [2, 0]], dtype=np.int32)),
            "line_frequency": (("line",), np.array([6.0, 13.0, 2.5])),
            "cluster_lines": (("cluster_id", "line"), np.array([[1, 0, 1], [0, 1, 0]], dtype=np.int8)),
        },
        coords={"cluster_id": [1, 2], "line": [0, 1, 2]},
    ).to_netcdf(path, engine="h5netcdf")
    assert cluster_lines(path, 1) == [6.0, 2.5] and cluster_lines(path, 2) == [13.0]
    write_detection(tmp_path / "bare.nc", [[1, 0], [0, 0]])
    assert cluster_lines(tmp_path / "bare.nc", 1) == []


@pytest.mark.parametrize(
    ("values", "message"),
    [
        (np.full((200, 3, 3), 7.0), "every selected pixel is constant"),
        (np.full((200, 3, 3), 1e308), r"values up to 1e\+308 overflow"),
    ],
)
def test_a_constant_or_overflowing_cube_is_a_one_line_error(values, message):
    """Nothing varies, or squares leave float64: a one-line DataError before any spectrum (a
    constant cube and a cube of 1e308 ended in "SVD did not converge" with a traceback)."""
    cube = xr.DataArray(values, dims=("time", "y", "x"), coords={"time": np.arange(200) / 50.0})
    with pytest.raises(DataError, match=message) as info:
        noise_levels(PixelMatrix(cube, np.ones((3, 3), bool)))
    assert "\n" not in str(info.value)
