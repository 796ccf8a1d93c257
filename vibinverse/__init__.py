"""vibinverse: measured pixel intensity series -> vibration parameters.

    import vibinverse as vi
    result = vi.fit(vi.load_series("frame.csv"), vi.load_scene("roof_frame.toml"))

See `vibinverse.api` for every public function.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("vibinverse")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.0.0+source"

from vibinverse.api import Observation, design, detect, fit, load_scene, load_series, posterior, series, simulate
from vibinverse.errors import DataError, InputError, NumericalError, SceneError, Unsupported, VibinverseError
from vibinverse.models import SignalModel, register_model
from vibinverse.priors import Prior
from vibinverse.result import Detection, FitResult, read_result

__all__ = [
    "DataError",
    "Detection",
    "FitResult",
    "InputError",
    "NumericalError",
    "Observation",
    "Prior",
    "SceneError",
    "SignalModel",
    "Unsupported",
    "VibinverseError",
    "__version__",
    "design",
    "detect",
    "fit",
    "load_scene",
    "load_series",
    "posterior",
    "read_result",
    "register_model",
    "series",
    "simulate",
]
