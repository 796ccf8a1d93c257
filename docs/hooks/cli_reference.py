"""MkDocs hook: the command-line reference (docs/reference/cli.md), generated at build time from the
argparse parser the `vibinverse` command itself runs (`vibinverse.cli.commands.build_parser`), so
the page cannot drift from the code. The page holds a marker, `<!-- cli-reference -->`, that the
hook replaces with one section per verb: its help line, description, usage, and a table of its
arguments (names, value, default, choices, help).

    python docs/hooks/cli_reference.py      # print the generated Markdown (tests/test_docs.py runs it)
"""

from __future__ import annotations

import argparse
import html
import os
import sys
from pathlib import Path

MARKER = "<!-- cli-reference -->"
PAGE = "reference/cli.md"
ROOT = Path(__file__).resolve().parents[2]
WIDTH = "100"  # columns of the usage lines, whatever the terminal building the site


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser, imported from the source tree beside this file."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from vibinverse.cli.commands import build_parser as build

    return build()


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Each verb's name and parser, in the order they were added."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _helps(parser: argparse.ArgumentParser) -> dict[str, str]:
    """Each verb's one-line help (the text `vibinverse --help` lists)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def _cell(text: object) -> str:
    """Text for a Markdown table cell: HTML-escaped, pipes escaped, one line."""
    return html.escape(" ".join(str(text).split()), quote=False).replace("|", "\\|")


def _exclusive(parser: argparse.ArgumentParser) -> dict[int, str]:
    """id(action) -> a note naming the other options it excludes."""
    notes = {}
    for group in parser._mutually_exclusive_groups:
        names = [a.option_strings[-1] for a in group._group_actions if a.option_strings]
        for a in group._group_actions:
            others = [n for n in names if a.option_strings and n != a.option_strings[-1]]
            if others:
                notes[id(a)] = "not with " + ", ".join(others)
    return notes


def _rows(parser: argparse.ArgumentParser) -> list[str]:
    formatter = parser._get_formatter()
    exclusive = _exclusive(parser)
    rows = []
    for a in parser._actions:
        if isinstance(a, (argparse._SubParsersAction, argparse._HelpAction)) or a.help == argparse.SUPPRESS:
            continue
        name = ", ".join(a.option_strings) if a.option_strings else a.dest
        if a.choices is not None:
            value = "{" + ",".join(str(c) for c in a.choices) + "}"
        elif a.nargs == 0:
            value = ""
        else:
            value = a.metavar if isinstance(a.metavar, str) else a.dest.upper() if a.option_strings else ""
        default = a.default
        shown = "" if default is None or default is False or default == argparse.SUPPRESS else f"`{default}`"
        text = formatter._expand_help(a) if a.help else ""
        extra = [exclusive[id(a)]] if id(a) in exclusive else []
        if a.option_strings and a.required:
            extra.append("required")
        if isinstance(a, argparse._AppendAction) and "repeat" not in text:
            extra.append("repeatable")
        note = f" ({'; '.join(extra)})" if extra else ""
        rows.append(f"| `{_cell(name)}` | {_cell(value)} | {shown} | {_cell(text + note)} |")
    return rows


def _section(name: str, parser: argparse.ArgumentParser, help_line: str, level: str = "##") -> list[str]:
    out = [f"{level} `{parser.prog}` {{#{name}}}", ""]
    if help_line:
        out += [_cell(help_line[0].upper() + help_line[1:]).rstrip(".") + ".", ""]
    if parser.description and parser.description != help_line:
        out += [_cell(parser.description), ""]
    out += ["```text", parser.format_usage().strip(), "```", ""]
    out += ["| argument | value | default | description |", "|---|---|---|---|", *_rows(parser), ""]
    return out


def render() -> str:
    """The generated reference: the options every verb shares, then one section per verb."""
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH
    try:
        parser = build_parser()
        verbs = subcommands(parser)
        helps = _helps(parser)
        out = _section("vibinverse", parser, parser.description or "")
        out += ["Verbs: " + ", ".join(f"[`{v}`](#{v})" for v in verbs) + ".", ""]
        for verb, sub in verbs.items():
            out += _section(verb, sub, helps.get(verb, ""))
    finally:
        if saved is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved
    return "\n".join(out)


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs calls hooks by this signature
    """MkDocs calls this for every page; the CLI page gets the generated reference."""
    if page.file.src_uri == PAGE and MARKER in markdown:
        return markdown.replace(MARKER, render())
    return markdown


if __name__ == "__main__":
    sys.stdout.write(render() + "\n")
