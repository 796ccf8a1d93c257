"""One exception hierarchy for everything a user can act on; the CLI maps it to exit codes in one
place (`vibinverse.cli.EXIT_CODES`).

    VibinverseError
    ├── InputError        an option, a file or an argument is invalid            (exit 2)
    │   ├── SceneError    a scene value (also a `forward.errors.SceneError`)     (exit 2)
    │   ├── DataError     a measured series or its file                          (exit 2)
    │   └── Unsupported   a method does not cover this model or these values     (exit 2)
    ├── NumericalError    a computation failed on valid input (no optimum, ...)  (exit 3)
    └── Interrupted       SIGINT or SIGTERM stopped a run; its checkpoint is intact (exit 130 / 143)

Every message is one line that names the field and, where there is one, the allowed range.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from forward.errors import SceneError as ForwardSceneError


class VibinverseError(Exception):
    """Base of every error vibinverse raises on purpose."""


class InputError(VibinverseError, ValueError):
    """An option, file or argument is invalid."""


class SceneError(InputError, ForwardSceneError):
    """A scene value is invalid (catchable as `forward.errors.SceneError` too)."""


class DataError(InputError):
    """A measured series (or its file) is invalid or cannot be read."""


class Unsupported(InputError):
    """A method does not cover this model or these free parameters; the message says which value."""


class NumericalError(VibinverseError, RuntimeError):
    """A computation failed on valid input (an optimizer found no finite optimum, ...)."""


class Interrupted(VibinverseError):
    """SIGINT/SIGTERM stopped a run (a sampler after a complete step: its checkpoint is intact)."""

    def __init__(self, message: str, signum: int = 2):
        super().__init__(message)
        self.signum = signum


@contextlib.contextmanager
def scene_errors() -> Iterator[None]:
    """Re-raise `forward`'s scene errors as `vibinverse.errors.SceneError` (the public API's boundary)."""
    try:
        yield
    except ForwardSceneError as exc:
        if isinstance(exc, VibinverseError):
            raise
        raise SceneError(str(exc)) from None
