"""Signal models behind one interface (`SignalModel`), found through a registry.

Importing this package registers the built-in models: `FrameModel` (a noise-driven resonance with
drive lines; Kalman likelihood), `DeterministicModel` (plate and ground vibrations; white-noise
likelihood) and `ModalModel` (a series without a scene: resonances, lines, drift and coloured
noise). A new model subclasses `SignalModel` and is decorated with `register_model`.
"""

from vibinverse.models.base import MODELS, LineTest, SignalModel, build_model, model_class_for, register_model
from vibinverse.models.deterministic import DeterministicModel
from vibinverse.models.frame import FrameModel
from vibinverse.models.modal import ModalModel
from vibinverse.models.multi_output import MultiOutputModel

__all__ = [
    "MODELS",
    "DeterministicModel",
    "FrameModel",
    "LineTest",
    "ModalModel",
    "MultiOutputModel",
    "SignalModel",
    "build_model",
    "model_class_for",
    "register_model",
]
