"""The stable API for distributions that add commands to the ``skinkit`` command line
(entry-point groups ``skinkit.commands`` and ``skinkit.commands.<group>``, each pointing at a
``click`` command).

Everything in ``__all__`` is public and kept stable. A command refuses bad input by raising a
:class:`skinkit.errors.SkinkitError` (the command line prints its one line, no traceback) and
takes its numeric options with the ranges the command line promises:

- :class:`FiniteFloat` a :class:`click.FloatRange` that also refuses NaN and infinities.

This module imports ``click``: it ranks with the command line, and only command plugins use it.
"""

from __future__ import annotations

from skinkit.cli._types import FiniteFloat

__all__ = ["FiniteFloat"]
