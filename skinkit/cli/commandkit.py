"""The former home of the command authors' kit, kept so that distributions written against it
still import: new code imports :mod:`skinkit.plugin.commands` (the declared plugin surface)."""

from __future__ import annotations

from skinkit.plugin.commands import FiniteFloat

__all__ = ["FiniteFloat"]
