"""Results: a parameter fit, and a sim-to-real gap report."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas import display, display_gap
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

    def __repr__(self) -> str:
        """A few lines: the model, convergence, each free parameter's value ± se [unit], the
        objective and the counts (never the arrays; :meth:`to_dict` has everything)."""
        return "\n".join(display.fit_lines(self))

    def _repr_html_(self) -> str:
        """The notebook view: a table of the parameters."""
        return display.fit_html(self)

    def to_dataframe(self) -> Any:
        """The parameters as a pandas DataFrame, one row each (fixed ones included), columns
        ``parameter``, ``value`` [SI], ``se`` [SI], ``unit``, ``free``, ``lower``, ``upper`` [SI],
        ``identifiable``. Needs pandas (``pip install skinkit[table]``)."""
        return display.fit_frame(self)

    def to_dict(self) -> dict[str, Any]:
        """The fit result as a JSON-ready dict."""
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
            **_se_reasons(self.se),
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
        """The fit result of :meth:`to_dict`'s dict."""
        d = dict(d)
        d["parameters"] = ParameterSet.from_list(d["parameters"])
        reasons = d.pop("se_reason", None) or {}
        if reasons and d.get("se") is not None:
            # a standard error written as null because it is infinite comes back infinite
            back = {SE_UNDETERMINED: math.inf, SE_NOT_A_NUMBER: math.nan}
            d["se"] = {k: (back.get(reasons.get(k), v) if v is None else v) for k, v in d["se"].items()}
        return cls(**d)


#: why a standard error is written as null (strict JSON has no infinity)
SE_UNDETERMINED = "undetermined: the data do not move this parameter (infinite standard error)"
SE_NOT_A_NUMBER = "not computed (not a number)"


def _se_reasons(se: dict[str, Any] | None) -> dict[str, Any]:
    """``{"se_reason": {name: reason}}`` for the standard errors that are not finite numbers
    (written as null); empty when every one is finite."""
    bad = {k: SE_NOT_A_NUMBER if math.isnan(float(v)) else SE_UNDETERMINED for k, v in (se or {}).items()
           if isinstance(v, (float, np.floating)) and not math.isfinite(float(v))}
    return {"se_reason": bad} if bad else {}


def _finite_or_none(x: Any) -> Any:
    """JSON-safe copies: NaN and infinities become None, arrays lists, in nested containers."""
    if isinstance(x, dict):
        return {str(k): _finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite_or_none(v) for v in x]
    if isinstance(x, np.ndarray):
        return _finite_or_none(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def _fraction(value: Any, field: str) -> float | None:
    """A shrinkage: a fraction of the excess residual removed (None when there was no excess).
    It may be negative (a model that fits worse) but never above 1 + rounding."""
    if value is None:
        return None
    x = as_float(value, field, "1", allow_nan=True)
    if math.isnan(x):
        return None
    if x > 1 + 1e-9:
        raise SchemaError(field, f"a fraction of the excess removed cannot exceed 1, got {x:g}")
    return x


@dataclass
class EffectScore:
    """One candidate effect of a gap diagnosis: its score test at the null, and its refit.

    Attributes:
        effect: the effect plugin's name.
        score: the Lagrange-multiplier (score) statistic [1]: the part of the noise-normalised
            residual's Σz² the effect's signature explains to first order, with the fitted
            parameters' directions projected out.
        p_value: its upper-tail probability (χ² with ``dof``), before the many-effects correction.
        dof: degrees of freedom of the test (the rank of the projected signature).
        refitted: whether the model was refitted with the effect added.
        delta_aic: AIC(with the effect) − AIC(without) [1] after the refit, or None.
        shrinkage: fraction of the excess residual (χ² − dof) the refit removed, or None.
        parameters: the effect's identified parameters ``{name: {"value", "se"}}`` [SI], or None.
        not_separable_from: effects leaving nearly the same signature on these protocols.
        extra: further JSON-ready facts (how the sensitivity was obtained, parameters held at
            their null, the admissible direction, held-out χ², ...).
    """

    effect: str
    score: float
    p_value: float
    dof: int = 0
    refitted: bool = False
    delta_aic: float | None = None
    shrinkage: float | None = None
    parameters: dict[str, dict[str, float]] | None = None
    not_separable_from: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        f = f"EffectScore[{self.effect!r}]"
        self.score = as_float(self.score, f"{f}.score", "1", lo=0)
        self.p_value = as_float(self.p_value, f"{f}.p_value", "1", lo=0, hi=1)
        if int(self.dof) < 0:
            raise SchemaError(f"{f}.dof", "must be >= 0")
        self.dof = int(self.dof)
        if self.delta_aic is not None:
            self.delta_aic = as_float(self.delta_aic, f"{f}.delta_aic", "1", allow_nan=True)
        self.shrinkage = _fraction(self.shrinkage, f"{f}.shrinkage")
        if self.parameters is not None:
            for name, v in self.parameters.items():
                if not isinstance(v, dict) or "value" not in v or "se" not in v:
                    raise SchemaError(f"{f}.parameters[{name!r}]", "must be {'value': ..., 'se': ...}")
        self.not_separable_from = [str(e) for e in self.not_separable_from]

    def to_dict(self) -> dict[str, Any]:
        """The candidate as a JSON-ready dict (non-finite numbers as None, ``extra`` merged in)."""
        return _finite_or_none({
            "effect": self.effect, "score": self.score, "p_value": self.p_value, "dof": self.dof,
            "refitted": self.refitted, "delta_aic": self.delta_aic, "shrinkage": self.shrinkage,
            "parameters": self.parameters, "not_separable_from": list(self.not_separable_from),
            **self.extra})

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EffectScore:
        """The candidate of :meth:`to_dict`'s dict (unknown keys into ``extra``)."""
        d = dict(d)
        known = {k: d.pop(k) for k in ("effect", "score", "p_value", "dof", "refitted", "delta_aic",
                                       "shrinkage", "parameters", "not_separable_from") if k in d}
        return cls(**known, extra=d)


#: the keys of a gap report's JSON form that other tools consume (others may be added)
GAP_KEYS = ("model", "session", "fit", "gap", "candidates", "named", "shrinkage")


@dataclass
class GapReport:
    """Where a calibrated model misses a session, which unmodelled effect explains it, how far
    the gap shrinks once that effect is added. Every residual is noise-normalised
    (each sample over its channel's noise), so force, motion and surface channels are
    commensurate and χ²/ν = 1 is the noise level.

    Attributes:
        model: the calibrated model's name.
        session: where the observations came from.
        fit: the calibration: ``parameters`` (free name -> SI value), ``chi2_per_dof``,
            ``n_forward``, and more (``se``, ``aic``, ``held_out``, ...).
        gap: step 1: ``significant``, ``chi2_per_dof`` and ``cells`` (per axis and label:
            ``share`` of the excess, ``chi2_per_dof``, ``p_value``, ``significant``), and
            optionally ``whiteness``, ``cross_correlation``, ``point_map``.
        candidates: every candidate effect of the first round, ranked by its score test.
        named: the effects named, in the order they were named (empty: none).
        shrinkage: ``overall`` and ``held_out`` fractions of the excess residual removed by the
            named effects, and ``cells`` (``axis``, ``label``, ``before``, ``after`` χ²/ν).
        extra: further JSON-ready keys at the top level of :meth:`to_dict` (``points``,
            ``point_map_after``, ``separation``, ``rounds``, ``messages``, ...).
    """

    model: str
    session: str = ""
    fit: dict[str, Any] = field(default_factory=dict)
    gap: dict[str, Any] = field(default_factory=dict)
    candidates: list[EffectScore] = field(default_factory=list)
    named: list[str] = field(default_factory=list)
    shrinkage: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for c in self.candidates:
            if not isinstance(c, EffectScore):
                raise SchemaError("GapReport.candidates", f"must be EffectScore, got {type(c).__name__}")
        known = {c.effect for c in self.candidates} | {e for r in self.extra.get("rounds", [])
                                                        for e in _round_effects(r)}
        for e in self.named:
            if e not in known:
                raise SchemaError("GapReport.named", f"effect {e!r} is not among the candidates")
        if "chi2_per_dof" in self.fit and self.fit["chi2_per_dof"] is not None:
            as_float(self.fit["chi2_per_dof"], "GapReport.fit.chi2_per_dof", "1", lo=0, allow_nan=True)
        if "chi2_per_dof" in self.gap and self.gap["chi2_per_dof"] is not None:
            as_float(self.gap["chi2_per_dof"], "GapReport.gap.chi2_per_dof", "1", lo=0, allow_nan=True)
        for key in ("overall", "held_out"):
            if key in self.shrinkage:
                self.shrinkage[key] = _fraction(self.shrinkage[key], f"GapReport.shrinkage.{key}")
        clash = sorted(set(self.extra) & set(GAP_KEYS))
        if clash:
            raise SchemaError("GapReport.extra", f"must not repeat the report's own keys {clash}")

    @property
    def best(self) -> EffectScore | None:
        """The candidate ranked first by its score test (None when none was tested)."""
        return self.candidates[0] if self.candidates else None

    @property
    def significant(self) -> bool:
        """Whether the calibrated model's residual is above the noise (step 1)."""
        return bool(self.gap.get("significant", False))

    def __repr__(self) -> str:
        """A few lines: the calibration, where the gap is, the effects named and the best
        candidates (never the arrays; :meth:`to_dict` has everything)."""
        return "\n".join(display_gap.gap_lines(self))

    def _repr_html_(self) -> str:
        """The notebook view: a table of the candidates, the verdict in words below."""
        return display_gap.gap_html(self)

    def to_dataframe(self, table: str = "candidates") -> Any:
        """A pandas DataFrame of the ``"candidates"`` (one row per candidate effect, ranked by
        its score test: ``effect``, ``named``, ``role``, ``score``, ``dof``, ``p_value``,
        ``significant``, ``refitted``, ``delta_aic``, ``shrinkage``, ``parameters``) or of the
        residual's ``"cells"`` (one row per protocol, channel, phase, frequency band, ...:
        ``axis``, ``label``, ``share`` of the excess, ``chi2_per_dof``, ``p_value``,
        ``significant``, ``chi2``, ``dof``, ``n`` samples, ``chi2_per_dof_after``). Needs pandas
        (``pip install skinkit[table]``)."""
        return display_gap.gap_frame(self, table)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (``skinkit gap diagnose --json``): the pinned keys of :data:`GAP_KEYS`,
        then ``extra``; NaN and infinities as null."""
        return _finite_or_none({
            "model": self.model, "session": self.session, "fit": self.fit, "gap": self.gap,
            "candidates": [c.to_dict() for c in self.candidates], "named": list(self.named),
            "shrinkage": self.shrinkage, **self.extra})

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GapReport:
        """The report of :meth:`to_dict`'s dict (unknown keys into ``extra``)."""
        d = dict(d)
        core = {k: d.pop(k) for k in GAP_KEYS if k in d}
        core["candidates"] = [EffectScore.from_dict(c) for c in core.get("candidates", [])]
        return cls(**core, extra=d)


def _round_effects(r: Any) -> list[str]:
    if not isinstance(r, dict):
        return []
    return [str(c.get("effect")) for c in r.get("candidates", []) if isinstance(c, dict)]
