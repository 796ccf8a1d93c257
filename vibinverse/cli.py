"""The `vibinverse` command line.

Bad input exits with code 2 and one line on stderr naming the problem; no traceback and no
partial output file.
"""

from __future__ import annotations

import argparse
import sys
from importlib.resources import files
from pathlib import Path

import numpy as np

from forward.errors import SceneError
from forward.reduce import DEFAULT_RTOL, compile_scene
from forward.scene_file import load_scene
from forward.sensor import observe
from vibinverse import __version__
from vibinverse.output import write_all
from vibinverse.simulation_io import plot_series, write_series_csv

DEMO_SCENE = "roof_elastic.toml"


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse prints usage too)
        raise SceneError(f"{self.prog}: {message}")


def builtin_scene(name: str) -> Path:
    """Path of a built-in scene (the files of examples/scenes/, installed as package data)."""
    return Path(str(files("vibinverse.scenes").joinpath(name)))


def _output_dir(path: str) -> Path:
    """Create the output directory `path` (one-line error if that is impossible)."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SceneError(f"-o: cannot create directory {out}: {exc.strerror or exc}") from None
    return out


def _simulate_to(scene_path: Path, overrides: list[str], seed: int | None, out: Path, plot: Path | None,
                 rtol: float | None = DEFAULT_RTOL, explain: bool = False) -> float:
    scene, table = load_scene(scene_path, overrides)
    if explain:
        print(compile_scene(scene, rtol=rtol if rtol is not None else DEFAULT_RTOL, seed=seed).explain())
    obs = observe(scene, seed, rtol)
    writers = {out: lambda p: write_series_csv(p, obs, table, seed, __version__)}
    if plot is not None:
        writers[plot] = lambda p: plot_series(p, obs, str(table.get("title") or scene_path.stem))
    write_all(writers)
    return obs.sensitivity


def cmd_simulate(args: argparse.Namespace) -> None:
    if not (args.rtol > 0 and np.isfinite(args.rtol)):
        raise SceneError(f"--rtol: {args.rtol:g} is outside the allowed range (0, inf)")
    s = _simulate_to(Path(args.scene), args.set or [], args.seed, Path(args.output),
                     Path(args.plot) if args.plot else None, None if args.dense else args.rtol, args.explain)
    print(f"sensitivity S = {s:.4e} (eq. 21); wrote {args.output}" + (f" and {args.plot}" if args.plot else ""))


def cmd_demo(args: argparse.Namespace) -> None:
    out = _output_dir(args.output)
    scene = builtin_scene(DEMO_SCENE)
    csv, png = out / "roof_elastic.csv", out / "roof_elastic.png"
    s = _simulate_to(scene, [], args.seed, csv, png)
    print(f"demo: paper sec. 4.1 elastic steel roof, quadrant footprint, view 0.015 rad off the lobe")
    print(f"sensitivity S = {s:.4e} (eq. 21)")
    print(f"wrote {csv} and {png}")


def cmd_study(args: argparse.Namespace) -> None:
    from vibinverse.studies import STUDIES

    out = _output_dir(args.output)
    names = list(STUDIES) if args.name == "all" else [args.name]
    for name in names:
        print(STUDIES[name][0](out))


def cmd_bench(args: argparse.Namespace) -> None:
    import json

    from vibinverse.bench.forward_bench import plot_speed_error, run

    targets = [Path(p) for p in (args.json, args.plot) if p]
    for p in targets:  # fail before the long run, not after it
        if not p.parent.is_dir():
            raise SceneError(f"output: cannot write {p}: no such directory")
    result = run(builtin_scene(""), args.quick)
    writers = {}
    if args.json:
        writers[Path(args.json)] = lambda p: p.write_text(json.dumps(result, indent=2))
    if args.plot:
        writers[Path(args.plot)] = lambda p: plot_speed_error(result["speed_error"], p)
    write_all(writers)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vibinverse", description="Passive optical vibrometry: simulate and invert pixel intensity series.")
    p.add_argument("--version", action="version", version=f"vibinverse {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    sim = sub.add_parser("simulate", help="scene file -> pixel intensity series (CSV) and its sensitivity")
    sim.add_argument("scene", help="scene file (TOML)")
    sim.add_argument("--set", action="append", metavar="dotted.key=value",
                     help="override a scene value, e.g. --set sensor.inclination='pi/3+0.02' (repeatable)")
    sim.add_argument("--seed", type=int, default=None, help="noise seed (reproducible output)")
    sim.add_argument("-o", "--output", required=True, help="output CSV: time,intensity,intensity_clean")
    sim.add_argument("--plot", help="also write a PNG of the series and its spectrum")
    sim.add_argument("--rtol", type=float, default=DEFAULT_RTOL,
                     help=f"accuracy of the fast evaluation, relative to each surface's peak-to-peak (default {DEFAULT_RTOL:g})")
    sim.add_argument("--dense", action="store_true", help="evaluate every subpixel at every sample (the reference)")
    sim.add_argument("--explain", action="store_true", help="print the evaluation chosen per surface and its error estimate")
    sim.set_defaults(func=cmd_simulate)

    from vibinverse.studies import STUDIES

    study = sub.add_parser("study", help="reproduce a figure of the paper",
                           description="Studies: " + "; ".join(f"{k}: {v[1]}" for k, v in STUDIES.items()))
    study.add_argument("name", choices=[*STUDIES, "all"], help="figure to reproduce, or all")
    study.add_argument("-o", "--output", default="studies", help="output directory (default: studies)")
    study.set_defaults(func=cmd_study)

    bench = sub.add_parser("bench", help="speed against error of the forward model (reference vs fast paths)")
    bench.add_argument("--quick", action="store_true", help="128x128 instead of 256x256 subpixels (a few minutes)")
    bench.add_argument("--json", help="write the results as JSON")
    bench.add_argument("--plot", help="write the speed-against-error plot (PNG)")
    bench.set_defaults(func=cmd_bench)

    demo = sub.add_parser("demo", help="run the main job on a built-in scene")
    demo.add_argument("-o", "--output", default="vibinverse-demo", help="output directory (default: vibinverse-demo)")
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        args.func(args)
    except SceneError as exc:
        print(f"vibinverse: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("vibinverse: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
