"""The distribution ships every package of the source tree (an editable install hides a missing one)."""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_directory_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for top in ("forward", "vibinverse")
        for p in (ROOT / top).rglob("__init__.py")
    }
    assert found - listed == set(), f"not shipped: {sorted(found - listed)}"
    assert "vibinverse.scenes" in listed  # examples/scenes, mapped in as package data
