"""Results: a parameter fit, and a sim-to-real gap report."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas._fields import as_array, as_float
from skinkit.schemas.parameters import ParameterSet


@dataclass
class FitResult:
    """The outcome of identifying a model's parameters.

    Attributes:
        model: model name (law, lumped model, ...).
        parameters: the identified set (fixed ones included).
        objective: final objective value [objective's own unit, e.g. m² for squared residuals].
        n_evaluations: number of model evaluations.
        converged: whether the optimiser met its convergence criterion.
        message: the optimiser's closing message.
        residual_rms_m: RMS of the position residuals [m], if position data were fitted.
        covariance: ``(n_free, n_free)`` covariance of the free parameters [SI²], or None.
        aic: Akaike information criterion (Eq 7.14), or None.
        aicc: its small-sample correction, or None.
        se: standard error per free parameter [SI], inflated by χ²/ν when the fit is worse than
            the noise explains.
        correlation: ``(n_free, n_free)`` correlation matrix, or None.
        identifiability: the metrics of Eqs 7.15-7.18, weak directions and problems in words.
        chi2_per_dof: Σz²/(m - n) of the weighted residual.
        residual_by_protocol, residual_by_channel: Σz² per protocol and per channel.
        held_out: RMS weighted residual per held-out protocol.
        n_forward, n_sensitivity: forward predictions solved during the fit, and how many of them
            carried sensitivities (replayed evaluations of a resumed fit are not counted).
        wall_s: wall time of the fit [s].
        starts: every start of a multi-start fit: its start values, result and objective.
        extra: further JSON-ready numbers (VAF, history, ...).
    """

    model: str
    parameters: ParameterSet
    objective: float
    n_evaluations: int = 0
    converged: bool = True
    message: str = ""
    residual_rms_m: float | None = None
    covariance: Any = None
    aic: float | None = None
    aicc: float | None = None
    se: dict[str, float] = field(default_factory=dict)
    correlation: Any = None
    identifiability: dict[str, Any] = field(default_factory=dict)
    chi2_per_dof: float | None = None
    residual_by_protocol: dict[str, float] = field(default_factory=dict)
    residual_by_channel: dict[str, float] = field(default_factory=dict)
    held_out: dict[str, float] = field(default_factory=dict)
    n_forward: int = 0
    n_sensitivity: int = 0
    wall_s: float = 0.0
    starts: list[dict[str, Any]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.parameters, ParameterSet):
            raise SchemaError("FitResult.parameters", "must be a ParameterSet")
        self.objective = as_float(self.objective, "FitResult.objective", "1", allow_nan=True)
        if int(self.n_evaluations) < 0:
            raise SchemaError("FitResult.n_evaluations", "must be >= 0")
        self.n_evaluations = int(self.n_evaluations)
        if self.residual_rms_m is not None:
            self.residual_rms_m = as_float(self.residual_rms_m, "FitResult.residual_rms_m", "m", lo=0)
        if self.covariance is not None:
            n = len(self.parameters.free_names)
            self.covariance = as_array(self.covariance, "FitResult.covariance", (n, n), "1", {})
        if self.correlation is not None:
            n = len(self.parameters.free_names)
            self.correlation = as_array(self.correlation, "FitResult.correlation", (n, n), "1", {})

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "parameters": self.parameters.to_list(),
            "objective": self.objective,
            "n_evaluations": self.n_evaluations,
            "converged": self.converged,
            "message": self.message,
            "residual_rms_m": self.residual_rms_m,
            "covariance": None if self.covariance is None else np.asarray(self.covariance).tolist(),
            "aic": self.aic,
            "aicc": self.aicc,
            "se": self.se,
            "correlation": None if self.correlation is None else np.asarray(self.correlation).tolist(),
            "identifiability": self.identifiability,
            "chi2_per_dof": self.chi2_per_dof,
            "residual_by_protocol": self.residual_by_protocol,
            "residual_by_channel": self.residual_by_channel,
            "held_out": self.held_out,
            "n_forward": self.n_forward,
            "n_sensitivity": self.n_sensitivity,
            "wall_s": self.wall_s,
            "starts": self.starts,
            "extra": self.extra,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FitResult:
        d = dict(d)
        d["parameters"] = ParameterSet.from_list(d["parameters"])
        return cls(**d)


@dataclass(frozen=True)
class EffectScore:
    """How much of the gap one candidate effect closes.

    ``gap_before_m`` and ``gap_after_m`` are residual RMS [m] on held-out data before and after
    adding the effect and refitting; ``reduction`` = 1 - after/before.
    """

    effect: str
    gap_before_m: float
    gap_after_m: float
    parameters: ParameterSet | None = None

    def __post_init__(self) -> None:
        for key in ("gap_before_m", "gap_after_m"):
            as_float(getattr(self, key), f"EffectScore[{self.effect!r}].{key}", "m", lo=0)

    @property
    def reduction(self) -> float:
        return 1.0 - self.gap_after_m / self.gap_before_m if self.gap_before_m > 0 else 0.0


@dataclass
class GapReport:
    """Where the calibrated model misses the data, which effect explains it, by how much.

    Attributes:
        model: the calibrated model's name.
        gap_rms_m: residual RMS of the calibrated model on held-out data [m].
        residual_by_point_m: ``(P,)`` RMS residual per tracked point [m], or None.
        candidates: scores of the candidate effects, best first.
        withheld_effect: in a virtual-lab check, the effect withheld from the model, else None.
    """

    model: str
    gap_rms_m: float
    residual_by_point_m: Any = None
    candidates: list[EffectScore] = field(default_factory=list)
    withheld_effect: str | None = None

    def __post_init__(self) -> None:
        self.gap_rms_m = as_float(self.gap_rms_m, "GapReport.gap_rms_m", "m", lo=0)
        if self.residual_by_point_m is not None:
            self.residual_by_point_m = as_array(self.residual_by_point_m, "GapReport.residual_by_point_m",
                                                ("P",), "m", {})
        self.candidates = sorted(self.candidates, key=lambda c: -c.reduction)

    @property
    def best(self) -> EffectScore | None:
        return self.candidates[0] if self.candidates else None

    def to_dict(self) -> dict[str, Any]:
        def nan_to_none(x: float) -> float | None:
            return None if isinstance(x, float) and math.isnan(x) else x
        return {
            "model": self.model,
            "gap_rms_m": self.gap_rms_m,
            "residual_by_point_m": None if self.residual_by_point_m is None
            else [nan_to_none(float(v)) for v in self.residual_by_point_m],
            "candidates": [{"effect": c.effect, "gap_before_m": c.gap_before_m,
                            "gap_after_m": c.gap_after_m, "reduction": c.reduction,
                            "parameters": None if c.parameters is None else c.parameters.to_list()}
                           for c in self.candidates],
            "withheld_effect": self.withheld_effect,
        }
