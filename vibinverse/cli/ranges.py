"""Numeric options checked at parse time: argparse `type=` functions that accept a number inside a
documented range and otherwise raise `argparse.ArgumentTypeError` naming the range, which the CLI's
parser turns into one line on stderr and exit 2 ("argument --seed: -1 is outside the allowed range
[0, 2^32)"). Every numeric option of every verb is declared with one of these."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable

SEED_MAX = 2**32 - 1  # numpy's and forward's seeds: [0, 2^32)
SEED_RANGE = "[0, 2^32)"
MAX_WORKERS = 1024  # threads or processes
MAX_STEPS = 10_000_000  # MCMC steps: the default is 20,000; 10^7 is days of sampling
MAX_COUNT = 1_000_000  # any other count (lines, pixels, frames per chunk, binning)
_INTEGER = re.compile(r"\s*[+-]?\d+\s*")


def _bound(v: float) -> str:
    return "inf" if v == math.inf else "-inf" if v == -math.inf else f"{v:g}"


def _shown(text: str) -> str:
    """The value as given, quoted and shortened: one line, whatever it holds."""
    return repr(text if len(text) <= 40 else text[:37] + "...")


def integer(lo: int, hi: int, shown: str | None = None) -> Callable[[str], int]:
    """An integer in [lo, hi] (`shown`: the range as the message writes it)."""
    allowed = shown or f"[{lo}, {hi}]"

    def parse(text: str) -> int:
        if not _INTEGER.fullmatch(text):
            raise argparse.ArgumentTypeError(f"{_shown(text)} is not an integer in the allowed range {allowed}")
        value = int(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{value} is outside the allowed range {allowed}")
        return value

    parse.__name__ = "integer"
    return parse


def real(lo: float, hi: float, *, low_open: bool = True, high_open: bool = True) -> Callable[[str], float]:
    """A finite number between lo and hi (an infinite bound is always open; NaN is refused)."""
    low_open, high_open = low_open or lo == -math.inf, high_open or hi == math.inf
    allowed = f"{'(' if low_open else '['}{_bound(lo)}, {_bound(hi)}{')' if high_open else ']'}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{_shown(text)} is not a number in the allowed range {allowed}") from None
        above = value > lo or (not low_open and value == lo)
        below = value < hi or (not high_open and value == hi)
        if not (math.isfinite(value) and above and below):
            raise argparse.ArgumentTypeError(f"{text.strip()} is outside the allowed range {allowed}")
        return value

    parse.__name__ = "number"
    return parse


seed = integer(0, SEED_MAX, SEED_RANGE)
workers = integer(1, MAX_WORKERS)
max_steps = integer(1, MAX_STEPS)
count = integer(1, MAX_COUNT)
positive = real(0.0, math.inf)  # rates, scales, thresholds: (0, inf)
