"""`vibinverse init`: write a commented scene file (DIR/scene.toml) for a real observation, from
flags, or from prompts when stdin is a terminal (`vibinverse.io.scene_template`)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import logging
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vibinverse.errors import InputError
from vibinverse.io.scene_template import ANSWER_RANGES, SceneAnswers, check_answer, flag, scene_template

logger = logging.getLogger("vibinverse")

SCENE_NAME = "scene.toml"  # the fixed file name inside the output directory
MAX_TRIES = 3  # prompts per answer before giving up
MAX_CORRECTIONS = 20  # answers asked again after the scene check refused one
_SUN_BY_DATE = ("date", "hour", "latitude", "longitude")
_SUN_BY_ANGLES = ("sun_inclination", "sun_azimuth")


# ----------------------------------------------------------------------------------- parsing values
def _hour(text: str) -> float:
    """Hours after midnight: "13.5" or "13:30" or "13:30:15"."""
    m = re.fullmatch(r"\s*(\d{1,2}):(\d{2})(?::(\d{2}(?:\.\d*)?))?\s*", text)
    if m:
        h, mi, s = int(m.group(1)), int(m.group(2)), float(m.group(3) or 0.0)
        if mi >= 60 or s >= 60:
            raise argparse.ArgumentTypeError(f"invalid clock time {text!r} (HH:MM or hours such as 13.5)")
        return h + mi / 60 + s / 3600
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid clock time {text!r} (HH:MM or hours such as 13.5)") from None


def _sizes(text: str) -> tuple[float, ...]:
    """One or two sizes: "50", "50 30", "50x30" or "50,30"."""
    parts = [p for p in re.split(r"[\s,xX]+", text.strip()) if p]
    try:
        return tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(f"invalid size {text!r} (one number, or two such as 50x30)") from None


#: how a user may write "no frequencies" (any case)
NO_FREQUENCIES = frozenset({"none", "-", "[]"})


def _frequencies(text: str) -> tuple[float, ...]:
    """Space- or comma-separated frequencies; "none" (or "-") for none."""
    if text.strip().lower() in NO_FREQUENCIES:
        return ()
    try:
        return tuple(float(p) for p in re.split(r"[\s,]+", text.strip()) if p)
    except ValueError:
        raise ValueError(f"invalid frequencies {text!r} (numbers in Hz, or none)") from None


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"invalid number {text!r}") from None


# --------------------------------------------------------------------------------------- the parser
def add_init_parser(sub: Any, parents: list) -> None:
    """Register the verb `init` on the subparsers `sub` (each of `parents` adds its options)."""
    defaults = SceneAnswers()
    p = sub.add_parser(
        "init",
        parents=parents,
        help="write a commented scene file for a real observation",
        description="Write DIR/scene.toml for `vibinverse fit DATA --scene DIR/scene.toml`: a roof on a resonant "
        "building frame seen by one pixel, every key commented. Angles on the command line are in degrees; the "
        'file holds radians (as "radians(DEG)" expressions). Answers not given are asked for when stdin is a '
        "terminal, else take their defaults.",
    )
    g = p.add_argument_group("observation")
    _arg(g, "--title", help=f"free text shown in plots (default: {defaults.title!r})")
    sun = p.add_argument_group("sun: by date, time and place, or by angles")
    _arg(sun, "--date", metavar="YYYY-MM-DD", help="local date of the observation")
    _arg(
        sun,
        "--hour",
        type=_hour,
        metavar="H",
        help="local clock time of the record's middle: 13.5 or 13:30, in [0, 24]",
    )
    _arg(sun, "--latitude", type=float, metavar="DEG", help="of the building, degrees north, in [-90, 90]")
    _arg(sun, "--longitude", type=float, metavar="DEG", help="of the building, degrees east, in [-180, 180]")
    _arg(
        sun,
        "--utc-offset",
        type=float,
        metavar="H",
        help="local clock time = UTC + offset, hours in [-14, 14] (default 0)",
    )
    _arg(
        sun,
        "--sun-inclination",
        type=float,
        metavar="DEG",
        help="instead of a date: the sun's elevation above the horizon, degrees in (0, 90] (default 60)",
    )
    _arg(
        sun,
        "--sun-azimuth",
        type=float,
        metavar="DEG",
        help="the sun's azimuth, degrees counter-clockwise from east (a compass bearing B is 90 - B; default 180)",
    )
    view = p.add_argument_group("sensor")
    _arg(
        view,
        "--view-inclination",
        type=float,
        metavar="DEG",
        help="the sensor's elevation seen from the roof, degrees in (0, 90]: 90 = straight down (nadir), a view "
        "zenith angle Z is 90 - Z (default: 0.01 rad above the sun's mirror direction, the specular lobe)",
    )
    _arg(
        view,
        "--view-azimuth",
        type=float,
        metavar="DEG",
        help="direction from the roof to the sensor, degrees counter-clockwise from east (a compass bearing B is "
        "90 - B; default: opposite the sun)",
    )
    _arg(view, "--fs", type=float, metavar="HZ", help=f"frame rate, Hz (default {defaults.fs:g})")
    _arg(view, "--duration", type=float, metavar="S", help=f"record length, s (default {defaults.duration:g})")
    _arg(
        view,
        "--footprint",
        type=float,
        nargs="+",
        metavar="M",
        help="the pixel's footprint on the ground, m: one size (a square) or east-west and north-south "
        f"(default {defaults.footprint[0]:g})",
    )
    _arg(
        view,
        "--resolution",
        type=int,
        metavar="N",
        help=f"subpixels per footprint side (default {defaults.resolution})",
    )
    roof = p.add_argument_group("roof")
    _arg(
        roof,
        "--roof",
        type=float,
        nargs="+",
        metavar="M",
        help=f"roof size, m: one size (a square) or east-west and north-south (default {defaults.roof[0]:g})",
    )
    _arg(
        roof,
        "--material",
        metavar="NAME",
        help=f"roof material: aluminium, glass, glass_paper, ground, steel (default {defaults.material})",
    )
    _arg(
        roof,
        "--background",
        metavar="NAME",
        help=f"what the footprint sees around the roof (default {defaults.background})",
    )
    _arg(
        roof,
        "--lobe-width",
        type=float,
        metavar="RAD",
        help=f"RMS facet slope of the roof, rad in (0, 0.5] (default {defaults.lobe_width:g})",
    )
    motion = p.add_argument_group("motion (guesses: fit estimates them)")
    _arg(
        motion,
        "--resonance",
        type=float,
        metavar="HZ",
        help=f"expected tilt resonance of the building, Hz in (0, fs/2) (default {defaults.resonance:g})",
    )
    _arg(
        motion,
        "--damping-ratio",
        type=float,
        metavar="ZETA",
        help=f"expected damping ratio of the tilt mode, in [0, 1) (default {defaults.damping_ratio:g})",
    )
    _arg(
        motion,
        "--drive",
        type=float,
        nargs="*",
        metavar="HZ",
        help="expected drive lines (machinery), Hz each in (0, fs/2); --drive alone: none "
        f"(default {' '.join(f'{f:g}' for f in defaults.drive)})",
    )
    _arg(
        motion,
        "--drive-amplitude",
        type=float,
        metavar="M",
        help=f"expected drive amplitude at the corner's base, m (default {defaults.drive_amplitude:g})",
    )
    _arg(
        motion,
        "--base-noise",
        type=float,
        metavar="M",
        help=f"expected RMS white base motion at each corner, m (default {defaults.base_noise:g})",
    )
    _arg(
        motion,
        "--noise-sigma",
        type=float,
        metavar="SIGMA",
        help="sensor noise sd in the data's units, if known (default: unknown, 0 in the file; fit estimates it)",
    )
    out = p.add_argument_group("output")
    _arg(out, "-o", "--output", default=".", metavar="DIR", help=f"output directory (default: .); writes {SCENE_NAME}")
    _arg(out, "--force", action="store_true", help=f"replace an existing DIR/{SCENE_NAME}")
    _arg(
        out,
        "--json",
        action="store_true",
        help='print {"scene": PATH, "paths": [PATH]} as one JSON document on stdout (the log goes to stderr)',
    )
    asking = out.add_mutually_exclusive_group()
    _arg(
        asking,
        "--interactive",
        action="store_true",
        help="ask for every answer not given (also when stdin is not a terminal)",
    )
    _arg(asking, "--no-input", action="store_true", help="never ask: answers not given take their defaults")
    p.set_defaults(func=cmd_init)


def _arg(group: Any, *flags: str, **kwargs: Any) -> argparse.Action:
    """`group.add_argument(*flags, **kwargs)`; a numeric answer's value is checked against its range
    at parse time (`_checked`: one line, exit 2)."""
    action = group.add_argument(*flags, **kwargs)
    if action.dest in ANSWER_RANGES or action.dest == "resolution":
        action.type = _checked(action.dest, action.type or str)
    return action


def _allowed(name: str) -> str:
    """The allowed range of a numeric answer, as the messages write it."""
    if name not in ANSWER_RANGES:
        return "an integer in [1, 4096]"  # resolution (`check_answer`)
    lo, hi, lo_open, hi_open = ANSWER_RANGES[name]
    return f"the range {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def _checked(name: str, parse: Callable[[str], Any]) -> Callable[[str], Any]:
    """argparse `type=` of a numeric answer: parsed by `parse`, then in its range (`check_answer`)."""

    def checked(text: str) -> Any:
        try:
            value = parse(text)
        except (ValueError, argparse.ArgumentTypeError):
            raise argparse.ArgumentTypeError(f"invalid value {text[:40]!r}; allowed: {_allowed(name)}") from None
        try:
            check_answer(name, value)
        except ValueError as exc:  # InputError is a ValueError
            message = str(exc).removeprefix(f"{flag(name)}: ")
            if "range" not in message and "integer in" not in message:
                message += f" (allowed: {_allowed(name)})"
            raise argparse.ArgumentTypeError(message) from None
        return value

    checked.__name__ = getattr(parse, "__name__", "value")
    return checked


# ---------------------------------------------------------------------------------------- prompting
# answer -> (question, parser); the order is the order of asking
_QUESTIONS: dict[str, tuple[str, Callable[[str], Any]]] = {
    "title": ("title", str),
    "date": ("date of the observation, YYYY-MM-DD (empty: give the sun's angles instead)", str),
    "hour": ("local clock time of the record's middle (13:30 or 13.5)", _hour),
    "latitude": ("latitude of the building, degrees north", _float),
    "longitude": ("longitude of the building, degrees east", _float),
    "utc_offset": ("local clock time minus UTC, hours", _float),
    "sun_inclination": ("sun elevation above the horizon, degrees", _float),
    "sun_azimuth": ("sun azimuth, degrees counter-clockwise from east", _float),
    "view_inclination": ("sensor elevation seen from the roof, degrees (90 = nadir)", _float),
    "view_azimuth": ("direction from the roof to the sensor, degrees counter-clockwise from east", _float),
    "fs": ("frame rate, Hz", _float),
    "duration": ("record length, s", _float),
    "footprint": ("pixel footprint on the ground, m (one size, or east-west x north-south)", _sizes),
    "roof": ("roof size, m (one size, or east-west x north-south)", _sizes),
    "material": ("roof material (aluminium, glass, glass_paper, ground, steel)", str),
    "resonance": ("expected tilt resonance of the building, Hz", _float),
    "drive": ("expected drive frequencies, Hz (several separated by spaces; none for none)", _frequencies),
    "noise_sigma": ("sensor noise sd in the data's units", _float),
    # asked only to correct a bad answer
    "resolution": ("subpixels per footprint side", int),
    "background": ("what the footprint sees around the roof (a material)", str),
    "lobe_width": ("RMS facet slope of the roof, rad", _float),
    "damping_ratio": ("expected damping ratio of the tilt mode", _float),
    "drive_amplitude": ("expected drive amplitude, m", _float),
    "base_noise": ("expected RMS base motion at each corner, m", _float),
}
_ASKED_IF_MISSING = ("title", "view_inclination", "view_azimuth", "fs", "duration", "footprint", "roof")
_ASKED_IF_MISSING += ("material", "resonance", "drive", "noise_sigma")
_SHOWN_DEFAULT = {
    "view_inclination": "near the specular direction",
    "view_azimuth": "opposite the sun",
    "noise_sigma": "unknown",
    "date": "",
    "hour": "required",
    "latitude": "required",
    "longitude": "required",
    "sun_inclination": "60",
    "sun_azimuth": "180",
}


class _EndOfInput(Exception):
    """stdin ended: the remaining answers take their defaults."""


def _shown(name: str) -> str:
    if name in _SHOWN_DEFAULT:
        return _SHOWN_DEFAULT[name]
    value = getattr(SceneAnswers(), name)
    if isinstance(value, tuple):
        return " ".join(f"{v:g}" for v in value) if value else "none"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _ask(name: str, values: dict[str, Any]) -> Any:
    """input() until the answer parses and lies in its range (`check_answer`; empty: None, the
    default); _EndOfInput at the end of stdin."""
    question, parse = _QUESTIONS[name]
    fs = values.get("fs")
    for _ in range(MAX_TRIES):
        try:
            text = input(f"{question} [{_shown(name)}]: ")
        except EOFError:
            raise _EndOfInput from None
        if not text.strip():
            if name in _SUN_BY_DATE[1:]:
                logger.warning(f"{flag(name)}: needed for the sun by date; try again")
                continue
            return None
        try:
            return check_answer(name, parse(text.strip()), fs if isinstance(fs, float) and fs > 0 else None)
        except (ValueError, argparse.ArgumentTypeError) as exc:  # InputError is a ValueError
            message = str(exc) if str(exc).startswith(flag(name)) else f"{flag(name)}: {exc}"
            logger.warning(f"{message}; try again")
    raise InputError(f"{flag(name)}: no valid answer after {MAX_TRIES} tries")


def _missing_questions(values: dict[str, Any]) -> list[str]:
    """The answers to ask for, in order: the title, the sun (by date, else by angles), then the others
    not given."""
    out = ["title"] if values.get("title") is None else []
    if not any(values.get(n) is not None for n in (*_SUN_BY_DATE, *_SUN_BY_ANGLES)):
        out.append("date")  # its answer decides which sun questions follow (`_prompt`)
    elif any(values.get(n) is not None for n in _SUN_BY_DATE):
        out += [n for n in (*_SUN_BY_DATE, "utc_offset") if values.get(n) is None]
    else:
        out += [n for n in _SUN_BY_ANGLES if values.get(n) is None]
    return out + [n for n in _ASKED_IF_MISSING[1:] if values.get(n) is None]


def _prompt(values: dict[str, Any], names: list[str]) -> bool:
    """Ask for `names` in order, in place; after a date, the rest of the sun (by date when one was
    given, else by angles). False when stdin ended (the remaining answers keep their defaults)."""
    try:
        for n in names:
            values[n] = _ask(n, values)
            if n == "date":
                sun = (*_SUN_BY_DATE[1:], "utc_offset") if values[n] is not None else _SUN_BY_ANGLES
                for m in sun:
                    if values.get(m) is None:
                        values[m] = _ask(m, values)
    except _EndOfInput:
        logger.info("init: end of input; the remaining answers take their defaults")
        return False
    return True


def _stdin_is_terminal() -> bool:
    try:
        return sys.stdin is not None and sys.stdin.isatty()
    except (ValueError, OSError):  # a closed or detached stdin
        return False


def _field_of(message: str) -> str | None:
    """The answer a one-line InputError names ("--fs: ..." -> "fs")."""
    m = re.match(r"--([a-z-]+):", message)
    return m.group(1).replace("-", "_") if m else None


# -------------------------------------------------------------------------------------- the command
def _answers_of(values: dict[str, Any]) -> SceneAnswers:
    fields = {f.name for f in dataclasses.fields(SceneAnswers)}
    given = {k: v for k, v in values.items() if k in fields and v is not None}
    for k in ("footprint", "roof", "drive"):
        if k in given:
            given[k] = tuple(given[k])
    return SceneAnswers(**given)


def _output_path(output: str, force: bool) -> Path:
    out = Path(output)
    if out.exists() and not out.is_dir():
        raise InputError(f"-o: {out} is a file; -o names an output directory (the scene is DIR/{SCENE_NAME})")
    path = out / SCENE_NAME
    if path.is_dir():
        raise InputError(f"-o: {path} is a directory; remove it or choose another output directory")
    if path.exists() and not force:
        raise InputError(f"-o: {path} exists; refusing to replace it (--force replaces it)")
    return path


def cmd_init(args: argparse.Namespace) -> dict[str, Any]:
    """Write DIR/scene.toml; returns {"scene": path, "paths": [path]} (printed by --json)."""
    from vibinverse.io.atomic import write_all

    fields = [f.name for f in dataclasses.fields(SceneAnswers)]
    values = {n: getattr(args, n, None) for n in fields}
    path = _output_path(args.output, args.force)  # before any question: a refusal should come first
    asking = args.interactive or (not args.no_input and _stdin_is_terminal())
    if asking:
        asking = _prompt(values, _missing_questions(values))
    for _ in range(MAX_CORRECTIONS):
        try:
            text = scene_template(_answers_of(values))
            break
        except InputError as exc:
            field = _field_of(str(exc))
            if not asking or field not in _QUESTIONS:
                raise
            logger.warning(str(exc))  # a bad answer: ask for it again
            asking = _prompt(values, [field])
    else:
        raise InputError(f"init: no valid set of answers after {MAX_CORRECTIONS} corrections")
    missing = [flag(n) for n in ("view_inclination", "view_azimuth") if values.get(n) is None]
    if missing:
        logger.warning(
            f"init: {' and '.join(missing)} not given: the sensor is assumed near the specular direction; "
            f"edit [sensor] in {path} to the real viewing geometry"
        )
    made = [p for p in (path.parent, *path.parent.parents) if not p.exists()]  # deepest first
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"-o: cannot create directory {path.parent}: {exc.strerror or exc}") from None
    try:
        write_all({path: lambda tmp: tmp.write_text(text, encoding="utf-8")})
    except BaseException:
        for p in made:  # a failed run leaves no empty directory behind
            with contextlib.suppress(OSError):
                p.rmdir()
        raise
    if not args.json:  # --json: `vibinverse.cli.main` prints the returned document instead
        defaulted = [
            flag(n)
            for n in ("fs", "duration", "footprint", "roof", "material", "resonance", "drive")
            if values.get(n) is None
        ]
        if defaulted:
            logger.info(f"init: defaults used for {', '.join(defaulted)} (see the comments in the file)")
        logger.info(f"wrote {path}; fit with: vibinverse fit DATA --scene {path}")
    return {"scene": str(path), "paths": [str(path)]}
