"""Decoded frames spilled once to block files: the same blocks, the same maps."""

import dask.array as da
import numpy as np
import xarray as xr

from vibinverse.imaging.detection_map import detection_map
from vibinverse.imaging.spill import Spill


def test_pieces_written_in_any_order_read_back_as_blocks(tmp_path):
    rng = np.random.default_rng(0)
    cube = rng.integers(0, 255, size=(50, 9, 7), dtype=np.uint8)
    cuts = [(slice(0, 4), slice(0, 7)), (slice(4, 9), slice(0, 3)), (slice(4, 9), slice(3, 7))]
    spill = Spill.create(tmp_path, cuts, 50, np.uint8)
    for t0, t1 in [(30, 50), (0, 12), (12, 30)]:
        assert spill.write(cube[t0:t1], t0) == t1 - t0
    for k, (ys, xs) in enumerate(cuts):
        assert np.array_equal(spill.read(k), cube[:, ys, xs])


def test_a_video_like_cube_gives_the_maps_of_the_same_cube_in_memory():
    """8-bit counts in pieces of whole frames that span many blocks (as decoded video) are spilled;
    the maps equal those of the same values held in memory as floats (never spilled)."""
    rng = np.random.default_rng(1)
    nt, ny, nx = 600, 40, 48
    t = np.arange(nt) / 100.0
    signal = 30 * np.sin(2 * np.pi * 17.3 * t)[:, None, None] * (np.arange(nx) > 30)[None, None, :]
    counts = np.clip(np.round(128 + rng.normal(0, 6, (nt, ny, nx)) + signal), 0, 255).astype(np.uint8)
    pieces = da.from_array(counts, chunks=(100, ny, nx))
    lazy = xr.DataArray(pieces, dims=("time", "y", "x"), coords={"time": t})
    held = xr.DataArray(counts.astype(np.float64), dims=("time", "y", "x"), coords={"time": t})
    memory = 2**20  # small: many blocks, nothing kept
    a = detection_map(lazy, workers=2, memory=memory)
    b = detection_map(held, workers=2, memory=memory)
    assert [round(ln.frequency, 6) for ln in a.lines] == [round(ln.frequency, 6) for ln in b.lines]
    assert abs(a.lines[0].frequency - 17.3) < 0.05 and a.lines[0].claimed
    for name in ("peak_snr", "peak_frequency", "cluster", "snr"):
        np.testing.assert_allclose(a.maps[name].values, b.maps[name].values, rtol=1e-9, atol=1e-12)
