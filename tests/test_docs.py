"""The documentation: the command-line reference generated from the parser covers every verb and
option (docs/hooks/cli_reference.py, the MkDocs hook that writes docs/reference/cli.md at build
time), and README.md stays a short page for newcomers, without dates. CI builds the whole site with
`mkdocs build --strict`."""

import argparse
import importlib.util
import re
import sys
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
HOOK = ROOT / "docs" / "hooks" / "cli_reference.py"


def _hook():
    spec = importlib.util.spec_from_file_location("cli_reference", HOOK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_cli_reference_has_every_verb_and_option_of_the_parser():
    from vibinverse.cli.commands import build_parser

    hook = _hook()
    page = hook.render()
    parser = build_parser()
    verbs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert len(verbs) >= 10
    for name, sub in verbs.items():
        assert f"## `vibinverse {name}` {{#{name}}}" in page, name
        section = page.split(f"{{#{name}}}", 1)[1].split("\n## ", 1)[0]
        assert f"usage: vibinverse {name}" in section
        for action in sub._actions:
            if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
                continue
            shown = ", ".join(action.option_strings) if action.option_strings else action.dest
            assert f"| `{shown}` |" in section, (name, shown)


def test_the_hook_fills_the_cli_page_and_leaves_the_others():
    hook = _hook()
    source = (ROOT / "docs" / hook.PAGE).read_text(encoding="utf-8")
    assert hook.MARKER in source

    def page(uri):
        return SimpleNamespace(file=SimpleNamespace(src_uri=uri))

    filled = hook.on_page_markdown(source, page(hook.PAGE), None, None)
    assert hook.MARKER not in filled and "{#fit}" in filled
    assert hook.on_page_markdown(source, page("index.md"), None, None) == source


def test_the_readme_is_short_and_carries_no_dates():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 160
    dates = re.findall(r"\b(?:19|20)\d\d-\d", text)
    assert dates == [], dates
    first_block = re.search(r"```[a-z]*\n(.*?)```", text, re.S).group(1).splitlines()
    assert first_block[:2] == ["pip install . && vibinverse demo", 'pip install -e ".[test]" && pytest -n auto']


def _update_pages():
    """docs/validation/update_pages.py as a module (registered in sys.modules, as its dataclass needs)."""
    spec = importlib.util.spec_from_file_location("update_pages", ROOT / "docs" / "validation" / "update_pages.py")
    pages = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = pages
    spec.loader.exec_module(pages)
    return pages


def test_the_real_data_page_shows_the_table_of_its_bench_json():
    """docs/validation/realdata.md's table is the one docs/validation/realdata_quick.json gives
    (`update_pages.py` writes both): no number on the page is typed by hand."""
    import json

    pages = _update_pages()
    result = json.loads(pages.REALDATA_JSON.read_text())
    assert pages.table_block(result) in pages.REALDATA_PAGE.read_text()
    assert not any("/work/" in r.get("path", "") for r in result["rows"])  # no machine's directories


def test_the_oma_page_shows_the_table_of_its_bench_json():
    """docs/validation/oma.md's table is the one docs/validation/oma_quick.json gives (`update_pages.py`)."""
    import json

    pages = _update_pages()
    result = json.loads(pages.OMA_JSON.read_text())
    assert pages.oma_block(result) in pages.OMA_PAGE.read_text()


def test_the_robustness_estimators_speed_and_calibration_pages_show_the_tables_of_their_bench_json():
    """docs/validation/robustness.md, estimators.md, speed.md (its two tables), calibration.md and
    oma.md's two calibration tables (from examples/oma_calibration.py's and io_calibration.py's JSON):
    each table is the one its stored JSON beside the page gives (`update_pages.py` writes both, from
    the bench's own table function), the figure is there where the block has one, and the page
    states the command that reproduces it."""
    import json

    pages = _update_pages()
    assert {b.name for b in pages.BLOCKS} == {
        "robustness",
        "estimators",
        "speed",
        "imaging",
        "calibration",
        "oma calibration",
        "io calibration",
    }
    for block in pages.BLOCKS:
        text = block.stored.read_text()
        assert "/work/" not in text and "/home/" not in text, block.name  # no machine's directories
        page = block.page.read_text()
        assert block.block(json.loads(text)) in page, block.name
        if block.figure is not None:
            assert block.figure.is_file() and block.figure.stat().st_size > 10_000, block.figure
            assert f"]({block.figure.name})" in page, block.name
        assert block.command in page and "update_pages.py" in page, block.name


def test_the_oma_calibration_tables_count_what_their_json_holds():
    """oma.md's calibration tables: one row per case of oma_calibration.json and per noise level and
    mode of io_calibration.json, Markdown (not a code block), each coverage with its standard error;
    the caption names the run's command with its settings."""
    import json

    pages = _update_pages()
    blocks = {b.name: b for b in pages.BLOCKS}
    oma = json.loads(blocks["oma calibration"].stored.read_text())
    text = blocks["oma calibration"].block(oma)
    assert "```" not in text and text.count("±") == 3 * len(oma["cases"])
    for r in oma["cases"]:
        assert f"| {r['case']} (" in text and r["what"] in text
        assert f"{r['frequency']['coverage']:.3f} ± {r['frequency']['se']:.3f}" in text
        assert r["frequency"]["n"] <= r["modes"] * (r["n_sets"] - r["failed"])  # a missed mode: no interval
    settings = oma["settings"]
    assert f"oma_calibration.py {settings['n_sets']} {' '.join(settings['cases'])}" in text
    io = json.loads(blocks["io calibration"].stored.read_text())
    text = blocks["io calibration"].block(io)
    rows = [line for line in text.splitlines() if line.startswith("| ") and "% of each channel" in line]
    assert len(rows) == sum(len(level["modes"]) for level in io["levels"]) and len(io["levels"]) >= 2
    for level in io["levels"]:
        for m in level["modes"]:
            assert m["found"] + m["missed"] == io["sets"]
            assert f"{m['coverage_damping_ratio']:.3f} ± {m['coverage_damping_ratio_se']:.3f}" in text
    noises = " ".join(f"{level['noise']:g}" for level in io["levels"])
    assert f"io_calibration.py {io['sets']} {io['fs']:g} {noises}" in text


def test_update_pages_regenerates_what_is_there_and_skips_the_rest(tmp_path, monkeypatch):
    """update_pages.py on a directory holding only some benches' JSON updates those pages and leaves
    the others; on a directory with none it stops with a message."""
    import dataclasses
    import json

    import pytest

    pages = _update_pages()
    with pytest.raises(SystemExit, match="no bench JSON"):
        pages.main(tmp_path)
    block = next(b for b in pages.BLOCKS if b.name == "estimators")
    page = tmp_path / "estimators.md"
    page.write_text(f"before\n{block.begin}\nold\n{block.end}\nafter\n")
    moved = dataclasses.replace(
        block, page=page, stored=tmp_path / "kept.json", figure=tmp_path / "kept.png", plot=lambda r, p: p.touch()
    )
    monkeypatch.setattr(pages, "BLOCKS", (moved,))
    bench = tmp_path / "bench"
    bench.mkdir()
    (bench / "estimators.json").write_text(block.stored.read_text())
    assert pages.main(bench) == ["estimators.json"]
    result = json.loads((tmp_path / "kept.json").read_text())
    assert page.read_text() == f"before\n{block.block(result)}\nafter\n"


def test_update_pages_writes_a_table_without_a_figure(tmp_path, monkeypatch):
    """A block without a figure (oma.md's io calibration table): update_pages.py splices its table and
    stores its JSON, and plots nothing."""
    import dataclasses
    import json

    pages = _update_pages()
    block = next(b for b in pages.BLOCKS if b.name == "io calibration")
    assert block.figure is None and block.plot is None
    page = tmp_path / "oma.md"
    page.write_text(f"before\n{block.begin}\nold\n{block.end}\nafter\n")
    moved = dataclasses.replace(block, page=page, stored=tmp_path / "kept.json")
    monkeypatch.setattr(pages, "BLOCKS", (moved,))
    bench = tmp_path / "bench"
    bench.mkdir()
    (bench / "io_calibration.json").write_text(block.stored.read_text())
    assert pages.main(bench) == ["io_calibration.json"]
    result = json.loads((tmp_path / "kept.json").read_text())
    assert page.read_text() == f"before\n{block.block(result)}\nafter\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bench", "kept.json", "oma.md"]
