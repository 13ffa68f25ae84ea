"""Stochastic system identification of skin (thesis chapter 4).

A stochastic force drives the probe; the force-to-position dynamics are identified as an
impulse response (:func:`estimate_irf`), a mass-spring-damper (:func:`identify_linear`:
K, B, I), a Wiener model (:func:`identify_wiener`: Is, Bs, C1, C2) or, for comparison, a
Hammerstein model. Results carry the VAF, confidence bounds and every warning raised on the
input (:mod:`skinkit.sysid.checks`); :mod:`skinkit.sysid.diagnostics` examines residuals.

Example::

    from skinkit.sysid import identify_wiener
    model = identify_wiener(record)          # a RobotRecord, normal axis
    model.to_dict()["C1_m"], model.vaf_wiener_pct
"""

from skinkit.sysid.checks import (
    ClippedForceWarning,
    ClippedPositionWarning,
    GapWarning,
    NaNWarning,
    NarrowbandInputWarning,
    NonCausalWarning,
    NonUniformSamplingWarning,
    PoorFitWarning,
    ShortRecordWarning,
    Signals,
    SysidError,
    SysidWarning,
    check_signals,
)
from skinkit.sysid.hammerstein import HammersteinModel, identify_hammerstein
from skinkit.sysid.irf import IRF, estimate_irf, estimate_irf_lstsq
from skinkit.sysid.linear import LinearModel, identify_linear
from skinkit.sysid.lti import SecondOrder
from skinkit.sysid.metrics import vaf
from skinkit.sysid.nonlinearity import StaticNonlinearity
from skinkit.sysid.record import record_signals
from skinkit.sysid.robot import RobotDynamics, calibrate_mass, calibrate_position, calibrate_springs
from skinkit.sysid.wiener import WienerModel, identify_wiener

__all__ = [
    "IRF",
    "ClippedForceWarning",
    "ClippedPositionWarning",
    "GapWarning",
    "HammersteinModel",
    "LinearModel",
    "NaNWarning",
    "NarrowbandInputWarning",
    "NonCausalWarning",
    "NonUniformSamplingWarning",
    "PoorFitWarning",
    "RobotDynamics",
    "SecondOrder",
    "ShortRecordWarning",
    "Signals",
    "StaticNonlinearity",
    "SysidError",
    "SysidWarning",
    "WienerModel",
    "calibrate_mass",
    "calibrate_position",
    "calibrate_springs",
    "check_signals",
    "estimate_irf",
    "estimate_irf_lstsq",
    "identify_hammerstein",
    "identify_linear",
    "identify_wiener",
    "record_signals",
    "vaf",
]
