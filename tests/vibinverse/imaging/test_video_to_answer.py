"""From video to answer, end to end: the sec. 4.2 roof rendered by the imager, written as an 8-bit
video, read back as it comes, its detection map, and the joint fit of the pixels the map marks.

The roof (50 m) sits in an 80 m field of view seen by 16 x 16 pixels of 5 m, so the pixels wholly on
it are exactly the 10 x 10 block [3, 13) x [3, 13); the ground around it does not move."""

import math

import numpy as np
import pytest

import vibinverse as vi
from forward.imager import render_cube
from forward.scene_file import load_scene
from tests.conftest import SCENES
from vibinverse.io.cube_writer import quantization_for, write_video

TILT = 2 * math.sqrt(3)  # Hz, the frame's tilt resonance (paper sec. 4.2)
DRIVE = 10.0  # Hz


@pytest.fixture(scope="module")
def roof_video(tmp_path_factory):
    scene, _ = load_scene(
        SCENES / "roof_frame.toml",
        ["footprint.x=[-40.0, 40.0]", "footprint.y=[-40.0, 40.0]", "noise.sigma=0.6"],
    )
    cube = render_cube(scene, 16, 16, seed=1)
    path = tmp_path_factory.mktemp("video") / "roof.mp4"
    write_video(path, cube.intensity, cube.fs, quantization=quantization_for(cube.intensity_clean))
    return path, cube


@pytest.mark.slow
def test_the_roof_video_gives_its_lines_its_pixels_and_its_frequencies(roof_video, tmp_path):
    path, cube = roof_video
    video = vi.open_video(path)
    assert video.dtype == np.uint8 and video.attrs["bit_depth"] == 8  # counts, as the camera gave them
    found = vi.detect(video)
    freqs = sorted(line.frequency for line in found.lines)
    assert len(freqs) == 2
    span = float(video.time[-1] - video.time[0])
    # within two Fourier bins (the map's refined peak of a damped resonance) and one bin (a line)
    assert freqs[0] == pytest.approx(TILT, abs=2.0 / span)
    assert freqs[1] == pytest.approx(DRIVE, abs=1.0 / span)
    roof = cube.coverage["roof"] >= 1.0
    assert roof.sum() == 100
    assert np.array_equal(found.cluster(1), roof)  # the right pixels, all of them and only them

    result = vi.fit(video, pixels=found.cluster(1), method="map")
    assert result.diagnostics["n_pixels"] == 100
    summary = result.summary()["parameters"]
    fitted = sorted(
        (v["median"], v["sd"]) for n, v in summary.items() if n.endswith("frequency") and v["median"] < 12.0
    )
    # the tilt resonance and the drive within 3 sd of the truth (Laplace sds: ~0.02 and ~0.007 Hz)
    (f_tilt, sd_tilt), (f_drive, sd_drive) = fitted[0], fitted[-1]
    assert abs(f_tilt - TILT) <= 3 * sd_tilt and sd_tilt < 0.05
    assert abs(f_drive - DRIVE) <= 3 * sd_drive and sd_drive < 0.02
    with pytest.raises(vi.InputError, match="cluster: 7"):
        found.cluster(7)

    # the report shows the detection map the pixels came from and each pixel's gain
    from vibinverse.report import write_report

    found.to_netcdf(tmp_path / "detection.nc")
    result.data["pixel_selection"] = f"{tmp_path / 'detection.nc'}:1"
    page = write_report(result.to_netcdf(tmp_path / "result.nc"), tmp_path).read_text()
    assert "<h2>Pixels</h2>" in page and "the detection map they were chosen from" in page
