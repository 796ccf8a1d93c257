"""A decoded recording written once to a scratch directory, block by block, so that the detection
map decodes a video once instead of once per block.

A video (or MRAW, TIFF) is read in pieces of whole frames: every block of pixels needs every
piece, and a read decodes whole frames. Read directly, each block decodes the whole recording
(60 blocks of a 640 x 420 video: 60 decodes, ~3 minutes for 888 frames). Kept in memory, a real
video outgrows the memory budget (3,336 frames of 640 x 420 bytes: 0.9 GB). Spilled, each piece
is decoded once and its pixels written to one file per block, at the piece's offset in time
(`os.pwrite`: pieces are written in any order, by any thread); a block is then one contiguous
read (time, y, x). The files live in a temporary directory removed when the map is done.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

logger = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class Spill:
    """One file per block `cuts[k]` (y slice, x slice) of a cube (nt, ny, nx) of `dtype`, each
    holding its block's samples in (time, y, x) order."""

    directory: Path
    cuts: tuple[tuple[slice, slice], ...]
    nt: int
    dtype: np.dtype

    @classmethod
    def create(cls, directory: Path, cuts: list[tuple[slice, slice]], nt: int, dtype: Any) -> Spill:
        """Allocate the files (sparse where the file system allows) in `directory`."""
        spill = cls(Path(directory), tuple(cuts), int(nt), np.dtype(dtype))
        for k in range(len(cuts)):
            with open(spill.path(k), "wb") as fh:
                fh.truncate(spill.nt * spill.pixels(k) * spill.dtype.itemsize)
        return spill

    @staticmethod
    def fits(directory: Path, nbytes: int) -> bool:
        """Whether `directory`'s file system has room for `nbytes` and a margin."""
        return shutil.disk_usage(directory).free > 1.2 * nbytes + 2**28

    def path(self, k: int) -> Path:
        return self.directory / f"block{k:05d}.bin"

    def pixels(self, k: int) -> int:
        ys, xs = self.cuts[k]
        return (ys.stop - ys.start) * (xs.stop - xs.start)

    def shape(self, k: int) -> tuple[int, int, int]:
        ys, xs = self.cuts[k]
        return self.nt, ys.stop - ys.start, xs.stop - xs.start

    def write(self, piece: np.ndarray, t0: int) -> int:
        """Write the frames `piece` (frames, ny, nx), starting at frame t0, into every block's file;
        returns the frames written."""
        piece = np.asarray(piece, dtype=self.dtype)
        for k, (ys, xs) in enumerate(self.cuts):
            part = np.ascontiguousarray(piece[:, ys, xs])
            fd = os.open(self.path(k), os.O_WRONLY)
            try:
                os.pwrite(fd, part.tobytes(), t0 * self.pixels(k) * self.dtype.itemsize)
            finally:
                os.close(fd)
        return int(piece.shape[0])

    def read(self, k: int) -> np.ndarray:
        """Block k's samples (time, y, x)."""
        return np.fromfile(self.path(k), dtype=self.dtype).reshape(self.shape(k))
