"""The documentation: the command-line reference generated from the parser covers every verb and
option (docs/hooks/cli_reference.py, the MkDocs hook that writes docs/reference/cli.md at build
time), and README.md stays a short page for newcomers, without dates. CI builds the whole site with
`mkdocs build --strict`."""

import argparse
import importlib.util
import re
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


def test_the_real_data_page_shows_the_table_of_its_bench_json():
    """docs/validation/realdata.md's table is the one docs/validation/realdata_quick.json gives
    (`update_pages.py` writes both): no number on the page is typed by hand."""
    import json

    spec = importlib.util.spec_from_file_location("update_pages", ROOT / "docs" / "validation" / "update_pages.py")
    pages = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pages)
    result = json.loads(pages.REALDATA_JSON.read_text())
    assert pages.table_block(result) in pages.REALDATA_PAGE.read_text()
    assert not any("/work/" in r.get("path", "") for r in result["rows"])  # no machine's directories


def test_the_oma_page_shows_the_table_of_its_bench_json():
    """docs/validation/oma.md's table is the one docs/validation/oma_quick.json gives (`update_pages.py`)."""
    import json

    spec = importlib.util.spec_from_file_location("update_pages", ROOT / "docs" / "validation" / "update_pages.py")
    pages = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pages)
    result = json.loads(pages.OMA_JSON.read_text())
    assert pages.oma_block(result) in pages.OMA_PAGE.read_text()
