"""Exception types. Every message names what is wrong and where, in one line."""

from __future__ import annotations


class SkinkitError(Exception):
    """Base class of every error skinkit raises on purpose (bad input, bad file, bad device)."""


class SchemaError(SkinkitError, ValueError):
    """A record was built with a field of the wrong shape, unit, type or value.

    ``field`` names the offending field (``"RobotRecord.tip_force"``).
    """

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class UnitError(SchemaError):
    """A quantity was given in a unit that is not convertible to the field's SI unit."""


class StoreError(SkinkitError):
    """An experiment file is missing, truncated, of the wrong version or malformed.

    ``path`` is the file, ``where`` the HDF5 object or CSV line concerned.
    """

    def __init__(self, path: str, where: str, problem: str) -> None:
        self.path = path
        self.where = where
        self.problem = problem
        loc = f"{path}:{where}" if where else str(path)
        super().__init__(f"{loc}: {problem}")


class RefusedError(SkinkitError):
    """A request refused before anything was done (no motion, nothing written): a programme
    over a safety limit, an option a plugin does not take. Nothing is recorded of it."""


class OptionError(RefusedError, ValueError):
    """A plugin (e.g. a robot driver) refused an option: an unknown name or a bad value."""


class PluginError(SkinkitError):
    """A plugin could not be found, imported, or does not satisfy its interface."""


class EffectError(SkinkitError):
    """An effect that does not exist, does not fit a model, or has a parameter out of range.

    ``entry`` names the model-file entry or effect concerned (``"effects[1].l1"``).
    """

    def __init__(self, entry: str, problem: str) -> None:
        self.entry = entry
        self.problem = problem
        super().__init__(f"{entry}: {problem}")


class ForwardError(SkinkitError):
    """A forward model cannot predict a session: a missing channel, a profile that does
    not cover the mesh, a protocol it cannot be driven by. ``entry`` names what is wrong."""

    def __init__(self, entry: str, problem: str) -> None:
        self.entry = entry
        self.problem = problem
        super().__init__(f"{entry}: {problem}")
