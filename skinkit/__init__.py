"""skinkit: measurements of living skin to mechanical models, and how far they are from reality.

The public API is what this package and its documented submodules export:

- :func:`skinkit.fit`       fit a model's parameters to a session in one call
- :func:`skinkit.diagnose`  diagnose a model's sim-to-real gap on a session in one call
- :mod:`skinkit.schemas`   typed, validated records in SI units
- :mod:`skinkit.interfaces` the interfaces plugins implement
- :mod:`skinkit.registry`  discovery and lazy loading of plugins by entry point
- :mod:`skinkit.store`     the HDF5 experiment file
- :mod:`skinkit.units`     unit conversion at the edges (mm, kPa, ...)
"""

from typing import Any

from skinkit.errors import SchemaError, SkinkitError, StoreError

__version__ = "0.1.0"

#: names defined in :mod:`skinkit.api`, imported on first use: that module loads the engines
#: (numpy, scipy, the forward models), which ``import skinkit`` alone does not
_LAZY = ("diagnose", "fit")

__all__ = ["SchemaError", "SkinkitError", "StoreError", "__version__", "diagnose", "fit"]


def __getattr__(name: str) -> Any:
    """``skinkit.fit`` and ``skinkit.diagnose``, from :mod:`skinkit.api` on first use."""
    if name in _LAZY:
        from skinkit import api

        value = getattr(api, name)
        globals()[name] = value     # later look-ups find it without this hook
        return value
    raise AttributeError(f"module 'skinkit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
