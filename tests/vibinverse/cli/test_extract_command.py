"""`vibinverse extract`: a region of a recording as a cube and as series that `load_series` reads;
bad inputs are one line, exit 2, and leave nothing behind."""

import contextlib
import io
import json
from fractions import Fraction

import numpy as np
import pytest

from tests.vibinverse.io.test_cube import RNG_SEED, vfr_stamps, write_video
from vibinverse.cli import main
from vibinverse.cli.extract_command import CUBE_WRITERS
from vibinverse.errors import DataError
from vibinverse.io.cube import open_cube
from vibinverse.io.series import load_series

FPS = 50.0


def call(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def extract(*args: str) -> dict:
    code, out, err = call("extract", *args, "--json")
    assert code == 0, err
    return json.loads(out)


def no_temporaries(folder):
    return not [p for p in folder.rglob("*") if p.name.endswith(".part")]


@pytest.fixture
def counts(tmp_path):
    """An 8-bit cube in a .npy file (no time stamps: --fps gives them)."""
    frames = np.random.default_rng(RNG_SEED).integers(0, 256, (20, 8, 10), dtype=np.uint8)
    np.save(tmp_path / "counts.npy", frames)
    return tmp_path / "counts.npy", frames


@pytest.fixture
def video(tmp_path):
    """A lossless gray video with a variable frame rate (ffv1 in Matroska, 1 ms stamps)."""
    rng = np.random.default_rng(RNG_SEED)
    frames = rng.integers(0, 256, (30, 8, 10), dtype=np.uint8)
    pts = vfr_stamps(30, 33, rng, dropped=[4, 17])
    return write_video(tmp_path / "vfr.mkv", frames, pts, Fraction(1, 1000)), frames, (pts - pts[0]) / 1000


def test_roi_writes_the_cube_and_reports_it(counts, tmp_path):
    path, frames = counts
    out = tmp_path / "out"
    doc = extract(path, "--fps", FPS, "--roi", "2:8,1:5", "-o", out)
    assert doc["paths"] == [str(out / "cube.nc")] and doc["cube"] == str(out / "cube.nc") and doc["series"] is None
    assert doc["shape"] == [20, 4, 6] and doc["dtype"] == "uint8" and doc["bit_depth"] == 8
    assert doc["fps"] == pytest.approx(FPS, rel=1e-12) and doc["irregular"] is False
    cube = open_cube(out / "cube.nc")
    assert cube.dtype == np.uint8 and np.array_equal(cube.values, frames[:, 1:5, 2:8])
    assert list(cube["row"].values) == [1, 2, 3, 4] and list(cube["col"].values) == [2, 3, 4, 5, 6, 7]
    assert cube.attrs["units"] == "counts" and cube.attrs["bit_depth"] == 8
    np.testing.assert_allclose(cube["time"].values, np.arange(20) / FPS, rtol=0, atol=1e-15)
    assert sorted(p.name for p in out.iterdir()) == ["cube.nc"]


def test_video_pixel_series_with_line_time_read_by_load_series(video, tmp_path):
    path, frames, stamps = video
    out = tmp_path / "out"
    line = 1e-4  # s per row: 8 rows read out in 0.8 ms < the 33 ms frame interval
    doc = extract(path, "--roi", "3:7,2:5", "--line-time", line, "--series", "pixel", "-o", out)
    assert doc["irregular"] is True and doc["n_series"] == 12 and doc["series"] == str(out / "series")
    files = sorted((out / "series").iterdir())
    assert len(files) == 12 and files[0].name == "y2_x3.csv"
    for y in range(2, 5):
        for x in range(3, 7):
            s = load_series(out / "series" / f"y{y}_x{x}.csv")
            # the row's delay is added to the frame's stamp: 17 significant digits keep it to rounding
            np.testing.assert_allclose(s.time, stamps + y * line, rtol=0, atol=1e-15)
            assert np.array_equal(s.intensity, frames[:, y, x])
            assert not s.uniform  # jitter and dropped frames are kept
    cube = open_cube(out / "cube.nc")
    np.testing.assert_allclose(cube["row_offset"].values, np.arange(2, 5) * line, rtol=1e-15)


def test_mask_binning_and_region_series(counts, tmp_path):
    path, frames = counts
    mask = np.zeros((8, 10), bool)
    mask[2:6, 1:9] = True
    mask[2, 1] = False
    np.save(tmp_path / "mask.npy", mask)
    out = tmp_path / "out"
    doc = extract(path, "--fps", FPS, "--mask", tmp_path / "mask.npy", "--bin", 2, "--series", "region", "-o", out)
    assert doc["paths"] == [str(out / "cube.nc"), str(out / "series.csv")] and doc["shape"] == [20, 2, 4]
    assert doc["dtype"] == "float64" and doc["bit_depth"] == 8  # binned counts are means, the depth is kept
    masked = np.where(mask[2:6, 1:9], frames[:, 2:6, 1:9], np.nan)
    binned = np.nanmean(masked.reshape(20, 2, 2, 4, 2), axis=(2, 4))  # the first bin has 3 pixels
    cube = open_cube(out / "cube.nc")
    np.testing.assert_allclose(cube.values, binned, rtol=1e-15)
    s = load_series(out / "series.csv")
    np.testing.assert_allclose(s.intensity, binned.mean(axis=(1, 2)), rtol=1e-14)  # sums of 8 values
    np.testing.assert_allclose(s.time, np.arange(20) / FPS, rtol=0, atol=1e-15)


def test_frames_and_zarr_output_replaced_by_a_second_run(counts, tmp_path):
    path, frames = counts
    out = tmp_path / "out"
    doc = extract(path, "--fps", FPS, "--frames", "3:15", "--format", "zarr", "--chunks", "4", "-o", out)
    assert doc["paths"] == [str(out / "cube.zarr")] and doc["shape"] == [12, 8, 10]
    cube = open_cube(out / "cube.zarr")
    assert np.array_equal(cube.values, frames[3:15]) and cube.attrs["first_frame"] == 3
    np.testing.assert_allclose(cube["time"].values, np.arange(12) / FPS, rtol=0, atol=1e-15)
    extract(path, "--fps", FPS, "--frames=-5:", "--format", "zarr", "-o", out)
    assert np.array_equal(open_cube(out / "cube.zarr").values, frames[-5:])
    assert sorted(p.name for p in out.iterdir()) == ["cube.zarr"] and no_temporaries(out)


def test_help_names_the_fixed_files():
    with pytest.raises(SystemExit) as done:
        call("extract", "--help")
    assert done.value.code == 0
    text = " ".join(output_help().split())
    assert (
        "-o DIR, --output DIR output directory (default: extract); writes cube.nc (--format netcdf) or cube.zarr "
        "(--format zarr), series.csv (--series region), series/y{Y}_x{X}.csv (--series pixel)" in text
    )


def output_help() -> str:
    from vibinverse.cli.commands import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices["extract"].format_help()


@pytest.fixture
def bad_files(tmp_path, video):
    np.save(tmp_path / "flat.npy", np.zeros((4, 5)))
    np.save(tmp_path / "mask.npy", np.ones((3, 3), bool))
    (tmp_path / "junk.mp4").write_bytes(b"not a video " * 50)
    (tmp_path / "codec.mkv").write_bytes(video[0].read_bytes().replace(b"V_FFV1", b"V_QQQQ"))
    (tmp_path / "a.xyz").write_text("x")
    return tmp_path


@pytest.mark.parametrize(
    "args,message",
    [
        (["none.mp4"], "input: file not found"),
        (["a.xyz"], "unknown file type '.xyz'; supported: .mp4"),
        (["counts.npy"], "fps: counts.npy carries no time stamps"),
        (["flat.npy", "--fps", "5"], r"frames of shape (4, 5)"),
        (["junk.mp4"], "as a video"),
        (["codec.mkv"], "video codec cannot be decoded"),
        (["counts.npy", "--fps", "5", "--roi", "0:11,0:4"], "roi: x 0:11, y 0:4; allowed 0 <= x0 < x1 <= 10"),
        (["counts.npy", "--fps", "5", "--roi", "0-4,0:4"], "invalid region '0-4,0:4'"),
        (["counts.npy", "--fps", "5", "--mask", "{d}/mask.npy"], r"mask: shape (3, 3); the frame's shape (8, 10)"),
        (["counts.npy", "--fps", "5", "--mask", "{d}/nomask.png"], "mask: file not found"),
        (["counts.npy", "--fps", "5", "--mask", "{d}/mask.npy", "--roi", "0:2,0:2"], "not allowed with argument"),
        (["counts.npy", "--fps", "5", "--bin", "0"], "--bin: 0 is outside the allowed range [1, 1000000]"),
        (["counts.npy", "--fps", "5", "--frames", "5:3"], "frames: 5:3 selects no frame"),
        (["counts.npy", "--fps", "5", "--line-time", "0.1"], "line_time: 0.1 s x 8 rows exceeds"),
        (["counts.npy", "--fps=-5"], "--fps: -5 is outside the allowed range (0, inf)"),
        (["counts.npy", "--fps", "5", "--variable", "v"], "variable: 'v' applies to netCDF and zarr"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_nothing_written(bad_files, counts, args, message):
    out = bad_files / "out"
    args = [str(bad_files / args[0]), *(a.format(d=bad_files) for a in args[1:])]
    code, _, err = call("extract", *args, "-o", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert message in err, err
    assert not out.exists()


def test_an_output_never_replaces_the_input(counts, tmp_path):
    path, _ = counts
    out = tmp_path / "out"
    extract(path, "--fps", FPS, "-o", out)
    before = (out / "cube.nc").read_bytes()
    code, _, err = call("extract", out / "cube.nc", "-o", out)
    assert code == 2 and "is the input" in err and (out / "cube.nc").read_bytes() == before


def test_a_failed_write_keeps_the_previous_outputs_and_leaves_no_temporary(counts, tmp_path, monkeypatch):
    path, _ = counts
    out = tmp_path / "out"
    extract(path, "--fps", FPS, "--series", "region", "-o", out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def half_written(ds, target, chunks):
        target.write_bytes(b"half")
        raise DataError("input: decoding failed at frame 7")

    monkeypatch.setitem(CUBE_WRITERS, "netcdf", half_written)
    code, _, err = call("extract", path, "--fps", FPS, "--roi", "0:4,0:4", "--series", "region", "-o", out)
    assert code == 2 and err.strip() == "vibinverse: error: input: decoding failed at frame 7"
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before and no_temporaries(out)
