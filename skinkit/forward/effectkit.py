"""The stable API for authors of candidate effects (``skinkit.effects``).

Everything in ``__all__`` is public and kept stable; the engine modules it re-exports from
may change. An effect edits a model description (the mapping a model file parses to) with the
vocabulary the forward models already read (``docs/effects.md``); what it needs from skinkit
beyond the core (:mod:`skinkit.errors` for :class:`~skinkit.errors.EffectError`,
:mod:`skinkit.schemas` for :class:`~skinkit.schemas.Parameter`, :mod:`skinkit.units`) is:

- :func:`quantity` a scalar in SI from a model-file value, a number (already SI) or a
  ``"<number> <unit>"`` string (``quantity("1.5 mm", "m", "layers[0].thickness")`` ->
  ``0.0015``), refusing anything else with an error naming the entry.
"""

from __future__ import annotations

from skinkit.fem.model import quantity

__all__ = ["quantity"]
