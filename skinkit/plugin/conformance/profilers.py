"""The conformance kit for surface profilers (``skinkit.profilers``): the stable API a profiler
author checks a profiler's declarations with (profiling itself needs calibrated views of a
speckled surface, which the author's own tests hold).

:func:`check_profiler` ``(profiler)`` -> :class:`~skinkit.plugin.conformance.report.Report`:

- ``interface``: the members of :class:`skinkit.interfaces.Profiler` and a name;
- ``options``: when declared, a mapping keyword -> a non-empty one-line description, every
  keyword one the profiler's constructor accepts (``skinkit vision profile`` passes them).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

from skinkit import registry
from skinkit.interfaces import Profiler, missing_members
from skinkit.plugin.conformance.report import Report


def _constructor_keywords(cls: type) -> set[str] | None:
    """Keyword names of ``cls``'s constructor; None when it takes ``**kwargs`` (anything goes)."""
    try:
        params = inspect.signature(cls).parameters.values()
    except (TypeError, ValueError):
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return {p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def check_profiler(profiler: Any) -> Report:
    """Check ``profiler`` (the registered object or the name of an installed one); see the module."""
    obj = registry.load("skinkit.profilers", profiler) if isinstance(profiler, str) else profiler
    report = Report("profiler", str(getattr(obj, "name", "?")))
    missing = missing_members(obj, Profiler)
    if not report.add("interface", not missing, f"missing {', '.join(missing)}" if missing else ""):
        return report
    options = getattr(obj, "options", None)
    if options is None:
        report.add("options", True, "none declared")
        return report
    problems = []
    if not isinstance(options, Mapping):
        problems.append(f"options must be a mapping keyword -> description, got {type(options).__name__}")
    else:
        problems += [f"{k}: no description" for k, v in options.items()
                     if not (isinstance(v, str) and v.strip())]
        cls = obj if isinstance(obj, type) else type(obj)
        accepted = _constructor_keywords(cls)
        if accepted is not None:
            problems += [f"{k}: not a keyword of the constructor" for k in options if k not in accepted]
    report.add("options", not problems, "; ".join(problems))
    return report


__all__ = ["check_profiler"]
