"""What the engines offer effect authors, gathered in one place for :mod:`skinkit.plugin.effects`.

Effect plugins import :mod:`skinkit.plugin.effects` (the declared, stable API: ``BaseEffect``,
``declare``, ``model_kind``, ``quantity``), not this module; it stays for code that imported
it before that package existed, and may change.

- :func:`quantity` a scalar in SI from a model-file value, a number (already SI) or a
  ``"<number> <unit>"`` string, refusing anything else with a
  :class:`skinkit.fem.errors.ModelError` naming the entry.
"""

from __future__ import annotations

from skinkit.fem.model import quantity

__all__ = ["quantity"]
