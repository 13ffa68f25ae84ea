"""The final model's parameters with the model's discretisation error estimated where they are.

A diagnosis that carries a finite-element model's discretisation error
(:mod:`skinkit.inverse.approximation`) estimates it once, at the calibration of the model as
given. When that model lacks what the data hold (the reason for diagnosing), its calibration sits
far from where the final model's does — on the virtual forearm the calibration without
pre-stress drives the fibre modulus k1 from 20 kPa to 12 Pa — and the mesh's error there is not
the final model's. The verdict's shares compare χ² under that one estimate (before and after an
effect, under the same noise model), so it stays; the final model's parameters and standard
errors, the numbers a user takes away (:mod:`skinkit.gap.calibrated`), are refitted once the
diagnosis has ended, with the error estimated again at the final model
(:func:`skinkit.inverse.approximation.refit`, its default passes). One pass would halve the cost
but does not settle the parameters: on the virtual forearm the second pass moves c, g1 and the
pre-stress angle by 5–11 of their standard errors.

Where the model's mesh cannot render what a parameter of the final model does — a region
effect smaller than an element or two, whose size and place the coarse mesh only smears — the
estimate says so (``resolution`` above :data:`skinkit.inverse.approximation.RESOLUTION_LIMIT`)
and the verdict warns that the parameter's value and interval are the mesh's. The refits stay on
the model's mesh: moved to the refined one (``member="auto"`` of
:func:`skinkit.inverse.approximation.refit`) on the scar sessions of ``skinkit bench scar``, the
scar's stiffness ratio was not covered more often (a case covered on the model's mesh was missed
on the refined one: ratio 6.3 ± 0.4 against 9.1), at several times the cost.

Cost: per pass, two solves on the model's mesh and two on one refined 2x (one batch), and a
refit of the final model from where it is; a second pass whose parameters stayed near the first
estimate moves it to first order instead of solving again
(:meth:`skinkit.inverse.approximation.ModelError.moved`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from skinkit.errors import SkinkitError
from skinkit.schemas import FitResult, Observations


def refit_final(spec: Mapping[str, Any], observations: Observations, result: FitResult, free: Sequence[str],
                load: Callable[[Mapping[str, Any]], Any], say: Callable[[str], None],
                max_iterations: int, warnings: list[dict[str, Any]] | None = None) -> FitResult | None:
    """``result`` (the final model ``spec``'s fit of ``free``) refitted with the model error
    estimated at it; its ``extra["model_error"]`` holds the estimate's summary. None (said, and a
    ``refit-failed`` warning appended to ``warnings``) when the estimate or the refit fails: the
    diagnosis's own final fit then stands."""
    from skinkit.inverse import fit
    from skinkit.inverse.approximation import refit

    say("final model: its discretisation error estimated again where it is, and refitted")
    model = load(spec)
    try:
        out, _ = refit(model, observations, result, list(free), fit, progress=say,
                       max_iterations=max_iterations)
    except SkinkitError as exc:
        message = f"final model not refitted with its own discretisation error: {exc}"
        say(message)
        if warnings is not None:
            warnings.append({"kind": "refit-failed", "where": "final model", "message": message})
        return None
    finally:
        model.close()
    return out


__all__ = ["refit_final"]
