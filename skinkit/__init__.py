"""skinkit: measurements of living skin to mechanical models, and how far they are from reality.

The public API is what this package and its documented submodules export:

- :mod:`skinkit.schemas`   typed, validated records in SI units
- :mod:`skinkit.interfaces` the interfaces plugins implement
- :mod:`skinkit.registry`  discovery and lazy loading of plugins by entry point
- :mod:`skinkit.store`     the HDF5 experiment file
- :mod:`skinkit.units`     unit conversion at the edges (mm, kPa, ...)
"""

from skinkit.errors import SchemaError, SkinkitError, StoreError

__version__ = "0.1.0"

__all__ = ["SchemaError", "SkinkitError", "StoreError", "__version__"]
