"""`vibinverse fit CUBE --pixels ...` (vibinverse.cli.fit_cube): the joint fit written like a single
fit plus pixels.csv, with all pixels, a mask and a detection map's cluster; one-line errors that
leave nothing behind."""

import csv
import json

import numpy as np
import pytest
import xarray as xr

from vibinverse.cli import main
from vibinverse.result import read_result

ORDER = ["--modes", "0", "--lines", "1", "--drift", "none", "--noise", "white", "--gain", "none", "--method", "map"]
GAINS = np.array([[1.0, -0.8, 0.6], [-1.2, 0.9, 0.0]])  # (y, x); pixel (1, 2) sees nothing


@pytest.fixture
def cube_file(tmp_path):
    """A 2 x 3-pixel cube of a 7.3 Hz line (amplitude 1 x the gains, mixed signs), noise sd 0.5,
    20 s at 50 Hz, as netCDF."""
    rng = np.random.default_rng(0)
    t = np.arange(1000) / 50.0
    y = 100 + GAINS[None] * np.cos(2 * np.pi * 7.3 * t)[:, None, None] + rng.normal(0, 0.5, (t.size, 2, 3))
    cube = xr.DataArray(y, dims=("time", "y", "x"), coords={"time": t}, name="intensity", attrs={"units": "counts"})
    cube["time"].attrs["units"] = "s"
    path = tmp_path / "cube.nc"
    cube.to_netcdf(path, engine="h5netcdf")
    return path


def run(capsys, *args):
    code = main([*args, "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 else None), err


def read_pixels(path):
    lines = path.read_text().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    rows = list(csv.DictReader(ln for ln in lines if not ln.startswith("#")))
    return comments, rows


def test_fit_all_pixels_writes_result_summary_and_the_pixel_table(tmp_path, cube_file, capsys):
    out = tmp_path / "fit"
    code, doc, err = run(capsys, "fit", str(cube_file), "--pixels", "all", *ORDER, "-o", str(out))
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["pixels.csv", "result.nc", "summary.json"]
    assert sorted(doc.pop("paths")) == sorted(str(out / n) for n in ("pixels.csv", "result.nc", "summary.json"))
    d = doc["diagnostics"]
    assert d["n_pixels"] == 6 and d["gain_convention"].startswith("relative to the SNR-weighted")
    assert doc["parameters"]["lines[0].frequency"]["median"] == pytest.approx(7.3, abs=0.01)
    assert doc["data"]["intensity_units"] == "counts" and "6 pixels combined" in doc["data"]["source"]
    comments, rows = read_pixels(out / "pixels.csv")
    assert [(int(r["y"]), int(r["x"])) for r in rows] == [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]
    signs = [int(r["sign"]) for r in rows]
    assert signs[:5] == [1, -1, 1, -1, 1] or signs[:5] == [-1, 1, -1, 1, -1]  # the sign is relative
    assert abs(float(rows[5]["gain"])) < 0.1 and float(rows[5]["snr_share"]) < 0.01  # the blind pixel
    assert sum(float(r["snr_share"]) for r in rows) == pytest.approx(1.0)
    assert comments[0].startswith("# gains: relative to the SNR-weighted")
    summary, _ = read_result(out / "result.nc")
    assert summary["data"]["pixels"]["gain"] == [float(r["gain"]) for r in rows]
    assert json.loads((out / "summary.json").read_text())["diagnostics"]["n_pixels"] == 6


def test_fit_a_mask_and_a_detection_cluster_with_a_reference_pixel(tmp_path, cube_file, capsys):
    mask = np.zeros((2, 3), bool)
    mask[0, :2] = mask[1, 1] = True
    np.save(tmp_path / "mask.npy", mask)
    out = tmp_path / "masked"
    code, doc, err = run(
        capsys,
        "fit",
        str(cube_file),
        "--pixels",
        str(tmp_path / "mask.npy"),
        "--reference",
        "0,1",
        *ORDER,
        "-o",
        str(out),
    )
    assert code == 0, err
    assert doc["diagnostics"]["n_pixels"] == 3 and doc["diagnostics"]["reference_pixel"] == [0, 1]
    _, rows = read_pixels(out / "pixels.csv")
    assert [float(r["gain"]) for r in rows] == pytest.approx([1 / -0.8, 1.0, 0.9 / -0.8], rel=0.05)
    # the line in the units of pixel (0, 1): amplitude |g| = 0.8 (SNR ~50 a pixel: within 5 %)
    assert doc["parameters"]["lines[0].amplitude"]["median"] == pytest.approx(0.8, rel=0.05)
    cluster = np.where(GAINS != 0, 1, 0).astype(np.int32)
    cluster[1, 0] = 2
    xr.Dataset({"cluster": (("y", "x"), cluster)}).to_netcdf(tmp_path / "detection.nc", engine="h5netcdf")
    out = tmp_path / "cluster"
    code, doc, err = run(
        capsys, "fit", str(cube_file), "--pixels", f"{tmp_path / 'detection.nc'}:1", *ORDER, "-o", str(out)
    )
    assert code == 0, err
    assert doc["diagnostics"]["n_pixels"] == 4
    assert [(int(r["y"]), int(r["x"])) for r in read_pixels(out / "pixels.csv")[1]] == [(0, 0), (0, 1), (0, 2), (1, 1)]


@pytest.mark.parametrize(
    "extra, message",
    [
        (
            lambda d: ["--pixels", str(d / "wrong.npy")],
            "pixels: the mask wrong.npy is 4 x 4; the cube's frame is 2 x 3",
        ),
        (lambda d: ["--pixels", str(d / "empty.npy")], "pixels: the selection is empty"),
        (lambda d: ["--pixels", f"{d / 'detection.nc'}:5"], "pixels: detection.nc has no cluster 5; its clusters: 1"),
        (lambda d: ["--pixels", str(d / "nothing.png")], "pixels: file not found"),
        (lambda d: ["--pixels", "all", "--fs", "50"], "--fs: applies to a series table"),
        (lambda d: ["--pixels", "all", "--scale", "0.01"], "--scale: metres per pixel apply to a displacement fit"),
        (lambda d: ["--pixels", "all", "--reference", "7,7"], "reference: pixel (7, 7) is not among the selected"),
        (lambda d: ["--displacement", "x"], "--displacement: applies to a cube fit; give --pixels"),
        (lambda d: ["--pixels", "all", "--band", "3-5"], "invalid band '3-5'"),
        (lambda d: ["--pixels", "all", "--sources", "0"], "--sources: 0 is outside the allowed range [1, 1000000]"),
        (lambda d: ["--pixels", "all", "--sources", "7"], "sources: 7; allowed: an integer in [1, 6]"),
        (lambda d: ["--sources", "2"], "--sources: applies to a cube fit; give --pixels"),
    ],
)
def test_bad_selections_and_options_are_one_line_and_leave_nothing(tmp_path, cube_file, capsys, extra, message):
    np.save(tmp_path / "wrong.npy", np.ones((4, 4), bool))
    np.save(tmp_path / "empty.npy", np.zeros((2, 3), bool))
    xr.Dataset({"cluster": (("y", "x"), np.ones((2, 3), np.int32))}).to_netcdf(
        tmp_path / "detection.nc", engine="h5netcdf"
    )
    out = tmp_path / "out"
    code = main(["fit", str(cube_file), *extra(tmp_path), *ORDER, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_the_mask_file_is_never_overwritten_by_an_output(tmp_path, cube_file, capsys):
    (tmp_path / "pixels.csv").write_text("a mask in disguise")
    code = main(["fit", str(cube_file), "--pixels", str(tmp_path / "pixels.csv"), *ORDER, "-o", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and "replace the input" in err
    assert (tmp_path / "pixels.csv").read_text() == "a mask in disguise"


def test_two_sources_write_a_gain_column_per_source(tmp_path, capsys):
    """A 3 x 4-pixel cube of two lines (7.3 Hz and 11.1 Hz, amplitude 1 x two different patterns,
    one of them of mixed signs; noise sd 0.5): --sources 2 finds both lines (each within 0.01 Hz:
    amplitude SNR ~60 a pixel, 20 s) and writes gain_0 and gain_1 per pixel, each within 0.15 of the
    pattern in its convention (sd ~0.01 a gain), the source kinds chosen as lines; the help says
    what --sources does."""
    rng = np.random.default_rng(1)
    t = np.arange(1000) / 50.0
    pa = np.array([[1.0, 0.8, 0.6, 0.4], [0.9, 0.7, 0.5, 0.3], [1.1, 0.9, 0.7, 0.5]])
    pb = np.array([[1.0, 0.5, -0.5, -1.0], [0.8, 0.4, -0.4, -0.8], [1.2, 0.6, -0.6, -1.2]])
    y = (
        100
        + pa[None] * np.cos(2 * np.pi * 7.3 * t + 0.2)[:, None, None]
        + pb[None] * np.cos(2 * np.pi * 11.1 * t + 1.0)[:, None, None]
        + rng.normal(0, 0.5, (t.size, 3, 4))
    )
    cube = xr.DataArray(y, dims=("time", "y", "x"), coords={"time": t}, name="intensity")
    path = tmp_path / "two.nc"
    cube.to_netcdf(path, engine="h5netcdf")
    out = tmp_path / "fit"
    code, doc, err = run(
        capsys, "fit", str(path), "--pixels", "all", "--sources", "2", "--method", "map", "-o", str(out)
    )
    assert code == 0, err
    d = doc["diagnostics"]
    assert d["n_sources"] == 2 and d["source_kinds"] == ["line", "line"]
    assert doc["parameters"]["lines[0].frequency"]["median"] == pytest.approx(7.3, abs=0.01)
    assert doc["parameters"]["lines[1].frequency"]["median"] == pytest.approx(11.1, abs=0.01)
    comments, rows = read_pixels(out / "pixels.csv")
    assert {"gain_0", "gain_1", "sign_0", "sign_1", "snr_share_0", "snr_share_1"} <= set(rows[0])
    assert any(c.startswith("# source 1: line") for c in comments)
    for j, pattern in ((0, pa), (1, pb)):
        g = np.array([float(r[f"gain_{j}"]) for r in rows])
        p = pattern.ravel()
        share = p**2 / np.sum(p**2)
        want = p * np.sign(p[np.argmax(share)]) / np.sum(share * np.abs(p))
        assert g == pytest.approx(want, abs=0.15)


def test_the_help_of_sources_says_what_it_does(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--sources K" in text and "K >= 2 sources" in text and "gain_0, gain_1" in text
