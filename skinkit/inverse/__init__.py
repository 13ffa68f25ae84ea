"""Identification: a forward model's parameters from a session (thesis 6.3, 7.6).

:func:`fit` minimises the weighted residual (:mod:`skinkit.inverse.objective`) with the
model's analytic Jacobian, in scaled coordinates (:mod:`skinkit.inverse.scaling`), and reports
what the data determine (:mod:`skinkit.inverse.identifiability`). Around it:
:func:`objective_grid` and :func:`profile_likelihood` (:mod:`skinkit.inverse.grid`),
:func:`select` (AIC and held-out error over parameter subsets, :mod:`skinkit.inverse.selection`),
:func:`rank_protocols` (D-optimal design, :mod:`skinkit.inverse.design`) and :func:`coverage`
(:mod:`skinkit.inverse.coverage`). Plots: :mod:`skinkit.inverse.plots`.
"""

from skinkit.inverse.coverage import coverage
from skinkit.inverse.design import rank_protocols
from skinkit.inverse.fit import FitError, aic, fit, fit_json, free_set, with_bounds
from skinkit.inverse.grid import objective_grid, profile_likelihood
from skinkit.inverse.objective import WEIGHTINGS, Objective, held_out_rms
from skinkit.inverse.selection import select

__all__ = ["WEIGHTINGS", "FitError", "Objective", "aic", "coverage", "fit", "fit_json", "free_set",
           "held_out_rms", "objective_grid", "profile_likelihood", "rank_protocols", "select", "with_bounds"]
