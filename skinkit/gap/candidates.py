"""A candidate effect's record in a round, whether its refit qualifies it to be named, and whether
a candidate is worth refitting at all once another has qualified (the screen)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.gap.score import ScoreTest
from skinkit.schemas import EffectScore, FitResult

#: an effect is named only if its refit lowers the AIC by more than this (:mod:`skinkit.gap.diagnose`)
AIC_MARGIN = 10.0
#: held-out χ² allowance per added parameter (:mod:`skinkit.gap.diagnose`)
HELD_OUT_ALLOWANCE = 2.0
#: a candidate is refitted after a qualifying refit of its round only if a drop of Σz² this many
#: times its score statistic (the first-order drop its refit brings) could lower the AIC below that refit's:
#: otherwise it could not win the round. A full refit removed 0.97x (tracking bias), 1.14x (an
#: inclusion at its scanned region) and 2.0x (pre-stress, nonlinear) its score on the virtual
#: forearm; 4 keeps that margin twice over.
SCREEN_FACTOR = 4.0


def fraction(before: float, after: float) -> float | None:
    """Fraction of the excess ``before`` removed (None when there was no excess)."""
    return None if before <= 0 else float(min((before - after) / before, 1.0))


def candidate_record(test: ScoreTest, survives: bool, state: dict[str, Any] | None,
                     base: dict[str, Any]) -> EffectScore:
    """The record of candidate ``test`` (its score test; ``survives``: after the correction) and,
    when refitted, of its refit ``state`` against the model ``base`` it would join."""
    extra = test.record()
    extra["significant"] = survives
    if state is None:
        return EffectScore(test.effect, test.statistic, test.p_value, test.dof, extra=extra)
    r: FitResult = state["result"]
    pars = {}
    for n in state["added"]:
        se = r.se.get(n)
        se = float(se) if se is not None and np.isfinite(se) else None
        v = float(r.parameters[n])
        pars[n] = {"value": v, "se": se, "unit": r.parameters.param(n).unit,
                   "interval": None if se is None else [v - 1.96 * se, v + 1.96 * se]}
    d_aic = float(r.aic - base["result"].aic)
    extra.update({"chi2_per_dof": state["chi2"] / state["dof"], "chi2_refit": state["chi2"],
                  "held_out_chi2": state["held_chi2"],
                  "held_out_chi2_before": base["held_chi2"], "converged": r.converged,
                  "n_forward": r.n_forward})
    shrink = fraction(base["chi2"] - base["dof"], state["chi2"] - state["dof"])
    return EffectScore(test.effect, test.statistic, test.p_value, test.dof, refitted=True, delta_aic=d_aic,
                       shrinkage=shrink, parameters=pars, extra=extra)


def qualifies(c: EffectScore, state: dict[str, Any], base: dict[str, Any]) -> tuple[bool, str]:
    """Whether refitted candidate ``c`` (its refit ``state``) may be named over ``base``, and why not."""
    if not c.extra.get("significant"):
        return False, "its score test does not survive the correction"
    if c.delta_aic is None or not c.delta_aic < -AIC_MARGIN:
        return False, f"its refit does not lower the AIC by more than {AIC_MARGIN:g} (ΔAIC {c.delta_aic:.1f})"
    if base["held_n"]:
        allowed = base["held_chi2"] + HELD_OUT_ALLOWANCE * len(state["added"])
        if state["held_chi2"] > allowed:
            return False, f"it worsens the held-out χ² ({base['held_chi2']:.1f} -> {state['held_chi2']:.1f})"
    return True, ""


def best_qualifying(states: Mapping[str, dict[str, Any]], top: Sequence[ScoreTest], base: dict[str, Any]
                    ) -> tuple[str, float] | None:
    """The refitted candidate of ``states`` that qualifies with the lowest ΔAIC: ``(effect, ΔAIC)``."""
    out = None
    for t in top:
        if t.effect in states:
            c = candidate_record(t, True, states[t.effect], base)
            if qualifies(c, states[t.effect], base)[0] and (out is None or c.delta_aic < out[1]):
                out = (t.effect, float(c.delta_aic))
    return out


def best_case_aic(test: ScoreTest, chi2: float, n: int) -> float | None:
    """The lowest AIC change [1] a refit of ``test``'s candidate could bring to a fit of Σz²
    ``chi2`` over ``n`` observations, were its drop :data:`SCREEN_FACTOR` times its score
    statistic (AIC = n ln(Σz²/n) + 2(k + 1), :func:`skinkit.inverse.fit.aic`); None when that
    drop would take Σz² to zero."""
    drop = SCREEN_FACTOR * test.statistic
    if not (chi2 > drop and n > 0):
        return None
    return n * math.log((chi2 - drop) / chi2) + 2 * len(test.tested)


def screened(test: ScoreTest, best: tuple[str, float] | None, fit: FitResult) -> str | None:
    """Why ``test``'s candidate is not worth refitting after the qualifying refit ``best``
    (``(effect, ΔAIC)``, :func:`best_qualifying`) of the model fitted as ``fit``, or None when
    its refit could still win."""
    chi2, n = fit.extra.get("chi2"), fit.extra.get("n_observations")
    could = None if best is None or chi2 is None or n is None else best_case_aic(test, float(chi2), int(n))
    if could is None or could < best[1]:
        return None
    return (f"not refitted: {SCREEN_FACTOR:g}x its score ({test.statistic:.4g}) would change the AIC by "
            f"{could:.1f} at best, not below the refit with {best[0]} (ΔAIC {best[1]:.1f}), so it could "
            "not be named instead")


def refit_order(top: Sequence[ScoreTest], fit: FitResult) -> list[ScoreTest]:
    """``top`` in the order to refit them: the largest AIC drop a refit could bring first
    (:func:`best_case_aic`), so that the screen (:func:`screened`) can spare the others' refits;
    the given order where the fit's χ² is not known. The order of refits does not change the
    round's verdict: a screened candidate could not have been named."""
    chi2, n = fit.extra.get("chi2"), fit.extra.get("n_observations")
    if chi2 is None or n is None:
        return list(top)

    def could(t: ScoreTest) -> float:
        v = best_case_aic(t, float(chi2), int(n))
        return -math.inf if v is None else v
    return sorted(top, key=could)


__all__ = ["AIC_MARGIN", "HELD_OUT_ALLOWANCE", "SCREEN_FACTOR", "best_case_aic", "best_qualifying",
           "candidate_record", "fraction", "qualifies", "refit_order", "screened"]
