"""The verbs of the `vibinverse` command line: argument parsing and printing over the public API
(`vibinverse.api`); no logic the API lacks.

One rule for every verb that writes files: `-o DIR` is an output directory (created if missing)
into which the verb writes fixed file names, listed in its help in one pattern (`vibinverse.cli.outputs.output_option`).
Every verb returns its results and the paths it wrote as a dict, which `--json` prints as one strict
JSON document on stdout (`vibinverse.cli.main`; the log then goes to stderr).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from forward.reduce import DEFAULT_RTOL, compile_scene
from vibinverse import __version__, api
from vibinverse.cli import ranges
from vibinverse.cli.outputs import created, output_dir, output_option
from vibinverse.detection import BROAD_DAMPING
from vibinverse.errors import InputError, scene_errors
from vibinverse.io import jsonio
from vibinverse.io.atomic import check_paths, write_all
from vibinverse.io.builtin import builtin_scene
from vibinverse.io.scenes import read_scene
from vibinverse.io.simulation import plot_series, write_series_csv
from vibinverse.report import prior_warnings
from vibinverse.verdict import verdict

logger = logging.getLogger("vibinverse")

DEMO_SCENE = "roof_frame.toml"
DEMO_SET = ("noise.sigma=0.6",)  # drive-line SNR ~10 (README: how SNR is defined)

# the fixed file names written into `-o DIR`
SERIES, SERIES_PLOT = "series.csv", "series.png"  # simulate, demo
RESULT, SUMMARY, CHAIN = "result.nc", "summary.json", "result.chain.h5"  # fit, demo
REPORT = "report.html"  # report, demo
STUDY_FILES = ("png", "csv", "json")  # study: NAME.png, NAME.csv, NAME.json
DESIGN_FILES = ("design.csv", "design.json", "design_sensitivity.png", "design_crlb.png")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse prints usage too)
        raise InputError(f"{self.prog}: {message}")

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> Any:
        # argparse drops a "--" given as an option's value (--seed=--) and then passes [] on as the
        # value, unchecked by the option's type: refuse it as a missing value
        if action.option_strings and action.nargs is None and list(arg_strings) == ["--"]:
            self.error(f"argument {'/'.join(action.option_strings)}: expected one argument")
        return super()._get_values(action, arg_strings)


# ---------------------------------------------------------------- -o DIR and --json, for every verb


def _check_outputs(outputs: dict[str, Path | None], inputs: dict[str, str | Path | None]) -> None:
    """`check_paths` with each output named by the option that placed it ("-o" files by name)."""
    check_paths({(k if k.startswith("--") else f"-o {Path(k).name}"): p for k, p in outputs.items()}, inputs)


def _result(doc: dict[str, Any], paths: list[Path]) -> dict[str, Any]:
    """What a verb returns: its results and the paths it wrote (printed by `--json`)."""
    return {**doc, "paths": [str(p) for p in paths]}


# ---------------------------------------------------------------- the verbs


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


def cmd_simulate(args: argparse.Namespace) -> dict[str, Any]:
    if not (0 < args.rtol < float("inf")):
        raise InputError(f"--rtol: {args.rtol:g} is outside the allowed range (0, inf)")
    if args.image is not None:
        return _simulate_image(args)
    for option, given in (("--video", args.video), ("--video-fps", args.video_fps is not None)):
        if given:
            raise InputError(f"{option}: needs --image NX,NY (a video is rendered from an image cube)")
    out = output_dir(args.output)
    csv, png = out / SERIES, (out / SERIES_PLOT if args.plot else None)
    _check_outputs({SERIES: csv, SERIES_PLOT: png}, {"scene": args.scene})
    with created(out):
        s = _simulate_to(
            Path(args.scene), args.set or [], args.seed, csv, png, None if args.dense else args.rtol, args.explain
        )
    written = [p for p in (csv, png) if p is not None]
    logger.info(f"sensitivity S = {s:.4e} (eq. 21); wrote {' and '.join(map(str, written))}")
    return _result({"sensitivity": s}, written)


CUBE, CUBE_PLOT, VIDEO = "cube.nc", "cube.png", "video.mp4"  # simulate --image


def _image_size(text: str) -> tuple[int, int]:
    """--image NX,NY: two pixel counts in [1, MAX_PIXELS_PER_SIDE] (one-line InputError)."""
    from forward.imager import MAX_PIXELS_PER_SIDE

    parts = text.split(",")
    allowed = f"two integers NX,NY in the allowed range [1, {MAX_PIXELS_PER_SIDE}]"
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise InputError(f"--image: {text!r} is not {allowed}")
    nx, ny = (int(p) for p in parts)
    if not (1 <= nx <= MAX_PIXELS_PER_SIDE and 1 <= ny <= MAX_PIXELS_PER_SIDE):
        raise InputError(f"--image: {nx},{ny} is outside {allowed}")
    return nx, ny


def _simulate_image(args: argparse.Namespace) -> dict[str, Any]:
    """simulate --image NX,NY: the footprint as an NX x NY-pixel cube (cube.nc), its mean frame
    (cube.png, --plot) and an 8-bit video of it (video.mp4, --video)."""
    import numpy as np

    from forward.imager import render_cube
    from vibinverse.io.cube_writer import MAX_FPS, plot_cube, quantization_for, write_cube_netcdf, write_video

    nx, ny = _image_size(args.image)
    if args.video_fps is not None:
        if not args.video:
            raise InputError("--video-fps: needs --video (it is the video's nominal frame rate)")
        if not (0 < args.video_fps <= MAX_FPS):
            raise InputError(f"--video-fps: {args.video_fps:g} is outside the allowed range (0, {MAX_FPS:g}]")
    out = output_dir(args.output)
    nc, png, video = out / CUBE, (out / CUBE_PLOT if args.plot else None), (out / VIDEO if args.video else None)
    _check_outputs({CUBE: nc, CUBE_PLOT: png, VIDEO: video}, {"scene": args.scene})
    with created(out):
        scene, table = read_scene(Path(args.scene), args.set or [])
        with scene_errors():
            cube = render_cube(scene, nx, ny, seed=args.seed, rtol=None if args.dense else args.rtol)
        if args.explain:
            logger.info(cube.explain())
        fs = scene.sampling.fs
        doc: dict[str, Any] = {"shape": list(cube.shape), "fs": fs, "evaluation": cube.evaluation}
        writers = {nc: lambda p: write_cube_netcdf(p, cube, table, args.seed, __version__)}
        if png is not None:
            outlines = [(s.name, s.x, s.y) for s in scene.surfaces]
            title = str(table.get("title") or Path(args.scene).stem)
            writers[png] = lambda p: plot_cube(p, cube, outlines, title)
        if video is not None:
            quant = quantization_for(cube.intensity_clean)  # the clean range, with a margin for the noise
            fps = args.video_fps if args.video_fps is not None else fs
            meta = {"capture_fps": fs, "seed": args.seed, "source": f"vibinverse {__version__} simulate --image"}
            frames = cube.intensity
            writers[video] = lambda p: write_video(p, frames, fps, quantization=quant, metadata=meta, suffix=".mp4")
            doc.update(video_fps=fps, quantization=quant.as_dict())
        write_all(writers)
    written = [p for p in (nc, png, video) if p is not None]
    s_max = float(np.nanmax(cube.sensitivity)) if np.any(np.isfinite(cube.sensitivity)) else float("nan")
    logger.info(
        f"cube of {ny} x {nx} pixels x {cube.shape[0]} samples, largest pixel sensitivity S = {s_max:.4e} "
        f"(eq. 21); wrote {', '.join(map(str, written))}"
    )
    return _result({**doc, "sensitivity_max": s_max}, written)


DEMO_WORKERS = 1  # threads (`ThreadMap`) gave no gain here: the stage after sampling is serial; a pool was slower
DEMO_STEPS = 7000  # the demo converges in ~1400 steps (R-hat <= 1.01, ESS >= 400); the cap keeps it < 3 min


def cmd_demo(args: argparse.Namespace) -> dict[str, Any]:
    """Simulate the paper's sec. 4.2 roof (SNR ~10 at the drive line), fit it (spectral -> MAP ->
    emcee) and write the report: the main job on built-in defaults."""
    from vibinverse.report import write_report

    out = output_dir(args.output)
    scene = builtin_scene(DEMO_SCENE)
    csv, png = out / SERIES, out / SERIES_PLOT
    warm = _compile_in_background()
    _check_outputs({n: out / n for n in (SERIES, SERIES_PLOT, RESULT, SUMMARY, CHAIN, REPORT)}, {})
    with created(out), warm:
        s = _simulate_to(scene, list(DEMO_SET), args.seed, csv, png)
        logger.info(
            f"demo: paper sec. 4.2 roof on a resonant frame, 20 s at 200 Hz, sensitivity S = {s:.3e}; wrote {csv}"
        )
        result = api.fit(
            csv,
            scene,
            overrides=DEMO_SET,
            method="auto",
            seed=args.seed,
            chain=out / CHAIN,
            max_steps=DEMO_STEPS,
            workers=DEMO_WORKERS,
            progress=not args.no_progress,
        )
        summary = result.summary()
        write_all(
            {
                out / RESULT: result.to_netcdf,
                out / SUMMARY: lambda p: p.write_text(jsonio.dumps(summary, indent=2)),
            }
        )
        report = write_report(out / RESULT, out)
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
    logger.info(f"verdict: {verdict(summary).headline}")
    written = [csv, png, out / RESULT, out / SUMMARY, *([out / CHAIN] if (out / CHAIN).exists() else []), report]
    return _result(summary, written)


@contextlib.contextmanager
def _compile_in_background() -> Iterator[None]:
    """Compile the frame model's kernels (numba; cached on disk for later runs) in a second process
    while this one simulates and runs the spectral and MAP stages: on a fresh install that takes
    ~7 s of the demo's time, which the second core absorbs. The process is stopped on the way out."""
    import subprocess
    import sys

    logger.info("compiling the Kalman filter kernels in a second process (numba; cached for later runs) ...")
    proc = subprocess.Popen(
        [sys.executable, "-c", "from vibinverse.models.frame import warm_up; warm_up()"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        yield
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait()


def cmd_study(args: argparse.Namespace) -> dict[str, Any]:
    from vibinverse.studies import STUDIES

    out = output_dir(args.output)
    names = list(STUDIES) if args.name == "all" else [args.name]
    files = {f"{n}.{ext}": out / f"{n}.{ext}" for n in names for ext in STUDY_FILES}
    _check_outputs(files, {})
    studies = {}
    with created(out):
        for name in names:
            line = STUDIES[name][0](out)
            logger.info(line)
            studies[name] = {"summary": line, "results": jsonio.loads((out / f"{name}.json").read_text())}
    return _result({"studies": studies}, list(files.values()))


def cmd_fit(args: argparse.Namespace) -> dict[str, Any]:
    from vibinverse.cli import fit_channels
    from vibinverse.cli import fit_cube as cube_fit
    from vibinverse.priors import parse_free

    if (args.workers is not None and args.workers < 1) or args.max_steps < 1:
        raise InputError("--workers and --max-steps: must be >= 1")
    if args.pixels is None and args.scene is None:  # several channels: operational modal analysis
        cube_fit.check_series_options(args, allow=("band",))  # a multi-channel fit takes --band too
        channels = fit_channels.channels_of(args)
        if channels is not None:
            return fit_channels.fit_channels(args, channels)
    fit_channels.check_series_options(args)
    if args.pixels is None:
        cube_fit.check_series_options(args)
    out = output_dir(args.output)
    nc = out / RESULT
    summary_path = Path(args.summary) if args.summary else out / SUMMARY
    chain = Path(args.chain) if args.chain else out / CHAIN
    pixels_csv = None if args.pixels is None else out / cube_fit.PIXELS
    _check_outputs(
        {
            RESULT: nc,
            "--summary" if args.summary else SUMMARY: summary_path,
            "--chain" if args.chain else CHAIN: chain,
            cube_fit.PIXELS: pixels_csv,
        },
        {
            "data": args.data,
            "--scene": args.scene,
            "--pixels": None if args.pixels is None else cube_fit.selection_file(args.pixels),
        },
    )
    if args.summary and not summary_path.parent.is_dir():
        raise InputError(f"--summary: cannot write {summary_path}: no such directory")
    with created(out):
        options = {
            "method": args.method,
            "seed": args.seed,
            "chain": chain,
            "resume": args.resume,
            "workers": args.workers,
            "max_steps": args.max_steps,
            "progress": not args.no_progress,
        }
        if args.pixels is not None:  # a cube: many pixels fitted jointly (vibinverse.cli.fit_cube)
            table = _fit_table(args)
            free = parse_free(args.free or [], table.get("infer"))
            result = cube_fit.fit_cube(args, table, {**options, "free": free or None})
        else:
            series = api.load_series(
                args.data, time_column=args.time_column, value_column=args.value_column, fs=args.fs
            )
            table = _fit_table(args)
            free = parse_free(args.free or [], table.get("infer"))
            logger.info(f"data: {series.describe()}")
            for note in series.notes:
                logger.info(f"data: {note}")
            result = api.fit(series, table, free=free or None, **options)
        summary = result.summary()
        writers = {nc: result.to_netcdf, summary_path: lambda p: p.write_text(jsonio.dumps(summary, indent=2))}
        if pixels_csv is not None:
            writers[pixels_csv] = lambda p: cube_fit.write_pixels_csv(p, result)
        write_all(writers)
    for name, v in summary["parameters"].items():
        interval = "" if v["q05"] is None else f"  90% [{v['q05']:.6g}, {v['q95']:.6g}]"
        truth = "" if v["truth"] is None else f"  truth {v['truth']:.6g}"
        logger.info(f"  {name:<44} {v['median']:.6g}{interval}{truth}")
    for d in result.detections:
        if d.product:
            logger.info(
                f"  {d.what} is a product of stronger tones ({d.product}): not claimed as a vibration of its own"
            )
        elif d.broad:
            logger.info(f"  {d.what} is a broad hump (damping ratio > {BROAD_DAMPING:g}): not claimed as a resonance")
        elif not d.detected:
            logger.info(f"  no {d.what} detected (log-likelihood gain {d.delta_loglike:.1f} < {d.threshold:.1f})")
    for note in prior_warnings(summary):
        logger.warning(note)
    written = [nc, summary_path, *([chain] if result.chains is not None and chain.exists() else [])]
    written += [pixels_csv] if pixels_csv is not None else []
    logger.info(f"wrote {', '.join(map(str, written))}")
    logger.info(f"verdict: {verdict(summary).headline}")
    return _result(summary, written)


MODAL_OPTIONS = ("modes", "lines", "decays", "drift", "noise", "gain")


def _fit_table(args: argparse.Namespace) -> dict[str, Any]:
    """The scene table of a fit: the scene file, or without one the generic modal model, whose
    order `--modes`, `--lines`, `--decays`, `--drift`, `--noise` and `--gain` fix (the rest is chosen
    by BIC)."""
    given = {k: getattr(args, k) for k in MODAL_OPTIONS if getattr(args, k) is not None}
    if args.scene is not None:
        for k in ("modes", "lines", "decays"):
            if k in given:
                raise InputError(
                    f"--{k}: fixes the order of the scene-less modal model; with --scene the scene describes "
                    "the signal (--noise, --drift and --gain add nuisance terms beside it)"
                )
        table = api.load_scene(args.scene, args.set or [])
        nuisance = dict(table.get("nuisance") or {})
        nuisance.update({k: given[k] for k in ("noise", "drift", "gain") if k in given})  # `NuisanceSpec` spellings
        if nuisance:
            table["nuisance"] = nuisance
        return table
    if args.set:
        raise InputError(
            "--set: overrides a scene value; give --scene, or fix the modal model by --modes, --lines, ..."
        )
    for k in ("modes", "lines", "decays"):
        if k in given and not 0 <= given[k] <= 6:
            raise InputError(f"--{k}: {given[k]} is outside the allowed range [0, 6]")
    if "drift" in given:
        given["drift"] = {"none": False}.get(given["drift"], given["drift"])
    if "gain" in given:
        from vibinverse.terms.nuisance import GAIN_WORDS

        given["gain"] = bool(GAIN_WORDS.get(given["gain"], 0))  # --gain drift / none: whether the gain drifts
    return {"modal": given}


def cmd_report(args: argparse.Namespace) -> dict[str, Any]:
    from vibinverse.report import write_report

    out = output_dir(args.output if args.output is not None else Path(args.result).parent)
    _check_outputs({REPORT: out / REPORT}, {"result": args.result})
    with created(out):
        path = write_report(Path(args.result), out)
    logger.info(f"wrote {path}")
    return _result({}, [path])


def cmd_design(args: argparse.Namespace) -> dict[str, Any]:
    from vibinverse.design.ranking import score
    from vibinverse.design.sweep import write_design

    out = output_dir(args.output)
    _check_outputs({n: out / n for n in DESIGN_FILES}, {"scene": args.scene})
    with created(out):
        result = api.design(
            args.scene,
            vary=args.vary or [],
            targets=args.target,
            threshold=args.threshold,
            workers=args.workers,
            overrides=args.set or [],
            progress=not args.no_progress,
            pixels=args.pixels,
        )
        written = write_design(result, out)
    rows = result["rows"]
    n_ok = sum(r["status"] == "ok" for r in rows)
    n_detectable = sum(r["status"] == "ok" and r["sensitivity"] >= result["threshold"] for r in rows)
    logger.info(
        f"{len(rows)} configurations in {result['seconds']:.1f} s ({n_ok} possible, "
        f"{n_detectable} detectable at S >= {result['threshold']:g})"
    )
    for i, r in enumerate(result["best"][:5], 1):
        where = ", ".join(f"{a.key}={_short(r[a.key])}" for a in result["axes"])
        logger.info(
            f"  {i}. {where}: S = {r['sensitivity']:.3g}, worst relative CRB sd = {score(r, result['targets']):.3g}"
        )
    logger.info(f"wrote {out / 'design.csv'}, {out / 'design.json'} and maps in {out}")
    doc = {
        "n_configurations": len(rows),
        "n_ok": n_ok,
        "n_detectable": n_detectable,
        "threshold": result["threshold"],
        "targets": result["targets"],
        "best": result["best"][:DESIGN_BEST],
        "seconds": result["seconds"],
    }
    return _result(doc, written)


DESIGN_BEST = 10  # rows of the ranking that --json prints (design.json holds all of them)


def _short(v: object) -> str:
    return f"{v:.5g}" if isinstance(v, float) else str(v)


def _bench_forward(quick: bool) -> tuple[dict, Any]:
    """The forward model's fast paths against the dense reference, the likelihoods, a design sweep."""
    from vibinverse.bench.forward_bench import plot_speed_error, run

    result = run(builtin_scene(""), quick)
    return result, lambda p: plot_speed_error(result["speed_error"], p)


def _bench_estimators(quick: bool) -> tuple[dict, Any]:
    """Spectral, SINDy, casadi, MAP and emcee against the Cramer-Rao bound."""
    from vibinverse.bench.estimators_bench import plot_speed_error, run

    sizes = {"n_seeds": 5, "n_coverage": 20, "mcmc_seeds": 4} if quick else {}
    result = run(builtin_scene(""), workers=min(2, os.cpu_count() or 1), **sizes)
    for scene in dict.fromkeys(r["scene"] for r in result["rows"]):
        logger.info(f"{scene}:")
        logger.info(_estimator_table([r for r in result["rows"] if r["scene"] == scene]))
    logger.info(f"estimator comparison: {result['seconds']:.0f} s")
    return result, lambda p: plot_speed_error(result["rows"], p)


def _bench_robustness(quick: bool) -> tuple[dict, Any]:
    """Our fits and the peers' on data that depart from the clean simulation as real data do."""
    from vibinverse.bench.robustness_bench import plot, run, table

    result = run(quick=quick, workers=min(2, os.cpu_count() or 1))
    logger.info(table(result))
    return result, lambda p: plot(result["rows"], p)


def _bench_oma(quick: bool) -> tuple[dict, Any]:
    """Multi-channel modal identification on simulated shear buildings, ours against pyOMA2's SSI-cov,
    FDD and EFDD (`vibinverse.bench.oma_bench`)."""
    from vibinverse.bench import oma_bench

    # compiled before the timed calls, as the peers' imports are: one untimed fit of a short record
    warm, _ = oma_bench.OMA_CASES[oma_bench.QUICK_CASES[0]].simulate(0, True)
    oma_bench.ours(warm, oma_bench.OMA_CASES[oma_bench.QUICK_CASES[0]].hints())
    result = oma_bench.run(quick=quick, ours=oma_bench.ours)
    logger.info(oma_bench.table(result))
    return result, lambda p: oma_bench.plot(result, p)


SCENE_TABLE, SCENE_FITS = "robustness_scene.txt", "robustness_scene_fits.jsonl"


def _bench_robustness_scene(args: argparse.Namespace, out: Path, js: Path) -> dict[str, Any]:
    """--robustness --scene: the scene column (`robustness_scene`) merged into robustness.json under
    "scene", so that an earlier run's modal columns stay; its table in robustness_scene.txt, and each
    data set's fits appended to robustness_scene_fits.jsonl as it finishes (a long run keeps them)."""
    from vibinverse.bench.robustness_bench import with_scene
    from vibinverse.bench.robustness_scene import FITTERS, SCENE_CASES, run, table

    cases = _case_names(args, list(SCENE_CASES))
    fitters = _listed("--fitters", args.fitters, FITTERS)
    txt, fits = out / SCENE_TABLE, out / SCENE_FITS
    _check_outputs({js.name: js, txt.name: txt, fits.name: fits}, {})
    with created(out):
        previous = None
        if js.is_file():
            with contextlib.suppress(ValueError, OSError):
                previous = jsonio.loads(js.read_text())
        fits.write_text("")  # this run's records only
        workers = args.workers if args.workers is not None else min(2, os.cpu_count() or 1)
        result = run(quick=args.quick, cases=cases, fitters=fitters, workers=workers, records=fits)
        text = table(result)
        logger.info(text)
        doc = with_scene(previous if isinstance(previous, dict) else None, result)
        write_all({js: lambda p: p.write_text(jsonio.dumps(doc, indent=2)), txt: lambda p: p.write_text(text + "\n")})
    logger.info(f'wrote {js} (under "scene"), {txt} and {fits}')
    return _result(result, [js, txt, fits])


def _bench_imaging(quick: bool) -> tuple[dict, Any]:
    """From image cube to answer: the imager, detection throughput and memory, the multi-pixel fit."""
    from vibinverse.bench.imaging_bench import plot, run

    result = run(builtin_scene(""), quick)
    logger.info(f"imaging benchmark: {result['seconds']:.0f} s")
    return result, lambda p: plot(result, p)


def _listed(flag: str, text: str | None, allowed: Sequence[str] | None = None) -> list[str] | None:
    """A comma-separated option as a list (None when not given), each name checked against
    `allowed` when given."""
    names = [c.strip() for c in text.split(",") if c.strip()] if text is not None else None
    for c in names or []:
        if allowed is not None and c not in allowed:
            raise InputError(f"{flag}: {c!r}; allowed: {', '.join(allowed)}")
    if names == [] and allowed is not None:
        raise InputError(f"{flag}: none given; allowed: {', '.join(allowed)}")
    return names


def _case_names(args: argparse.Namespace, allowed: Sequence[str] | None = None) -> list[str] | None:
    """--cases as a list (None: all), each checked against `allowed` when given, and --workers >= 1."""
    cases = _listed("--cases", args.cases, allowed)
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers: {args.workers}; allowed: 1 or more")
    return cases


def _tabled_bench(out: Path, js: Path, compute: Any, table: Any, plot: Any, log: Path | None = None) -> dict[str, Any]:
    """A bench that writes its JSON, its table (STEM.txt) and its figure (STEM.png): `compute()`
    runs it, `table(result)` and `plot(result, path)` render it, written when it ends; `log`, a
    file `compute` appends to as it goes (checked and reported with the others)."""
    txt, png = js.with_suffix(".txt"), js.with_suffix(".png")
    _check_outputs({js.name: js, txt.name: txt, png.name: png, **({log.name: log} if log else {})}, {})
    with created(out):
        result = compute()
        text = table(result)
        logger.info(text)
        write_all(
            {
                js: lambda p: p.write_text(jsonio.dumps(result, indent=2)),
                txt: lambda p: p.write_text(text + "\n"),
                png: lambda p: plot(result, p),
            }
        )
    logger.info(f"wrote {js}, {txt} and {png}" + (f" (and {log})" if log else ""))
    return _result(result, [js, txt, png, *([log] if log else [])])


def _bench_realdata(args: argparse.Namespace, out: Path, js: Path) -> dict[str, Any]:
    """--realdata: our tool on the measured recordings of the real-data corpus, each case run as a
    user would and scored against its independent reference (`vibinverse.bench.realdata_bench`);
    realdata.json (every claim), realdata.txt (the table), realdata.png."""
    from vibinverse.bench.realdata_bench import plot, run, table
    from vibinverse.bench.realdata_cases import load_cases, select

    cases = _case_names(args)
    select(load_cases(), cases)  # the corpus and the case names, checked before anything is written
    return _tabled_bench(out, js, lambda: run(quick=args.quick, cases=cases, workers=args.workers), table, plot)


def _bench_calibration(args: argparse.Namespace, out: Path, js: Path) -> dict[str, Any]:
    """--calibration: coverage of the 90 % intervals over many simulated data sets per case
    (`vibinverse.bench.calibration_bench`); calibration.json (every fit), calibration.txt,
    calibration.png, and calibration_fits.jsonl (each fit as it ends: a stopped run keeps them)."""
    from vibinverse.bench.calibration_bench import CALIBRATION_CASES, plot, run, table

    cases = _case_names(args, list(CALIBRATION_CASES))
    workers = args.workers if args.workers is not None else min(2, os.cpu_count() or 1)
    fits = out / "calibration_fits.jsonl"

    def compute() -> dict[str, Any]:
        fits.write_text("")  # this run's records only, each appended as its fit ends
        return run(quick=args.quick, cases=cases, workers=workers, records=fits)

    return _tabled_bench(out, js, compute, table, plot, log=fits)


#: `vibinverse bench` modes: the flag that picks one (None: the default), its file stem, its runner
BENCH_MODES: dict[str | None, tuple[str, Any]] = {
    None: ("bench", _bench_forward),
    "estimators": ("estimators", _bench_estimators),
    "robustness": ("robustness", _bench_robustness),
    "imaging": ("imaging", _bench_imaging),
    "realdata": ("realdata", None),  # writes its own files: BENCH_WITH_ARGS
    "oma": ("oma", _bench_oma),
    "calibration": ("calibration", None),  # writes its own files: BENCH_WITH_ARGS
}

#: modes that take the parsed options and write their own files: (args, output dir, JSON path) -> result
BENCH_WITH_ARGS: dict[str, Any] = {"realdata": _bench_realdata, "calibration": _bench_calibration}


def cmd_bench(args: argparse.Namespace) -> dict[str, Any]:
    mode = next((m for m in BENCH_MODES if m is not None and getattr(args, m)), None)
    with_cases = args.scene or mode in BENCH_WITH_ARGS  # --cases, --workers: --robustness --scene, --realdata, ...
    scene_only = {"--workers": args.workers is not None, "--cases": args.cases is not None}
    if not with_cases and any(scene_only.values()):
        raise InputError(
            f"{next(k for k, v in scene_only.items() if v)}: "
            "only with --robustness --scene, --realdata or --calibration"
        )
    if args.scene and mode != "robustness":
        raise InputError("--scene: the scene column of the robustness bench; give --robustness --scene")
    if args.fitters is not None and not args.scene:
        raise InputError("--fitters: only with --robustness --scene")
    stem, runner = BENCH_MODES[mode]
    out = output_dir(args.output)
    js, png = out / f"{stem}.json", out / f"{stem}.png"
    if args.scene:
        return _bench_robustness_scene(args, out, js)
    if mode in BENCH_WITH_ARGS:
        return BENCH_WITH_ARGS[mode](args, out, js)
    _check_outputs({js.name: js, png.name: png}, {})
    with created(out):
        result, plotter = runner(args.quick)
        write_all({js: lambda p: p.write_text(jsonio.dumps(result, indent=2)), png: plotter})
    logger.info(f"wrote {js} and {png}")
    return _result(result, [js, png])


def _estimator_table(rows: list[dict]) -> str:
    fmt = lambda v, f: format("-", f">{f.split('.')[0]}") if v is None else format(v, f)
    lines = [
        f"{'method':<11}{'SNR':>4} {'parameter':<20}{'bias':>11}{'rmse':>11}{'crlb_sd':>11}{'rmse/crlb':>10}"
        f"{'cover90':>8}{'time_s':>8}{'failed':>7}"
    ]
    for r in rows:
        ratio = r["rmse"] / r["crlb_sd"] if r["rmse"] is not None and r["crlb_sd"] else None
        lines.append(
            f"{r['method']:<11}{r['snr']:>4} {r['param'].rsplit('.', 1)[-1]:<20}{fmt(r['bias'], '11.3g')}"
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
    from vibinverse.io.cube_writer import MAX_FPS as VIDEO_FPS_MAX

    p = _Parser(
        prog="vibinverse", description="Passive optical vibrometry: simulate and invert pixel intensity series."
    )
    p.add_argument("--version", action="version", version=f"vibinverse {__version__}")
    _verbosity_options(p, False)
    verbosity = argparse.ArgumentParser(add_help=False)
    _verbosity_options(verbosity, argparse.SUPPRESS)  # before or after the verb; not reset by the verb
    printing = argparse.ArgumentParser(add_help=False)  # every verb that prints results
    printing.add_argument(
        "--json",
        action="store_true",
        help="print the results and the paths written as one JSON document on stdout (the log goes to stderr)",
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    sim = sub.add_parser(
        "simulate",
        parents=[verbosity, printing],
        help="scene file -> pixel intensity series (CSV) and its sensitivity, or with --image an image cube and video",
    )
    sim.add_argument("scene", help="scene file (TOML)")
    sim.add_argument(
        "--set",
        action="append",
        metavar="dotted.key=value",
        help="override a scene value, e.g. --set sensor.inclination='pi/3+0.02' (repeatable)",
    )
    sim.add_argument(
        "--seed", type=ranges.seed, default=None, help=f"noise seed (reproducible output), in {ranges.SEED_RANGE}"
    )
    output_option(
        sim,
        "simulation",
        f"{SERIES}, {SERIES_PLOT} (with --plot); with --image: {CUBE}, {CUBE_PLOT} (with --plot), "
        f"{VIDEO} (with --video)",
    )
    sim.add_argument(
        "--plot",
        action="store_true",
        help=f"also write {SERIES_PLOT} (the series and its spectrum), or with --image {CUBE_PLOT} (the mean frame "
        "with the surfaces outlined)",
    )
    sim.add_argument(
        "--image",
        metavar="NX,NY",
        help=f"render the footprint as an imager of NX x NY pixels (each 1 to 4096; each pixel sampled by "
        f"footprint.resolution^2 subpixels) and write the cube {CUBE} (time, y, x) instead of {SERIES}",
    )
    sim.add_argument(
        "--video",
        action="store_true",
        help=f"with --image, also write {VIDEO}: the noisy cube as 8-bit gray (lossless H.264), the clean cube's "
        "range plus 5 %% on each side mapped to counts 0-255 (the mapping is in the file's comment and --json)",
    )
    sim.add_argument(
        "--video-fps",
        type=ranges.real(0.0, VIDEO_FPS_MAX, high_open=False),
        metavar="F",
        help="the video's nominal frame rate (default: the scene's sampling.fs), e.g. 30 for a slow-motion file",
    )
    sim.add_argument(
        "--rtol",
        type=ranges.positive,
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
        parents=[verbosity, printing],
        help="reproduce a figure of the paper",
        description="Studies: " + "; ".join(f"{k}: {v[1]}" for k, v in STUDIES.items()),
    )
    study.add_argument("name", choices=[*STUDIES, "all"], help="figure to reproduce, or all")
    output_option(study, "studies", ", ".join(f"NAME.{ext}" for ext in STUDY_FILES) + " per study")
    study.set_defaults(func=cmd_study)

    fit = sub.add_parser(
        "fit",
        parents=[verbosity, printing],
        help="measured series + scene -> posterior of resonances, drives, vibration "
        "lines and noise (a frame scene: Kalman likelihood; plate or ground: white noise)",
    )
    fit.add_argument(
        "data",
        help="series: CSV/TSV (delimiter sniffed; columns time,intensity), Parquet, .npy, .npz (arrays time,intensity, "
        "or named arrays), netCDF, or a LabVIEW Measurement file (.lvm, or any text file starting 'LabVIEW "
        "Measurement'); NaN = gap; with --pixels an image cube or video",
    )
    fit.add_argument(
        "--time-column",
        metavar="NAME",
        help="time column of a CSV/TSV or Parquet table, or time array of an .npz (default: time); an lvm file's "
        "time is its X_Value column",
    )
    fit.add_argument(
        "--value-column",
        metavar="NAME",
        help="value column of a CSV/TSV or Parquet table (default: intensity); the channel of an lvm file, or the "
        "array or named column of an .npz (a name, or a 0-based index), needed when the file holds several",
    )
    fit.add_argument(
        "--fs",
        type=ranges.positive,
        metavar="HZ",
        help="sampling rate of a table without a time column, an .npz without time or rate, or an lvm file without "
        "X_Value columns: time = arange(n) / fs",
    )
    fit.add_argument(
        "--scene",
        help="scene file describing the observation (TOML); without it the generic modal model "
        "(resonances, lines, drift and coloured noise in intensity units, the order chosen by BIC)",
    )
    fit.add_argument(
        "--modes",
        type=ranges.integer(0, 36),
        metavar="K",
        help="without --scene: fix the number of resonances (0-6 of a series, 1-36 of a multi-channel table)",
    )
    fit.add_argument(
        "--lines", type=ranges.integer(0, 6), metavar="L", help="without --scene: fix the number of lines (0-6)"
    )
    fit.add_argument(
        "--decays",
        type=ranges.integer(0, 6),
        metavar="D",
        help="without --scene: fix the number of free decays (0-6: rings from one excitation, a pluck or a blow; "
        "their onset the likeliest)",
    )
    fit.add_argument(
        "--drift",
        choices=("none", "walk", "integrated"),
        help="fix the drift term (random walk, or integrated); with --scene a nuisance term beside the scene's model",
    )
    fit.add_argument(
        "--noise",
        choices=("white", "ar1", "1/f"),
        help="fix the noise model (white + which term); with --scene a nuisance term beside the scene's model",
    )
    fit.add_argument(
        "--gain",
        choices=("none", "drift"),
        help="fix the multiplicative gain drift (a cloud dims the whole signal): none, or drift (6 cosines, 0.5-3 "
        "cycles per record); with --scene it multiplies the scene's signal",
    )
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
        help="spectral | sindy | casadi | map | importance | mcmc | auto (default: spectral -> SINDy (frame "
        "scenes) -> casadi -> emcee, each seeding the next; without a scene, and past 20,000 samples, importance "
        "in place of emcee); map is a derivative-free MAP (scipy); importance: the MAP's Laplace approximation "
        "corrected by importance sampling (PSIS), emcee when its check fails",
    )
    fit.add_argument("--seed", type=ranges.seed, default=0, help=f"random seed, in {ranges.SEED_RANGE}")
    fit.add_argument(
        "--workers",
        type=ranges.workers,
        default=None,
        help="the sampler's workers: threads where the likelihood releases the GIL (frame, modal), else "
        "processes; also the modal order search's threads (each step's candidates). Default: this "
        "process's cores, at most 4, as threads (the same numbers on any count)",
    )
    fit.add_argument(
        "--max-steps", type=ranges.max_steps, default=20000, help=f"cap on MCMC steps, in [1, {ranges.MAX_STEPS}]"
    )
    fit.add_argument("--chain", metavar="FILE", help=f"HDF5 checkpoint of the sampler (default: DIR/{CHAIN})")
    fit.add_argument("--resume", action="store_true", help="continue an interrupted MCMC run from its checkpoint")
    fit.add_argument("--no-progress", action="store_true")
    from vibinverse.cli.fit_channels import add_channel_options
    from vibinverse.cli.fit_cube import PIXELS, add_cube_options

    add_cube_options(fit)
    add_channel_options(fit)
    output_option(
        fit,
        "fit",
        f"{RESULT}, {SUMMARY}, {CHAIN} (the MCMC checkpoint), {PIXELS} (with --pixels)",
    )
    fit.add_argument("--summary", metavar="FILE", help=f"write the summary JSON here instead (default: DIR/{SUMMARY})")
    fit.set_defaults(func=cmd_fit)

    report = sub.add_parser("report", parents=[verbosity, printing], help="result netCDF -> self-contained HTML report")
    report.add_argument("result", help=f"a result file of fit or demo ({RESULT})")
    output_option(report, None, REPORT, shown="the result file's directory")
    report.set_defaults(func=cmd_report)

    design = sub.add_parser(
        "design",
        parents=[verbosity, printing],
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
    design.add_argument(
        "--threshold",
        type=ranges.real(0.0, float("inf"), low_open=False),
        default=1e-4,
        help="detectability threshold on S (default 1e-4)",
    )
    design.add_argument("--set", action="append", metavar="dotted.key=value", help="override a scene value")
    design.add_argument(
        "--pixels",
        type=ranges.count,
        default=1,
        help="N equal pixels fitted jointly (fit CUBE --pixels): the multi-pixel Cramer-Rao bound (default 1)",
    )
    design.add_argument("--workers", type=ranges.workers, default=1, help=f"processes, in [1, {ranges.MAX_WORKERS}]")
    design.add_argument("--no-progress", action="store_true")
    output_option(design, "design", ", ".join(DESIGN_FILES))
    design.set_defaults(func=cmd_design)

    bench = sub.add_parser(
        "bench",
        parents=[verbosity, printing],
        help="speed against error of the forward model (reference vs fast paths)",
    )
    bench.add_argument(
        "--quick", action="store_true", help="the same table at lower precision, within 5 minutes on 2 cores"
    )
    output_option(
        bench,
        "bench",
        "bench.json, bench.png (with --estimators: estimators.json, estimators.png; "
        "with --robustness: robustness.json, robustness.png, with --scene robustness.json, robustness_scene.txt, "
        "robustness_scene_fits.jsonl; with --imaging: imaging.json, imaging.png; with --realdata: realdata.json, "
        "realdata.txt, realdata.png; with --oma: oma.json, oma.png; with --calibration: calibration.json, "
        "calibration.txt, calibration.png, calibration_fits.jsonl)",
    )
    which = bench.add_mutually_exclusive_group()
    which.add_argument(
        "--estimators",
        action="store_true",
        help="instead: spectral, SINDy, casadi and emcee against the Cramer-Rao bound (sec. 4.2 scene, "
        "SNR 3/10/30; ~15 min, --quick ~3 min)",
    )
    which.add_argument(
        "--robustness",
        action="store_true",
        help="instead: our fits, celerite2 and SSI-cov (pip install '.[peers]') on gaps, jitter, coloured noise, "
        "drift, gain drift, a weak line, three modes and noise alone (~1.5 h, --quick ~4 min)",
    )
    which.add_argument(
        "--imaging",
        action="store_true",
        help="instead: the imager (64 x 64 px x 4000 frames), detection throughput against a numpy rfft and its "
        "peak memory, the multi-pixel fit's cost and sd against the number of pixels (~2 min, --quick ~1 min)",
    )
    which.add_argument(
        "--realdata",
        action="store_true",
        help="instead: the real recordings of the corpus ($VIBINVERSE_REALDATA, default ../shared/realdata-dev: "
        "tuning-fork videos, LIGO lines, shaker tones, a plate sweep, a slab, a footbridge), each run as a user would "
        "and scored against its independent reference; every fit in its own process with a limit of 300 s "
        "(--quick: 60 s, the 250 fps videos and one file per series case, ~5 min)",
    )
    which.add_argument(
        "--oma",
        action="store_true",
        help="instead: multi-channel modal identification on simulated shear buildings (3-8 storeys, a close pair, "
        "coloured forcing, drift, 2-12 channels, 10 min-2 h), ours against pyOMA2's SSI-cov, FDD and EFDD: "
        "frequency and damping errors, MAC, 90 %% coverage, time (--quick: three short cases)",
    )
    which.add_argument(
        "--calibration",
        action="store_true",
        help="instead: coverage of the fit's 90 %% intervals (with its standard error, z RMS) over 200 simulated "
        "data sets per case: the robustness departures, each fitted with the term that models it, a sway of 2 "
        "cycles, a 50-frame clip (hours: AR(1) noise falls back to emcee; --quick: 10 sets a case, a 60 s limit)",
    )
    bench.add_argument(
        "--scene",
        action="store_true",
        help="with --robustness: instead the scene column, the same departures on data simulated from "
        "roof_frame.toml, fitted with the scene (nuisance terms by BIC, and white noise only) and without it; "
        'merged into robustness.json under "scene", the table in robustness_scene.txt, the fits in '
        "robustness_scene_fits.jsonl (50 data sets a case: hours; --quick: 1 data set of 4 fast cases, ~2 min)",
    )
    bench.add_argument(
        "--cases",
        metavar="A,B",
        help="with --robustness --scene, --realdata or --calibration: these cases only, in this order (default: all)",
    )
    bench.add_argument(
        "--fitters",
        metavar="A,B",
        help="with --robustness --scene: these fitters only (ours-scene, ours-scene-white, ours; default: all three)",
    )
    bench.add_argument(
        "--workers",
        type=ranges.workers,
        metavar="N",
        help="with --robustness --scene, --realdata or --calibration: processes (default: min(2, cores))",
    )
    bench.set_defaults(func=cmd_bench)

    demo = sub.add_parser("demo", parents=[verbosity, printing], help="run the main job on a built-in scene")
    output_option(demo, "vibinverse-demo", ", ".join((SERIES, SERIES_PLOT, RESULT, SUMMARY, CHAIN, REPORT)))
    demo.add_argument("--seed", type=ranges.seed, default=0, help=f"random seed, in {ranges.SEED_RANGE}")
    demo.add_argument("--no-progress", action="store_true")
    demo.set_defaults(func=cmd_demo)
    from vibinverse.cli.init_command import add_init_parser

    add_init_parser(sub, [verbosity])
    from vibinverse.cli.extract_command import add_extract_parser

    add_extract_parser(sub, [verbosity, printing])
    from vibinverse.cli.detect_command import add_detect_parser

    add_detect_parser(sub, [verbosity, printing])
    return p
