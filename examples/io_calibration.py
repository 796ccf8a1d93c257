"""Calibration of input-output identification's 90 % intervals (`vibinverse.oma.identify` with a
measured input, `vibinverse.oma.input_output`): the coverage of the true frequency and damping
ratio over many simulated records of two modes on three channels driven by a measured
band-limited force (`forward.motion.forced_modes`), each with its binomial standard error, and the
z-scores' mean and sd (a mode reported without an interval counts as not holding the truth).

    python examples/io_calibration.py [N_SETS] [FS] [NOISE]

N_SETS defaults to 50, FS to 200 Hz, NOISE (sensor noise over each channel's sd) to 0.05. Prints
one JSON document (docs/validation/oma.md quotes it)."""

# ruff: noqa: T201  (an example prints its results)
from __future__ import annotations

import json
import math
import sys

import numpy as np

from forward.motion.forced_modes import forced_modes
from vibinverse.io.channels import Channels
from vibinverse.oma import identify

MODES = ((12.0, 0.02), (31.0, 0.015))
RESIDUES = np.array([[1.0, 0.6, -0.3], [0.4, -0.9, 0.7]])


def record(seed: int, fs: float, noise: float) -> Channels:
    t, force, y = forced_modes(MODES, RESIDUES, fs=fs, duration=120.0, noise=noise, seed=seed)
    names, units = ("force", "a", "b", "c"), ("N", "m", "m", "m")
    return Channels(t, np.column_stack([force, y]), names, units, "forced", inputs=("force",))


def main(argv: list[str]) -> int:
    n = int(argv[0]) if argv else 50
    fs = float(argv[1]) if len(argv) > 1 else 200.0
    noise = float(argv[2]) if len(argv) > 2 else 0.05
    rows: dict[float, list[tuple[bool, bool, float, float]]] = {f: [] for f, _ in MODES}
    missed = dict.fromkeys(rows, 0)
    for seed in range(n):
        result = identify(record(seed, fs, noise), quantity="displacement", band=(5.0, 60.0))
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
    out = {"sets": n, "fs": fs, "noise": noise, "modes": []}
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
        out["modes"].append(entry)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
