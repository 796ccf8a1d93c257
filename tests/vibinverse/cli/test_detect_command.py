"""`vibinverse detect`: DIR/detection.nc (the `cluster` map the multi-pixel fit reads), DIR/lines.csv
and DIR/detection.png from a netCDF cube and from an h264 video as it comes; --json; the same result
on a dask.distributed cluster; bad input is one line, exit 2, and leaves nothing behind."""

import contextlib
import csv
import io
import json
import math
import re

import numpy as np
import pytest
import xarray as xr

from tests.conftest import run_cli
from vibinverse.cli import main
from vibinverse.cli.detect_command import DETECTION, DETECTION_PLOT, LINES

FS = 100.0
F0 = 9.3  # Hz
BLOCK = (slice(6, 12), slice(15, 19))  # 6 x 4 pixels carrying the line


def call(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def strict_json(text: str):
    return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON token {c}"))


def block_mask(shape, block=BLOCK):
    m = np.zeros(shape, dtype=bool)
    m[block] = True
    return m


@pytest.fixture
def cube_nc(tmp_path):
    """A 24 x 32-pixel netCDF cube of 8-bit counts, 1024 frames at 100 Hz, a line of 1.5 counts
    (mixed signs) in a 6 x 4 block over noise of 1.5 counts: SNR ~ N A^2 / 4 sigma^2 = 256."""
    rng = np.random.default_rng(31)
    nt, ny, nx = 1024, 24, 32
    t = np.arange(nt) / FS
    gains = np.zeros((ny, nx))
    gains[BLOCK] = rng.choice([-1.5, 1.5], gains[BLOCK].shape)
    analog = 120 + 1.5 * rng.standard_normal((nt, ny, nx)) + np.sin(2 * np.pi * F0 * t)[:, None, None] * gains
    counts = np.clip(np.round(analog), 0, 255).astype(np.uint8)
    path = tmp_path / "cube.nc"
    cube = xr.DataArray(counts, dims=("time", "y", "x"), coords={"time": ("time", t, {"units": "s"})})
    cube.attrs.update(units="counts", bit_depth=8)
    cube.to_dataset(name="intensity").to_netcdf(path, engine="h5netcdf")
    return path


def test_detect_writes_the_map_the_lines_and_the_plot(cube_nc, tmp_path):
    out = tmp_path / "new" / "det"
    code, stdout, err = call("detect", cube_nc, "-o", out, "--json", "--workers", "2")
    assert code == 0, err
    doc = strict_json(stdout)
    paths = [str(out / n) for n in (DETECTION, DETECTION_PLOT, LINES)]
    assert doc["paths"] == paths and doc["n_lines"] == 1 and doc["n_clusters"] == 1
    (row,) = doc["lines"]
    assert abs(row["frequency_hz"] - F0) < FS / 1024  # within the resolution 1/T
    assert (row["cluster"], row["n_pixels"], row["bbox_y0"], row["bbox_y1"], row["bbox_x0"], row["bbox_x1"]) == (
        1, 24, 6, 12, 15, 19,
    )  # fmt: skip
    assert (
        re.search(r"line 0: 9\.\d+ Hz \(or [\d.]+ Hz if aliased\), SNR \d+", err) and "cluster 1 (24 px)" in err
    )  # the log: stderr
    with xr.open_dataset(out / DETECTION, engine="h5netcdf") as ds:
        # the contract of `vibinverse fit CUBE --pixels DIR/detection.nc:K`: cluster == K
        assert ds["cluster"].dtype == np.int32 and ds["cluster"].dims == ("y", "x")
        assert np.array_equal(ds["cluster"].values == 1, block_mask((24, 32)))
        assert ds["line_of_cluster"].values.tolist() == [0]
        assert ds["snr"].dims == ("line", "y", "x") and ds["line_frequency"].attrs["units"] == "Hz"
        assert ds["mean_frame"].attrs["units"] == "counts"
        for name, var in ds.data_vars.items():
            assert var.attrs.get("units") and var.attrs.get("long_name"), name
    with open(out / LINES, encoding="utf-8") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert len(rows) == 1 and int(rows[0]["n_pixels"]) == 24
    assert math.isclose(float(rows[0]["frequency_hz"]), row["frequency_hz"], rel_tol=1e-9)
    assert (out / DETECTION_PLOT).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in out.iterdir() if p.name.endswith(".part")]


def test_detect_a_video_as_it_comes(tmp_path):
    """An h264 mp4 (lossy, 4:2:0) at 60 fps: a block flickering by 4 counts over noise of 6 counts."""
    av = pytest.importorskip("av")
    if "libx264" not in av.codecs_available:
        pytest.skip("this FFmpeg build has no h264 encoder")
    rng = np.random.default_rng(32)
    n, ny, nx, fps = 600, 32, 48, 60
    t = np.arange(n) / fps
    frames = 110 + 6 * rng.standard_normal((n, ny, nx))
    frames[:, 8:16, 10:20] += 4 * np.sin(2 * np.pi * 7.5 * t)[:, None, None]
    frames = np.clip(np.round(frames), 0, 255).astype(np.uint8)
    path = tmp_path / "flicker.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=fps, options={"crf": "18"})
        stream.width, stream.height, stream.pix_fmt = nx, ny, "yuv420p"
        for img in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="gray")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    code, stdout, err = call("detect", path, "-o", tmp_path / "out", "--json")
    assert code == 0, err
    doc = strict_json(stdout)
    assert doc["n_lines"] == 1 and abs(doc["lines"][0]["frequency_hz"] - 7.5) < fps / n
    with xr.open_dataset(tmp_path / "out" / DETECTION, engine="h5netcdf") as ds:
        assert np.array_equal(ds["cluster"].values == 1, block_mask((ny, nx), (slice(8, 16), slice(10, 20))))


def test_detect_on_a_dask_cluster_gives_the_same_lines(cube_nc, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as c:
        code, stdout, err = call("detect", cube_nc, "-o", tmp_path / "d", "--json", "--scheduler", c.scheduler_address)
    assert code == 0, err
    code, local, err = call("detect", cube_nc, "-o", tmp_path / "l", "--json")
    assert code == 0, err
    assert strict_json(stdout)["lines"] == strict_json(local)["lines"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--band", "40:30"], "--band: 40:30 is not a band; allowed 0 <= fmin < fmax <= 50 Hz (Nyquist)"),
        (["--band", "1-2"], "argument --band: invalid band '1-2' (fmin:fmax in Hz"),
        (["--alpha", "1.5"], "--alpha: 1.5 is outside the allowed range (0, 1)"),
        (["--memory", "lots"], "argument --memory: invalid size 'lots'"),
        (["--memory", "1kB", "--workers", "2"], "--memory: 0.98 kiB is too little for 2 thread(s)"),
        (["--workers", "0"], "--workers: 0 is outside the allowed range [1, 1024]"),
        (["--channel", "x"], "argument --channel: invalid choice"),
    ],
)
def test_bad_options_are_one_line_exit_2_and_write_nothing(cube_nc, tmp_path, args, message):
    out = tmp_path / "o"
    code, _, err = call("detect", cube_nc, "-o", out, *args)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_bad_files_are_one_line_exit_2(cube_nc, tmp_path):
    r = run_cli("detect", str(tmp_path / "missing.nc"), "-o", str(tmp_path / "o"))
    assert r.returncode == 2 and "file not found" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "Traceback" not in r.stderr and not (tmp_path / "o").exists()
    inside = tmp_path / "o2" / DETECTION  # the input where the map would go: refused before any work
    inside.parent.mkdir()
    inside.write_bytes(cube_nc.read_bytes())
    before = inside.read_bytes()
    code, _, err = call("detect", inside, "-o", inside.parent)
    assert code == 2 and "replace the input" in err and inside.read_bytes() == before
    assert sorted(p.name for p in inside.parent.iterdir()) == [DETECTION]
