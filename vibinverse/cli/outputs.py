"""`-o DIR` for every verb: checked before any work, created only for the run, removed again when
a refused run leaves it empty; and the one help pattern that documents it."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
from collections.abc import Iterator
from pathlib import Path

from vibinverse.errors import InputError

# what may end a line for some reader: C0 controls, DEL, NEL, and the Unicode line and paragraph separators
_LINE_BREAKERS = re.compile("[\x00-\x1f\x7f\x85\u2028\u2029]")


def one_line(text: object) -> str:
    """User-given text (a file name, a units attribute, a title) for one line of a text file, e.g.
    a CSV '#' comment: every character that could end the line is written as its escape (\\n)."""
    return _LINE_BREAKERS.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), str(text))


def output_dir(path: str | Path) -> Path:
    """`-o DIR`, checked before any work: an existing directory we may write into, or a path where
    one can be made (one-line InputError if not). Nothing is created here (`created` does that)."""
    out = Path(path)
    try:
        first = next((p for p in (out, *out.parents) if p.exists()), Path.cwd())
    except OSError as exc:
        raise InputError(f"-o: cannot create directory {out}: {exc.strerror or exc}") from None
    if not first.is_dir():
        if first == out:
            raise InputError(f"-o: {out} is not a directory; give a directory")
        raise InputError(f"-o: cannot create directory {out}: {first} is not a directory")
    if not os.access(first, os.W_OK | os.X_OK):
        raise InputError(f"-o: cannot {'write into' if first == out else 'create'} directory {out}: permission denied")
    return out


@contextlib.contextmanager
def created(out: Path) -> Iterator[Path]:
    """Make the output directory `out` (and missing parents) for the block; when the block fails,
    remove the directories it made that are still empty, so that a refused run leaves nothing."""
    made = [p for p in (out, *out.parents) if not p.exists()]  # deepest first
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"-o: cannot create directory {out}: {exc.strerror or exc}") from None
    try:
        yield out
    except BaseException:
        for p in made:
            try:
                p.rmdir()
            except OSError:
                break
        raise


def output_option(parser: argparse.ArgumentParser, default: str | None, writes: str, shown: str = "") -> None:
    """The `-o DIR` option of a verb that writes files: one help pattern for all verbs
    ("output directory (default: X); writes a.csv, b.png"; tests/vibinverse/cli/test_commands.py)."""
    help = f"output directory (default: {shown or default}); writes {writes}"
    parser.add_argument("-o", "--output", metavar="DIR", default=default, help=help)
