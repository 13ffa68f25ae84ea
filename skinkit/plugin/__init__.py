"""The declared package for plugin authors: one module per kind of plugin, each the stable API
for that kind, and a conformance kit per kind.

- laws (``skinkit.laws``): :mod:`skinkit.plugin.laws`, kit :mod:`.conformance.laws`;
- trackers (``skinkit.trackers``): :mod:`skinkit.plugin.trackers`, kit :mod:`.conformance.trackers`;
- profilers (``skinkit.profilers``): :mod:`skinkit.plugin.profilers`, kit
  :mod:`.conformance.profilers`;
- optimisers (``skinkit.optimisers``): :mod:`skinkit.plugin.optimisers`, kit
  :mod:`.conformance.optimisers`;
- effects (``skinkit.effects``): :mod:`skinkit.plugin.effects`, kit :mod:`.conformance.effects`;
- drivers (``skinkit.drivers``): :mod:`skinkit.plugin.drivers`, kit :mod:`.conformance.drivers`;
- commands (``skinkit.commands``, ``skinkit.commands.<group>``): :mod:`skinkit.plugin.commands`
  (it imports ``click``, so it ranks with the command line).

A plugin imports these modules and the contract (:mod:`skinkit.errors`, :mod:`skinkit.units`,
:mod:`skinkit.schemas`, :mod:`skinkit.registry`, :mod:`skinkit.interfaces`) and nothing else
of skinkit: what each module's ``__all__`` names is kept stable, everything else is engine
internals. This package imports none of its modules, so importing it costs nothing.
"""

from __future__ import annotations

#: entry-point group -> the module of its stable API
KITS: dict[str, str] = {
    "skinkit.laws": "skinkit.plugin.laws",
    "skinkit.trackers": "skinkit.plugin.trackers",
    "skinkit.profilers": "skinkit.plugin.profilers",
    "skinkit.optimisers": "skinkit.plugin.optimisers",
    "skinkit.effects": "skinkit.plugin.effects",
    "skinkit.drivers": "skinkit.plugin.drivers",
    "skinkit.commands": "skinkit.plugin.commands",
}

#: entry-point group -> the module of its conformance kit (commands have none)
CONFORMANCE: dict[str, str] = {
    "skinkit.laws": "skinkit.plugin.conformance.laws",
    "skinkit.trackers": "skinkit.plugin.conformance.trackers",
    "skinkit.profilers": "skinkit.plugin.conformance.profilers",
    "skinkit.optimisers": "skinkit.plugin.conformance.optimisers",
    "skinkit.effects": "skinkit.plugin.conformance.effects",
    "skinkit.drivers": "skinkit.plugin.conformance.drivers",
}

__all__ = ["CONFORMANCE", "KITS"]
