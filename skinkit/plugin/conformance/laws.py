"""The conformance kit for constitutive laws (``skinkit.laws``): the stable API a law author
checks a law with.

- :func:`check_law` ``(law, p=None, n=12, seed=0)`` -> :class:`ConformanceReport`: the law's
  stress against differences of its energy, its tangent against differences of its stress
  (with minor and major symmetries), objectivity, zero stress at ``C = I``, positive initial
  moduli and tension answered with tension — at ``p`` (default: the declared values) and
  over parameter sets spread across the declared bounds that the law's own ``inadmissible``
  accepts (:func:`check_ranges`, :func:`parameter_sets`);
- :func:`initial_moduli` small-strain bulk and shear moduli [Pa] from the tangent at ``C = I``;
- :func:`sample_deformations` the seeded deformation gradients ``(n, 3, 3)`` the checks use;
- :class:`CheckResult` one check (name, passed, worst relative error, tolerance, detail).

Implemented by :mod:`skinkit.fem.conformance` (an engine module that may change).
"""

from __future__ import annotations

from skinkit.fem.conformance import (
    DERIVATIVE_RTOL,
    CheckResult,
    ConformanceReport,
    check_law,
    check_ranges,
    initial_moduli,
    parameter_sets,
    sample_deformations,
)

__all__ = [
    "DERIVATIVE_RTOL",
    "CheckResult",
    "ConformanceReport",
    "check_law",
    "check_ranges",
    "initial_moduli",
    "parameter_sets",
    "sample_deformations",
]
