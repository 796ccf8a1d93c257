"""Writing result files all-or-nothing: a failed run leaves no partial file behind."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from vibinverse.errors import InputError


def check_paths(outputs: dict[str, str | Path | None], inputs: dict[str, str | Path | None]) -> None:
    """Refuse, before any work, an output that is a directory, two outputs at one path, and an output
    at an input's path (that would replace the input). Keys name the options in the message."""
    seen: dict[Path, str] = {}
    ins = {Path(p).resolve(): k for k, p in inputs.items() if p is not None}
    for key, p in outputs.items():
        if p is None:
            continue
        path = Path(p)
        if path.is_dir():
            raise InputError(f"{key}: {path} is a directory; give a file path")
        real = path.resolve()
        if real in ins:
            raise InputError(f"{key}: {path} is also the input {ins[real]}; writing it would replace the input")
        if real in seen:
            raise InputError(f"{key}: {path} is also the output {seen[real]}; give each output its own path")
        seen[real] = key


@contextlib.contextmanager
def staged(paths: list[Path]) -> Iterator[list[Path]]:
    """Yield temporary paths beside `paths`; on success move them all into place, else delete them.

    Raises InputError (one line) when a destination's directory is missing or not writable.
    """
    temps: list[Path] = []
    try:
        for p in paths:
            try:
                fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part", dir=p.parent)
            except OSError as exc:
                raise InputError(f"output: cannot write {p}: {exc.strerror or exc}") from None
            os.close(fd)
            os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results should be readable like any file
            temps.append(Path(tmp))
        yield temps
        for tmp, p in zip(temps, paths):
            os.replace(tmp, p)
        temps = []
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)


def write_all(writers: dict[Path, Callable[[Path], None]]) -> None:
    """Run each writer on a temporary file, then move every file into place together."""
    targets = list(writers)
    check_paths({str(p): p for p in targets}, {})
    with staged(targets) as temps:
        for tmp, target in zip(temps, targets):
            writers[target](tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
