"""Sweep specifications (`--vary KEY=start:stop:num | KEY=a,b,c`) and the design keys.

Any scene value is addressable by its dotted key (`sun.inclination`, `sampling.fs`,
`surfaces.roof.motion.drive_frequency[0]`). Design keys say what an observer controls directly:

- ``sensor.offset``: view offset (rad) from the specular direction of the sun: the sensor looks at
  elevation sun + offset, azimuth sun + pi (works with a sun given by date and hour too).
- ``footprint.center``: move the footprint (keeping its size) so its centre is at (c, c) m;
  ``footprint.center_x`` / ``footprint.center_y`` move one axis.
- ``footprint.width``: a square footprint of side w (m) keeping its corner (x0, y0).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from forward.errors import SceneError as ForwardSceneError
from forward.validation import expression
from vibinverse.errors import SceneError
from vibinverse.scene_keys import set_value

DESIGN_KEYS = ("sensor.offset", "footprint.center", "footprint.center_x", "footprint.center_y", "footprint.width")
CATEGORICAL = ("sensor.polarizer", "sensor.radiometry", ".material")  # keys (or key endings) taking words

MAX_VALUES = 10_000  # values on one axis
MAX_CONFIGURATIONS = 50_000  # configurations in one sweep


@dataclass(frozen=True)
class Axis:
    """One swept scene value."""

    key: str
    values: tuple[Any, ...]

    @property
    def numeric(self) -> bool:
        return all(isinstance(v, float) for v in self.values)


def parse_vary(spec: str) -> Axis:
    """`KEY=start:stop:num` (num >= 1 evenly spaced values, ends included) or `KEY=a,b,c`."""
    key, sep, text = spec.partition("=")
    key, text = key.strip(), text.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise SceneError(f"--vary: expected dotted.key=start:stop:num or dotted.key=a,b,c, got {spec!r}")
    if not text:
        raise SceneError(f"--vary {key}: empty range; give start:stop:num (num >= 1) or a,b,c")
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise SceneError(f"--vary {key}: a range is start:stop:num, got {text!r}")
        start, stop = (_number(p, key) for p in parts[:2])
        try:
            num = int(parts[2])
        except ValueError:
            raise SceneError(f"--vary {key}: num must be an integer >= 1, got {parts[2]!r}") from None
        if num < 1:
            raise SceneError(f"--vary {key}: empty range (num = {num}); allowed num >= 1")
        if num > MAX_VALUES:
            raise SceneError(f"--vary {key}: {num} values; allowed 1..{MAX_VALUES} per axis")
        return Axis(key, tuple(float(v) for v in np.linspace(start, stop, num)))
    items = [p.strip() for p in text.split(",")]
    if any(not p for p in items):
        raise SceneError(f"--vary {key}: empty item in the list {text!r}")
    if any(key == c or key.endswith(c) for c in CATEGORICAL):
        return Axis(key, tuple(_number(p, key) if _is_number(p) else p.strip("'\"") for p in items))
    return Axis(key, tuple(_number(p, key) for p in items))


def _is_number(text: str) -> bool:
    try:
        expression(text, "")
        return True
    except ForwardSceneError:
        return False


def _number(text: str, key: str) -> float:
    try:
        value = expression(text.strip(), key)
    except ForwardSceneError:
        raise SceneError(f"--vary {key}: {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise SceneError(f"--vary {key}: {text.strip()!r} is not a finite number")
    return value


def configure(table: dict, assignments: dict[str, Any]) -> dict:
    """A copy of the scene `table` with each swept value set (design keys last: the view offset
    follows the sun wherever the sweep puts it)."""
    out = copy.deepcopy(table)
    plain = {k: v for k, v in assignments.items() if k not in DESIGN_KEYS}
    for key, value in plain.items():
        set_value(out, key, value)
    for key in DESIGN_KEYS:
        if key in assignments:
            _apply_design_key(out, key, float(assignments[key]))
    return out


def _apply_design_key(table: dict, key: str, value: float) -> None:
    if key == "sensor.offset":
        from forward.scene_file import scene_from_table

        sun = scene_from_table(table).sun  # the sun as the rest of the configuration places it
        if not 0.0 < sun.inclination + value < math.pi / 2:
            raise SceneError(
                f"sensor.offset: {value:g} rad puts the view at elevation "
                f"{sun.inclination + value:g} rad; allowed: inside (0, pi/2)"
            )
        table.setdefault("sensor", {})
        table["sensor"]["inclination"] = sun.inclination + value
        table["sensor"]["azimuth"] = sun.azimuth + math.pi
        return
    fp = table.setdefault("footprint", {})
    x, y = ([_coordinate(v, f"footprint.{a}") for v in fp.get(a, [0.0, 1.0])] for a in ("x", "y"))
    if key == "footprint.width":
        if not value > 0:
            raise SceneError(f"footprint.width: {value:g} m; allowed range (0, inf)")
        fp["x"], fp["y"] = [x[0], x[0] + value], [y[0], y[0] + value]
        return
    axes = {"footprint.center": ("x", "y"), "footprint.center_x": ("x",), "footprint.center_y": ("y",)}[key]
    for a, (lo, hi) in zip(("x", "y"), (x, y)):
        if a in axes:
            half = (hi - lo) / 2
            fp[a] = [value - half, value + half]


def _coordinate(v: Any, key: str) -> float:
    return expression(v, key) if isinstance(v, str) else float(v)


def grid(axes: list[Axis]) -> list[dict[str, Any]]:
    """Every combination of the axes' values (the first axis varies slowest); a sweep of more than
    MAX_CONFIGURATIONS is refused before any is built (at ~1-10 ms each it would run for hours)."""
    count = math.prod(len(a.values) for a in axes)
    if count > MAX_CONFIGURATIONS:
        sizes = " x ".join(f"{len(a.values)} ({a.key})" for a in axes)
        raise SceneError(
            f"--vary: {sizes} = {count:,} configurations; allowed at most {MAX_CONFIGURATIONS:,}: "
            "sweep fewer values or fewer axes"
        )
    configs: list[dict[str, Any]] = [{}]
    for axis in axes:
        configs = [{**c, axis.key: v} for c in configs for v in axis.values]
    return configs
