"""The verbs of the `vibinverse` command line: argument parsing and printing over the public API
(`vibinverse.api`); no logic the API lacks."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from forward.reduce import DEFAULT_RTOL, compile_scene
from vibinverse import __version__, api
from vibinverse.errors import InputError, scene_errors
from vibinverse.io import jsonio
from vibinverse.io.atomic import check_paths, write_all
from vibinverse.io.builtin import builtin_scene
from vibinverse.io.scenes import read_scene
from vibinverse.io.simulation import plot_series, write_series_csv

logger = logging.getLogger("vibinverse")

DEMO_SCENE = "roof_frame.toml"
DEMO_SET = ("noise.sigma=0.6",)  # drive-line SNR ~10 (README: how SNR is defined)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse prints usage too)
        raise InputError(f"{self.prog}: {message}")


def _output_dir(path: str) -> Path:
    """Create the output directory `path` (one-line error if that is impossible)."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"-o: cannot create directory {out}: {exc.strerror or exc}") from None
    return out


def _simulate_to(
    scene_path: Path,
    overrides: list[str],
    seed: int | None,
    out: Path,
    plot: Path | None,
    rtol: float | None = DEFAULT_RTOL,
    explain: bool = False,
) -> float:
    scene, table = read_scene(scene_path, overrides)
    if explain:
        with scene_errors():
            logger.info(compile_scene(scene, rtol=rtol if rtol is not None else DEFAULT_RTOL, seed=seed).explain())
    obs = api.simulate(table, seed=seed, rtol=rtol)
    writers = {out: lambda p: write_series_csv(p, obs, table, seed, __version__)}
    if plot is not None:
        writers[plot] = lambda p: plot_series(p, obs, str(table.get("title") or scene_path.stem))
    write_all(writers)
    return obs.sensitivity


def cmd_simulate(args: argparse.Namespace) -> None:
    if not (0 < args.rtol < float("inf")):
        raise InputError(f"--rtol: {args.rtol:g} is outside the allowed range (0, inf)")
    check_paths({"-o": args.output, "--plot": args.plot}, {"scene": args.scene})
    s = _simulate_to(
        Path(args.scene),
        args.set or [],
        args.seed,
        Path(args.output),
        Path(args.plot) if args.plot else None,
        None if args.dense else args.rtol,
        args.explain,
    )
    logger.info(f"sensitivity S = {s:.4e} (eq. 21); wrote {args.output}" + (f" and {args.plot}" if args.plot else ""))


DEMO_STEPS = 7000  # the demo converges near 1500 steps (50 x tau, tau ~ 30); the cap keeps it < 3 min


def cmd_demo(args: argparse.Namespace) -> None:
    """Simulate the paper's sec. 4.2 roof (SNR ~10 at the drive line), fit it (spectral -> MAP ->
    emcee) and write the report: the main job on built-in defaults."""
    from vibinverse.report import write_report

    out = _output_dir(args.output)
    scene = builtin_scene(DEMO_SCENE)
    csv, png = out / "frame.csv", out / "frame.png"
    s = _simulate_to(scene, list(DEMO_SET), args.seed, csv, png)
    logger.info(f"demo: paper sec. 4.2 roof on a resonant frame, 20 s at 200 Hz, sensitivity S = {s:.3e}; wrote {csv}")
    result = api.fit(
        csv,
        scene,
        overrides=DEMO_SET,
        method="auto",
        seed=args.seed,
        chain=out / "result.chain.h5",
        max_steps=DEMO_STEPS,
        progress=not args.no_progress,
    )
    summary = result.summary()
    write_all(
        {
            out / "result.nc": result.to_netcdf,
            out / "result.json": lambda p: p.write_text(jsonio.dumps(summary, indent=2)),
        }
    )
    report = write_report(out / "result.nc", out)
    logger.info("parameter                                     median      90% interval              truth")
    for name, v in summary["parameters"].items():
        logger.info(f"  {name:<42} {v['median']:<11.5g} [{v['q05']:.5g}, {v['q95']:.5g}]  {v['truth']:.5g}")
    d = summary["diagnostics"]
    logger.info(
        f"MCMC: {d['n_steps']} steps, R-hat {d['rhat_max']:.3f}, ESS {d['ess_min']:.0f}, "
        f"{'converged' if d['converged'] else 'NOT converged (the report says what to do)'}; "
        + ", ".join(f"{k} {v:.1f} s" for k, v in summary["timing"].items())
    )
    logger.info(f"report: {report}")


def cmd_study(args: argparse.Namespace) -> None:
    from vibinverse.studies import STUDIES

    out = _output_dir(args.output)
    names = list(STUDIES) if args.name == "all" else [args.name]
    for name in names:
        logger.info(STUDIES[name][0](out))


def cmd_fit(args: argparse.Namespace) -> None:
    from vibinverse.priors import parse_free

    if args.workers < 1 or args.max_steps < 1:
        raise InputError("--workers and --max-steps: must be >= 1")
    out, summary_path = Path(args.output), Path(args.summary)
    chain = Path(args.chain) if args.chain else out.with_suffix(".chain.h5")
    check_paths({"-o": out, "--summary": summary_path, "--chain": chain}, {"data": args.data, "--scene": args.scene})
    for p in (out, summary_path):
        if not p.parent.is_dir():
            raise InputError(f"output: cannot write {p}: no such directory")
    series = api.load_series(args.data, time_column=args.time_column, value_column=args.value_column, fs=args.fs)
    table = api.load_scene(args.scene, args.set or [])
    free = parse_free(args.free or [], table.get("infer"))
    logger.info(f"data: {series.describe()}")
    for note in series.notes:
        logger.info(f"data: {note}")
    result = api.fit(
        series,
        table,
        method=args.method,
        free=free or None,
        seed=args.seed,
        chain=chain,
        resume=args.resume,
        workers=args.workers,
        max_steps=args.max_steps,
        progress=not args.no_progress,
    )
    summary = result.summary()
    write_all({out: result.to_netcdf, summary_path: lambda p: p.write_text(jsonio.dumps(summary, indent=2))})
    for name, v in summary["parameters"].items():
        interval = "" if v["q05"] is None else f"  90% [{v['q05']:.6g}, {v['q95']:.6g}]"
        truth = "" if v["truth"] is None else f"  truth {v['truth']:.6g}"
        logger.info(f"  {name:<44} {v['median']:.6g}{interval}{truth}")
    for d in result.detections:
        if not d.detected:
            logger.info(f"  no {d.what} detected (log-likelihood gain {d.delta_loglike:.1f} < {d.threshold:.1f})")
    logger.info(f"wrote {out} and {summary_path}")


def cmd_report(args: argparse.Namespace) -> None:
    from vibinverse.report import write_report

    out = _output_dir(args.output)
    check_paths({"-o": out / "report.html"}, {"result": args.result})
    path = write_report(Path(args.result), out)
    logger.info(f"wrote {path}")


def cmd_design(args: argparse.Namespace) -> None:
    from vibinverse.design.ranking import score
    from vibinverse.design.sweep import write_design

    result = api.design(
        args.scene,
        vary=args.vary or [],
        targets=args.target,
        threshold=args.threshold,
        workers=args.workers,
        overrides=args.set or [],
        progress=not args.no_progress,
    )
    out = _output_dir(args.output)
    write_design(result, out)
    rows = result["rows"]
    n_ok = sum(r["status"] == "ok" for r in rows)
    logger.info(
        f"{len(rows)} configurations in {result['seconds']:.1f} s ({n_ok} possible, "
        f"{sum(r['status'] == 'ok' and r['sensitivity'] >= result['threshold'] for r in rows)} detectable "
        f"at S >= {result['threshold']:g})"
    )
    for i, r in enumerate(result["best"][:5], 1):
        where = ", ".join(f"{a.key}={_short(r[a.key])}" for a in result["axes"])
        logger.info(
            f"  {i}. {where}: S = {r['sensitivity']:.3g}, worst relative CRB sd = {score(r, result['targets']):.3g}"
        )
    logger.info(f"wrote {out / 'design.csv'}, {out / 'design.json'} and maps in {out}")


def _short(v: object) -> str:
    return f"{v:.5g}" if isinstance(v, float) else str(v)


def cmd_bench(args: argparse.Namespace) -> None:
    targets = [Path(p) for p in (args.json, args.plot) if p]
    check_paths({"--json": args.json, "--plot": args.plot}, {})
    for p in targets:  # fail before the long run, not after it
        if not p.parent.is_dir():
            raise InputError(f"output: cannot write {p}: no such directory")
    if args.estimators:
        from vibinverse.bench.estimators_bench import plot_speed_error
        from vibinverse.bench.estimators_bench import run as run_estimators

        sizes = {"n_seeds": 5, "n_coverage": 20, "mcmc_seeds": 4} if args.quick else {}
        result = run_estimators(builtin_scene(""), **sizes)
        for scene in dict.fromkeys(r["scene"] for r in result["rows"]):
            logger.info(f"{scene}:")
            logger.info(_estimator_table([r for r in result["rows"] if r["scene"] == scene]))
        logger.info(f"estimator comparison: {result['seconds']:.0f} s")
        rows = result["rows"]
    else:
        from vibinverse.bench.forward_bench import plot_speed_error, run

        result = run(builtin_scene(""), args.quick)
        rows = result["speed_error"]
    writers = {}
    if args.json:
        writers[Path(args.json)] = lambda p: p.write_text(jsonio.dumps(result, indent=2))
    if args.plot:
        writers[Path(args.plot)] = lambda p: plot_speed_error(rows, p)
    write_all(writers)


def _estimator_table(rows: list[dict]) -> str:
    fmt = lambda v, f: format("-", f">{f.split('.')[0]}") if v is None else format(v, f)
    lines = [
        f"{'method':<9}{'SNR':>4} {'parameter':<20}{'bias':>11}{'rmse':>11}{'crlb_sd':>11}{'rmse/crlb':>10}"
        f"{'cover90':>8}{'time_s':>8}{'failed':>7}"
    ]
    for r in rows:
        ratio = r["rmse"] / r["crlb_sd"] if r["rmse"] is not None and r["crlb_sd"] else None
        lines.append(
            f"{r['method']:<9}{r['snr']:>4} {r['param'].rsplit('.', 1)[-1]:<20}{fmt(r['bias'], '11.3g')}"
            f"{fmt(r['rmse'], '11.3g')}{fmt(r['crlb_sd'], '11.3g')}{fmt(ratio, '10.2f')}"
            f"{fmt(r['coverage90'], '8.2f')}{r['time_s']:8.2f}{r['n_failed']:>4}/{r['n']}"
        )
    return "\n".join(lines)


def _verbosity_options(parser: argparse.ArgumentParser, default: object) -> None:
    loud = parser.add_mutually_exclusive_group()
    loud.add_argument("-q", "--quiet", action="store_true", default=default, help="print errors and warnings only")
    loud.add_argument(
        "-v", "--verbose", action="store_true", default=default, help="also print the stages' details (debug log)"
    )


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="vibinverse", description="Passive optical vibrometry: simulate and invert pixel intensity series."
    )
    p.add_argument("--version", action="version", version=f"vibinverse {__version__}")
    _verbosity_options(p, False)
    verbosity = argparse.ArgumentParser(add_help=False)
    _verbosity_options(verbosity, argparse.SUPPRESS)  # before or after the verb; not reset by the verb
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    sim = sub.add_parser(
        "simulate", parents=[verbosity], help="scene file -> pixel intensity series (CSV) and its sensitivity"
    )
    sim.add_argument("scene", help="scene file (TOML)")
    sim.add_argument(
        "--set",
        action="append",
        metavar="dotted.key=value",
        help="override a scene value, e.g. --set sensor.inclination='pi/3+0.02' (repeatable)",
    )
    sim.add_argument("--seed", type=int, default=None, help="noise seed (reproducible output)")
    sim.add_argument("-o", "--output", required=True, help="output CSV: time,intensity,intensity_clean")
    sim.add_argument("--plot", help="also write a PNG of the series and its spectrum")
    sim.add_argument(
        "--rtol",
        type=float,
        default=DEFAULT_RTOL,
        help=f"accuracy of the fast evaluation, relative to each surface's peak-to-peak (default {DEFAULT_RTOL:g})",
    )
    sim.add_argument("--dense", action="store_true", help="evaluate every subpixel at every sample (the reference)")
    sim.add_argument(
        "--explain", action="store_true", help="print the evaluation chosen per surface and its error estimate"
    )
    sim.set_defaults(func=cmd_simulate)

    from vibinverse.studies import STUDIES

    study = sub.add_parser(
        "study",
        parents=[verbosity],
        help="reproduce a figure of the paper",
        description="Studies: " + "; ".join(f"{k}: {v[1]}" for k, v in STUDIES.items()),
    )
    study.add_argument("name", choices=[*STUDIES, "all"], help="figure to reproduce, or all")
    study.add_argument("-o", "--output", default="studies", help="output directory (default: studies)")
    study.set_defaults(func=cmd_study)

    fit = sub.add_parser(
        "fit",
        parents=[verbosity],
        help="measured series + scene -> posterior of resonances, drives, vibration "
        "lines and noise (a frame scene: Kalman likelihood; plate or ground: white noise)",
    )
    fit.add_argument(
        "data",
        help="series: CSV/TSV (delimiter sniffed; columns time,intensity), Parquet, .npy, .npz or netCDF; NaN = gap",
    )
    fit.add_argument("--time-column", metavar="NAME", help="time column of a CSV/TSV or Parquet table (default: time)")
    fit.add_argument(
        "--value-column", metavar="NAME", help="value column of a CSV/TSV or Parquet table (default: intensity)"
    )
    fit.add_argument(
        "--fs", type=float, metavar="HZ", help="sampling rate of a table without a time column: time = arange(n) / fs"
    )
    fit.add_argument("--scene", required=True, help="scene file describing the observation (TOML)")
    fit.add_argument("--set", action="append", metavar="dotted.key=value", help="override a scene value")
    fit.add_argument(
        "--free",
        action="append",
        metavar="NAME=PRIOR",
        help="free parameter with prior, e.g. surfaces.roof.motion.tilt_frequency='uniform(2,5)'",
    )
    fit.add_argument(
        "--method",
        default="auto",
        help="spectral | sindy | casadi | map | mcmc | auto (default: spectral -> SINDy (frame scenes) "
        "-> casadi -> emcee, each seeding the next); map is a derivative-free MAP (scipy)",
    )
    fit.add_argument("--seed", type=int, default=0)
    fit.add_argument("--workers", type=int, default=1, help="processes for the sampler")
    fit.add_argument("--max-steps", type=int, default=20000, help="cap on MCMC steps")
    fit.add_argument("--chain", help="HDF5 checkpoint of the sampler (default: OUTPUT with .chain.h5)")
    fit.add_argument("--resume", action="store_true", help="continue an interrupted MCMC run from its checkpoint")
    fit.add_argument("--no-progress", action="store_true")
    fit.add_argument("-o", "--output", required=True, help="result netCDF (opens in ArviZ)")
    fit.add_argument("--summary", required=True, help="result summary JSON")
    fit.set_defaults(func=cmd_fit)

    report = sub.add_parser("report", parents=[verbosity], help="result netCDF -> self-contained HTML report")
    report.add_argument("result")
    report.add_argument("-o", "--output", default="report", help="output directory")
    report.set_defaults(func=cmd_report)

    design = sub.add_parser(
        "design",
        parents=[verbosity],
        help="where, when and how to look: sensitivity, line SNR and "
        "Cramer-Rao bounds over a sweep of observation choices",
    )
    design.add_argument("scene", help="scene file (TOML)")
    design.add_argument(
        "--vary",
        action="append",
        metavar="KEY=start:stop:num|KEY=a,b,c",
        help="sweep a scene value or design key (repeat for a grid); default: a sweep suited to the scene",
    )
    design.add_argument(
        "--target",
        action="append",
        metavar="PARAM",
        help="parameter whose Cramer-Rao sd to report (repeat); default: frequency and amplitude",
    )
    design.add_argument("--threshold", type=float, default=1e-4, help="detectability threshold on S (default 1e-4)")
    design.add_argument("--set", action="append", metavar="dotted.key=value", help="override a scene value")
    design.add_argument("--workers", type=int, default=1, help="processes")
    design.add_argument("--no-progress", action="store_true")
    design.add_argument("-o", "--output", default="design", help="output directory (default: design)")
    design.set_defaults(func=cmd_design)

    bench = sub.add_parser(
        "bench", parents=[verbosity], help="speed against error of the forward model (reference vs fast paths)"
    )
    bench.add_argument("--quick", action="store_true", help="128x128 instead of 256x256 subpixels (a few minutes)")
    bench.add_argument("--json", help="write the results as JSON")
    bench.add_argument("--plot", help="write the speed-against-error plot (PNG)")
    bench.add_argument(
        "--estimators",
        action="store_true",
        help="instead: spectral, SINDy, casadi and emcee against the Cramer-Rao bound (sec. 4.2 scene, "
        "SNR 3/10/30; ~15 min, --quick ~3 min)",
    )
    bench.set_defaults(func=cmd_bench)

    demo = sub.add_parser("demo", parents=[verbosity], help="run the main job on a built-in scene")
    demo.add_argument("-o", "--output", default="vibinverse-demo", help="output directory (default: vibinverse-demo)")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--no-progress", action="store_true")
    demo.set_defaults(func=cmd_demo)
    return p
