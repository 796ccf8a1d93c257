"""forward: scene (surfaces, materials, motions, sun, sensor) -> pixel intensity series.

Never imports `vibinverse`.
"""

from forward.errors import SceneError
from forward.render import pixel_signal, sensitivity
from forward.scene_file import load_scene, scene_from_table
from forward.sensor import Observation, observe

__all__ = ["Observation", "SceneError", "load_scene", "observe", "pixel_signal", "scene_from_table", "sensitivity"]
