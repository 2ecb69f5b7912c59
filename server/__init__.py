"""The pendant service: REST menus over the emulated controllers, the DB and the solvers."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("pendant")  # pyproject.toml's [project] version, as installed
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
