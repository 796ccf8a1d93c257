"""Calibration of the multi-channel identification's 90 % intervals (`vibinverse.oma.identify`):
the coverage of the true frequency, damping ratio and shape components over many simulated data
sets of bench cases (`vibinverse.bench.oma_bench.OMA_CASES`: shear buildings simulated exactly,
`forward.motion.shear_building`), each with its binomial standard error.

    python examples/oma_calibration.py [N_SETS] [CASE ...] [--quick] [-o FILE]

N_SETS defaults to 50, CASE to three_storey (several cases run one after the other); --quick uses
each case's short record. Prints one JSON document, or writes it to FILE with -o: the settings
(data sets, quick, cases) and, per case, its description, channels, rate and record length, the
coverage of f, ζ (pooled and per mode) and the shape components with their standard errors and
interval counts, the fraction of modes found, failures and wall times. docs/validation/oma.md's
calibration table is made from it (`python docs/validation/update_pages.py DIR`, the file named
DIR/oma_calibration.json)."""

# ruff: noqa: T201  (an example prints its results)
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from vibinverse.bench.oma_bench import OMA_CASES, coverage, ours


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        """A bad argument: one line, no traceback."""
        raise SystemExit(f"{self.prog}: {message} (--help for usage)")


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"at least 1, not {n}")
    return n


def parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="oma_calibration.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("n_sets", nargs="?", type=_count, default=50, metavar="N_SETS", help="data sets per case (50)")
    ap.add_argument("cases", nargs="*", metavar="CASE", help=f"bench cases (three_storey): {', '.join(OMA_CASES)}")
    ap.add_argument("--quick", action="store_true", help="each case's short record")
    ap.add_argument("-o", "--output", type=Path, metavar="FILE", help="write the JSON to FILE instead of printing it")
    return ap


def calibrate(case: str, n_sets: int, quick: bool) -> dict[str, Any]:
    """`coverage` of our identification over n_sets data sets of `case`, with the case's description."""
    c = OMA_CASES[case]
    start = time.perf_counter()
    result = coverage(ours, case, n_sets, quick=quick)
    return {
        **result,
        "what": c.what,
        "modes": len(c.frequencies()),
        "channels": len(c.channels),
        "fs": c.fs,
        "duration": c.span(quick),
        "quick": quick,
        "wall_seconds": time.perf_counter() - start,
    }


def main(argv: list[str]) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    cases = args.cases or ["three_storey"]
    unknown = [c for c in cases if c not in OMA_CASES]
    if unknown:
        ap.error(f"unknown case {', '.join(map(repr, unknown))}; allowed: {', '.join(OMA_CASES)}")
    if args.output is not None:
        try:  # before the run, not after it
            args.output.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            ap.error(f"-o {args.output}: {e.strerror}")
    start = time.perf_counter()
    rows = [calibrate(case, args.n_sets, args.quick) for case in cases]
    out = {
        "settings": {"n_sets": args.n_sets, "quick": args.quick, "cases": cases},
        "cases": rows,
        "seconds": time.perf_counter() - start,
    }
    text = json.dumps(out, indent=1)
    if args.output is None:
        print(text)
    else:
        args.output.write_text(text + "\n")
        print(f"oma_calibration.py: wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
