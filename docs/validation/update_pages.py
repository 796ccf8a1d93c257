"""Regenerate the validation pages' measured tables and figures from the bench's JSON output, so that
no number on them is typed by hand:

    vibinverse bench --realdata --quick -o bench
    vibinverse bench --oma --quick -o bench
    python docs/validation/update_pages.py bench

writes docs/validation/realdata_quick.json (the bench's rows, paths relative to the corpus),
realdata_quick.png (its figure) and the table of realdata.md between its two markers; likewise
oma_quick.json, oma_quick.png and oma.md's table from oma.json. tests/test_docs.py checks that each
page's table is the one its JSON gives."""

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
OMA_PAGE, OMA_JSON, OMA_FIGURE = HERE / "oma.md", HERE / "oma_quick.json", HERE / "oma_quick.png"
OMA_BEGIN, OMA_END = "<!-- oma table: update_pages.py -->", "<!-- end of the oma table -->"


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
    splice(REALDATA_PAGE, BEGIN, END, table_block(result))
    REALDATA_JSON.write_text(json.dumps(result, indent=1) + "\n")
    plot(result, REALDATA_FIGURE)


def splice(page_path: Path, begin: str, end: str, block: str) -> None:
    """Replace the block between the markers `begin` and `end` (each once on the page) by `block`."""
    page = page_path.read_text()
    if page.count(begin) != 1 or page.count(end) != 1:
        raise SystemExit(f"update_pages: {page_path} needs the markers {begin!r} and {end!r} once each")
    head, rest = page.split(begin)
    page_path.write_text(head + block + rest.split(end, 1)[1])


def oma_block(result: dict[str, Any]) -> str:
    """oma.md's block: the markers around the OMA bench's table."""
    from vibinverse.bench.oma_bench import table as oma_table

    return f"{OMA_BEGIN}\n```\n{oma_table(result)}\n```\n{OMA_END}"


def update_oma(bench_dir: Path) -> None:
    """oma_quick.json, oma_quick.png and oma.md's table from bench_dir/oma.json."""
    from vibinverse.bench.oma_bench import plot as oma_plot

    result = json.loads((bench_dir / "oma.json").read_text())
    splice(OMA_PAGE, OMA_BEGIN, OMA_END, oma_block(result))
    OMA_JSON.write_text(json.dumps(result, indent=1) + "\n")
    oma_plot(result, OMA_FIGURE)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python docs/validation/update_pages.py BENCH_DIR")
    bench = Path(sys.argv[1])
    done = []
    if (bench / "realdata.json").is_file():
        update_realdata(bench)
        done.append("realdata")
    if (bench / "oma.json").is_file():
        update_oma(bench)
        done.append("oma")
    if not done:
        raise SystemExit(f"update_pages: neither realdata.json nor oma.json in {bench}; run `vibinverse bench` first")
