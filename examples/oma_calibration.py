"""Calibration of the multi-channel identification's 90 % intervals (`vibinverse.oma.identify`):
the coverage of the true frequency, damping ratio and shape components over many simulated data
sets of one bench case (`vibinverse.bench.oma_bench.OMA_CASES`: shear buildings simulated exactly,
`forward.motion.shear_building`), each with its binomial standard error.

    python examples/oma_calibration.py [N_SETS] [CASE] [--quick]

N_SETS defaults to 50, CASE to three_storey; --quick uses the case's short record. Prints one JSON
document (docs/guide/methods.md quotes it)."""

# ruff: noqa: T201  (an example prints its results)
from __future__ import annotations

import json
import sys

from vibinverse.bench.oma_bench import coverage, ours


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    args = [a for a in argv if a != "--quick"]
    n = int(args[0]) if args else 50
    case = args[1] if len(args) > 1 else "three_storey"
    print(json.dumps(coverage(ours, case, n, quick=quick), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
