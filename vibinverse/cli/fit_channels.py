"""`vibinverse fit TABLE` of a table with several value columns: operational modal analysis
(`vibinverse.oma.identify`): frequencies, damping ratios and unit mode shapes with 90 % intervals,
the MAC matrix and the stabilization-style diagram. Writes summary.json (the identification), modes.csv
(one row per mode), oma.png and report.html. `cmd_fit` (vibinverse.cli.commands) calls in here when the table holds
several channels (or --channels is given); the options are added by `add_channel_options`."""

from __future__ import annotations

import argparse
import csv
import logging
import math
from pathlib import Path
from typing import Any

from vibinverse.cli.outputs import created, output_dir
from vibinverse.errors import DataError, InputError, Unsupported
from vibinverse.io import jsonio
from vibinverse.io.atomic import check_paths, write_all
from vibinverse.io.channels import Channels, load_channels
from vibinverse.io.file_basics import csv_cell

logger = logging.getLogger("vibinverse")

MODES_CSV, FIGURE, SUMMARY, REPORT = "modes.csv", "oma.png", "summary.json", "report.html"
#: options of the multi-channel fit only
CHANNEL_OPTIONS = ("channels", "inputs", "geometry", "quantity")
#: the --method values a multi-channel fit accepts: its one estimator (Bayesian FFT + Laplace)
OMA_METHODS = frozenset({"auto", "spectral"})
#: options of the single-series fit that a multi-channel fit refuses (scene, model order, sampler)
SERIES_ONLY = ("scene", "lines", "decays", "drift", "noise", "gain", "set", "free", "chain", "resume", "summary")


def add_channel_options(parser: argparse.ArgumentParser) -> None:
    """The fit parser's options of a multi-channel table."""
    parser.add_argument(
        "--channels",
        metavar="all|A,B,C",
        help="a table with several value columns (CSV/TSV/Parquet, .npy N x (1 + C), .npz, netCDF (time, channel), "
        "lvm, TDMS, .mat, UFF 58): fit these channels together (default: all of them): operational modal "
        f"analysis, writing {SUMMARY}, {MODES_CSV}, {FIGURE} and {REPORT}",
    )
    parser.add_argument(
        "--input",
        dest="inputs",
        action="append",
        metavar="NAME",
        help="a channel that is measured excitation (a hammer's or shaker's force, a drive voltage): left out of "
        "the responses whose modes are identified (repeat, or A,B)",
    )
    parser.add_argument(
        "--geometry", metavar="FILE", help="CSV name,x,y,z (metres): the sensors' positions, kept with the shapes"
    )
    parser.add_argument(
        "--quantity",
        choices=("displacement", "velocity", "acceleration"),
        help="what the response channels measure (default: from their units; acceleration when they do not say)",
    )


def channels_of(args: argparse.Namespace) -> Channels | None:
    """The multi-channel table of a fit, or None for a single-series fit. With a --channels, --input,
    --geometry or --quantity option the file must read as channels; without one a file goes the
    multi-channel way only when it does not read as one series and holds two or more response channels."""
    from vibinverse.io.series import load_series

    given = [n for n in CHANNEL_OPTIONS if getattr(args, n, None) is not None]
    if args.pixels is not None or args.value_column is not None:
        if given:
            other = "--pixels" if args.pixels is not None else "--value-column"
            raise InputError(f"{_flag(given[0])}: applies to a multi-channel table; not with {other}")
        return None
    if given:
        return _load(args)
    try:
        load_series(args.data, time_column=args.time_column, value_column=None, fs=args.fs)
        return None
    except DataError as exc:
        try:
            channels = _load(args)
        except InputError:
            raise exc from None
        if len(channels.responses) < 2:
            raise exc from None
        return channels


def check_series_options(args: argparse.Namespace) -> None:
    """A fit of one series, a scene or a cube refuses the multi-channel options (one line naming the first)."""
    for name in CHANNEL_OPTIONS:
        if getattr(args, name, None) is not None:
            why = "--scene" if args.scene is not None else "--pixels" if args.pixels is not None else "one series"
            raise InputError(f"{_flag(name)}: applies to a multi-channel table; not with {why}")


def _flag(name: str) -> str:
    """The option's spelling on the command line."""
    return {"inputs": "--input"}.get(name, "--" + name.replace("_", "-"))


def _load(args: argparse.Namespace) -> Channels:
    inputs = [n.strip() for item in args.inputs or [] for n in item.split(",") if n.strip()]
    return load_channels(
        args.data,
        channels=args.channels,
        time_column=args.time_column,
        fs=args.fs,
        inputs=inputs,
        geometry=args.geometry,
    )


def fit_channels(args: argparse.Namespace, channels: Channels) -> dict[str, Any]:
    """Identify the modes of `channels` and write the outputs (module docstring)."""
    from vibinverse.oma import identify
    from vibinverse.oma.plots import plot_oma
    from vibinverse.oma.report import write_oma_report
    from vibinverse.oma.spectral_matrix import check_values

    for name in SERIES_ONLY:
        value = getattr(args, name, None)
        if value not in (None, False, []):
            raise Unsupported(f"{_flag(name)}: applies to a single-series fit; this table has several channels")
    if args.method not in OMA_METHODS:
        raise Unsupported(
            f"--method {args.method}: a multi-channel table is fitted by the spectral (Bayesian FFT) likelihood with "
            "a Laplace posterior; allowed: auto, spectral"
        )
    out = output_dir(args.output)
    files = {n: out / n for n in (SUMMARY, MODES_CSV, FIGURE, REPORT)}
    check_paths({f"-o {n}": p for n, p in files.items()}, {"data": args.data, "--geometry": args.geometry})
    check_values(channels)  # a table the fit cannot take is refused before "data: ..." is announced
    logger.info(f"data: {channels.describe()}")
    for note in channels.notes:
        logger.info(f"data: {note}")
    with created(out):
        result = identify(
            channels,
            modes=args.modes,
            quantity=args.quantity,
            band=getattr(args, "band", None),
            seed=args.seed,
        )
        doc = result.to_json()
        doc["source"] = str(args.data)
        if channels.positions is not None:
            resp = [channels.index(n) for n in result.names]
            doc["positions"] = {n: channels.positions[i].tolist() for n, i in zip(result.names, resp, strict=True)}
        write_all(
            {
                files[SUMMARY]: lambda p: p.write_text(jsonio.dumps(doc, indent=2)),
                files[MODES_CSV]: lambda p: _write_modes(p, result),
                files[FIGURE]: lambda p: plot_oma(result, p),
                files[REPORT]: lambda p: write_oma_report(result, p, str(args.data)),
            }
        )
    for line in result.table().splitlines():
        logger.info(line)
    logger.info(f"wrote {', '.join(str(p) for p in files.values())}")
    return {**doc, "paths": [str(p) for p in files.values()]}


def _write_modes(path: Path, result: Any) -> None:
    """One row per mode: f, zeta with their 90 % intervals and sd, then each channel's shape component
    with its interval."""
    head = ["mode", "frequency_hz", "frequency_q05", "frequency_q95", "frequency_sd", "damping_ratio",
            "damping_ratio_q05", "damping_ratio_q95", "damping_ratio_sd"]  # fmt: skip
    for n in result.names:
        head += [f"shape[{n}]", f"shape[{n}]_q05", f"shape[{n}]_q95"]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([csv_cell(h) for h in head])
        for i, m in enumerate(result.modes, 1):
            row: list[Any] = [i, m.frequency, *m.frequency_interval, m.frequency_sd, m.damping_ratio]
            row += [*m.damping_ratio_interval, m.damping_ratio_sd]
            for c in range(len(result.names)):
                row += [m.shape[c], *m.shape_interval[c]]
            # an interval not computed (the posterior not locally Gaussian) is an empty cell
            w.writerow([("" if math.isnan(v) else f"{v:.10g}") if isinstance(v, float) else v for v in row])
