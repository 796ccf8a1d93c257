"""forward: scene (surfaces, materials, motions, sun, sensor) -> pixel intensity series.

Never imports `vibinverse`. The names below load on first use (`import forward.errors` stays light).
"""

from importlib import import_module
from typing import Any

_WHERE = {
    "SceneError": "forward.errors",
    "pixel_signal": "forward.render",
    "sensitivity": "forward.render",
    "load_scene": "forward.scene_file",
    "scene_from_table": "forward.scene_file",
    "Observation": "forward.sensor",
    "observe": "forward.sensor",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        value = getattr(import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'forward' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
