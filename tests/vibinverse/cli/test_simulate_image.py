"""`vibinverse simulate SCENE --image NX,NY`: the cube, its mean frame and an 8-bit video."""

import argparse
import json
import re
from fractions import Fraction

import av
import imageio.v3 as iio
import numpy as np
import pytest
import xarray as xr

from forward.scene import MEMORY_LIMIT_ENV
from tests.conftest import SCENES
from vibinverse.cli import main
from vibinverse.cli.commands import build_parser
from vibinverse.io.cube_writer import Quantization

FRAME = str(SCENES / "roof_frame.toml")
VIEW = ["--set", "footprint.x=[-40, 40]", "--set", "footprint.y=[-40, 40]", "--set", "sampling.duration=0.5"]


def simulate_help() -> str:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return next(a for a in sub.choices["simulate"]._actions if "-o" in a.option_strings).help


def documented_after(marker: str) -> set[str]:
    """The file names the -o help lists after `marker` ("writes" or "with --image:")."""
    text = simulate_help().split("; writes ", 1)[1]
    part = text.split("with --image:", 1)[1] if marker == "image" else text.split("with --image:", 1)[0]
    return set(re.findall(r"[\w*][\w.*]*\.(?:csv|png|json|nc|mp4)\b", part))


def run_json(capsys, *args):
    code = main([*args, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out), err


def test_image_writes_the_documented_cube_plot_and_video(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["simulate", FRAME, *VIEW, "--set", "noise.sigma=2", "--image", "8,6", "--seed", "4"]
    doc, err = run_json(capsys, *args, "--plot", "--video", "--explain", "-o", str(out))
    files = {"cube.nc", "cube.png", "video.mp4"}
    assert {p.name for p in out.iterdir()} == files == documented_after("image")
    assert doc["paths"] == [str(out / n) for n in ("cube.nc", "cube.png", "video.mp4")]
    assert doc["shape"] == [100, 6, 8] and doc["fs"] == 200.0 and doc["video_fps"] == 200.0
    # 10 m x 13.3 m pixels: 6 columns x 4 rows see the roof, 8 of them only roof
    assert doc["evaluation"] == {"roof": {"rigid": 24}, "background": {"static": 40}}
    assert "cube of 6 x 8 pixels" in err and "rigid 24 px" in err  # --explain, on stderr with --json
    with xr.open_dataset(out / "cube.nc", engine="h5netcdf") as ds:
        cube = ds["intensity"].values
        assert ds.attrs["seed"] == 4 and json.loads(ds.attrs["scene"])["noise"]["sigma"] == 2
    frames = iio.imread(out / "video.mp4", plugin="pyav", format="gray")
    q = Quantization(doc["quantization"]["offset"], doc["quantization"]["step"])
    np.testing.assert_array_equal(frames.reshape(cube.shape), q.counts(cube))  # the quantized cube, exactly


def test_video_fps_sets_the_nominal_rate_of_a_slow_motion_file(tmp_path, capsys):
    out = tmp_path / "slow"
    doc, _ = run_json(
        capsys, "simulate", FRAME, *VIEW, "--image", "4,4", "--video", "--video-fps", "30", "-o", str(out)
    )
    assert doc["video_fps"] == 30.0 and doc["fs"] == 200.0
    with av.open(str(out / "video.mp4")) as c:  # a stream's properties only while its container is open
        stream = c.streams.video[0]
        rate = stream.average_rate
        stamps = [f.pts * f.time_base for f in c.decode(stream)]
        comment = json.loads(c.metadata["comment"])
    assert rate == 30 and stamps == [Fraction(i, 30) for i in range(100)]
    assert comment["capture_fps"] == 200.0 and comment["fps"] == 30.0
    assert {p.name for p in out.iterdir()} == {"cube.nc", "video.mp4"}


def test_without_image_the_series_is_written_as_before(tmp_path, capsys):
    doc, _ = run_json(capsys, "simulate", FRAME, "--set", "sampling.duration=0.5", "-o", str(tmp_path / "s"))
    assert set(doc) == {"sensitivity", "paths"} and doc["paths"] == [str(tmp_path / "s" / "series.csv")]
    assert documented_after("writes") == {"series.csv", "series.png"}


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--image", "0,4"], "--image: 0,4 is outside two integers NX,NY in the allowed range [1, 4096]"),
        (["--image", "4,5000"], "--image: 4,5000 is outside"),
        (["--image", "8"], "--image: '8' is not two integers NX,NY"),
        (["--image", "a,b"], "--image: 'a,b' is not two integers"),
        (["--image=-2,3"], "--image: '-2,3' is not two integers"),
        (["--video"], "--video: needs --image NX,NY"),
        (["--video-fps", "30"], "--video-fps: needs --image NX,NY"),
        (["--image", "4,4", "--video-fps", "30"], "--video-fps: needs --video"),
        (["--image", "4,4", "--video", "--video-fps", "-1"], "--video-fps: -1 is outside the allowed range (0, 1e+06]"),
        (["--image", "4,4", "--seed", "-3"], "seed: -3 is outside the allowed range [0, 2^32)"),
    ],
)
def test_bad_options_exit_2_with_one_line_and_write_nothing(tmp_path, capsys, extra, message):
    code = main(["simulate", FRAME, *VIEW, *extra, "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_a_cube_beyond_the_memory_limit_is_refused_before_work(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "1e9")  # 512 x 512 pixels x 4000 samples x 3 float64 = 25 GB
    code = main(["simulate", FRAME, "--image", "512,512", "-o", str(tmp_path / "big")])
    err = capsys.readouterr().err
    assert code == 2 and "4000 samples x 262144 pixels" in err and "nx, ny" in err
    assert len(err.strip().splitlines()) == 1 and list(tmp_path.iterdir()) == []


def test_help_documents_the_options():
    text = simulate_help()
    assert re.fullmatch(r"output directory \(default: simulation\); writes .+", text)
    for name in ("cube.nc", "cube.png", "video.mp4"):
        assert name in text
