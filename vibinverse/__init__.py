"""vibinverse: measured pixel intensity series -> vibration parameters.

    import vibinverse as vi
    result = vi.fit(vi.load_series("frame.csv"), vi.load_scene("roof_frame.toml"))

See `vibinverse.api` for every public function. The names load on first use, so that the command
line starts (and answers Ctrl-C) before numpy, scipy and the forward model are imported.
"""

import sys
from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from types import ModuleType
from typing import Any

try:
    __version__ = version("vibinverse")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.0.0+source"

_PUBLIC = {
    "vibinverse.api": (
        "Observation",
        "design",
        "detect",
        "fit",
        "load_scene",
        "load_series",
        "open_cube",
        "open_video",
        "posterior",
        "series",
        "simulate",
        "simulate_cube",
    ),
    "vibinverse.errors": ("DataError", "InputError", "NumericalError", "SceneError", "Unsupported", "VibinverseError"),
    "vibinverse.models": ("SignalModel", "register_model"),
    "vibinverse.priors": ("Prior",),
    "vibinverse.result": ("Detection", "FitResult", "read_result"),
}
_WHERE = {name: module for module, names in _PUBLIC.items() for name in names}

__all__ = sorted([*_WHERE, "__version__"])


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        value = getattr(import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'vibinverse' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__


class _Package(ModuleType):
    """Keeps the API's functions bound when a submodule of the same name loads: importing
    `vibinverse.design.sweep` or `vibinverse.posterior` would otherwise replace `vi.design` and
    `vi.posterior` by those modules (the import system sets a loaded submodule on its package)."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _WHERE and isinstance(value, ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
