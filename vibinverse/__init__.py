"""vibinverse: measured pixel intensity series -> vibration parameters (and the CLI)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("vibinverse")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.0.0+source"
