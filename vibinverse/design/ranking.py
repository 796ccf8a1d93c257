"""How a design sweep ranks its configurations: the parameter pinned worst decides."""

from __future__ import annotations

import math
from typing import Any


def score(row: dict[str, Any], targets: list[str]) -> float:
    """The worst relative Cramer-Rao sd over the targets: the parameter pinned worst decides."""
    rel = [row.get(f"rel_crlb {t}", math.inf) for t in targets]
    return max(rel) if rel else math.inf


def rank(rows: list[dict[str, Any]], targets: list[str], threshold: float) -> list[dict[str, Any]]:
    """Configurations that work, detectable ones (S >= threshold) first, then by `score`, then by S."""
    ok = [r for r in rows if r.get("status") == "ok"]
    return sorted(ok, key=lambda r: (r["sensitivity"] < threshold, score(r, targets), -r["sensitivity"]))
