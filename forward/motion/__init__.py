"""Surface motions. The optics sees a motion only through the slopes of the surface."""

from forward.motion.base import ModalMotion, Motion
from forward.motion.frame import FrameMotion, FrameParameters
from forward.motion.ground import RayleighMotion
from forward.motion.plate import PlateMotion, poisson_shape

# kind -> builder(table, x_range, y_range): how a scene file names a motion. New motions register
# here; the scene code has no special cases.
MOTION_CLASSES: dict[str, type[Motion]] = {"plate": PlateMotion, "frame": FrameMotion, "rayleigh": RayleighMotion}
MOTION_KINDS = {kind: cls.from_table for kind, cls in MOTION_CLASSES.items()}

__all__ = [
    "MOTION_CLASSES",
    "MOTION_KINDS",
    "FrameMotion",
    "FrameParameters",
    "ModalMotion",
    "Motion",
    "PlateMotion",
    "RayleighMotion",
    "poisson_shape",
]
