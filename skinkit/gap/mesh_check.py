"""The finite-element diagnosis's discretisation check: the calibrated model's mesh error in the
score step's residual space, and the candidates that explain only what a finer mesh would.

When a candidate's score test is significant and the mesh's error is not carried as noise, the
calibrated model is solved once on a mesh with every element count doubled
(:func:`skinkit.inverse.discretisation.error_in_residual`); the difference to the coarse
prediction, whitened as the residual, is a direction whose size rests on an assumed convergence
order but whose shape does not, so it is projected out at any size (:func:`mesh_only`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.gap.score import ScoreTest, corrected
from skinkit.schemas import Observations, Prediction


def discretisation(model: Any, observations: Observations, values: Mapping[str, float], coarse: Prediction,
                   sens: Any, alpha: float, say: Callable[[str], None]) -> dict[str, Any] | None:
    """The calibrated model's discretisation error in the score step's residual space (``e``,
    exact − coarse, whitened) with the residual figures of
    :func:`skinkit.inverse.discretisation.residual_check`; None (said) when it cannot be made."""
    from skinkit.inverse.discretisation import error_in_residual, residual_check
    try:
        e, summary, _ = error_in_residual(model, observations, dict(values), coarse, progress=say)
    except SkinkitError as exc:
        say(f"discretisation check not made: {exc}")
        return None
    if e.size != sens.z.size:
        say("discretisation check not made: its residual does not match the score step's")
        return None
    chk = residual_check(sens.z, sens.J_theta, e)
    return {**summary, **{k: v for k, v in chk.items() if k != "bias"}, "e": e, "explains": []}


def mesh_only(disc: Mapping[str, Any] | None, sens: Any, tests: Sequence[ScoreTest], ok: Mapping[str, bool],
              alpha: float, adjust: Callable[[list[ScoreTest]], list[ScoreTest]] | None = None) -> list[str]:
    """The candidates significant on the residual but no longer once the discretisation error's
    signature ``e`` is projected out beside the fitted parameters' (at any size: the estimate's
    size rests on an assumed order, its shape does not): what they would explain, a finer mesh
    would explain too. ``adjust``: what the score step does to its tests' p-values (a region
    scan's adjustment, :mod:`skinkit.gap.scan_step`), done to these tests too."""
    if disc is None or not np.any(disc["e"]):
        return []
    from skinkit.gap.score import score_all
    exact = score_all(sens, nuisance=disc["e"][:, None])
    ok_exact = corrected(adjust(exact) if adjust is not None else exact, alpha)
    return [t.effect for t in tests if ok[t.effect] and not ok_exact.get(t.effect, False)]


__all__ = ["discretisation", "mesh_only"]
