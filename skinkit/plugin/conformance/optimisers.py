"""The conformance kit for optimisers (``skinkit.optimisers``): the stable API an optimiser
author checks an optimiser with.

:func:`check_optimiser` ``(optimiser)`` -> :class:`~skinkit.plugin.conformance.report.Report`:

- ``interface``: the members of :class:`skinkit.interfaces.Optimiser` and a name;
- ``least squares``: ``y = a (1 - exp(-b t))`` sampled without noise from ``(8.6, 0.51)``,
  started at ``(5, 1)`` within ``[0, 20] x [0, 5]``: ``x`` within 1e-4 (relative) of the
  answer, ``success``, ``fun`` below 1e-8 and ``nfev > 0``;
- ``active bound``: ``r(x) = x - 3`` within ``[0, 2]`` ends on the bound (1e-6);

both with the exact Jacobian (``jac``), which a gradient-based optimiser needs and a
derivative-free one may ignore;
- ``start unchanged``: ``minimise`` does not write into ``x0``, ``lower`` or ``upper``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit import registry
from skinkit.interfaces import Optimiser, missing_members
from skinkit.plugin.conformance.report import Report


def check_optimiser(optimiser: Any) -> Report:
    """Check ``optimiser`` (a plugin object or the name of an installed one); see the module."""
    opt = registry.create("skinkit.optimisers", optimiser) if isinstance(optimiser, str) else optimiser
    if isinstance(opt, type):
        opt = opt()
    report = Report("optimiser", str(getattr(opt, "name", "?")))
    missing = missing_members(opt, Optimiser)
    if not report.add("interface", not missing, f"missing {', '.join(missing)}" if missing else ""):
        return report
    t = np.linspace(0, 10, 50)
    y = 8.6 * (1 - np.exp(-0.51 * t))
    x0, lo, hi = np.array([5.0, 1.0]), np.array([0.0, 0.0]), np.array([20.0, 5.0])
    given = (x0.copy(), lo.copy(), hi.copy())
    try:
        def jac(x: np.ndarray) -> np.ndarray:
            e = np.exp(-x[1] * t)
            return np.column_stack([1 - e, x[0] * t * e])

        res = opt.minimise(lambda x: x[0] * (1 - np.exp(-x[1] * t)) - y, x0, lo, hi, jac=jac)
        x = np.asarray(res.x, dtype=float)
        ok = (bool(res.success) and np.allclose(x, [8.6, 0.51], rtol=1e-4) and float(res.fun) < 1e-8
              and int(res.nfev) > 0)
        report.add("least squares", ok, f"x {x.tolist()}, fun {float(res.fun):.1e}, nfev {res.nfev}, "
                   f"success {res.success}: {res.message}")
    except Exception as exc:  # a third-party optimiser may raise anything
        report.add("least squares", False, f"{type(exc).__name__}: {exc}")
    same = all(np.array_equal(a, b) for a, b in zip((x0, lo, hi), given, strict=True))
    report.add("start unchanged", same, "" if same else "minimise wrote into x0, lower or upper")
    try:
        res = opt.minimise(lambda x: np.array([x[0] - 3.0]), np.array([0.5]), np.array([0.0]),
                           np.array([2.0]), jac=lambda x: np.ones((1, 1)))
        xb = float(np.asarray(res.x, dtype=float)[0])
        report.add("active bound", abs(xb - 2.0) <= 1e-6, f"x {xb} (the bound is 2)")
    except Exception as exc:  # a third-party optimiser may raise anything
        report.add("active bound", False, f"{type(exc).__name__}: {exc}")
    return report


__all__ = ["check_optimiser"]
