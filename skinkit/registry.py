"""Plugin discovery over entry points, lazy loading, and a load report.

Listing reads only distribution metadata; a plugin's module is imported the first time it
is loaded. A plugin that fails to import, or does not provide the members of its group's
interface, is reported with its error and never stops the others from loading.
"""

from __future__ import annotations

import sys
import traceback
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from skinkit.errors import PluginError

#: the plugin groups, in the order of :data:`skinkit.interfaces.GROUPS` (which maps each to
#: its interface); named here so that listing plugins imports neither the interfaces nor numpy
GROUP_NAMES: tuple[str, ...] = ("skinkit.drivers", "skinkit.trackers", "skinkit.profilers",
                                "skinkit.laws", "skinkit.optimisers", "skinkit.effects")


@dataclass(frozen=True)
class PluginInfo:
    """One entry point: its group, name, target (``module:attr``) and distribution."""

    group: str
    name: str
    value: str
    dist: str | None


@dataclass(frozen=True)
class PluginStatus:
    """The outcome of loading one plugin: ``status`` is ``"ok"`` or ``"error"``."""

    info: PluginInfo
    status: str
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The status as a plain dict (name, distribution, target, status, error)."""
        return {"name": self.info.name, "dist": self.info.dist, "value": self.info.value,
                "status": self.status, "error": self.error}


#: status of a plugin listed from its metadata and not imported
UNCHECKED = "unchecked"


def _known(group: str) -> None:
    if group not in GROUP_NAMES:
        raise PluginError(f"unknown plugin group {group!r}; groups are {sorted(GROUP_NAMES)}")


#: entry points per (group, sys.path): a diagnosis asks for its effects' names thousands of
#: times, and each scan of the installed distributions' metadata takes milliseconds; a
#: distribution added on a new path entry is seen, one installed into a path already scanned
#: after :func:`clear_cache`
_groups: dict[tuple[str, tuple[str, ...]], list[EntryPoint]] = {}


def _group(group: str) -> list[EntryPoint]:
    _known(group)
    key = (group, tuple(sys.path))
    if key not in _groups:
        _groups[key] = sorted(entry_points(group=group), key=lambda ep: ep.name)
    return list(_groups[key])


def _info(group: str, ep: EntryPoint) -> PluginInfo:
    dist = getattr(ep, "dist", None)
    return PluginInfo(group, ep.name, ep.value, dist.name if dist is not None else None)


def available(group: str) -> list[PluginInfo]:
    """Plugins registered under ``group``, without importing them."""
    return [_info(group, ep) for ep in _group(group)]


def listing(groups: list[str] | None = None) -> dict[str, list[PluginInfo]]:
    """Every plugin of ``groups`` (all by default) from entry-point metadata alone: names,
    targets and distributions, no plugin module imported (one scan of the installed
    distributions for all groups, so that listing stays fast)."""
    wanted = groups or list(GROUP_NAMES)
    for group in wanted:
        _known(group)
    eps = entry_points()
    return {g: [_info(g, ep) for ep in sorted(eps.select(group=g), key=lambda ep: ep.name)]
            for g in wanted}


def names(group: str) -> list[str]:
    """Names of the plugins registered under ``group``."""
    return [ep.name for ep in _group(group)]


_cache: dict[tuple[str, str], Any] = {}


def load(group: str, name: str) -> Any:
    """Import and return the object registered as ``name`` in ``group``, interface-checked.

    Raises :class:`PluginError` naming the plugin when it is unknown, fails to import, or
    lacks members of its interface.
    """
    key = (group, name)
    if key in _cache:
        return _cache[key]
    matches = [ep for ep in _group(group) if ep.name == name]
    if not matches:
        raise PluginError(f"no plugin {name!r} in {group}; available: {names(group) or 'none'}")
    if len(matches) > 1:
        dists = [_info(group, ep).dist for ep in matches]
        raise PluginError(f"plugin {name!r} in {group} is registered by several distributions: {dists}")
    ep = matches[0]
    info = _info(group, ep)
    try:
        obj = ep.load()
    except Exception as exc:  # a third-party import may raise anything
        raise PluginError(
            f"plugin {name!r} in {group} (from {info.dist}, {info.value}) failed to import: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    from skinkit.interfaces import GROUPS, missing_members

    missing = missing_members(obj, GROUPS[group])
    if missing:
        raise PluginError(
            f"plugin {name!r} in {group} (from {info.dist}, {info.value}) does not satisfy the "
            f"{GROUPS[group].__name__} interface: missing {', '.join(missing)}"
        )
    _cache[key] = obj
    return obj


def create(group: str, name: str, *args: Any, **kwargs: Any) -> Any:
    """Load ``name`` from ``group`` and, if it is a class, instantiate it with the arguments."""
    obj = load(group, name)
    return obj(*args, **kwargs) if isinstance(obj, type) else obj


def report(groups: list[str] | None = None) -> dict[str, list[PluginStatus]]:
    """Load every plugin of ``groups`` (all by default) and report each one's status."""
    out: dict[str, list[PluginStatus]] = {}
    for group in groups or list(GROUP_NAMES):
        statuses = []
        for ep in _group(group):
            info = _info(group, ep)
            try:
                load(group, ep.name)
            except PluginError as exc:
                cause = exc.__cause__
                detail = str(exc)
                if cause is not None and getattr(cause, "__traceback__", None) is not None:
                    # The last frame locates the failing line in the plugin for its author.
                    frame = traceback.extract_tb(cause.__traceback__)[-1]
                    detail += f" [at {frame.filename}:{frame.lineno}]"
                statuses.append(PluginStatus(info, "error", detail))
            else:
                statuses.append(PluginStatus(info, "ok"))
        out[group] = statuses
    return out


def clear_cache() -> None:
    """Forget loaded plugins and the entry points read (tests, or after installing a
    distribution at run time)."""
    _cache.clear()
    _groups.clear()
