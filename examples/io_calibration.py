"""Calibration of input-output identification's 90 % intervals (`vibinverse.oma.identify` with a
measured input, `vibinverse.oma.input_output`): the coverage of the true frequency and damping
ratio over many simulated records of two modes on three channels driven by a measured
band-limited force (`forward.motion.forced_modes`), each with its binomial standard error, and the
z-scores' mean and sd (a mode reported without an interval counts as not holding the truth).

    python examples/io_calibration.py [N_SETS] [FS] [NOISE ...] [-o FILE]

N_SETS defaults to 50, FS to 200 Hz, NOISE (sensor noise over each channel's sd) to 0.05; several
noise levels run one after the other on the same seeds. Prints one JSON document, or writes it to
FILE with -o: the settings (records, rate, record length, band, true modes) and, per noise level,
per mode, the records where it was found, missed or had no interval, the coverages with their
standard errors and the z-scores. docs/validation/oma.md's input-output table is made from it
(`python docs/validation/update_pages.py DIR`, the file named DIR/io_calibration.json)."""

# ruff: noqa: T201  (an example prints its results)
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from forward.motion.forced_modes import forced_modes
from vibinverse.io.channels import Channels
from vibinverse.oma import identify

MODES = ((12.0, 0.02), (31.0, 0.015))
RESIDUES = np.array([[1.0, 0.6, -0.3], [0.4, -0.9, 0.7]])
DURATION = 120.0  # s
BAND = (5.0, 60.0)  # Hz, the analysis band


def record(seed: int, fs: float, noise: float) -> Channels:
    t, force, y = forced_modes(MODES, RESIDUES, fs=fs, duration=DURATION, noise=noise, seed=seed)
    names, units = ("force", "a", "b", "c"), ("N", "m", "m", "m")
    return Channels(t, np.column_stack([force, y]), names, units, "forced", inputs=("force",))


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        """A bad argument: one line, no traceback."""
        raise SystemExit(f"{self.prog}: {message} (--help for usage)")


def _number(kind: type, low: float, strict: bool):
    """An argparse type: `kind(text)`, above `low` (strictly or not)."""

    def convert(text: str):
        try:
            x = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a {'whole ' if kind is int else ''}number: {text!r}") from None
        if not math.isfinite(x) or x < low or (strict and x == low):
            raise argparse.ArgumentTypeError(f"{'above' if strict else 'at least'} {low:g}, not {text}")
        return x

    return convert


def parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="io_calibration.py", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "n_sets",
        nargs="?",
        type=_number(int, 1, False),
        default=50,
        metavar="N_SETS",
        help="records per noise level (50)",
    )
    ap.add_argument(
        "fs",
        nargs="?",
        type=_number(float, 2 * BAND[1], True),
        default=200.0,
        metavar="FS",
        help="sampling rate, Hz (200)",
    )
    ap.add_argument(
        "noise",
        nargs="*",
        type=_number(float, 0.0, False),
        metavar="NOISE",
        help="sensor noise over each channel's sd (0.05)",
    )
    ap.add_argument("-o", "--output", type=Path, metavar="FILE", help="write the JSON to FILE instead of printing it")
    return ap


def calibrate(n: int, fs: float, noise: float) -> list[dict[str, Any]]:
    """Per true mode, over the records of seeds 0..n-1: found, missed, no interval, the coverages
    of f and zeta with their binomial se, the z-scores' mean and sd."""
    rows: dict[float, list[tuple[bool, bool, float, float]]] = {f: [] for f, _ in MODES}
    missed = dict.fromkeys(rows, 0)
    for seed in range(n):
        result = identify(record(seed, fs, noise), quantity="displacement", band=BAND)
        for f, zeta in MODES:
            near = [m for m in result.modes if abs(m.frequency - f) < 0.05 * f]
            if not near:
                missed[f] += 1
                continue
            m = min(near, key=lambda m: abs(m.frequency - f))
            lo_f, hi_f = m.frequency_interval
            lo_z, hi_z = m.damping_ratio_interval
            rows[f].append(
                (
                    lo_f <= f <= hi_f,
                    lo_z <= zeta <= hi_z,
                    (m.frequency - f) / m.frequency_sd if m.frequency_sd > 0 else math.nan,
                    (m.damping_ratio - zeta) / m.damping_ratio_sd if m.damping_ratio_sd > 0 else math.nan,
                )
            )
    modes = []
    for f, zeta in MODES:
        a = np.array(rows[f], dtype=float)
        k = len(a)
        # a mode without an interval (its Hessian not positive definite) holds the truth in none
        no_interval = int(np.isnan(a[:, 2]).sum()) if k else 0
        entry = {"frequency": f, "damping_ratio": zeta, "found": k, "missed": missed[f], "no_interval": no_interval}
        for i, name in enumerate(("frequency", "damping_ratio")):
            c = float(a[:, i].mean()) if k else math.nan
            entry[f"coverage_{name}"] = c
            entry[f"coverage_{name}_se"] = math.sqrt(c * (1 - c) / k) if k else math.nan
            entry[f"z_{name}_mean"] = float(np.nanmean(a[:, 2 + i])) if k > no_interval else math.nan
            entry[f"z_{name}_sd"] = float(np.nanstd(a[:, 2 + i])) if k > no_interval else math.nan
        modes.append(entry)
    return modes


def _finite(x: Any) -> Any:
    """NaN (no records to count) as null: the JSON stays standard."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x


def main(argv: list[str]) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    if args.output is not None:
        try:  # before the run, not after it
            args.output.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            ap.error(f"-o {args.output}: {e.strerror}")
    start = time.perf_counter()
    levels = []
    for noise in args.noise or [0.05]:
        t0 = time.perf_counter()
        modes = calibrate(args.n_sets, args.fs, noise)
        levels.append({"noise": noise, "modes": modes, "seconds": time.perf_counter() - t0})
    out = {
        "sets": args.n_sets,
        "fs": args.fs,
        "duration": DURATION,
        "band": list(BAND),
        "channels": RESIDUES.shape[1],
        "true_modes": [{"frequency": f, "damping_ratio": z} for f, z in MODES],
        "levels": levels,
        "seconds": time.perf_counter() - start,
    }
    text = json.dumps(_finite(out), indent=1)
    if args.output is None:
        print(text)
    else:
        args.output.write_text(text + "\n")
        print(f"io_calibration.py: wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
