"""Scene files (TOML): read, override by dotted key, validate into a `Scene`.

Every numeric value may be a number or a string expression such as "pi/3 + 0.015". Units: SI,
angles in rad, frequencies in Hz. The README documents the schema.
"""

from __future__ import annotations

import codecs
import copy
import math
import tomllib
from pathlib import Path
from typing import Any

from forward.errors import SceneError
from forward.materials import Fresnel, material_from_spec
from forward.motion import MOTION_CLASSES, MOTION_KINDS
from forward.polarizer import Polarizer
from forward.scene import Footprint, Load, Noise, Sampling, Scene, Sensor, Sun, Surface, estimate_memory
from forward.validation import MAX_DEPTH, Table, check_depth, one_line

MAX_SAMPLES = 100_000_000
MAX_FILE_BYTES = 16 * 2**20  # a scene file holds settings, not data; this also bounds reading a device or pipe
# an elevation of 1e-9 rad is far below any observable geometry (refraction alone bends light by ~1e-2
# rad at the horizon); below it, denormal angles broke the solvers (5e-324 gave an SVD failure)
_INCLINATION = {"lo": 1e-9, "hi": math.pi / 2}
_POSITIVE = {"lo": 0.0, "lo_open": True}


def read_table(path: str | Path) -> dict[str, Any]:
    """The raw TOML table of a scene file (UTF-8, a byte-order mark allowed, at most MAX_FILE_BYTES,
    tables and arrays nested at most MAX_DEPTH levels)."""
    p = Path(path)
    name = one_line(p, 300)
    try:
        with p.open("rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise SceneError(f"scene: file not found: {name}") from None
    except IsADirectoryError:
        raise SceneError(f"scene: {name} is a directory, not a scene file") from None
    except OSError as exc:
        raise SceneError(f"scene: cannot read {name}: {one_line(exc.strerror or exc)}") from None
    if len(data) > MAX_FILE_BYTES:
        raise SceneError(f"scene: {name} is larger than 16 MiB; allowed at most 16 MiB (a scene file holds settings)")
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(
            f"scene: {name} is not a UTF-8 TOML file (byte {exc.start} is {data[exc.start]:#04x}; a binary file?)"
        ) from None
    if "\x00" in text:
        raise SceneError(f"scene: {name} is not a UTF-8 TOML file (byte {data.index(0)} is 0x00; a binary file?)")
    if not text.strip():
        raise SceneError(f"scene: {name} is empty; a scene needs at least [sun], [sensor], [sampling] and [footprint]")
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"scene: {name} is not valid TOML: {one_line(exc, 200)}") from None
    except RecursionError:  # tomllib recurses once per level of arrays and inline tables
        raise SceneError(
            f"scene: {name}: nesting deeper than {MAX_DEPTH} levels of tables and arrays; allowed at most {MAX_DEPTH}"
        ) from None
    check_depth(table)
    return table


def apply_overrides(table: dict[str, Any], overrides: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """A copy of `table` with each "dotted.key=value" applied; value is read as TOML (a bare word is a string)."""
    check_depth(table)  # before the deep copy, which recurses
    out = copy.deepcopy(table)
    for item in overrides:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise SceneError(f"--set: expected dotted.key=value, got {one_line(repr(item))}")
        value = parse_value(text.strip(), key)
        node = out
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise SceneError(f"--set {one_line(key)}: {one_line(part)} is a value, not a table")
        node[parts[-1]] = value
    check_depth(out)
    return out


def parse_value(text: str, key: str = "value") -> Any:
    """A TOML value ("1e-3", "[0, 25]", "true", "'p'"), else the text itself as a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:  # tomllib recurses once per level of arrays and inline tables
        raise SceneError(
            f"--set {one_line(key)}: nesting deeper than {MAX_DEPTH} levels of tables and arrays; "
            f"allowed at most {MAX_DEPTH}"
        ) from None


def load_scene(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> tuple[Scene, dict[str, Any]]:
    """(Scene, the table it was built from, overrides applied)."""
    table = apply_overrides(read_table(path), overrides)
    return scene_from_table(table), table


def scene_from_table(data: dict[str, Any]) -> Scene:
    """Validate a scene table into a `Scene`; a SceneError names the first bad key.

    The scene's memory estimate (`forward.scene.estimate_memory`) is checked from the sizes of its
    lists before any motion is built, so that 300 000 drive lines are refused at once; `observe`
    checks the simulation's own estimate (per-run motions, the dense path) before it allocates."""
    check_depth(data)
    top = Table(data, "")
    top.raw("title", "")
    top.raw("infer", None)  # read by `vibinverse fit` (free parameters and priors)
    top.raw("nuisance", None)  # read by `vibinverse fit` (coloured noise, drift, gain drift beside the scene)
    sun = _sun(top.table("sun"))
    sensor = _sensor(top.table("sensor"))
    sampling = _sampling(top.table("sampling"))
    noise = _noise(top.table("noise", required=False))
    footprint = _footprint(top.table("footprint"))
    loads = _raw_loads(data.get("surfaces"))
    estimate_memory(sampling.n_samples, footprint.resolution**2, loads.values()).check()
    background = _surface(
        top.table("background", required=False) or Table({}, "background"),
        "background",
        footprint.x,
        footprint.y,
        allow_motion=False,
    )
    surfaces_table = top.table("surfaces", required=False) or Table({}, "surfaces")
    surfaces = []
    for name in list(surfaces_table.data):
        t = surfaces_table.table(name)
        surfaces.append(_surface(t, name, t.interval("x"), t.interval("y"), allow_motion=True))
    surfaces_table.done()
    top.done()
    for s in surfaces:
        if s.motion is not None and s.motion.max_frequency() >= sampling.fs / 2:
            raise SceneError(
                f"surfaces.{s.name}.motion.frequency: {s.motion.max_frequency():g} Hz is at or above "
                f"the Nyquist frequency {sampling.fs / 2:g} Hz; allowed range (0, fs/2)"
            )
    return Scene(sun, sensor, footprint, tuple(surfaces), background, sampling, noise)


def _raw_loads(surfaces: object) -> dict[str, Load]:
    """Each moving surface's load from the raw table, before its motion is built: the number of
    lines is the length of the longest of its kind's `line_keys` (e.g. drive_frequency); any other
    key, known or not, is checked when the motion is built."""
    loads = {}
    for name, spec in surfaces.items() if isinstance(surfaces, dict) else ():
        motion = spec.get("motion") if isinstance(spec, dict) else None
        if not isinstance(motion, dict):
            continue
        kind = motion.get("kind")
        keys = MOTION_CLASSES[kind].line_keys if isinstance(kind, str) and kind in MOTION_CLASSES else ()
        lines, key = 1, f"surfaces.{name}.motion"
        for k, v in motion.items():
            if k not in keys:
                continue
            if isinstance(v, list) and len(v) > lines and not isinstance(v[0], (list, dict)):
                lines, key = len(v), f"surfaces.{name}.motion.{k}"
        loads[str(name)] = Load(str(name), lines, one_line(key))
    return loads


def _sun(t: Table) -> Sun:
    """Sun by angles (inclination, azimuth) or by place and time (date, hour, latitude, longitude)."""
    if t.has("date") or t.has("hour"):
        for clash in ("inclination", "azimuth"):
            if t.has(clash):
                raise SceneError(f"{t.path(clash)}: give the sun either by angles or by date and hour, not both")
        from forward.solar import sun_angles

        elevation, azimuth = sun_angles(
            t.raw("date"),
            t.number("hour", lo=0.0, hi=24.0),
            t.number("latitude", lo=-90.0, hi=90.0),
            t.number("longitude", lo=-180.0, hi=180.0),
            t.number("utc_offset", 0.0, lo=-14.0, hi=14.0),
        )
    else:
        elevation, azimuth = t.number("inclination", **_INCLINATION), t.number("azimuth")
    sun = Sun(elevation, azimuth, t.number("irradiance", 1.0, **_POSITIVE))
    t.done()
    return sun


def _sensor(t: Table) -> Sensor:
    sensor = Sensor(
        t.number("inclination", **_INCLINATION),
        t.number("azimuth"),
        Polarizer.parse(t.raw("polarizer", "none"), t.path("polarizer")),
        t.choice("radiometry", "projected", ("projected", "paper")),
    )
    t.done()
    return sensor


def _sampling(t: Table) -> Sampling:
    s = Sampling(t.number("fs", **_POSITIVE), t.number("duration", **_POSITIVE), t.number("start", 0.0))
    n = s.duration * s.fs
    if not (math.isfinite(n) and 2 <= s.n_samples <= MAX_SAMPLES):
        raise SceneError(
            f"sampling: duration * fs = {s.n_samples if math.isfinite(n) else n} samples; "
            f"allowed range [2, {MAX_SAMPLES}]"
        )
    t.done()
    return s


def _noise(t: Table | None) -> Noise:
    if t is None:
        return Noise()
    n = Noise(
        t.number("sigma", 0.0, lo=0.0),
        t.number("photons_per_unit", 0.0, lo=0.0),
        t.integer("adc_bits", 0, 0, 32),
        t.number("adc_full_scale", 0.0, lo=0.0),
    )
    t.done()
    return n


def _footprint(t: Table) -> Footprint:
    f = Footprint(t.interval("x"), t.interval("y"), t.integer("resolution", 128, 1, 4096))
    t.done()
    return f


def _surface(t: Table, name: str, x: tuple[float, float], y: tuple[float, float], allow_motion: bool) -> Surface:
    material = material_from_spec(t.raw("material", "ground"), t.path("material"))
    lobe = None
    if isinstance(material, Fresnel):
        # below 1e-9 rad the lobe's normalization 1 / (2 pi m^2) leaves float64 (and no surface is
        # that smooth: a polished mirror's RMS slope is ~1e-5 rad)
        lobe = t.number("lobe_width", lo=1e-9, hi=0.5)
    motion = None
    mt = t.table("motion", required=False) if allow_motion else None
    if mt is not None:
        kind = mt.choice("kind", None, tuple(MOTION_KINDS))
        motion = MOTION_KINDS[kind](mt, x, y)
        mt.done()
    t.done()
    return Surface(name, x, y, material, lobe, motion)
