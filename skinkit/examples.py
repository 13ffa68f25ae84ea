"""The example and preset model files that ship inside the package.

They are package data (read through :mod:`importlib.resources`), so an installed skinkit finds
them wherever it runs; in a source checkout ``docs/models/`` links to the same files.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from skinkit.errors import SkinkitError

_PACKAGE_DIR = ("data", "models")


def _folder() -> Path:
    root = resources.files("skinkit").joinpath(*_PACKAGE_DIR)
    # skinkit is installed as plain files (never zipped: the engines read model files by path)
    return Path(str(root))


def example_models() -> list[str]:
    """Names (file stems, e.g. ``"invivo_quick"``) of the model files shipped with skinkit."""
    return sorted(p.stem for p in _folder().glob("*.toml"))


def example_model(name: str) -> Path:
    """Path of the shipped model file ``name`` (a stem such as ``"invivo_quick"``, with or
    without ``.toml``); :class:`SkinkitError` listing the shipped names when there is none."""
    stem = name[:-5] if name.endswith(".toml") else name
    path = _folder() / f"{stem}.toml"
    if not path.is_file():
        raise SkinkitError(f"no shipped model file {name!r}; shipped: {', '.join(example_models())}")
    return path
