"""Identification: a forward model's parameters from a session (thesis 6.3, 7.6).

:func:`fit` minimises the weighted residual (:mod:`skinkit.inverse.objective`) with the
model's analytic Jacobian, in scaled coordinates (:mod:`skinkit.inverse.scaling`), and reports
what the data determine (:mod:`skinkit.inverse.identifiability`).
"""

from skinkit.inverse.fit import FitError, aic, fit, fit_json, free_set
from skinkit.inverse.objective import WEIGHTINGS, Objective, held_out_rms

__all__ = ["WEIGHTINGS", "FitError", "Objective", "aic", "fit", "fit_json", "free_set", "held_out_rms"]
