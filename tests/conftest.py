from pathlib import Path

import pytest

from forward.scene_file import load_scene

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


@pytest.fixture
def scene():
    """scene("roof_elastic", "footprint.resolution=32", ...) -> Scene from an example file with overrides."""

    def make(name, *overrides):
        return load_scene(SCENES / f"{name}.toml", list(overrides))[0]

    return make
