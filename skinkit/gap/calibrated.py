"""The diagnosed model as a model file: ``model.toml`` beside ``gap.json``.

The final model of a diagnosis is the input model with the effects it added (``[[effects]]``
tables) and every calibrated parameter — the model's own and the added effects' — at the values
of the last refit. :func:`write_model` writes it with :func:`skinkit.inverse.calibrated.write_calibrated`,
so it loads and predicts like any model file, and its ``[calibration]`` table records the
session, the objective (the noise-weighted residual every fit of the diagnosis minimises) and
each parameter's 95 % interval.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from skinkit.inverse.calibrated import write_calibrated
from skinkit.schemas import GapReport


def write_model(report: GapReport, model: str | os.PathLike[str] | Mapping[str, Any],
                out_dir: str | os.PathLike[str], *, workers: int | None = 1) -> Path:
    """Write ``out_dir/model.toml``: ``model`` (the model file or description that was diagnosed,
    as given to :func:`skinkit.gap.diagnose.diagnose`) with ``report``'s added effects and final
    parameter values [SI]. Returns the path."""
    from skinkit.forward import load, read_description

    ex = report.extra
    values = {str(k): float(v) for k, v in dict(ex.get("final_parameters") or {}).items()}
    se = {str(k): (None if v is None else float(v)) for k, v in dict(ex.get("final_se") or {}).items()}
    chi2 = dict(ex.get("chi2") or {})
    dof = chi2.get("dof_after")
    notes = {"chi2_per_dof": chi2["after"] / dof if dof else None,
             "effects_added": [str(t.get("instance", t.get("name"))) for t in ex.get("effects_model") or []],
             "causes": [str(n) for n in report.named]}
    model_file = None if isinstance(model, Mapping) else model
    return write_calibrated(out_dir, read_description(model), values, se, session=report.session,
                            objective="noise", command="skinkit gap diagnose",
                            effects=list(ex.get("effects_model") or []), model_file=model_file, notes=notes,
                            loader=lambda s: load(s, workers=workers))


__all__ = ["write_model"]
