"""Measured series: the file formats, validation, and what a series can resolve."""

import numpy as np
import pytest

from vibinverse.errors import VibinverseError
from vibinverse.io.series import check_resolves, load_series, validate


def test_csv_with_comments_truth_and_gaps(tmp_path):
    p = tmp_path / "d.csv"
    rows = "\n".join(f"{0.01 * i},{'' if i == 7 else np.sin(i)},{np.sin(i)}" for i in range(40))
    p.write_text('# vibinverse simulate\n# scene: {"a": 1}\ntime,intensity,intensity_clean\n' + rows + "\n")
    s = load_series(p)
    assert s.scene == {"a": 1} and s.n_gaps == 1 and s.uniform and s.fs == pytest.approx(100.0)
    np.save(tmp_path / "d.npy", np.column_stack([s.time, s.intensity]))
    np.savez(tmp_path / "d.npz", time=s.time, intensity=s.intensity)
    import xarray as xr

    xr.Dataset({"intensity": ("time", s.intensity)}, coords={"time": s.time}).to_netcdf(
        tmp_path / "d.nc", engine="h5netcdf"
    )
    for name in ("d.npy", "d.npz", "d.nc"):
        other = load_series(tmp_path / name)
        np.testing.assert_array_equal(other.time, s.time)
        assert other.n_gaps == 1


@pytest.mark.parametrize(
    "t, x, message",
    [
        (np.r_[0.0, 2.0, 1.0, np.arange(3, 30.0)], np.zeros(30), "strictly increasing"),
        (np.arange(30.0), np.r_[np.inf, np.zeros(29)], "infinite"),
        (np.arange(5.0), np.zeros(5), "at least 16"),
        (np.arange(30.0), np.r_[np.zeros(10), np.full(20, np.nan)], "valid samples"),
    ],
)
def test_bad_series(t, x, message):
    with pytest.raises(VibinverseError, match=message):
        validate(t, x)


def test_series_too_short_or_too_slow_for_a_frequency():
    s = validate(np.arange(100) * 0.01, np.zeros(100))
    with pytest.raises(VibinverseError, match="Nyquist"):
        check_resolves(s, 60.0, "drive_frequency")
    with pytest.raises(VibinverseError, match="3 cycles"):
        check_resolves(s, 1.0, "tilt_frequency")
