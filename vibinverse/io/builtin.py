"""The built-in scenes: the files of examples/scenes, installed as the package data `vibinverse.scenes`."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def builtin_scene(name: str) -> Path:
    """Path of built-in scene `name` ("roof_frame" or "roof_frame.toml"); "" gives the folder."""
    if name and not name.endswith(".toml"):
        name += ".toml"
    return Path(str(files("vibinverse.scenes").joinpath(name)))
