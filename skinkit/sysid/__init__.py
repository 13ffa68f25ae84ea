"""Stochastic system identification of skin (thesis chapter 4).

A stochastic force drives the probe; the force-to-position dynamics are identified as an
impulse response (:func:`estimate_irf`), a mass-spring-damper (:func:`identify_linear`:
K, B, I), a Wiener model (:func:`identify_wiener`: Is, Bs, C1, C2) or, for comparison, a
Hammerstein model. Results carry the VAF, confidence bounds and every warning raised on the
input (:mod:`skinkit.sysid.checks`); :mod:`skinkit.sysid.diagnostics` examines residuals.
Also: input design (:mod:`~skinkit.sysid.inputs`), robot calibration and removal
(:mod:`~skinkit.sysid.robot`), incremental protocols (:mod:`~skinkit.sysid.incremental`),
cohort CVs (:mod:`~skinkit.sysid.cohort`), figures (:mod:`~skinkit.sysid.plots`).

Example::

    from skinkit.sysid import identify_wiener
    model = identify_wiener(record)          # a RobotRecord, normal axis
    model.to_dict()["C1_m"], model.vaf_wiener_pct
"""

from skinkit.sysid.checks import (
    ClippedForceWarning,
    ClippedPositionWarning,
    GapWarning,
    MemoryWarning,
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
from skinkit.sysid.cohort import cv_table
from skinkit.sysid.diagnostics import ResidualDiagnostics, compare, diagnose, residual_diagnostics
from skinkit.sysid.hammerstein import HammersteinModel, identify_hammerstein
from skinkit.sysid.incremental import (
    IncrementalResult,
    detect_segments,
    identify_incremental,
    youngs_modulus,
)
from skinkit.sysid.inputs import Programme, Segment, gaussian_force, incremental, preconditioning
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
    "IncrementalResult",
    "Programme",
    "ResidualDiagnostics",
    "Segment",
    "compare",
    "cv_table",
    "detect_segments",
    "diagnose",
    "gaussian_force",
    "identify_incremental",
    "incremental",
    "preconditioning",
    "residual_diagnostics",
    "youngs_modulus",
    "ClippedForceWarning",
    "ClippedPositionWarning",
    "GapWarning",
    "HammersteinModel",
    "LinearModel",
    "MemoryWarning",
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
