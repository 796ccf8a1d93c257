"""Bench row for `vibinverse design`: the wall time of an n x n sweep (view offset x footprint
placement on the elastic roof) through the reduced model and the analytic Fisher information."""

from __future__ import annotations

import logging
from pathlib import Path

from forward.scene_file import read_table
from vibinverse.design.sweep import run_design

LOG = logging.getLogger(__name__).info


def design_row(scene_path: Path, n: int, workers: tuple[int, ...] = (1, 2), log=LOG) -> dict:
    """{"configurations", "seconds": {workers: s}, "ms_per_configuration": {workers: ms}}."""
    table = read_table(scene_path)
    vary = [f"sensor.offset=-0.04:0.04:{n}", f"footprint.center=0:25:{n}"]
    seconds = {}
    for w in workers:
        seconds[str(w)] = run_design(table, vary, None, workers=w)["seconds"]
        log(
            f"  design {n}x{n} on {scene_path.stem}, {w} worker(s): {seconds[str(w)]:.1f} s "
            f"({1e3 * seconds[str(w)] / n**2:.2f} ms per configuration)"
        )
    return {
        "configurations": n * n,
        "seconds": seconds,
        "ms_per_configuration": {w: 1e3 * s / n**2 for w, s in seconds.items()},
    }
