"""Conformance kits: one module per plugin kind, each the stable API its plugin authors (and
skinkit's own tests) check a plugin with.

- :mod:`.laws` ``check_law(law)``: stress, tangent, objectivity, reference state, positive
  moduli and tension over the admissible parameters;
- :mod:`.effects` ``check_effect(effect)``: declarations, the copy, the null, the refusal of
  other model kinds, and the sensitivity of predictions, on small built-in models;
- :mod:`.optimisers` ``check_optimiser(optimiser)``: bound-constrained least squares with known
  answers;
- :mod:`.trackers` ``check_tracker(tracker)``: known sub-pixel shifts of a synthetic speckle;
- :mod:`.profilers` ``check_profiler(profiler)``: what the profiler declares;
- :mod:`.drivers` ``check_driver(driver)``: members and declarations, without moving a robot.

Every kit returns a :class:`~skinkit.plugin.conformance.report.Report` (``passed``, ``str()``
one line per check, ``to_dict()``). Nothing is imported here, so importing this package costs
nothing.
"""

from __future__ import annotations

__all__: list[str] = []
