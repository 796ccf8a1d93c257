"""Reading and writing: measured series, scene files, simulated series, all-or-nothing outputs."""

from vibinverse.io.atomic import staged, write_all
from vibinverse.io.scenes import builtin_scene, load_scene, read_scene, scene_of
from vibinverse.io.series import Series, load_series, validate

__all__ = [
    "Series",
    "builtin_scene",
    "load_scene",
    "load_series",
    "read_scene",
    "scene_of",
    "staged",
    "validate",
    "write_all",
]
