"""The package version, from the installed distribution's metadata (one source: pyproject)."""

from importlib.metadata import PackageNotFoundError, version

try:
    #: The installed distribution's version (``pyproject.toml``'s ``version``).
    __version__ = version("bwdesign")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"
