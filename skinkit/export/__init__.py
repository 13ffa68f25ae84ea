"""Exports of skinkit models to other solvers' input formats.

:mod:`skinkit.export.febio` writes a finite-element model file (and, optionally, the recorded
drive of a session) as an FEBio model (``.feb``, FEBio spec 4.0). An engine: it reads model
files through :mod:`skinkit.fem` and sessions through :mod:`skinkit.forward`, and never
imports the command line or the applications.
"""

from __future__ import annotations

__all__: list[str] = []
