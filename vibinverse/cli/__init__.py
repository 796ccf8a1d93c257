"""The `vibinverse` command line: a thin layer over the public API (`vibinverse.api`).

Errors are mapped to exit codes here, in one place (`EXIT_CODES`): bad input exits with code 2 and
one line on stderr naming the problem, with no traceback and no partial output file.

Each verb returns its results and the paths it wrote as a dict; with `--json`, `main` prints that
dict as one strict JSON document on stdout and sends the log (and anything else printed) to stderr.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys

from forward.errors import SceneError as ForwardSceneError
from vibinverse.errors import InputError, Interrupted, NumericalError, VibinverseError

# the most specific class first; forward's scene errors count as input errors
EXIT_CODES: tuple[tuple[type[BaseException], int], ...] = (
    (InputError, 2),
    (ForwardSceneError, 2),
    (NumericalError, 3),
    (VibinverseError, 1),
)
SIGNAL_EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}  # 128 + the signal's number, as shells report it


class _ConsoleHandler(logging.Handler):
    """Messages to the current sys.stdout (sys.stderr with `to_stderr`, when stdout carries JSON),
    warnings and errors to sys.stderr (streams looked up per record)."""

    def __init__(self, to_stderr: bool = False) -> None:
        super().__init__()
        self.to_stderr = to_stderr

    def emit(self, record: logging.LogRecord) -> None:
        stream = sys.stderr if self.to_stderr or record.levelno >= logging.WARNING else sys.stdout
        try:
            stream.write(self.format(record) + "\n")
            stream.flush()
        except BrokenPipeError:  # the reader stopped (e.g. head): `main` ends quietly
            raise
        except Exception:  # noqa: BLE001 - logging must never raise
            self.handleError(record)


def configure_logging(quiet: bool = False, verbose: bool = False, json: bool = False) -> None:
    """The package's log to the console: INFO by default, WARNING with -q, DEBUG with -v; all of it
    on stderr with `json` (--json: stdout carries the JSON document only)."""
    root = logging.getLogger("vibinverse")
    for h in [h for h in root.handlers if isinstance(h, _ConsoleHandler)]:
        root.removeHandler(h)
    handler = _ConsoleHandler(to_stderr=json)
    handler.setFormatter(logging.Formatter("%(message)s"))
    root.addHandler(handler)
    root.setLevel(logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO)
    root.propagate = False


def exit_code(exc: BaseException) -> int:
    """The exit code of an error (`EXIT_CODES`; an interruption by its signal, `SIGNAL_EXIT`)."""
    if isinstance(exc, Interrupted):
        return SIGNAL_EXIT.get(exc.signum, 130)
    return next(code for cls, code in EXIT_CODES if isinstance(exc, cls))


def _terminate(signum: int, frame: object) -> None:
    """SIGTERM outside a sampler: stop like Ctrl-C (a sampler installs its own handler, which
    finishes the current step and flushes the checkpoint first)."""
    raise Interrupted("terminated", signum=signum)


_SIGINT_SEEN = {"seen": False}


def _interrupt(signum: int, frame: object) -> None:
    """Ctrl-C: remembered, then raised as KeyboardInterrupt (Python's own handler). A C extension
    that catches it inside a Python callback raises its own error instead (casadi's IPOPT:
    "RuntimeError: ... returned a result with an exception set"), which `main` then reads as the
    interruption it is."""
    _SIGINT_SEEN["seen"] = True
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Run one command; the exit code. The package logger's console handler, level and propagation
    are restored afterwards, so a caller that runs `main` in its own process keeps its logging."""
    previous = signal.signal(signal.SIGTERM, _terminate) if _main_thread() else None
    previous_int = signal.signal(signal.SIGINT, _interrupt) if _main_thread() else None
    _SIGINT_SEEN["seen"] = False
    package = logging.getLogger("vibinverse")
    saved = (list(package.handlers), package.level, package.propagate)
    try:
        from vibinverse.cli.commands import build_parser

        configure_logging()
        args = build_parser().parse_args(argv)
        as_json = bool(getattr(args, "json", False))
        configure_logging(getattr(args, "quiet", False), getattr(args, "verbose", False), as_json)
        if as_json:
            print_json(run_quietly(args))
        else:
            args.func(args)
    except Interrupted as exc:
        print(f"vibinverse: {exc}", file=sys.stderr)
        return exit_code(exc)
    except (VibinverseError, ForwardSceneError) as exc:
        print(f"vibinverse: error: {exc}", file=sys.stderr)
        return exit_code(exc)
    except KeyboardInterrupt:
        print("vibinverse: interrupted", file=sys.stderr)
        return SIGNAL_EXIT[signal.SIGINT]
    except BrokenPipeError:  # output piped into a reader that stopped (e.g. head)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes stdout at exit
        return 0
    except Exception as exc:  # Ctrl-C inside a C extension comes back as its error (an import's ImportError)
        if not (_interrupted(exc) or _SIGINT_SEEN["seen"]):
            raise
        print("vibinverse: interrupted", file=sys.stderr)
        return SIGNAL_EXIT[signal.SIGINT]
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)
        package.handlers[:], package.propagate = saved[0], saved[2]
        package.setLevel(saved[1])
    return 0


def run_quietly(args: object) -> object:
    """Run the verb with anything it or a library prints sent to stderr; return its result."""
    with contextlib.redirect_stdout(sys.stderr):
        return args.func(args)


def print_json(doc: object) -> None:
    """--json: the verb's result as one strict JSON document on stdout (non-finite numbers null)."""
    from vibinverse.io import jsonio

    sys.stdout.write(jsonio.dumps(doc if doc is not None else {}, indent=2) + "\n")
    sys.stdout.flush()


def entry() -> None:
    """The console script and `python -m vibinverse`: exit with `main`'s code. An interruption ends
    the process at once: when Ctrl-C lands inside an import, CPython marks it unhandled even though
    `main` handled it, and re-raises SIGINT at exit (status -2 instead of 130). Outputs are written
    atomically and the checkpoint after every step, so nothing is left to flush but the streams."""
    code = main()
    if code in SIGNAL_EXIT.values():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


def _interrupted(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is in the exception's chain (a module whose initialization Ctrl-C
    stopped raises "ImportError: initialization failed" from it)."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return False


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


if __name__ == "__main__":
    entry()
