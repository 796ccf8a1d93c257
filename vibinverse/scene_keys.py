"""Scene values by dotted name: read one, write one, list every number of a scene table.

"surfaces.roof.motion.drive_frequency" is the first element of a list; "...[i]" picks element i.
Numbers may be expressions ("pi/3 + 0.01"), as in scene files.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from forward.errors import SceneError as ForwardSceneError
from forward.validation import expression
from vibinverse.errors import SceneError


def get_value(table: dict, key: str) -> float:
    """The numeric value at dotted `key` ("...drive_frequency" is the first line, "[i]" picks one)."""
    node: Any = table
    parts = key.split(".")
    for part in parts:
        base, idx = _split_index(part)
        if not isinstance(node, dict) or base not in node:
            raise SceneError(f"{key}: no such scene value")
        node = node[base]
        if isinstance(node, list):
            node = node[idx if idx is not None else 0]
    if isinstance(node, str):
        try:
            return expression(node, key)
        except ForwardSceneError as exc:
            raise SceneError(str(exc)) from None
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise SceneError(f"{key}: not a number")
    return float(node)


def set_value(table: dict, key: str, value: Any) -> None:
    """Set dotted `key` in `table`; SceneError names the key. As in `get_value`, "a.b[i]" is
    element i of a list and a plain "a.b" on a list is its first element."""
    node: Any = table
    parts = key.split(".")
    for part in parts[:-1]:
        node = node.setdefault(_split_index(part)[0], {})
        if not isinstance(node, dict):
            raise SceneError(f"{key}: {part} is a value, not a table")
    try:
        base, idx = _split_index(parts[-1])
    except ValueError:
        raise SceneError(f"{key}: the index is not an integer") from None
    current = node.get(base)
    if idx is None and not isinstance(current, list):
        node[base] = value
        return
    idx = idx or 0
    items = list(current) if isinstance(current, list) else ([current] if current is not None else [])
    if not 0 <= idx < len(items):
        raise SceneError(f"{key}: index {idx} is outside the list of {len(items)} values")
    items[idx] = value
    node[base] = items


def _split_index(part: str) -> tuple[str, int | None]:
    if part.endswith("]") and "[" in part:
        base, idx = part[:-1].split("[", 1)
        return base, int(idx)
    return part, None


def is_number(v: Any) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    if isinstance(v, str):
        try:
            expression(v, "")
            return True
        except ForwardSceneError:
            return False
    return False


def numeric_keys(table: dict, prefix: str = "") -> Iterator[str]:
    """Every dotted name of a number in `table` (a list of numbers gives "name" and "name[i]")."""
    for k, v in table.items():
        name = prefix + k
        if isinstance(v, dict):
            yield from numeric_keys(v, name + ".")
        elif isinstance(v, list) and v and all(is_number(e) for e in v):
            yield name
            yield from (f"{name}[{i}]" for i in range(len(v)))
        elif is_number(v):
            yield name
