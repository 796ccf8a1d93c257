"""Image cubes: every reader on small generated files (video with a variable frame rate, Photron MRAW,
TIFF, .npy, netCDF, zarr), the time stamps and counts that come back, laziness, and one-line errors."""

import sys
import tracemalloc
from fractions import Fraction

import dask.array as da
import numpy as np
import pandas as pd
import pytest
import xarray as xr
from hypothesis import given
from hypothesis import strategies as st

from vibinverse.errors import DataError, InputError
from vibinverse.io import cube as cube_module
from vibinverse.io.cube import CHUNK_BYTES, READERS, REC709, extract_region, open_cube, read_mask, sampling
from vibinverse.io.video import NpyFrames, stamps_seconds

RNG_SEED = 20240501


def write_video(path, frames, pts, time_base, codec="ffv1", pix_fmt="gray", in_format="gray", rate=30, options=None):
    """Frames with explicit presentation stamps `pts` (in `time_base`) through PyAV (a test that writes
    a video is skipped without it; the other readers' tests run)."""
    av = pytest.importorskip("av")
    with av.open(str(path), "w") as c:
        s = c.add_stream(codec, rate=rate, options=options or {})
        s.width, s.height, s.pix_fmt = frames.shape[2], frames.shape[1], pix_fmt
        s.time_base = s.codec_context.time_base = time_base  # the encoder's too, or it rounds to 1/rate
        for img, p in zip(frames, pts):
            f = av.VideoFrame.from_ndarray(img, format=in_format)
            f.pts, f.time_base = int(p), time_base
            for packet in s.encode(f):
                c.mux(packet)
        for packet in s.encode():
            c.mux(packet)
    return path


def vfr_stamps(n, step, rng, dropped):
    """Stamps of a variable-frame-rate recording: a nominal step with jitter, some frames dropped."""
    pts = np.arange(n + len(dropped)) * step + rng.integers(0, step // 8, n + len(dropped))
    return np.delete(pts, dropped)


@pytest.fixture
def gray_mkv(tmp_path):
    """Lossless 8-bit gray video (ffv1 in Matroska, 1 ms time base), variable frame rate."""
    rng = np.random.default_rng(RNG_SEED)
    frames = rng.integers(0, 256, (24, 12, 20), dtype=np.uint8)
    pts = vfr_stamps(24, 33, rng, dropped=[5, 6, 13])
    return write_video(tmp_path / "vfr.mkv", frames, pts, Fraction(1, 1000)), frames, pts


# ------------------------------------------------------------------------------------------ video
def test_vfr_video_stamps_and_lossless_counts_come_back_exactly(gray_mkv):
    path, frames, pts = gray_mkv
    cube = open_cube(path)
    assert cube.dims == ("time", "y", "x") and cube.name == "intensity"
    # Matroska keeps milliseconds: the stamps are (pts - pts[0]) ms, correctly rounded to float64
    expected = np.array([float(Fraction(int(p - pts[0]), 1000)) for p in pts])
    assert np.array_equal(cube["time"].values, expected)
    assert cube["time"].attrs["units"] == "s"
    assert cube.dtype == np.uint8 and np.array_equal(cube.values, frames)  # ffv1 is lossless
    assert cube.attrs["units"] == "counts" and cube.attrs["bit_depth"] == 8
    assert cube.attrs["nominal_fps"] == 30.0 and cube.attrs["source"] == "vfr.mkv"
    assert sampling(cube)["irregular"]  # jitter of up to 4 ms of 33 and dropped frames


def test_h264_mp4_stamps_exact_and_chunks_decode_as_the_whole(tmp_path):
    """B-frames and a keyframe every 10 frames: each chunk seeks to a keyframe and decodes to the
    same frames as one pass over the file (decoding is deterministic: compared exactly)."""
    rng = np.random.default_rng(RNG_SEED)
    frames = rng.integers(0, 256, (60, 16, 32, 3), dtype=np.uint8)
    pts = vfr_stamps(60, 3000, rng, dropped=[7, 30, 31])  # 1/90000 time base: ~30 fps
    path = write_video(
        tmp_path / "vfr.mp4", frames, pts, Fraction(1, 90000), "libx264", "yuv420p", "rgb24", options={"g": "10"}
    )
    whole = open_cube(path, chunks=60)
    assert np.array_equal(whole["time"].values, stamps_seconds(pts, Fraction(1, 90000)))
    assert whole.dtype == np.uint8 and "luma plane" in whole.attrs["channel"]  # YUV: the stored luma
    pieces = open_cube(path, chunks=7)
    assert pieces.data.chunks[0] == (7,) * 8 + (4,)
    assert np.array_equal(pieces.values, whole.values)
    assert np.array_equal(pieces[23:41, 3:9, ::3].values, whole.values[23:41, 3:9, ::3])


def test_gray_h264_in_full_range_gives_its_counts_back(tmp_path):
    """Lossless H.264 (qp 0) of gray frames in full range, as `vibinverse simulate --video` writes
    it: the luma plane is the counts, exactly, in 8-bit integers."""
    av = pytest.importorskip("av")
    frames = np.random.default_rng(RNG_SEED).integers(0, 256, (20, 16, 24), dtype=np.uint8)
    with av.open(str(tmp_path / "gray.mp4"), "w") as c:
        s = c.add_stream("libx264", rate=30, options={"qp": "0"})
        s.width, s.height, s.pix_fmt = 24, 16, "gray"
        s.codec_context.color_range = 2  # full range (JPEG)
        for i, img in enumerate(frames):
            f = av.VideoFrame.from_ndarray(img, format="gray")
            f.pts = i
            for packet in s.encode(f):
                c.mux(packet)
        for packet in s.encode():
            c.mux(packet)
    cube = open_cube(tmp_path / "gray.mp4", chunks=6)
    assert cube.dtype == np.uint8 and np.array_equal(cube.values, frames)
    assert np.array_equal(open_cube(tmp_path / "gray.mp4", channel="g").values, frames)  # R = G = B


def test_default_video_chunks_start_at_keyframes(tmp_path, monkeypatch):
    """With a keyframe every 6 frames and room for 13 frames per chunk, the default chunks hold two
    whole groups each (no chunk decodes another's frames); explicit chunks stay regular."""
    frames = np.random.default_rng(RNG_SEED).integers(0, 256, (40, 8, 8), dtype=np.uint8)
    path = write_video(tmp_path / "g.mkv", frames, np.arange(40) * 20, Fraction(1, 1000), options={"g": "6"})
    monkeypatch.setattr(cube_module, "CHUNK_BYTES", 13 * 64)  # 13 frames of 8 x 8 bytes
    cube = open_cube(path)
    assert cube.data.chunks[0] == (12, 12, 12, 4) and np.array_equal(cube.values, frames)
    assert open_cube(path, chunks=13).data.chunks[0] == (13, 13, 13, 1)
    monkeypatch.setattr(cube_module, "CHUNK_BYTES", 4 * 64)  # a group longer than a chunk is split
    assert open_cube(path).data.chunks[0] == (4, 2) * 6 + (4,)


def test_fps_overrides_the_container_rate(gray_mkv):
    path, _, _ = gray_mkv
    native = open_cube(path)
    slow = open_cube(path, fps=600.0)  # a 600 fps capture stored as a 30 fps file: 20x shorter times
    nominal = native.attrs["nominal_fps"]
    np.testing.assert_allclose(slow["time"].values, native["time"].values * nominal / 600.0, rtol=1e-15, atol=0)
    assert sampling(slow)["irregular"]  # the jitter is kept, only scaled


@pytest.fixture
def rgb_mkv(tmp_path):
    rng = np.random.default_rng(RNG_SEED + 1)
    frames = rng.integers(0, 256, (6, 10, 14, 3), dtype=np.uint8)
    path = write_video(tmp_path / "rgb.mkv", frames, np.arange(6) * 40, Fraction(1, 1000), "ffv1", "bgr0", "rgb24")
    return path, frames


def test_luminance_and_single_channels_of_an_rgb_video(rgb_mkv):
    path, frames = rgb_mkv  # ffv1 bgr0: the planes come back exactly
    for i, name in enumerate("rgb"):
        cube = open_cube(path, channel=name)
        assert cube.dtype == np.uint8 and np.array_equal(cube.values, frames[..., i]), name
    lum = open_cube(path)
    assert lum.dtype == np.float64 and lum.attrs["bit_depth"] == 8
    # Rec. 709 weights; the only error is the float64 rounding of a 3-term sum of values <= 255
    np.testing.assert_allclose(lum.values, frames @ np.array(REC709), rtol=1e-13)


def test_high_bit_depth_gray_video_keeps_its_counts(tmp_path):
    rng = np.random.default_rng(RNG_SEED + 2)
    frames = rng.integers(0, 4096, (5, 8, 12), dtype=np.uint16)
    # 12-bit counts given as 16 bits by bit replication (v << 4 | v >> 8), which the encoder's
    # conversion to 12 bits inverts exactly; ffv1 is lossless, so the counts come back as they were
    given = (frames << 4) | (frames >> 8)
    path = write_video(
        tmp_path / "g12.mkv", given, np.arange(5) * 10, Fraction(1, 1000), "ffv1", "gray12le", "gray16le"
    )
    cube = open_cube(path)
    assert cube.dtype == np.uint16 and cube.attrs["bit_depth"] == 12
    assert np.array_equal(cube.values, frames)


def test_opening_a_video_decodes_at_most_its_first_frame(gray_mkv, monkeypatch):
    av = pytest.importorskip("av")
    path, frames, _ = gray_mkv
    opened = []
    real_open = av.open
    monkeypatch.setattr(av, "open", lambda *a, **k: opened.append(a[0]) or real_open(*a, **k))
    cube = open_cube(path, chunks=8)
    assert len(opened) == 2  # the packet pass (no decoding) and the first frame
    assert np.array_equal(cube[9:12].values, frames[9:12])  # one chunk: one more open
    assert len(opened) == 3


# ----------------------------------------------------------------------------------- Photron MRAW
@pytest.mark.parametrize("bits,top", [(8, 256), (16, 4096)])
def test_mraw_via_pymraw_writer(tmp_path, bits, top):
    pymraw = pytest.importorskip("pyMRAW")
    frames = np.random.default_rng(RNG_SEED).integers(0, top, (9, 6, 10), dtype=np.uint16)
    pymraw.save_mraw(frames, str(tmp_path / "rec.cih"), bit_depth=bits, info_dict={"Record Rate(fps)": 5000})
    for name in ("rec.cih", "rec.mraw"):
        cube = open_cube(tmp_path / name, chunks=4)
        assert np.array_equal(cube.values, frames) and cube.dtype == (np.uint8 if bits == 8 else np.uint16)
        assert cube.attrs["bit_depth"] == (8 if bits == 8 else 12)  # pyMRAW's 16-bit files carry 12 bits
        assert np.array_equal(cube["time"].values, np.arange(9) / 5000.0)


def test_mraw_12_bit_packed_without_a_rate_needs_fps(tmp_path):
    pymraw = pytest.importorskip("pyMRAW")
    frames = np.random.default_rng(RNG_SEED).integers(0, 4096, (7, 6, 10), dtype=np.uint16)
    pymraw.save_mraw(frames, str(tmp_path / "rec.cih"), info_dict={"Record Rate(fps)": 0, "Color Bit": 12})
    a, b = frames.reshape(-1)[0::2], frames.reshape(-1)[1::2]  # Photron packing: 2 pixels in 3 bytes
    packed = np.stack([a >> 4, ((a & 15) << 4) | (b >> 8), b & 255], axis=1).astype(np.uint8)
    packed.tofile(tmp_path / "rec.mraw")
    with pytest.raises(InputError, match=r"^fps: .*no time stamps"):
        open_cube(tmp_path / "rec.cih")
    cube = open_cube(tmp_path / "rec.cih", fps=2000.0, chunks=3)
    assert np.array_equal(cube.values, frames) and cube.attrs["bit_depth"] == 12
    assert np.array_equal(cube["time"].values, np.arange(7) / 2000.0)


# --------------------------------------------------------------------------------- TIFF and .npy
def test_tiff_stack(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    frames = np.random.default_rng(RNG_SEED).integers(0, 4096, (8, 6, 5), dtype=np.uint16)
    tifffile.imwrite(tmp_path / "plain.tif", frames)
    with pytest.raises(InputError, match=r"^fps: "):
        open_cube(tmp_path / "plain.tif")
    cube = open_cube(tmp_path / "plain.tif", fps=100.0, chunks=3)
    assert np.array_equal(cube.values, frames) and cube.attrs["bit_depth"] == 16
    assert np.array_equal(cube["time"].values, np.arange(8) / 100.0)
    assert np.array_equal(cube[2:7, 1:4, 3].values, frames[2:7, 1:4, 3])
    tifffile.imwrite(tmp_path / "ij.tif", frames, imagej=True, metadata={"axes": "TYX", "finterval": 0.004})
    ij = open_cube(tmp_path / "ij.tif")  # ImageJ's frame interval is a rate
    assert ij.attrs["nominal_fps"] == 250.0 and np.allclose(ij["time"].values, np.arange(8) * 0.004, atol=1e-15)
    rgb = np.random.default_rng(1).integers(0, 256, (3, 4, 5, 3), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "rgb.tif", rgb, photometric="rgb")
    assert np.array_equal(open_cube(tmp_path / "rgb.tif", fps=1.0, channel="b").values, rgb[..., 2])


def test_npy_memory_mapped(tmp_path):
    frames = np.random.default_rng(RNG_SEED).normal(size=(10, 4, 6))
    np.save(tmp_path / "c.npy", frames)
    cube = open_cube(tmp_path / "c.npy", fps=50.0)
    assert np.array_equal(cube.values, frames) and cube.attrs["units"] == "1" and "bit_depth" not in cube.attrs
    assert np.array_equal(cube["time"].values, np.arange(10) / 50.0)
    np.save(tmp_path / "u.npy", frames.astype(np.uint16))
    u = open_cube(tmp_path / "u.npy", fps=50.0)
    assert u.dtype == np.uint16 and u.attrs["units"] == "counts" and u.attrs["bit_depth"] == 16


def test_a_large_npy_is_not_read_when_opened_or_sliced(tmp_path):
    psutil = pytest.importorskip("psutil")
    shape = (1024, 512, 512)  # 256 MiB of uint8, a sparse file: nothing written
    np.lib.format.open_memmap(tmp_path / "big.npy", mode="w+", dtype=np.uint8, shape=shape).flush()
    np.save(tmp_path / "tiny.npy", np.zeros((3, 4, 4), np.uint8))
    open_cube(tmp_path / "tiny.npy", fps=1.0)[0:2, 1:2, 1:3].load()  # imports and caches: not measured
    rss = psutil.Process().memory_info().rss
    tracemalloc.start()
    cube = open_cube(tmp_path / "big.npy", fps=1000.0)
    region = cube[500:510, 100:110, 200:220].values
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert isinstance(cube.data, da.Array) and region.shape == (10, 10, 20) and not region.any()
    assert cube.data.chunks[0][0] == CHUNK_BYTES // (512 * 512)  # 256 frames of 256 KiB: 64 MiB
    # a whole read allocates 256 MiB, one chunk 64 MiB; the region (2 kB) is read alone (~0.1 MiB
    # measured: dask passes the slice to the memory map)
    assert peak < 4 * 2**20, peak
    assert psutil.Process().memory_info().rss - rss < 16 * 2**20


@pytest.fixture(scope="module")
def index_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("index") / "a.npy"
    np.save(path, np.arange(12 * 5 * 7).reshape(12, 5, 7))
    return path


@given(t=st.integers(-14, 14) | st.slices(12), y=st.integers(-5, 4) | st.slices(5), x=st.slices(7))
def test_frame_source_indexes_like_numpy(index_file, t, y, x):
    """A FrameSource (here the .npy one) answers any basic index as numpy does on the array."""
    arr = np.load(index_file)
    source = NpyFrames(index_file, arr.shape, arr.dtype)
    try:
        expected = arr[t, y, x]
    except IndexError:
        with pytest.raises(IndexError):
            source[t, y, x]
        return
    got = source[t, y, x]
    assert got.shape == expected.shape and np.array_equal(got, expected)


# ---------------------------------------------------------------------------------- netCDF, zarr
def mv_cube(n=20):
    t = pd.date_range("2024-05-01T12:00:00", periods=n, freq="10ms")
    data = np.random.default_rng(RNG_SEED).normal(size=(n, 4, 5))
    return xr.DataArray(data, dims=("time", "y", "x"), coords={"time": t}, attrs={"units": "mV"}).to_dataset(
        name="voltage"
    )


@pytest.mark.parametrize("suffix", [".nc", ".zarr"])
def test_netcdf_and_zarr_with_datetime_time_and_units(tmp_path, suffix):
    ds = mv_cube()
    path = tmp_path / f"c{suffix}"
    ds.to_netcdf(path, engine="h5netcdf") if suffix == ".nc" else ds.to_zarr(path, consolidated=False)
    cube = open_cube(path, chunks=6)
    assert cube.attrs["units"] == "mV" and cube.dtype == np.float64
    assert np.array_equal(cube.values, ds["voltage"].values)
    # datetime64 in ns: 10 ms steps are exact in ns, then one division by 1e9 per stamp
    np.testing.assert_allclose(cube["time"].values, np.arange(20) * 0.01, rtol=0, atol=1e-15)
    assert cube["time"].attrs["reference"] == "2024-05-01T12:00:00"
    assert cube.data.chunks[0] == (6, 6, 6, 2)


def test_netcdf_variable_choice_dims_and_numeric_time_units(tmp_path):
    ds = mv_cube()
    ds["other"] = ds["voltage"] * 2
    ds["flat"] = ds["voltage"].isel(time=0)
    ds.to_netcdf(tmp_path / "two.nc", engine="h5netcdf")
    with pytest.raises(DataError, match="several 3-D variables"):
        open_cube(tmp_path / "two.nc")
    with pytest.raises(InputError, match=r"^variable: .*no variable 'nope'"):
        open_cube(tmp_path / "two.nc", variable="nope")
    assert np.array_equal(open_cube(tmp_path / "two.nc", variable="other").values, 2 * ds["voltage"].values)
    # another dimension order and name, a numeric time in ms
    frame = xr.DataArray(
        np.arange(24.0).reshape(3, 4, 2), dims=("row", "col", "frame"), coords={"frame": ("frame", [5.0, 7.5])}
    )
    frame["frame"].attrs["units"] = "ms"
    frame.to_dataset(name="v").to_netcdf(tmp_path / "ms.nc", engine="h5netcdf")
    cube = open_cube(tmp_path / "ms.nc")
    assert cube.dims == ("time", "y", "x") and cube.shape == (2, 3, 4)
    np.testing.assert_allclose(cube["time"].values, [0.0, 0.0025], rtol=0, atol=1e-18)
    assert np.array_equal(cube.values, frame.values.transpose(2, 0, 1))


# ------------------------------------------------------------------------------------------ errors
def test_unknown_missing_empty_and_wrong_rank(tmp_path):
    with pytest.raises(DataError, match=r"^input: file not found"):
        open_cube(tmp_path / "none.mp4")
    (tmp_path / "a.xyz").write_text("x")
    with pytest.raises(DataError, match=r"^input: .*unknown file type '.xyz'; supported: .*\.mp4.*\.zarr") as e:
        open_cube(tmp_path / "a.xyz")
    assert all(s in str(e.value) for s in READERS)
    (tmp_path / "e.npy").write_bytes(b"")
    with pytest.raises(DataError, match="is empty"):
        open_cube(tmp_path / "e.npy", fps=1.0)
    np.save(tmp_path / "flat.npy", np.zeros((4, 4)))
    with pytest.raises(DataError, match=r"frames of shape \(4, 4\)"):
        open_cube(tmp_path / "flat.npy", fps=1.0)
    np.save(tmp_path / "none.npy", np.zeros((0, 4, 4)))
    with pytest.raises(DataError, match="has no frames"):
        open_cube(tmp_path / "none.npy", fps=1.0)
    np.save(tmp_path / "b.npy", np.zeros((3, 4, 4), dtype=bool))
    with pytest.raises(DataError, match="real numbers are needed"):
        open_cube(tmp_path / "b.npy", fps=1.0)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"fps": 0.0}, r"^fps: 0.0 Hz; allowed range \(0, inf\)"),
        ({"fps": float("nan")}, r"^fps: nan Hz"),
        ({"chunks": 0}, r"^chunks: 0; allowed"),
        ({"channel": "lum"}, r"^channel: 'lum'; allowed: luminance, r, g, b"),
        ({"variable": "v"}, r"^variable: 'v' applies to netCDF and zarr"),
    ],
)
def test_bad_arguments(tmp_path, kwargs, message):
    np.save(tmp_path / "c.npy", np.zeros((3, 4, 4)))
    with pytest.raises(InputError, match=message):
        open_cube(tmp_path / "c.npy", **{"fps": 1.0, **kwargs})


def test_bad_videos(gray_mkv, tmp_path):
    av = pytest.importorskip("av")
    path, _, _ = gray_mkv
    bad = tmp_path / "codec.mkv"  # the codec id renamed: a stream FFmpeg has no decoder for
    bad.write_bytes(path.read_bytes().replace(b"V_FFV1", b"V_QQQQ"))
    with pytest.raises(DataError, match="video codec cannot be decoded"):
        open_cube(bad)
    (tmp_path / "junk.mp4").write_bytes(b"not a video " * 50)
    with pytest.raises(DataError, match=r"^input: cannot open .*junk.mp4 as a video"):
        open_cube(tmp_path / "junk.mp4")
    c = av.open(str(tmp_path / "empty.mkv"), "w")
    s = c.add_stream("ffv1", rate=30)
    s.width, s.height, s.pix_fmt = 8, 8, "gray"
    c.close()
    with pytest.raises(DataError, match=r"empty\.mkv"):
        open_cube(tmp_path / "empty.mkv")


def test_stamps_not_strictly_increasing_name_the_frame(tmp_path):
    ds = xr.Dataset({"v": (("time", "y", "x"), np.zeros((5, 2, 2)))}, coords={"time": [0.0, 0.1, 0.2, 0.2, 0.3]})
    ds.to_netcdf(tmp_path / "dup.nc", engine="h5netcdf")
    with pytest.raises(DataError, match=r"not strictly increasing: frame 3 at 0.2 s after frame 2 at 0.2 s"):
        open_cube(tmp_path / "dup.nc")


def test_a_missing_optional_library_names_the_extra(gray_mkv, monkeypatch):
    monkeypatch.setitem(sys.modules, "av", None)  # import av now raises ImportError
    with pytest.raises(InputError, match=r"needs the Python package 'av': pip install 'vibinverse\[imaging\]'"):
        open_cube(gray_mkv[0])


# ----------------------------------------------------------------------------------------- extract
def test_extract_region_roi_bin_frames_line_time(tmp_path):
    frames = np.random.default_rng(RNG_SEED).integers(0, 256, (12, 8, 10), dtype=np.uint8)
    np.save(tmp_path / "c.npy", frames)
    cube = open_cube(tmp_path / "c.npy", fps=100.0, chunks=5)
    part = extract_region(cube, frames=slice(3, 11), roi=(2, 8, 1, 7), binning=2, line_time=1e-4)
    expected = frames[3:11, 1:7, 2:8].reshape(8, 3, 2, 3, 2).mean(axis=(2, 4))
    assert part.dtype == np.float64 and np.allclose(part.values, expected, rtol=1e-15)
    assert part.attrs["bit_depth"] == 8 and part.attrs["binning"] == 2 and part.attrs["first_frame"] == 3
    assert list(part["row"].values) == [1, 3, 5] and list(part["col"].values) == [2, 4, 6]
    np.testing.assert_allclose(part["row_offset"].values, [1.5e-4, 3.5e-4, 5.5e-4], rtol=1e-12)  # bin means
    np.testing.assert_allclose(part["time"].values, np.arange(8) / 100.0, rtol=0, atol=1e-15)
    assert part.data.chunks[0] == (2, 5, 1)  # the source's chunks (5 frames), cut at frames 3 and 11
    with pytest.raises(InputError, match=r"^line_time: 0.01 s x 8 rows exceeds the frame interval 0.01 s"):
        extract_region(cube, line_time=0.01)


def test_extract_region_mask_and_read_mask(tmp_path):
    from PIL import Image

    frames = np.arange(3 * 6 * 7, dtype=np.uint16).reshape(3, 6, 7)
    np.save(tmp_path / "c.npy", frames)
    mask = np.zeros((6, 7), bool)
    mask[1:4, 2:6] = True
    mask[2, 3] = False
    Image.fromarray(mask.astype(np.uint8) * 255).save(tmp_path / "m.png")
    assert np.array_equal(read_mask(tmp_path / "m.png"), mask)
    part = extract_region(open_cube(tmp_path / "c.npy", fps=1.0), mask=read_mask(tmp_path / "m.png"))
    assert part.shape == (3, 3, 4) and list(part["row"].values) == [1, 2, 3]
    values = part.values
    assert np.isnan(values[:, 1, 1]).all() and np.array_equal(values[:, 0, 0], frames[:, 1, 2])
    with pytest.raises(InputError, match=r"^mask: shape \(2, 2\); the frame's shape \(6, 7\)"):
        extract_region(open_cube(tmp_path / "c.npy", fps=1.0), mask=np.ones((2, 2), bool))


def test_a_contiguous_netcdf4_cube_is_mapped_and_reads_the_same_values(tmp_path):
    """A netCDF-4 cube stored contiguous and uncompressed is read by memory map (no per-read HDF5
    overhead): the values equal xarray's own read exactly, NaN included. A compressed cube, or
    integer counts with a fill value (which xarray masks), keep the xarray path."""
    from vibinverse.io.cube import mapped
    from vibinverse.io.video import MappedFrames

    rng = np.random.default_rng(2)
    a = rng.random((50, 6, 5))
    a[3, 2, 1] = np.nan
    path = tmp_path / "plain.nc"
    xr.Dataset({"intensity": (("time", "y", "x"), a)}, coords={"time": np.arange(50) * 0.01}).to_netcdf(
        path, engine="h5netcdf"
    )
    assert isinstance(mapped(path, "intensity"), MappedFrames)
    got = open_cube(path)
    np.testing.assert_array_equal(got.values, a)
    np.testing.assert_array_equal(got[7:31, 1:4, 2].values, a[7:31, 1:4, 2])  # a read of a region
    # the dask array is built without hashing or copying the values: its chunks read the file
    assert not any(isinstance(v, np.ndarray) and v.size > 1 for v in dict(got.data.dask).values())
    # stored (x, time, y): time comes first, the other axes in their stored order (as xarray's read)
    swapped = tmp_path / "swapped.nc"
    xr.Dataset(
        {"intensity": (("x", "time", "y"), a.transpose(2, 0, 1))}, coords={"time": np.arange(50) * 0.01}
    ).to_netcdf(swapped, engine="h5netcdf")
    assert mapped(swapped, "intensity").shape == (5, 50, 6)
    np.testing.assert_array_equal(open_cube(swapped).values, a.transpose(0, 2, 1))
    packed = tmp_path / "packed.nc"
    counts = rng.integers(0, 255, (50, 6, 5)).astype(np.uint8)
    xr.Dataset({"intensity": (("time", "y", "x"), counts)}, coords={"time": np.arange(50) * 0.01}).to_netcdf(
        packed, engine="h5netcdf", encoding={"intensity": {"zlib": True, "_FillValue": 255}}
    )
    assert mapped(packed, "intensity") is None
    ref = xr.open_dataset(packed, engine="h5netcdf")["intensity"].values
    np.testing.assert_array_equal(open_cube(packed).values, ref)
