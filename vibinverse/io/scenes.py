"""Scene files for the inverse side: `forward`'s loader behind vibinverse's error type, and the
built-in scenes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from forward.scene import Scene
from forward.scene_file import load_scene as forward_load_scene
from forward.scene_file import scene_from_table
from vibinverse.errors import scene_errors
from vibinverse.io.builtin import builtin_scene

__all__ = ["builtin_scene", "load_scene", "read_scene", "scene_of"]


def read_scene(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> tuple[Scene, dict[str, Any]]:
    """(Scene, its table) from a TOML scene file with `dotted.key=value` overrides; a bad file or
    value raises `vibinverse.errors.SceneError` naming the key."""
    with scene_errors():
        return forward_load_scene(Path(path), list(overrides))


def load_scene(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> dict[str, Any]:
    """The validated scene table of a TOML file (what `fit`, `design` and `simulate` take)."""
    return read_scene(path, overrides)[1]


def scene_of(table: dict[str, Any]) -> Scene:
    """The forward model's Scene of a table (validated; one-line SceneError)."""
    with scene_errors():
        return scene_from_table(table)
