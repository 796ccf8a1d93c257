"""The cube writers: a netCDF that re-makes its truth, and 8-bit video whose counts come back exactly."""

import json
from fractions import Fraction

import av
import imageio.v3 as iio
import numpy as np
import pytest
import xarray as xr
from hypothesis import given
from hypothesis import strategies as st

from forward.imager import render_cube
from forward.scene_file import load_scene, scene_from_table
from tests.conftest import SCENES
from vibinverse.errors import InputError
from vibinverse.io.cube_writer import (
    CUBE_VARIABLE,
    Quantization,
    coverage_variable,
    cube_dataset,
    plot_cube,
    quantization_for,
    write_cube_netcdf,
    write_video,
)

VIEW = ["footprint.x=[-40, 40]", "footprint.y=[-40, 40]", "sampling.duration=0.5", "noise.sigma=2"]


@pytest.fixture(scope="module")
def made():
    scene, table = load_scene(SCENES / "roof_frame.toml", VIEW)
    return table, render_cube(scene, 7, 5, seed=11)  # odd sizes on purpose (4:2:0 video wants even ones)


def read_video(path):
    """(counts (T, ny, nx) through imageio's PyAV plugin, stamps as exact fractions, comment JSON)."""
    frames = iio.imread(path, plugin="pyav", format="gray")
    with av.open(str(path)) as c:
        stream = c.streams.video[0]
        stamps = [f.pts * f.time_base for f in c.decode(stream)]
        comment = json.loads(c.metadata.get("comment") or c.metadata.get("COMMENT"))
    return frames.reshape(frames.shape[:3]), stamps, comment


def test_netcdf_carries_units_coordinates_and_the_truth(tmp_path, made):
    table, cube = made
    path = write_cube_netcdf(tmp_path / "cube.nc", cube, table, seed=11, version="9.9")
    assert [p.name for p in tmp_path.iterdir()] == ["cube.nc"]  # no temporary left beside it
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        da = ds[CUBE_VARIABLE]
        assert da.dims == ("time", "y", "x") and da.dtype == np.float64
        assert [v for v in ds.data_vars if ds[v].ndim == 3] == [CUBE_VARIABLE]  # the only cube: readers pick it
        assert da.attrs["units"] == "sr-1" and "eq. 22" in da.attrs["long_name"]
        assert ds.time.attrs["units"] == "s" and ds.x.attrs["units"] == "m" and ds.y.attrs["units"] == "m"
        np.testing.assert_array_equal(ds.x, cube.x)
        np.testing.assert_array_equal(ds.time, cube.time)
        np.testing.assert_array_equal(da, cube.intensity)
        np.testing.assert_array_equal(ds["coverage_roof"], cube.coverage["roof"])
        assert ds["coverage_roof"].attrs["surface"] == "roof"
        assert ds.attrs["seed"] == 11 and ds.attrs["fs"] == 200.0 and "9.9" in ds.attrs["source"]
        scene = scene_from_table(json.loads(ds.attrs["scene"]))
        again = render_cube(scene, ds.sizes["x"], ds.sizes["y"], seed=int(ds.attrs["seed"]))
        np.testing.assert_array_equal(again.intensity, da)  # the truth re-made from the file alone


def test_failed_netcdf_write_leaves_the_old_file(tmp_path, made, monkeypatch):
    table, cube = made
    path = tmp_path / "cube.nc"
    path.write_text("old")

    def fail(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", fail)
    with pytest.raises(OSError):
        write_cube_netcdf(path, cube, table)
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["cube.nc"]


def test_coverage_variable_names():
    assert coverage_variable("roof") == "coverage_roof"
    assert coverage_variable("glass pane/2") == "coverage_glass_pane_2"
    assert coverage_variable("a b", ["coverage_a_b"]) == "coverage_a_b_1"


@pytest.mark.parametrize("name", ["video.mp4", "video.mkv"])
def test_video_counts_come_back_exactly(tmp_path, made, name):
    _, cube = made
    quant = quantization_for(cube.intensity_clean)
    got = write_video(tmp_path / name, cube.intensity, 200.0, quantization=quant, metadata={"seed": 11})
    assert got == quant and [p.name for p in tmp_path.iterdir()] == [name]
    frames, stamps, comment = read_video(tmp_path / name)
    expected = quant.counts(cube.intensity)
    assert frames.dtype == np.uint8 and frames.shape == cube.shape == (100, 5, 7)
    np.testing.assert_array_equal(frames, expected)  # lossless: every count of every frame
    assert stamps == [Fraction(i, 200) for i in range(100)]  # 5 ms steps: exact in either container
    assert comment["quantization"] == quant.as_dict() and comment["seed"] == 11 and comment["fps"] == 200.0
    assert expected.min() > 0 and expected.max() < 255  # sd-2 noise stays inside the 5 % margins here


def test_mp4_stamps_are_exact_at_any_rate_and_mkv_rounds_to_milliseconds(tmp_path):
    frames = np.random.default_rng(0).integers(0, 256, (31, 4, 6), dtype=np.uint8)
    assert write_video(tmp_path / "a.mp4", frames, 30.0) is None  # counts as given
    back, stamps, comment = read_video(tmp_path / "a.mp4")
    np.testing.assert_array_equal(back, frames)
    assert stamps == [Fraction(i, 30) for i in range(31)] and "quantization" not in comment
    write_video(tmp_path / "a.mkv", frames, 30.0)
    _, mkv, _ = read_video(tmp_path / "a.mkv")
    err = max(abs(float(s) - i / 30) for i, s in enumerate(mkv))
    assert 1e-4 < err <= 0.5e-3  # Matroska's 1 ms clock: why the CLI writes MP4


@given(lo=st.floats(-1e3, 1e3), width=st.floats(1e-3, 1e3), u=st.floats(0, 1))
def test_quantization_error_is_at_most_half_a_step_inside_the_range(lo, width, u):
    q = quantization_for(np.array([lo, lo + width]))
    assert q.step == pytest.approx(width * 1.1 / 255, rel=1e-9)  # 5 % margin on each side
    x = lo + u * width
    assert abs(float(q.intensity(q.counts(x))) - x) <= q.step / 2 * (1 + 1e-9)


def test_quantization_clips_outside_the_range():
    q = Quantization(offset=0.0, step=1.0)
    np.testing.assert_array_equal(q.counts([-5.0, 0.4, 254.6, 300.0]), [0, 0, 255, 255])


@pytest.mark.parametrize(
    "name, frames, fps, message",
    [
        ("v.avi", np.zeros((2, 3, 3)), 10.0, "unknown video suffix; allowed: .mp4, .mkv"),
        ("v.mp4", np.zeros((2, 3, 3)), 0.0, "--video-fps: 0.0 is outside the allowed range (0, 1e+06]"),
        ("v.mp4", np.zeros((2, 3, 3)), float("nan"), "--video-fps: nan"),
        ("v.mp4", np.zeros((2, 3)), 10.0, "(time, y, x) array, got shape (2, 3)"),
        ("v.mp4", np.full((2, 3, 3), np.nan), 10.0, "must be finite"),
    ],
)
def test_bad_video_input_is_one_line_and_writes_nothing(tmp_path, name, frames, fps, message):
    with pytest.raises(InputError) as exc:
        write_video(tmp_path / name, frames, fps)
    assert message in str(exc.value) and "\n" not in str(exc.value)
    assert list(tmp_path.iterdir()) == []


def test_mean_frame_plot(tmp_path, made):
    _, cube = made
    plot_cube(tmp_path / "cube.png", cube, [("roof", (-25.0, 25.0), (-25.0, 25.0))], "roof")
    assert (tmp_path / "cube.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_dataset_without_table_or_seed(made):
    _, cube = made
    ds = cube_dataset(cube)
    assert ds.attrs["seed"] == "none" and ds.attrs["scene"] == "{}"
