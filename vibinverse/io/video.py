"""Frame sources of camera recordings, read lazily: small picklable array-likes (`FrameSource`:
shape, dtype, ndim, __getitem__) that read only the frames asked for, so that
`dask.array.from_array` makes a lazy cube of them and a distributed worker reopens the file itself.

- video containers (.mp4 .mov .avi .mkv .webm) through PyAV: a cheap first pass reads every frame's
  presentation time stamp from the packets without decoding (`scan_video`); each chunk then seeks
  to the keyframe before it and decodes only what it needs (`VideoFrames`);
- Photron .cih/.cihx + .mraw through pyMRAW: its header reader, memory-mapped 8/16-bit frames and
  its unpacker of 12-bit packed frames, applied per chunk (`scan_mraw`);
- multi-page TIFF through tifffile's zarr store (`scan_tiff`), and .npy memory-mapped (`npy_frames`).

`vibinverse.io.cube.open_cube` turns these into the (time, y, x) DataArray.
"""

from __future__ import annotations

import functools
import importlib
import logging
from abc import ABC, abstractmethod
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError

logger = logging.getLogger(__name__)

IMAGING_EXTRA = "pip install 'vibinverse[imaging]'"


def need(module: str, what: str) -> ModuleType:
    """Import an optional library of the imaging extra, else a one-line InputError naming the extra."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"input: {what} needs the Python package {module!r}: {IMAGING_EXTRA}") from None


def first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# ----------------------------------------------------------------------------------- the base class
class FrameSource(ABC):
    """A lazily read stack of frames, shape (time, y, x) or (time, y, x, channel).

    Subclasses implement `read(lo, hi, rest)`: frames lo..hi-1 with the index `rest` (slices or
    integers of the other axes) applied. Indexing a time slice reads only that range, so dask's
    fused getters read a region of interest without the rest of the frame where the format allows.
    Instances hold a path and numbers only (no open file), so they pickle to dask workers."""

    shape: tuple[int, ...]
    dtype: np.dtype

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @abstractmethod
    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        """Frames lo..hi-1 with `rest` applied to the other axes."""

    def chunk_sizes(self, n: int) -> tuple[int, ...]:
        """The default chunks along time for about `n` frames each (here: regular)."""
        total = self.shape[0]
        return (n,) * (total // n) + ((total % n,) if total % n else ())

    @property
    def token(self) -> tuple:
        """What, besides the file, tells this source's values apart (dask's key names)."""
        return (type(self).__name__,)

    def __getitem__(self, key: Any) -> np.ndarray:
        key = key if isinstance(key, tuple) else (key,)
        if any(k is Ellipsis for k in key):
            i = key.index(Ellipsis)
            key = key[:i] + (slice(None),) * (self.ndim - len(key) + 1) + key[i + 1 :]
        key = key + (slice(None),) * (self.ndim - len(key))
        n, first, rest = self.shape[0], key[0], key[1:]
        if isinstance(first, slice):
            start, stop, step = first.indices(n)
            frames = range(start, stop, step)
            if len(frames) == 0:
                return np.empty((0, *np.empty(self.shape[1:], dtype=np.bool_)[rest].shape), self.dtype)
            if step < 0:
                block = self.read(frames[-1], frames[0] + 1, rest)
                return block[::step]
            return self.read(frames[0], frames[-1] + 1, rest)[::step]
        if isinstance(first, (int, np.integer)):
            i = int(first) + n if first < 0 else int(first)
            if not 0 <= i < n:
                raise IndexError(f"frame {first} out of range for {n} frames")
            return self.read(i, i + 1, rest)[0]
        index = np.asarray(first)  # an array of frame numbers (fancy indexing)
        index = np.where(index < 0, index + n, index)
        lo, hi = int(index.min()), int(index.max()) + 1
        return self.read(lo, hi, rest)[index - lo]


class ChannelFrames(FrameSource):
    """One channel of the colour frames (time, y, x, 3|4) of another source: a plane as stored,
    or the float64 sum of R, G, B with `weights`. The region asked for is cut before the sum, so a
    region of interest costs the sum over its pixels only."""

    def __init__(self, source: FrameSource, weights: tuple[float, float, float]):
        self.source, self.weights = source, tuple(float(w) for w in weights)
        self.shape = tuple(source.shape[:3])
        self.plane = next((i for i, w in enumerate(self.weights) if w == 1.0), None)
        if self.plane is not None and sum(w != 0 for w in self.weights) > 1:
            self.plane = None
        self.dtype = source.dtype if self.plane is not None else np.dtype(np.float64)

    @property
    def token(self) -> tuple:
        return ("channel", self.weights, *self.source.token)

    def chunk_sizes(self, n: int) -> tuple[int, ...]:
        return self.source.chunk_sizes(n)

    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        block = self.source.read(lo, hi, (*rest, slice(None)))
        if self.plane is not None:
            return np.ascontiguousarray(block[..., self.plane])
        out = block[..., 0] * self.weights[0]  # float64: uint8 * a Python float
        for c in (1, 2):
            out += block[..., c] * self.weights[c]
        return out


# ------------------------------------------------------------------------------------------- video
@dataclass(frozen=True)
class VideoScan:
    """What the first pass over a video found: the lazy frames and their time stamps."""

    frames: VideoFrames
    time: NDArray[np.float64]  # seconds since the first frame, from each frame's presentation stamp
    nominal_fps: float | None  # the container's (average) frame rate
    bit_depth: int
    codec: str
    luma: bool  # colour video read as its luma plane


class VideoFrames(FrameSource):
    """Frames of a video stream decoded on demand with PyAV, matched to their presentation time
    stamps `pts` (stream time base, increasing). Gray pixel formats come out as stored (uint8, or
    uint16 for 9-16 bits); colour as RGB, 8 (rgb24) or 16 bits (rgb48le)."""

    def __init__(
        self,
        path: Path,
        stream: int,
        pts: NDArray[np.int64],
        keyframe: NDArray[np.bool_],
        to_format: str | None,
        shape: tuple[int, ...],
        dtype: np.dtype,
    ):
        self.path, self.stream, self.pts, self.keyframe = path, stream, pts, keyframe
        self.to_format, self.shape, self.dtype = to_format, shape, np.dtype(dtype)

    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        """Frames lo..hi-1, each cut to `rest` as it is decoded (a region costs its own size)."""
        out = np.empty((hi - lo, *np.empty(self.shape[1:], dtype=np.bool_)[rest].shape), self.dtype)
        keys = np.flatnonzero(self.keyframe[: lo + 1])
        seek = int(self.pts[keys[-1]]) if keys.size and keys[-1] > 0 else None
        filled = self._decode(lo, hi, out, rest, seek)
        if not filled.all() and seek is not None:  # a seek that landed after the frames: from the start
            logger.debug(f"{self.path}: seeking to {seek} missed frames {lo}..{hi - 1}; decoding from the start")
            filled = self._decode(lo, hi, out, rest, None)
        if not filled.all():
            k = lo + int(np.argmin(filled))
            raise DataError(f"input: {self.path}: frame {k} (pts {self.pts[k]}) could not be decoded")
        return out

    def _decode(self, lo: int, hi: int, out: np.ndarray, rest: tuple, seek: int | None) -> NDArray[np.bool_]:
        """Decode from the keyframe at `seek` (None: the start) up to frame hi - 1, keeping lo..hi-1."""
        av = need("av", "reading video")
        want = {int(p): i for i, p in enumerate(self.pts[lo:hi])}
        filled = np.zeros(hi - lo, dtype=bool)
        last = int(self.pts[hi - 1])
        try:
            with av.open(str(self.path)) as container:
                stream = container.streams.video[self.stream]
                stream.thread_type = "AUTO"  # FFmpeg decodes on several threads
                if seek is not None:
                    container.seek(seek, stream=stream, backward=True, any_frame=False)
                for frame in container.decode(stream):
                    if frame.pts is None:
                        continue
                    i = want.get(int(frame.pts))
                    if i is not None:
                        image = frame.to_ndarray(format=self.to_format) if self.to_format else frame.to_ndarray()
                        out[i] = image[rest]
                        filled[i] = True
                    if frame.pts >= last:
                        break
        except av.error.FFmpegError as exc:
            raise DataError(f"input: {self.path}: decoding failed: {first_line(exc)}") from None
        return filled

    def chunk_sizes(self, n: int) -> tuple[int, ...]:
        """Chunks of at most `n` frames that start at keyframes where the groups of pictures allow
        (whole groups per chunk; a group longer than `n` is split): a chunk that starts at a
        keyframe decodes no frame of another chunk, whatever order dask computes them in."""
        total, cuts, start, prev = self.shape[0], [], 0, 0
        for end in [*np.flatnonzero(self.keyframe)[1:].tolist(), total]:  # the end of each group
            if end - start > n and prev > start:
                cuts.append(prev)
                start = prev
            while end - start > n:
                start += n
                cuts.append(start)
            prev = end
        return tuple(int(d) for d in np.diff([0, *cuts, total]))


def _frame_layout(frame: Any, channel: str) -> tuple[str | None, int, np.dtype, int]:
    """(to_ndarray format, channels, dtype, bit depth) of a decoded frame. Gray pixel formats come
    as stored; YUV frames, for the luminance, as their luma plane (Y', the encoder's own weighted
    sum of R', G', B', in full range: integer counts, exact for a gray video); anything else, or one
    colour channel, as RGB (8 or 16 bits)."""
    fmt = frame.format
    bits = max(c.bits for c in fmt.components)
    gray = fmt.name.startswith("gray")
    if gray and len(fmt.components) == 1 and not fmt.name.startswith("grayf"):
        return None, 1, np.dtype(np.uint8 if bits <= 8 else np.uint16), bits
    yuv = not (gray or fmt.is_rgb or fmt.has_palette) and len(fmt.components) >= 3
    if yuv and channel == "luminance":
        if bits <= 8:
            return "gray", 1, np.dtype(np.uint8), 8
        depth = bits if bits in (9, 10, 12, 14, 16) else 16
        return f"gray{depth}le", 1, np.dtype(np.uint16), depth
    if bits <= 8:
        return "rgb24", 3, np.dtype(np.uint8), 8
    return "rgb48le", 3, np.dtype(np.uint16), 16  # swscale rescales to the 16-bit range


def scan_video(path: Path, channel: str = "luminance") -> VideoScan:
    """Read a video's frame time stamps (packets only, no decoding) and decode its first frame (the
    pixel format and size; a codec PyAV cannot decode is refused here, not in a later chunk).
    `channel` "luminance" reads YUV video as its luma plane (`_frame_layout`)."""
    av = need("av", f"reading {path.suffix} video")
    try:
        container = av.open(str(path))
    except av.error.FFmpegError as exc:
        raise DataError(f"input: cannot open {path} as a video: {first_line(exc)}") from None
    with container:
        if not container.streams.video:
            raise DataError(f"input: {path} has no video stream")
        stream = container.streams.video[0]
        if stream.codec_context is None:
            raise DataError(
                f"input: {path}: its video codec cannot be decoded by this PyAV (FFmpeg) build; re-encode it, "
                "e.g. ffmpeg -i IN -c:v ffv1 OUT.mkv"
            )
        codec = stream.codec_context.name
        index, tb = stream.index, stream.time_base
        rate = stream.average_rate or stream.guessed_rate
        pts, key = [], []
        try:
            for packet in container.demux(stream):
                if not packet.size or getattr(packet, "is_discard", False):
                    continue  # the flush packet at the end; frames an edit list drops
                stamp = packet.pts if packet.pts is not None else packet.dts
                if stamp is None:
                    raise DataError(f"input: {path}: frame {len(pts)} has no time stamp")
                pts.append(stamp)
                key.append(packet.is_keyframe)
        except av.error.FFmpegError as exc:
            raise DataError(f"input: {path}: reading the frames failed: {first_line(exc)}") from None
    if not pts:
        raise DataError(f"input: {path} has no frames")
    order = np.argsort(np.asarray(pts, dtype=np.int64), kind="stable")  # decode order -> presentation order
    pts_sorted = np.asarray(pts, dtype=np.int64)[order]
    keyframe = np.asarray(key, dtype=bool)[order]
    try:
        with av.open(str(path)) as container:
            first = next(container.decode(container.streams.video[0]), None)
    except av.error.FFmpegError as exc:
        raise DataError(f"input: {path}: the {codec} video cannot be decoded: {first_line(exc)}") from None
    if first is None:
        raise DataError(f"input: {path}: no frame of the {codec} video could be decoded")
    to_format, channels, dtype, bits = _frame_layout(first, channel)
    shape = (pts_sorted.size, first.height, first.width, *((channels,) if channels > 1 else ()))
    frames = VideoFrames(path, index, pts_sorted, keyframe, to_format, shape, dtype)
    luma = channels == 1 and not first.format.name.startswith("gray")
    return VideoScan(frames, stamps_seconds(pts_sorted, tb), float(rate) if rate else None, bits, codec, luma)


def stamps_seconds(pts: NDArray[np.int64], time_base: Fraction) -> NDArray[np.float64]:
    """Seconds since the first stamp: (pts - pts[0]) * time_base, each value correctly rounded (the
    integer product is exact below 2**53, then one division)."""
    tb = Fraction(time_base)
    return ((pts - pts[0]) * tb.numerator).astype(np.float64) / tb.denominator


# --------------------------------------------------------------------------------- Photron MRAW
@dataclass(frozen=True)
class MrawScan:
    frames: MrawFrames
    nominal_fps: float | None  # the header's record rate; None when it gives none
    bit_depth: int


class MrawFrames(FrameSource):
    """Frames of a Photron .mraw file: 8/16-bit memory-mapped, 12-bit packed unpacked per chunk by
    pyMRAW; `shift` right-aligns counts stored in the high bits ("EffectiveBit Side: Higher")."""

    def __init__(self, path: Path, shape: tuple[int, int, int], bits: int, shift: int):
        self.path, self.shape, self.bits, self.shift = path, shape, bits, shift
        self.dtype = np.dtype(np.uint8 if bits == 8 else np.uint16)

    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        _, h, w = self.shape
        if self.bits == 12:
            pymraw = need("pyMRAW", "reading 12-bit Photron MRAW")
            size = h * w * 3 // 2
            raw = np.memmap(self.path, dtype=np.uint8, mode="r", offset=lo * size, shape=((hi - lo) * size,))
            block = pymraw.nb_read_uint12(np.asarray(raw)).reshape(hi - lo, h, w)[(slice(None), *rest)]
        else:
            offset = lo * h * w * self.dtype.itemsize
            mm = np.memmap(self.path, dtype=self.dtype, mode="r", offset=offset, shape=(hi - lo, h, w))
            block = np.array(mm[(slice(None), *rest)])
        if self.shift:
            block >>= self.shift
        return block


def _cih_value(cih: dict, key: str, path: Path) -> Any:
    if key not in cih:
        raise DataError(f"input: {path}: the header has no {key!r}")
    return cih[key]


def scan_mraw(path: Path) -> MrawScan:
    """A Photron recording from its header (.cih or .cihx, read by pyMRAW) and the .mraw beside it
    (either may be given)."""
    pymraw = need("pyMRAW", "reading Photron MRAW")
    header = next((path.with_suffix(s) for s in (".cih", ".cihx") if path.with_suffix(s).is_file()), None)
    if path.suffix.lower() in (".cih", ".cihx"):
        header = path
    if header is None:
        raise DataError(f"input: {path}: no header {path.stem}.cih or {path.stem}.cihx beside it")
    mraw = header.with_suffix(".mraw")
    if not mraw.is_file():
        raise DataError(f"input: {header}: no {mraw.name} beside it")
    try:
        cih = pymraw.get_cih(str(header))
    except Exception as exc:  # noqa: BLE001 - pyMRAW raises anything on a malformed header
        raise DataError(f"input: cannot read the Photron header {header}: {first_line(exc)}") from None
    fmt = str(_cih_value(cih, "File Format", header))
    if fmt.lower() != "mraw":
        raise DataError(f"input: {header}: File Format {fmt}; only MRaw recordings are read")
    try:
        n, h, w = (int(_cih_value(cih, k, header)) for k in ("Total Frame", "Image Height", "Image Width"))
        bits = int(_cih_value(cih, "Color Bit", header))
        depth = int(cih.get("EffectiveBit Depth", bits))
        rate = float(cih.get("Record Rate(fps)", 0) or 0)
    except (TypeError, ValueError) as exc:
        raise DataError(f"input: {header}: a header value is not a number: {first_line(exc)}") from None
    if bits not in (8, 12, 16):
        raise DataError(f"input: {header}: Color Bit {bits}; allowed 8, 12 or 16 (monochrome recordings)")
    if n < 1:
        raise DataError(f"input: {header} has no frames (Total Frame {n})")
    if bits == 12 and (h * w) % 2:
        raise DataError(f"input: {header}: 12-bit frames of {h} x {w} (odd) pixels do not fill whole bytes")
    need_bytes = n * h * w * bits // 8
    if mraw.stat().st_size < need_bytes:
        raise DataError(
            f"input: {mraw} holds {mraw.stat().st_size} bytes; its header's {n} frames of {h} x {w} at {bits} "
            f"bits need {need_bytes}"
        )
    side = str(cih.get("EffectiveBit Side", "Lower")).lower()
    shift = bits - depth if side == "higher" and 0 < depth < bits else 0
    nominal = rate if np.isfinite(rate) and rate > 0 else None
    return MrawScan(MrawFrames(mraw, (n, h, w), bits, shift), nominal, depth if 0 < depth <= bits else bits)


# ---------------------------------------------------------------------------------- TIFF stacks
@dataclass(frozen=True)
class TiffScan:
    frames: TiffFrames
    nominal_fps: float | None  # 1 / the ImageJ frame interval, when the file records one
    bit_depth: int


class TiffFrames(FrameSource):
    """Pages of a TIFF stack through tifffile's zarr store (one open store per file and process);
    `keep`: the stored axes that are the cube's (the others are singletons, indexed at 0)."""

    def __init__(self, path: Path, shape: tuple[int, ...], dtype: np.dtype, keep: tuple[bool, ...]):
        self.path, self.shape, self.dtype, self.keep = path, shape, np.dtype(dtype), keep

    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        st = self.path.stat()
        arr = _tiff_array(str(self.path), st.st_mtime_ns, st.st_size)
        given = iter((slice(lo, hi), *rest))
        return np.asarray(arr[tuple(next(given) if k else 0 for k in self.keep)])


@functools.lru_cache(maxsize=8)
def _tiff_array(path: str, mtime_ns: int, size: int) -> Any:
    """The zarr array of a TIFF's first series (cached per file version: opening parses the pages)."""
    tifffile, zarr = need("tifffile", "reading TIFF"), need("zarr", "reading TIFF")
    return zarr.open(tifffile.imread(path, aszarr=True), mode="r")


def scan_tiff(path: Path) -> TiffScan:
    """A multi-page TIFF (its first series) as a stack of frames: singleton axes dropped."""
    tifffile = need("tifffile", "reading TIFF")
    need("zarr", "reading TIFF")
    try:
        with tifffile.TiffFile(path) as tf:
            series = tf.series[0]
            shape, dtype, axes = tuple(series.shape), series.dtype, series.axes
            bits = int(tf.pages[0].bitspersample)
            interval = (tf.imagej_metadata or {}).get("finterval")
    except Exception as exc:  # noqa: BLE001 - tifffile raises many kinds on a malformed file
        raise DataError(f"input: cannot read {path} as TIFF: {first_line(exc)}") from None
    keep = tuple(n > 1 or a in "YX" for a, n in zip(axes, shape))
    shape = tuple(n for k, n in zip(keep, shape) if k)
    if len(shape) == 2:
        raise DataError(f"input: {path} holds one image ({shape[0]} x {shape[1]}); a stack of frames is needed")
    nominal = 1.0 / float(interval) if interval and float(interval) > 0 else None
    return TiffScan(TiffFrames(path, shape, dtype, keep), nominal, bits)


# ------------------------------------------------------------------------------------------- .npy
class NpyFrames(FrameSource):
    """A .npy array memory-mapped anew by each read (nothing open between reads)."""

    def __init__(self, path: Path, shape: tuple[int, ...], dtype: np.dtype):
        self.path, self.shape, self.dtype = path, shape, np.dtype(dtype)

    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        return np.array(np.load(self.path, mmap_mode="r")[(slice(lo, hi), *rest)])


class MappedFrames(FrameSource):
    """An array stored contiguous and uncompressed at byte `offset` of a file (an HDF5 dataset),
    memory-mapped anew by each read, its axes taken in the order `axes` (time first). A read
    returns a view of the map: no copy (the pages are read when the values are used), and, unlike
    a memory map handed to dask whole, nothing is hashed or copied when the dask array is built."""

    def __init__(
        self, path: Path, offset: int, stored: tuple[int, ...], dtype: np.dtype, axes: tuple[int, ...] | None = None
    ):
        self.path, self.offset, self.stored, self.dtype = path, int(offset), tuple(stored), np.dtype(dtype)
        self.axes = tuple(axes) if axes is not None else tuple(range(len(self.stored)))
        self.shape = tuple(self.stored[a] for a in self.axes)

    def with_axes(self, axes: tuple[int, ...]) -> MappedFrames:
        """The same stored array, its axes taken in the order `axes`."""
        return MappedFrames(self.path, self.offset, self.stored, self.dtype, axes)

    @property
    def token(self) -> tuple:
        return ("mapped", self.offset, self.stored, str(self.dtype), self.axes)

    def read(self, lo: int, hi: int, rest: tuple) -> np.ndarray:
        if self.axes[0] == 0:  # time stored first: map frames lo..hi only (FrameSource asks hi > lo)
            frame = int(np.prod(self.stored[1:])) * self.dtype.itemsize
            shape = (hi - lo, *self.stored[1:])
            mm = np.memmap(self.path, mode="r", dtype=self.dtype, offset=self.offset + lo * frame, shape=shape)
            return mm.transpose(self.axes)[(slice(None), *rest)]
        mm = np.memmap(self.path, mode="r", dtype=self.dtype, offset=self.offset, shape=self.stored)
        return mm.transpose(self.axes)[(slice(lo, hi), *rest)]


def npy_frames(path: Path) -> NpyFrames:
    """The frames of a .npy array (its header only is read here)."""
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise DataError(f"input: cannot read {path} as .npy: {first_line(exc)}") from None
    if not isinstance(arr, np.ndarray):
        raise DataError(f"input: {path} is not a .npy array")
    return NpyFrames(path, arr.shape, arr.dtype)
