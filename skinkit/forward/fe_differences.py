"""Derivatives of a finite-element model's parameters that no analytic route covers, by
differences of whole solves (:meth:`skinkit.forward.fe.FEForwardModel.predict`)."""

from __future__ import annotations

import math
from typing import Any

from skinkit.errors import ForwardError
from skinkit.forward import stages
from skinkit.schemas import Observations, ParameterSet, Prediction


def central_differences(model: Any, params: ParameterSet, observations: Observations, pred: Prediction,
                         names: list[str]) -> None:
    """Derivatives of the parameters no analytic route covers, by differences of whole
    solves: central with a step of 1e-5 of the parameter's scale, or, at a bound, the
    second-order one-sided formula (−3 f₀ + 4 f₁ − f₂)/(2h) into the admissible range."""
    def part(i: int, j: int) -> Any:   # the j-th of parameter i's two solves, as progress
        return stages.portion((2 * i + j) / (2 * len(names)), (2 * i + j + 1) / (2 * len(names)))

    for i, nm in enumerate(names):
        p = params.param(nm)
        scale = abs(p.value) if p.value != 0 else (
            0.01 * (p.upper - p.lower) if math.isfinite(p.upper - p.lower) else 1.0)
        h = 1e-5 * max(scale, 1e-12)
        if p.value - h >= p.lower and p.value + h <= p.upper:
            with part(i, 0):
                up = model.predict(params.with_values({nm: p.value + h}), observations)
            with part(i, 1):
                dn = model.predict(params.with_values({nm: p.value - h}), observations)
            for proto, chans in pred.protocols.items():
                for cname, cp in chans.items():
                    diff = up.protocols[proto][cname].values - dn.protocols[proto][cname].values
                    cp.d[nm] = diff / (2 * h)
            continue
        sgn = 1.0 if p.value - h < p.lower else -1.0
        if not (p.lower <= p.value + 2 * sgn * h <= p.upper):
            raise ForwardError(nm, "cannot be differentiated: its bounds leave no room for a step")
        with part(i, 0):
            f1 = model.predict(params.with_values({nm: p.value + sgn * h}), observations)
        with part(i, 1):
            f2 = model.predict(params.with_values({nm: p.value + 2 * sgn * h}), observations)
        for proto, chans in pred.protocols.items():
            for cname, cp in chans.items():
                a, b = f1.protocols[proto][cname].values, f2.protocols[proto][cname].values
                cp.d[nm] = sgn * (-3 * cp.values + 4 * a - b) / (2 * h)


__all__ = ["central_differences"]
