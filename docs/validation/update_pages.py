"""Regenerate the validation pages' measured tables and figures from the bench's JSON output, so that
no number on them is typed by hand:

    vibinverse bench --realdata --quick -o bench
    python docs/validation/update_pages.py bench

writes docs/validation/realdata_quick.json (the bench's rows, paths relative to the corpus),
realdata_quick.png (its figure) and the table of realdata.md between its two markers.
tests/test_docs.py checks that the page's table is the one its JSON gives."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from vibinverse.bench.realdata_bench import plot, table

HERE = Path(__file__).resolve().parent
REALDATA_PAGE = HERE / "realdata.md"
REALDATA_JSON = HERE / "realdata_quick.json"
REALDATA_FIGURE = HERE / "realdata_quick.png"
BEGIN, END = "<!-- realdata table: update_pages.py -->", "<!-- end of the realdata table -->"


def relative(result: dict[str, Any]) -> dict[str, Any]:
    """The bench's result with every file path relative to the corpus (no machine's directories)."""

    def cut(path: str) -> str:
        marker = "realdata-dev/"
        return path.split(marker, 1)[1] if marker in path else Path(path).name

    rows = [{**r, "path": cut(r["path"])} if "path" in r else r for r in result["rows"]]
    settings = dict(result.get("settings", {}))
    if "files" in settings:
        settings["files"] = [cut(f) for f in settings["files"]]
    return {**result, "rows": rows, "settings": settings}


def table_block(result: dict[str, Any]) -> str:
    """The page's block: the markers around the bench's table."""
    return f"{BEGIN}\n```\n{table(result)}\n```\n{END}"


def update_realdata(bench_dir: Path) -> None:
    """realdata_quick.json, realdata_quick.png and realdata.md's table from bench_dir/realdata.json."""
    source = bench_dir / "realdata.json"
    if not source.is_file():
        raise SystemExit(f"update_pages: no {source}; run `vibinverse bench --realdata --quick -o {bench_dir}` first")
    result = relative(json.loads(source.read_text()))
    page = REALDATA_PAGE.read_text()
    if page.count(BEGIN) != 1 or page.count(END) != 1:
        raise SystemExit(f"update_pages: {REALDATA_PAGE} needs the markers {BEGIN!r} and {END!r} once each")
    head, rest = page.split(BEGIN)
    tail = rest.split(END, 1)[1]
    REALDATA_JSON.write_text(json.dumps(result, indent=1) + "\n")
    plot(result, REALDATA_FIGURE)
    REALDATA_PAGE.write_text(head + table_block(result) + tail)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python docs/validation/update_pages.py BENCH_DIR")
    update_realdata(Path(sys.argv[1]))
