"""Strict JSON for every file vibinverse writes (RFC 8259: no NaN or Infinity tokens).

`dumps` writes a non-finite float as null and, when the document is a JSON object, names each such
null with the number it stands for in a top-level "non_finite" object keyed by JSON Pointer
(RFC 6901), e.g. {"/parameters/noise.sigma/prior_bounds/0": "-Infinity"}. `loads` reads strict or
lenient JSON and puts those numbers back. numpy scalars and arrays become Python numbers and lists.

    from vibinverse.io import jsonio
    path.write_text(jsonio.dumps(summary, indent=2))
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

NON_FINITE = "non_finite"  # the top-level key of the record


def to_jsonable(obj: Any, record: dict[str, str] | None = None, pointer: str = "") -> Any:
    """`obj` with numpy values as Python ones, tuples as lists and non-finite floats as None; each
    None that replaced a number is added to `record` as {JSON pointer: "NaN" | "Infinity" | "-Infinity"}."""
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    elif isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        if math.isfinite(obj):
            return obj
        if record is not None:
            record[pointer] = "NaN" if math.isnan(obj) else ("Infinity" if obj > 0 else "-Infinity")
        return None
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            key = _key(k)
            out[key] = to_jsonable(v, record, f"{pointer}/{_escape(str(key))}")
        return out
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, record, f"{pointer}/{i}") for i, v in enumerate(obj)]
    return obj


def dumps(obj: Any, *, record: bool = True, **kw: Any) -> str:
    """Strict JSON text of `obj` (json.dumps keywords, e.g. indent, pass through; allow_nan is
    always False). With `record`, a top-level object gets the "non_finite" record of the nulls
    that stand for non-finite numbers (when there are any)."""
    kw.pop("allow_nan", None)
    notes: dict[str, str] = {}
    doc = to_jsonable(obj, notes)
    if record and notes and isinstance(doc, dict):
        old = doc.get(NON_FINITE)
        doc[NON_FINITE] = {**old, **notes} if isinstance(old, dict) else notes
    return json.dumps(doc, allow_nan=False, **kw)


def loads(text: str | bytes) -> Any:
    """Parse JSON written by `dumps` (or lenient JSON with NaN/Infinity tokens) and restore the
    numbers its "non_finite" record names; the record itself is removed."""
    doc = json.loads(text)
    if isinstance(doc, dict) and isinstance(doc.get(NON_FINITE), dict):
        notes = doc.pop(NON_FINITE)
        for pointer, value in notes.items():
            _restore(doc, str(pointer), value)
    return doc


_NUMBERS = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def _restore(doc: Any, pointer: str, value: Any) -> None:
    """Put the number back at `pointer` when the pointer leads to a null; ignore anything else."""
    if not isinstance(value, str) or value not in _NUMBERS or not pointer.startswith("/"):
        return
    *path, last = [_unescape(p) for p in pointer[1:].split("/")]
    node = doc
    for part in [*path, last]:
        parent = node
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return
    if node is None:
        parent[last if isinstance(parent, dict) else int(last)] = _NUMBERS[value]


def _key(k: Any) -> Any:
    """A key as json.dumps writes it (so that the pointers name the keys of the text)."""
    if isinstance(k, np.generic):
        k = k.item()
    if isinstance(k, (bool, int, float)) or k is None:
        return json.dumps(k)
    return k  # str, or a type json refuses


def _escape(part: str) -> str:
    return part.replace("~", "~0").replace("/", "~1")


def _unescape(part: str) -> str:
    return part.replace("~1", "/").replace("~0", "~")
